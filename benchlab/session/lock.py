"""The owner lock: the one process that writes a session holds ``owner.lock`` (an OS lock
the kernel drops when that process dies) with its pid, host and command inside."""

from __future__ import annotations

import fcntl
import json
import os
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from benchlab.session.layout import (
    OWNER_FILE,
)


def session_holder(folder: str | os.PathLike[str]) -> dict[str, Any] | None:
    """Who holds the session's owner lock right now (``pid``, ``host``, ``since``,
    ``command``), or ``None`` when no live process does."""
    path = Path(folder) / OWNER_FILE
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None  # no lock file: written before locks existed, or never run
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                record = json.loads(os.pread(fd, 4096, 0).decode("utf-8") or "{}")
            except ValueError:
                record = {}
            return record if isinstance(record, dict) else {}
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


#: How long :meth:`Session.hold` keeps trying a lock that is taken: a reader asking who
#: holds it (:func:`session_holder`) takes it shared for microseconds, which is not "busy".
HOLD_RETRY_S = 0.05


def _lock_exclusive(fd: int) -> bool:
    """Take the owner lock; False when another process still holds it after
    :data:`HOLD_RETRY_S`."""
    deadline = time.monotonic() + HOLD_RETRY_S
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.002)


def describe_holder(holder: Mapping[str, Any]) -> str:
    """``"pid 4242 on bench-pc (benchlab run mtf, since ...)"`` for error messages."""
    text = f"pid {holder.get('pid', '?')} on {holder.get('host', '?')}"
    extra = ", ".join(str(v) for v in (holder.get("command"), holder.get("since") and
                                        f"since {holder['since']}") if v)
    return f"{text} ({extra})" if extra else text


