"""Every device exchange as a cassette (``benchlab --trace-io FILE``), replayable with
``benchlab --replay FILE`` (:mod:`benchlab.drivers.trace.replay`).

A cassette is JSON Lines (gzip-compressed when the name ends in ``.gz``). The first line is a
header; then one line per event, in the order they happened::

    {"cassette": 1, "started": "2026-11-28 10:00:00 +0000"}
    {"n": 1, "t": 0.0012, "dev": "camera", "dir": ">", "ep": 1, "len": 3, "hex": "01 01 01"}
    {"n": 2, "t": 0.0013, "dev": "camera", "dir": "<", "ep": 129, "len": 5, "hex": "01 03 01 00 06"}
    {"n": 9, "t": 0.0150, "dev": "camera", "dir": "<", "ep": 130, "len": 1311232, "b64": "..."}
    {"n": 4, "t": 0.2000, "dev": "camera", "dir": "<", "ep": 129, "timeout": true}
    {"n": 5, "t": 0.3000, "dev": "led", "open": "/dev/ttyUSB0", "baud": 9600}

``dir`` is ``>`` host to device, ``<`` device to host; short transfers are written in hex
(with their ASCII in ``text``), long ones (frames) in base64. A read that timed out is an
event too: replay must time out in the same place. ``note`` lines are free text. Off by
default; recording then costs one ``None`` check.

``benchlab --append --trace-io FILE`` adds a recording to an existing cassette: a ``note``
line ``recording appended ...`` starts it and its exchanges are numbered on from the file's
last one (a gzip cassette gets a new gzip member, which readers join), so an exchange number
names one exchange of the whole file.
"""

from __future__ import annotations

import base64
import gzip
import json
import threading
import time
from pathlib import Path
from typing import Any, TextIO, cast

CASSETTE_VERSION = 1
#: Transfers up to this long are written in hex (readable); longer ones in base64.
MAX_HEX_BYTES = 256

_lock = threading.Lock()
_out: TextIO | None = None
_t0 = 0.0
_n = 0


def open_text(path: str | Path, mode: str) -> TextIO:
    """A cassette file for text I/O, gzip-compressed when its name ends in ``.gz``."""
    if str(path).endswith(".gz"):
        # Level 1: frames (base64 of noisy pixels) take ~0.1 s each at the default level 9,
        # which would slow a recorded bring-up tenfold, for a file a few % smaller.
        return gzip.open(path, mode + "t", encoding="ascii",  # type: ignore[return-value]
                         compresslevel=1)
    return cast(TextIO, open(path, mode, encoding="ascii", buffering=1))  # noqa: SIM115


def start(path: str | Path, *, after: int | None = None) -> None:
    """Write a new cassette to ``path`` from now on (line-buffered, so a crash keeps it).

    Parameters
    ----------
    path
        The cassette file.
    after
        Append to the existing cassette ``path`` whose last event is number ``after`` (the
        caller has checked it is a cassette: :func:`benchlab.drivers.trace.cassette.
        last_event_number`); None writes a new file.
    """
    global _out, _t0, _n
    stop()
    now = time.strftime("%Y-%m-%d %H:%M:%S %z")
    fh = open_text(path, "w" if after is None else "a")
    with _lock:
        _out, _t0, _n = fh, time.monotonic(), after or 0
        if after is None:
            fh.write(json.dumps({"cassette": CASSETTE_VERSION, "started": now}) + "\n")
    if after is not None:
        note("cassette", f"recording appended {now}")


def stop() -> None:
    """Close the cassette (safe to call when none is being written)."""
    global _out
    with _lock:
        fh, _out = _out, None
    if fh is not None:
        fh.close()


def active() -> bool:
    return _out is not None


def _write(event: dict[str, Any]) -> None:
    global _n
    with _lock:
        if _out is None:
            return
        _n += 1
        line = {"n": _n, "t": round(time.monotonic() - _t0, 6), **event}
        _out.write(json.dumps(line) + "\n")


def note(device: str, text: str) -> None:
    """A free-text line (device lost, ...) between the exchanges."""
    if _out is not None:
        _write({"dev": device, "note": text})


def opened(device: str, **what: Any) -> None:
    """A device was opened: ``port``/``baud`` (serial) or ``vid``/``pid`` (USB)."""
    if _out is not None:
        _write({"dev": device, "open": what})


def record(device: str, direction: str, data: bytes | bytearray | memoryview,
           ep: int | None = None) -> None:
    """One transfer: ``direction`` is ``">"`` (to the device) or ``"<"`` (from it); ``ep`` the
    USB endpoint (None on a serial line)."""
    if _out is None:
        return
    raw = bytes(data)
    event: dict[str, Any] = {"dev": device, "dir": direction}
    if ep is not None:
        event["ep"] = ep
    event["len"] = len(raw)
    if len(raw) <= MAX_HEX_BYTES:
        event["hex"] = raw.hex(" ")
        event["text"] = "".join(chr(b) if 32 <= b < 127 else "." for b in raw)
    else:
        event["b64"] = base64.b64encode(raw).decode("ascii")
    _write(event)


def timed_out(device: str, ep: int | None = None) -> None:
    """A read that got nothing before its timeout."""
    if _out is not None:
        _write({"dev": device, "dir": "<", **({"ep": ep} if ep is not None else {}),
                "timeout": True})
