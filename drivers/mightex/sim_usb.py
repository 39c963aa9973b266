"""A pyusb backend (``usb.backend.IBackend``) that puts simulated Mightex cameras on a bus.

Any pyusb client can find and drive them::

    backend = SimCameraBackend([SimulatedCamera()])
    dev = usb.core.find(idVendor=0x04B4, idProduct=0x0428, backend=backend)
    dev.set_configuration(); dev.write(0x01, b"\\x01\\x01\\x01"); dev.read(0x81, 255)

Descriptors follow the FX2 camera: one configuration, interface 0 with bulk endpoints 0x01
(commands), 0x81 (replies), 0x82 (frames), 512-byte packets (USB 2.0 high speed). Transfers
never wait: an empty endpoint raises pyusb's timeout error at once, a camera that was unplugged
raises ``USBError`` with ``errno.ENODEV`` like libusb's "no such device".
"""

from __future__ import annotations

import errno
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import usb.backend
import usb.core

from benchlab.drivers.mightex import protocol as p

if TYPE_CHECKING:
    from benchlab.drivers.mightex.sim import SimulatedCamera

_LIBUSB_TIMEOUT = -7
_LIBUSB_NO_DEVICE = -4
_LIBUSB_INVALID = -2
_STRING_MANUFACTURER, _STRING_PRODUCT, _STRING_SERIAL = 1, 2, 3


class DeviceUnplugged(Exception):
    """The simulated camera is not on the bus (raised by the firmware, mapped to ENODEV)."""


@dataclass
class _Endpoint:
    bEndpointAddress: int
    bLength: int = 7
    bDescriptorType: int = 0x05
    bmAttributes: int = 0x02  # bulk
    wMaxPacketSize: int = 512
    bInterval: int = 0
    bRefresh: int = 0
    bSynchAddress: int = 0
    extra_descriptors: list[int] = field(default_factory=list)


@dataclass
class _Interface:
    bLength: int = 9
    bDescriptorType: int = 0x04
    bInterfaceNumber: int = 0
    bAlternateSetting: int = 0
    bNumEndpoints: int = 3
    bInterfaceClass: int = 0xFF  # vendor specific
    bInterfaceSubClass: int = 0
    bInterfaceProtocol: int = 0
    iInterface: int = 0
    extra_descriptors: list[int] = field(default_factory=list)


@dataclass
class _Configuration:
    bLength: int = 9
    bDescriptorType: int = 0x02
    wTotalLength: int = 9 + 9 + 3 * 7
    bNumInterfaces: int = 1
    bConfigurationValue: int = 1
    iConfiguration: int = 0
    bmAttributes: int = 0x80  # bus powered
    bMaxPower: int = 250  # 500 mA in 2 mA units
    extra_descriptors: list[int] = field(default_factory=list)


@dataclass
class _DeviceDescriptor:
    idVendor: int
    idProduct: int
    bus: int
    address: int
    bLength: int = 18
    bDescriptorType: int = 0x01
    bcdUSB: int = 0x0200
    bDeviceClass: int = 0
    bDeviceSubClass: int = 0
    bDeviceProtocol: int = 0
    bMaxPacketSize0: int = 64
    bcdDevice: int = 0x0000
    iManufacturer: int = _STRING_MANUFACTURER
    iProduct: int = _STRING_PRODUCT
    iSerialNumber: int = _STRING_SERIAL
    bNumConfigurations: int = 1
    port_number: int | None = None
    port_numbers: tuple[int, ...] | None = None
    speed: int | None = 3  # high speed (libusb LIBUSB_SPEED_HIGH)


_ENDPOINTS = (_Endpoint(p.EP_COMMAND_OUT), _Endpoint(p.EP_REPLY_IN), _Endpoint(p.EP_FRAME_IN))


@dataclass(frozen=True)
class _SimDevice:
    """What enumerate_devices yields: one camera in one plug-in 'generation'."""

    camera: SimulatedCamera
    generation: int
    bus: int
    address: int


def _timeout(what: str) -> usb.core.USBTimeoutError:
    return usb.core.USBTimeoutError(f"Operation timed out ({what})", _LIBUSB_TIMEOUT,
                                    errno.ETIMEDOUT)


def _no_device() -> usb.core.USBError:
    return usb.core.USBError("No such device (it may have been disconnected)",
                             _LIBUSB_NO_DEVICE, errno.ENODEV)


