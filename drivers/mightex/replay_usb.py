"""A pyusb backend that answers the camera driver with a cassette's recorded bytes.

The camera it presents has the recorded VID/PID and the FX2 descriptors of the simulated
one. Each write must be the next recorded write, each read gets the next recorded read of
its endpoint (a recorded timeout times out again); anything else raises
:class:`~benchlab.drivers.trace.cassette.ReplayDivergedError` naming the exchange. No simulator
runs: the frames are the recorded ones, byte for byte.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import usb.backend

from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.sim_usb import (
    _ENDPOINTS,
    _Configuration,
    _DeviceDescriptor,
    _Endpoint,
    _Interface,
    _timeout,
)
from benchlab.drivers.trace.cassette import Exchange, ReplayDivergedError, show


@dataclass(frozen=True)
class _ReplayDevice:
    vid: int
    pid: int


class ReplayUsbBackend(usb.backend.IBackend):
    """pyusb backend replaying ``exchanges`` (the cassette's camera events, in order)."""

    def __init__(self, exchanges: Sequence[Exchange]) -> None:
        super().__init__()
        self._events = [e for e in exchanges if e.direction != "open"]
        opened = next((e.opened for e in exchanges if e.direction == "open"), None) or {}
        self._device = _ReplayDevice(int(str(opened.get("vid", p.VENDOR_ID))),
                                     int(str(opened.get("pid", p.DEFAULT_PID))))
        self._next = 0

    @property
    def remaining(self) -> int:
        """Recorded camera exchanges not replayed yet."""
        return len(self._events) - self._next

    def sleep(self, seconds: float) -> None:
        """The driver's protocol waits: a recording needs none."""

    def _diverged(self, did: str) -> ReplayDivergedError:
        if self._next >= len(self._events):
            return ReplayDivergedError(
                f"replay diverged after the last recorded camera exchange: {did}, recorded "
                "nothing more")
        e = self._events[self._next]
        return ReplayDivergedError(
            f"replay diverged at exchange {e.n}: {did}, recorded {e.describe()}")

    # ---- enumeration and descriptors ---------------------------------------------------------
    def enumerate_devices(self) -> Iterator[_ReplayDevice]:
        yield self._device

    def get_parent(self, dev: _ReplayDevice) -> None:
        return None

    def get_device_descriptor(self, dev: _ReplayDevice) -> _DeviceDescriptor:
        return _DeviceDescriptor(dev.vid, dev.pid, 1, 2)

    def get_configuration_descriptor(self, dev: _ReplayDevice, config: int) -> _Configuration:
        if config != 0:
            raise IndexError("the camera has one configuration")
        return _Configuration()

    def get_interface_descriptor(self, dev: _ReplayDevice, intf: int, alt: int,
                                 config: int) -> _Interface:
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError("the camera has one interface, one alternate setting")
        return _Interface()

    def get_endpoint_descriptor(self, dev: _ReplayDevice, ep: int, intf: int, alt: int,
                                config: int) -> _Endpoint:
        return _ENDPOINTS[ep]

    def open_device(self, dev: _ReplayDevice) -> _ReplayDevice:
        return dev

    def close_device(self, dev_handle: _ReplayDevice) -> None:
        pass

    def set_configuration(self, dev_handle: _ReplayDevice, config_value: int) -> None:
        pass

    def get_configuration(self, dev_handle: _ReplayDevice) -> int:
        return 1

    def set_interface_altsetting(self, dev_handle: _ReplayDevice, intf: int,
                                 altsetting: int) -> None:
        pass

    def claim_interface(self, dev_handle: _ReplayDevice, intf: int) -> None:
        pass

    def release_interface(self, dev_handle: _ReplayDevice, intf: int) -> None:
        pass

    def is_kernel_driver_active(self, dev_handle: _ReplayDevice, intf: int) -> bool:
        return False

    def detach_kernel_driver(self, dev_handle: _ReplayDevice, intf: int) -> None:
        pass

    def attach_kernel_driver(self, dev_handle: _ReplayDevice, intf: int) -> None:
        pass

    # ---- transfers ---------------------------------------------------------------------------
    def bulk_write(self, dev_handle: _ReplayDevice, ep: int, intf: int, data: Any,
                   timeout: int) -> int:
        sent = bytes(data)
        e = self._events[self._next] if self._next < len(self._events) else None
        if e is None or e.direction != ">" or e.ep != ep or e.data != sent:
            raise self._diverged(f"sent {show(sent)}")
        self._next += 1
        return len(sent)

    def bulk_read(self, dev_handle: _ReplayDevice, ep: int, intf: int, buff: Any,
                  timeout: int) -> int:
        e = self._events[self._next] if self._next < len(self._events) else None
        if e is None or e.direction != "<" or e.ep != ep:
            raise self._diverged(f"read EP 0x{ep:02X}")
        self._next += 1
        if e.timeout:
            raise _timeout(f"EP 0x{ep:02X} (recorded)")
        out = memoryview(buff).cast("B")
        if len(e.data) > len(out):
            raise self._diverged(f"read {len(out)} bytes from EP 0x{ep:02X} "
                                 f"({len(e.data)} recorded)")
        out[: len(e.data)] = e.data
        return len(e.data)

    def ctrl_transfer(self, dev_handle: _ReplayDevice, bmRequestType: int, bRequest: int,
                      wValue: int, wIndex: int, data: Any, timeout: int) -> int:
        return 0
