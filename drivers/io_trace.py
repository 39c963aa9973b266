"""Byte-level trace of every device exchange, for support cases (``benchlab --trace-io FILE``).

One line per transfer::

    12.345678 led      >     9  4d 4f 44 45 20 31 20 30 0a  |MODE 1 0.|

seconds since the trace started, device, direction (``>`` host to device, ``<`` device to
host), byte count, the bytes in hex and as ASCII. Camera frames (megabytes) are shown by their
first bytes and their length. Off by default; recording then costs one ``None`` check.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TextIO

#: Bytes shown of one transfer longer than this (camera frames).
MAX_SHOWN_BYTES = 64

_lock = threading.Lock()
_out: TextIO | None = None
_t0 = 0.0


def start(path: str | Path) -> None:
    """Append the trace to ``path`` from now on (line-buffered, so a crash keeps it)."""
    global _out, _t0
    stop()
    fh = open(path, "a", encoding="ascii", buffering=1)  # noqa: SIM115 - kept open until stop()
    with _lock:
        _out, _t0 = fh, time.monotonic()
        fh.write(f"# benchlab I/O trace started {time.strftime('%Y-%m-%d %H:%M:%S %z')}; "
                 "columns: seconds device direction(> to device, < from device) bytes hex "
                 "|ascii|\n")


def stop() -> None:
    """Close the trace file (safe to call when no trace runs)."""
    global _out
    with _lock:
        fh, _out = _out, None
    if fh is not None:
        fh.close()


def active() -> bool:
    return _out is not None


def note(device: str, text: str) -> None:
    """A free-text line (port opened, device lost) between the byte lines."""
    with _lock:
        if _out is not None:
            _out.write(f"{time.monotonic() - _t0:11.6f} {device:<8} #  {text}\n")


def record(device: str, direction: str, data: bytes | bytearray | memoryview) -> None:
    """One transfer: ``direction`` is ``">"`` (to the device) or ``"<"`` (from it)."""
    if _out is None:
        return
    n = len(data)
    shown = bytes(data[:MAX_SHOWN_BYTES])
    text = "".join(chr(b) if 32 <= b < 127 else "." for b in shown)
    more = f" ... (+{n - len(shown)} bytes)" if n > len(shown) else ""
    line = (f"{time.monotonic() - _t0:11.6f} {device:<8} {direction} {n:5d}  "
            f"{shown.hex(' ')}{more}  |{text}|\n")
    with _lock:
        if _out is not None:
            _out.write(line)
