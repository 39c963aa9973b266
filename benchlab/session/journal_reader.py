"""Read an append-only JSON-lines journal incrementally.

A session's ``events.jsonl`` only ever grows: each process appends whole lines (a crash can
leave a torn last line, which the next append terminates and follows with a
``journal_repaired`` event). :class:`JournalReader` parses only the bytes appended since its
last read, so asking for the journal after every saved frame costs the new line, not the
whole file: a session's bookkeeping stays linear in its frames.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

#: The event that terminates a torn line (written by ``Session.log_event``).
JOURNAL_REPAIRED = "journal_repaired"


class JournalError(ValueError):
    """A line in the middle of the journal is corrupt (``line`` counts from 1)."""

    def __init__(self, path: Path, line: int) -> None:
        super().__init__(f"{path}: line {line} is corrupt")
        self.path = path
        self.line = line


def file_identity(st: os.stat_result) -> tuple[int, ...]:
    """What changes when a file is replaced or written: device, inode, size, mtime, ctime."""
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


class JournalReader:
    """The parsed events of one journal file, brought up to date on each :meth:`read`.

    Parameters
    ----------
    path
        The journal file.

    Notes
    -----
    The reader keeps the byte offset just past the last complete line it parsed. When the file
    has the same inode and is at least that long, only the bytes after the offset are read
    and parsed; otherwise (replaced, truncated) the whole file is parsed again and
    :attr:`generation` goes up, so callers that keep state derived from the events know to
    rebuild it. The returned list is shared: callers read it and never change it.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        #: Bumped whenever the events are parsed from the start again.
        self.generation = 0
        self._events: list[dict[str, Any]] = []
        self._offset_bytes = 0
        self._lines = 0  # complete lines consumed, for the line number in an error
        self._inode: int | None = None
        self._identity: tuple[int, ...] | None = None
        self._pending_bad: int | None = None  # a corrupt line waiting for its repair event
        self._complete = False  # True when the last read ended at the end of the file

    def read(self) -> tuple[bool, list[dict[str, Any]]]:
        """``(complete, events)``: every whole event so far, in order.

        ``complete`` is False when the file ends in a torn line (a crash mid-append, or an
        append under way in another process): that fragment is not an event yet.

        Raises
        ------
        FileNotFoundError
            If the journal does not exist.
        JournalError
            If a line other than the last is corrupt and no ``journal_repaired`` event
            follows it.
        """
        st = self.path.stat()
        identity = file_identity(st)
        if identity == self._identity:
            return self._complete, self._events
        if st.st_ino != self._inode or st.st_size < self._offset_bytes:
            self._restart(st.st_ino)
        with self.path.open("rb") as fh:
            fh.seek(self._offset_bytes)
            raw = fh.read()
        end = raw.rfind(b"\n") + 1  # only whole lines are consumed
        try:
            for chunk in raw[:end].split(b"\n")[:-1]:
                self._lines += 1
                self._take(chunk)
        except JournalError:
            self._restart(-1)  # parse from the start next time: nothing half-read is kept
            self._identity = None
            raise
        self._offset_bytes += end
        self._complete = end == len(raw)
        if self._complete and self._pending_bad is not None:
            # A corrupt line is the last whole line: it may yet be repaired by the next
            # append, so it is treated like a torn tail until then.
            self._complete = False
        self._identity = identity
        return self._complete, self._events

    def _restart(self, inode: int) -> None:
        self.generation += 1
        self._events = []
        self._offset_bytes = self._lines = 0
        self._inode = inode
        self._pending_bad = None

    def _take(self, chunk: bytes) -> None:
        if not chunk.strip():
            return
        try:
            rec = json.loads(chunk.decode("utf-8"))
            if not isinstance(rec, dict) or "kind" not in rec:
                raise ValueError("not an event object")
        except ValueError:
            if self._pending_bad is not None:
                raise JournalError(self.path, self._pending_bad) from None
            self._pending_bad = self._lines
            return
        if self._pending_bad is not None:
            if rec.get("kind") != JOURNAL_REPAIRED:
                raise JournalError(self.path, self._pending_bad)
            self._pending_bad = None
        self._events.append(rec)
