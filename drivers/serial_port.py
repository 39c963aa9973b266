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

from typing import Any

import serial

try:  # pyserial lets termios.error (not an OSError) escape on a hung-up pty/tty
    from termios import error as _TermiosError
except ImportError:  # pragma: no cover - non-POSIX
    _TermiosError = OSError  # type: ignore[misc, assignment]

#: What reading, writing or opening a serial port can raise.
IO_ERRORS = (serial.SerialException, OSError, _TermiosError)


def open_serial(url: str, baudrate: int, **settings: Any) -> serial.Serial:
    """Open ``url`` (a device path or any pyserial URL) at ``baudrate`` with ``settings``
    (``bytesize``, ``parity``, ``stopbits``, ``rtscts``, ``timeout``, ``write_timeout``)."""
    return serial.serial_for_url(url, baudrate, **settings)
