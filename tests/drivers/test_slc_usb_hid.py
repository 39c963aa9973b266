"""Finding SLCs plugged in by USB (HID) in a folder laid out like /sys/bus/usb/devices: by
their USB strings (manufacturer "Mightex", product "SLC-..."), never by opening a device."""

from __future__ import annotations

from pathlib import Path

from benchlab.drivers.slc.usb_hid import UsbSlc, usb_slcs


def _device(root: Path, name: str, **attributes: str) -> None:
    (root / name).mkdir(parents=True)
    for key, value in attributes.items():
        (root / name / key).write_text(value + "\n")


def test_only_mightex_slcs_are_found_in_bus_order(tmp_path: Path) -> None:
    _device(tmp_path, "usb1", manufacturer="Linux xhci-hcd", product="xHCI Host Controller")
    _device(tmp_path, "1-3", manufacturer="Mightex", product="SLC-SA04-U", serial="04-1",
            idVendor="abcd", idProduct="00ef")
    _device(tmp_path, "1-1.4", manufacturer="Mightex Systems", product="SLC-MA02-U",
            idVendor="1234", idProduct="5678")  # no serial string
    _device(tmp_path, "1-3:1.0", bInterfaceClass="03")  # an interface: no strings
    _device(tmp_path, "1-4", manufacturer="Mightex", product="USB-BUF-CCD-1")  # a camera
    _device(tmp_path, "1-5", manufacturer="Other Ltd", product="SLC-1000 scale")
    found = usb_slcs(tmp_path)
    assert found == [
        UsbSlc("SLC-MA02-U", "", 0x1234, 0x5678, "1-1.4"),
        UsbSlc("SLC-SA04-U", "04-1", 0xABCD, 0x00EF, "1-3"),
    ]
    assert found[1].describe() == "SLC-SA04-U serial 04-1 (usb 1-3, abcd:00ef)"
    assert found[0].describe() == "SLC-MA02-U (usb 1-1.4, 1234:5678)"


def test_no_sysfs_and_odd_entries_find_nothing_without_raising(tmp_path: Path) -> None:
    assert usb_slcs(tmp_path / "absent") == []
    (tmp_path / "file").write_text("not a folder of devices")
    assert usb_slcs(tmp_path / "file") == []
    _device(tmp_path / "bus", "1-1", manufacturer="Mightex", idVendor="zz")
    (tmp_path / "bus" / "1-1" / "product").mkdir()  # unreadable as a file
    _device(tmp_path / "bus", "1-2", manufacturer="Mightex", product="SLC-X", idVendor="zz",
            idProduct="")
    assert usb_slcs(tmp_path / "bus") == [UsbSlc("SLC-X", "", 0, 0, "1-2")]