class SimCameraBackend(usb.backend.IBackend):
    """pyusb backend presenting ``cameras`` (connected ones only) on bus 1, addresses 2, 3...

    Parameters
    ----------
    cameras : sequence of SimulatedCamera
        Firmware objects; unplugging one removes it from enumeration until it is replugged.
    """

    def __init__(self, cameras: Sequence[SimulatedCamera]) -> None:
        super().__init__()
        self.cameras = list(cameras)
        self._config_value: dict[int, int] = {}

    def sleep(self, seconds: float) -> None:
        """A protocol wait of the driver (after 0x30, while a camera powers up), spent on the
        cameras' own clock: simulated clocks move on at once, wall-clock cameras really wait."""
        waited = False
        for cam in self.cameras:
            advance = getattr(cam.clock, "advance", None)
            if advance is not None:
                advance(seconds)
            elif not waited:
                time.sleep(seconds)
                waited = True

    def now(self) -> float:
        """The host's clock as the cameras see it: the first camera's clock, seconds."""
        return self.cameras[0].clock.now() if self.cameras else time.monotonic()

    # ------------------------------------------------------------------ enumeration

    def enumerate_devices(self) -> Iterator[_SimDevice]:
        for i, cam in enumerate(self.cameras):
            if cam.connected:
                yield _SimDevice(cam, cam.generation, 1, 2 + i)

    def get_parent(self, dev: _SimDevice) -> None:
        return None

    def get_device_descriptor(self, dev: _SimDevice) -> _DeviceDescriptor:
        return _DeviceDescriptor(p.VENDOR_ID, dev.camera.pid, dev.bus, dev.address)

    def get_configuration_descriptor(self, dev: _SimDevice, config: int) -> _Configuration:
        if config != 0:
            raise IndexError("the camera has one configuration")
        return _Configuration()

    def get_interface_descriptor(self, dev: _SimDevice, intf: int, alt: int,
                                 config: int) -> _Interface:
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError("the camera has one interface, one alternate setting")
        return _Interface()

    def get_endpoint_descriptor(self, dev: _SimDevice, ep: int, intf: int, alt: int,
                                config: int) -> _Endpoint:
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError("no such interface")
        return _ENDPOINTS[ep]

    # ------------------------------------------------------------------ handles

    @staticmethod
    def _alive(handle: _SimDevice) -> SimulatedCamera:
        cam = handle.camera
        if not cam.connected or cam.generation != handle.generation:
            raise _no_device()
        return cam

    def open_device(self, dev: _SimDevice) -> _SimDevice:
        self._alive(dev)
        return dev

    def close_device(self, dev_handle: _SimDevice) -> None:
        pass

    def set_configuration(self, dev_handle: _SimDevice, config_value: int) -> None:
        self._alive(dev_handle)
        self._config_value[id(dev_handle.camera)] = config_value

    def get_configuration(self, dev_handle: _SimDevice) -> int:
        self._alive(dev_handle)
        return self._config_value.get(id(dev_handle.camera), 1)

    def set_interface_altsetting(self, dev_handle: _SimDevice, intf: int, altsetting: int) -> None:
        self._alive(dev_handle)

    def claim_interface(self, dev_handle: _SimDevice, intf: int) -> None:
        self._alive(dev_handle)

    def release_interface(self, dev_handle: _SimDevice, intf: int) -> None:
        pass  # releasing a vanished device's interface succeeds silently, like libusb

    def is_kernel_driver_active(self, dev_handle: _SimDevice, intf: int) -> bool:
        return False

    def detach_kernel_driver(self, dev_handle: _SimDevice, intf: int) -> None:
        pass

    def attach_kernel_driver(self, dev_handle: _SimDevice, intf: int) -> None:
        pass

    def clear_halt(self, dev_handle: _SimDevice, ep: int) -> None:
        self._alive(dev_handle)

    def reset_device(self, dev_handle: _SimDevice) -> None:
        self._alive(dev_handle)

    # ------------------------------------------------------------------ transfers

    def bulk_write(self, dev_handle: _SimDevice, ep: int, intf: int, data: Any,
                   timeout: int) -> int:
        cam = self._alive(dev_handle)
        if ep != p.EP_COMMAND_OUT:
            raise usb.core.USBError(f"endpoint 0x{ep:02X} is not an OUT endpoint",
                                    _LIBUSB_INVALID, errno.EINVAL)
        try:
            cam.write_command(bytes(data))
        except DeviceUnplugged:
            raise _no_device() from None
        return len(data)

    def bulk_read(self, dev_handle: _SimDevice, ep: int, intf: int, buff: Any,
                  timeout: int) -> int:
        cam = self._alive(dev_handle)
        out = memoryview(buff).cast("B")
        try:
            if ep == p.EP_REPLY_IN:
                data: bytes | memoryview | None = cam.read_reply(len(out))
            elif ep == p.EP_FRAME_IN:
                data = cam.read_frame_data(len(out))
            else:
                raise usb.core.USBError(f"endpoint 0x{ep:02X} is not an IN endpoint",
                                        _LIBUSB_INVALID, errno.EINVAL)
        except DeviceUnplugged:
            raise _no_device() from None
        if data is None:
            raise _timeout(f"EP 0x{ep:02X}")
        out[: len(data)] = data
        return len(data)

    def ctrl_transfer(self, dev_handle: _SimDevice, bmRequestType: int, bRequest: int,
                      wValue: int, wIndex: int, data: Any, timeout: int) -> int:
        cam = self._alive(dev_handle)
        is_in = bool(bmRequestType & 0x80)
        if is_in and bRequest == 0x06 and wValue >> 8 == 0x03:  # GET_DESCRIPTOR (string)
            index = wValue & 0xFF
            if index == 0:
                body = (0x0409).to_bytes(2, "little")  # English (US)
            else:
                text = {_STRING_MANUFACTURER: "Mightex", _STRING_PRODUCT: cam.model,
                        _STRING_SERIAL: cam.serial}.get(index)
                if text is None:
                    raise usb.core.USBError("Pipe error", -9, errno.EPIPE)
                body = text.encode("utf-16-le")
            desc = bytes((2 + len(body), 0x03)) + body
            out = memoryview(data).cast("B")
            n = min(len(out), len(desc))
            out[:n] = desc[:n]
            return n
        if is_in and bRequest == 0x00:  # GET_STATUS: bus powered, no remote wake-up
            out = memoryview(data).cast("B")
            n = min(len(out), 2)
            out[:n] = b"\x00\x00"[:n]
            return n
        if is_in:
            raise usb.core.USBError("Pipe error", -9, errno.EPIPE)  # request not supported
        return len(data) if data is not None else 0
