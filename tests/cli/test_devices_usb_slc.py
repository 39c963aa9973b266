"""``benchlab devices`` on a machine with an SLC plugged in by USB (HID): listed as an LED
controller with the reason benchlab cannot drive it (the USB bus is a folder laid out like
/sys/bus/usb/devices; no serial port is present)."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchlab.cli.devices.serial import list_serial_devices
from benchlab.cli.main import main


@pytest.fixture
def usb_bus_with_an_slc(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    device = tmp_path / "3-1"
    device.mkdir()
    for key, value in {"manufacturer": "Mightex", "product": "SLC-SA04-U",
                       "serial": "04-0001", "idVendor": "abcd", "idProduct": "0102"}.items():
        (device / key).write_text(value + "\n")
    monkeypatch.setattr("benchlab.drivers.slc.usb_hid.SYSFS_USB_DEVICES", tmp_path)
    monkeypatch.setattr("serial.tools.list_ports.comports", lambda: [])
    return tmp_path


def test_an_slc_on_usb_is_listed_with_why_it_cannot_be_driven(
    usb_bus_with_an_slc: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert list_serial_devices(simulate=False) == [
        {"kind": "led", "model": "SLC-SA04-U", "serial": "04-0001", "firmware": "",
         "port": "usb 3-1 abcd:0102",
         "error": "USB HID: benchlab drives the SLC over RS232 only"}]
    assert main(["devices"]) == 0
    (line,) = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("led")]
    assert line.split()[:3] == ["led", "SLC-SA04-U", "04-0001"]
    assert line.endswith("usb 3-1 abcd:0102  (USB HID: benchlab drives the SLC over RS232 only)")
