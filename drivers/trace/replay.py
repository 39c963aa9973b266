"""Replaying a cassette (``benchlab --replay FILE``): the drivers talk to recorded devices.

:func:`start` loads the cassette; from then on a camera opened without a backend gets a
:class:`~benchlab.drivers.mightex.replay_usb.ReplayUsbBackend`, and a serial device opened
by :func:`~benchlab.drivers.serial_port.open_serial` gets a :class:`ReplaySerialDevice` - a
pseudo-terminal that answers each recorded write with the reads recorded after it. A driver
that sends anything else gets "replay diverged at exchange N: sent X, recorded Y": from the
USB backend as an exception, from a serial device as a dropped line whose reason
:func:`divergence` returns (the CLI prints it).

APT keep-alives (0x0492) go out on the host's timer, at no fixed place in a sequence: they
are left out of the comparison on both sides.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from benchlab.drivers.simulation.pty_device import PtyDevice
from benchlab.drivers.trace.cassette import Exchange, ReplayDivergedError, load, show

_APT_KEEPALIVE = bytes.fromhex("92 04 00 00 50 01")

_exchanges: list[Exchange] | None = None
_serial_devices: dict[str, ReplaySerialDevice] = {}
_usb_backend: Any = None


class ReplaySerialDevice(PtyDevice):
    """One serial device of a cassette, served on a pseudo-terminal."""

    name = "replay"

    def __init__(self, device: str, exchanges: list[Exchange]) -> None:
        super().__init__()
        self.device = device
        self._events = [e for e in exchanges if e.direction in (">", "<") and not e.timeout
                        and e.data != _APT_KEEPALIVE]
        self._next = 0
        self._pending = b""
        self.diverged: str | None = None

    def on_tick(self, now_s: float) -> None:
        pass

    def _answer(self) -> None:
        """Send every recorded read up to the next recorded write."""
        while self._next < len(self._events) and self._events[self._next].direction == "<":
            self.write(self._events[self._next].data)
            self._next += 1

    def on_bytes(self, data: bytes) -> None:
        if self.diverged is not None:
            return
        self._pending += data.replace(_APT_KEEPALIVE, b"")
        while self._pending:
            self._answer()
            if self._next >= len(self._events):
                self._fail(f"sent {show(self._pending)}, recorded nothing more", None)
                return
            e = self._events[self._next]
            if self._pending.startswith(e.data):
                self._pending = self._pending[len(e.data):]
                self._next += 1
                self._answer()
            elif not e.data.startswith(self._pending):
                self._fail(f"sent {show(self._pending)}", e)
                return
            else:
                return  # the rest of this write is on its way

    def _fail(self, did: str, e: Exchange | None) -> None:
        where = f"at exchange {e.n}" if e is not None else f"on {self.device}"
        self.diverged = (f"replay diverged {where}: {did}"
                         + (f", recorded {e.describe()}" if e is not None else ""))
        self.drop_connection()


def start(path: str | Path) -> None:
    """Replay ``path`` for every device opened from now on (until :func:`stop`)."""
    global _exchanges
    stop()
    _exchanges = load(path)


def stop() -> None:
    global _exchanges, _usb_backend
    for dev in _serial_devices.values():
        dev.stop()
    _serial_devices.clear()
    _exchanges, _usb_backend = None, None


def active() -> bool:
    return _exchanges is not None


def usb_backend() -> Any:
    """The replaying pyusb backend (None when no cassette is replayed)."""
    global _usb_backend
    if _exchanges is None:
        return None
    if _usb_backend is None:
        from benchlab.drivers.mightex.replay_usb import ReplayUsbBackend

        _usb_backend = ReplayUsbBackend([e for e in _exchanges if e.device == "camera"])
    return _usb_backend


def serial_port_for(device: str, url: str) -> str:
    """The port to open for ``device``: ``url``, or the replaying pseudo-terminal."""
    if _exchanges is None:
        return url
    dev = _serial_devices.get(device)
    if dev is None:
        mine = [e for e in _exchanges if e.device == device]
        if not mine:
            raise ReplayDivergedError(
                f"replay diverged: the cassette has no {device} exchanges, but the {device} "
                f"was opened ({url})")
        dev = ReplaySerialDevice(device, mine)
        dev.start()
        _serial_devices[device] = dev
    return dev.port


def divergence() -> str | None:
    """Why a replayed serial device dropped the line, if it did."""
    for dev in _serial_devices.values():
        if dev.diverged is not None:
            return dev.diverged
    return None


def divergence_behind(exc: BaseException) -> str | None:
    """While a cassette is replayed: the divergence that ``exc`` is a consequence of - a
    serial device that dropped the line, or a :class:`ReplayDivergedError` among its causes
    (a step failure wraps it) - else None. What goes wrong after a divergence says nothing
    about the devices or the measurement: the divergence is the one thing to report."""
    if _exchanges is None:
        return None
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, ReplayDivergedError):
            return str(cause)
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return divergence()
