"""Mightex SLC LED controllers plugged in by USB: the HID side, which benchlab cannot drive.

An SLC's USB port enumerates as a HID device, driven by the vendor's DLL, not as a serial
line; benchlab speaks only the RS232 protocol. When no serial port answers, ``benchlab
doctor`` looks here so it can say "the controller is plugged in by USB" instead of "nothing
found". There is no public list of the SLC's USB product ids, so a controller is recognised
the way independent Linux tools recognise it: by its USB strings, manufacturer "Mightex" and a
product name containing "SLC-". Linux shows those strings to every user in sysfs, so no device
is opened.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

__all__ = ["SYSFS_USB_DEVICES", "UsbSlc", "usb_slcs"]

SYSFS_USB_DEVICES = Path("/sys/bus/usb/devices")


@dataclass(frozen=True)
class UsbSlc:
    """One SLC seen on the USB bus."""

    product: str  # the USB product string, e.g. "SLC-MA04-U"
    serial: str
    vendor_id: int
    product_id: int
    where: str  # the sysfs name: bus-port path, e.g. "1-2.3"

    def describe(self) -> str:
        serial = f" serial {self.serial}" if self.serial else ""
        return (f"{self.product}{serial} (usb {self.where}, "
                f"{self.vendor_id:04x}:{self.product_id:04x})")


def _attribute(device: Path, name: str) -> str:
    try:
        return (device / name).read_text(encoding="utf-8", errors="replace").strip()
    except OSError:  # absent on interfaces and hubs; unreadable: not ours to judge
        return ""


def _hex(text: str) -> int:
    try:
        return int(text, 16)
    except ValueError:
        return 0


def usb_slcs(sysfs: Path | None = None) -> list[UsbSlc]:
    """Every Mightex SLC on the USB bus, in sysfs order; none where there is no sysfs.

    Parameters
    ----------
    sysfs : Path, optional
        The folder of USB devices (default :data:`SYSFS_USB_DEVICES`; a test gives its own).
    """
    try:
        devices = sorted((sysfs or SYSFS_USB_DEVICES).iterdir())
    except OSError:
        return []
    found = []
    for device in devices:
        product = _attribute(device, "product")
        if "SLC-" not in product or "Mightex" not in _attribute(device, "manufacturer"):
            continue
        found.append(UsbSlc(product=product, serial=_attribute(device, "serial"),
                            vendor_id=_hex(_attribute(device, "idVendor")),
                            product_id=_hex(_attribute(device, "idProduct")),
                            where=device.name))
    return found
