"""Opening a serial port, and the errors a serial exchange can raise - once for every driver.

Ports are opened with :func:`serial.serial_for_url`, so besides a device path
(``/dev/ttyUSB0``, ``COM3``) any pyserial URL works, e.g.

- ``hwgrep://0403:6001`` or ``hwgrep://FTXYZ123`` - the first port whose description or
  hardware id (USB VID:PID, USB serial number) matches the regular expression: a stable choice
  when ``/dev/ttyUSB*`` numbers change between boots;
- ``spy:///dev/ttyUSB0?file=trace.txt`` - the real port, with every byte and control line
  change written as a hex dump (to stderr without ``file=``).
"""

from __future__ import annotations

import logging
import threading
from typing import Any

import serial

from benchlab.drivers.trace import io_trace

try:  # pyserial lets termios.error (not an OSError) escape on a hung-up pty/tty
    from termios import error as _TermiosError
except ImportError:  # pragma: no cover - non-POSIX
    _TermiosError = OSError  # type: ignore[misc, assignment]

log = logging.getLogger(__name__)

#: What reading, writing or opening a serial port can raise.
IO_ERRORS = (serial.SerialException, OSError, _TermiosError)


def open_serial(url: str, baudrate: int, *, device: str = "serial",
                **settings: Any) -> serial.Serial:
    """Open ``url`` (a device path or any pyserial URL) at ``baudrate`` with ``settings``
    (``bytesize``, ``parity``, ``stopbits``, ``rtscts``, ``timeout``, ``write_timeout``).

    While a cassette is recorded (:mod:`benchlab.drivers.trace.io_trace`), every byte read or
    written on the port is recorded under ``device``; while one is replayed
    (:mod:`benchlab.drivers.trace.replay`), the port is the replaying pseudo-terminal instead.
    """
    from benchlab.drivers.trace import replay

    url = replay.serial_port_for(device, url)
    port = serial.serial_for_url(url, baudrate, **settings)
    log.debug("%s: opened %s at %d baud", device, url, baudrate)
    if io_trace.active():
        io_trace.opened(device, port=url, baud=baudrate)
        _trace(port, device)
    return port


def _trace(port: serial.Serial, device: str) -> None:
    """Record this port's reads and writes (wraps the instance's methods)."""
    read, write, read_until = port.read, port.write, port.read_until
    inside_read_until = threading.local()

    def traced_read(size: int = 1) -> bytes:
        data: bytes = read(size)
        if data and not getattr(inside_read_until, "on", False):
            io_trace.record(device, "<", data)
        return data

    def traced_read_until(expected: bytes = b"\n", size: int | None = None) -> bytes:
        inside_read_until.on = True  # pyserial's read_until reads byte by byte: one line
        try:
            data: bytes = read_until(expected, size)
        finally:
            inside_read_until.on = False
        if data:
            io_trace.record(device, "<", data)
        return data

    def traced_write(data: bytes) -> int | None:
        io_trace.record(device, ">", data)
        written: int | None = write(data)
        return written

    port.read, port.write, port.read_until = traced_read, traced_write, traced_read_until
