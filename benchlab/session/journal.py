"""The session's journal (``events.jsonl``): appending events, reading them as the file
grows, and the steps it records as done."""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path
from typing import Any

from benchlab.session.folder import SessionFolder
from benchlab.session.journal_reader import JournalError, JournalReader
from benchlab.session.layout import (
    EVENTS_FILE,
    SessionError,
    _check_name,
    _now_iso,
    _plain,
)
from benchlab.storage import naming


class SessionJournal(SessionFolder):
    """Appends to and reads the journal."""

    def __init__(self, path: Path, meta: dict[str, Any]) -> None:
        super().__init__(path, meta)
        #: The journal, parsed as it grows (only appended bytes are read again).
        self._journal_reader = JournalReader(self.path / EVENTS_FILE)
        #: Guards the reader and the indexes built from it (frames are loaded from several
        #: threads).
        self._journal_lock = threading.RLock()

    # ------------------------------------------------------------------ journal
    def finish(self, status: str = "completed") -> None:
        """Record the end of the run: status and ``finished_at`` in ``session.json``."""
        self.log_event("session_finished", status=status)
        self.update_meta(status=status, finished_at=_now_iso())

    @property
    def events_path(self) -> Path:
        """The append-only journal."""
        return self.path / EVENTS_FILE

    def log_event(self, kind: str, *, durable: bool = True, **data: Any) -> None:
        """Append one event line to ``events.jsonl``, flushed and fsync'd before returning.

        ``durable=False`` skips the fsync, for events that resume does not depend on (a
        re-analysis started, a results version written): the next durable event, or the
        page cache's own write-back, carries them to disk.
        """
        record = {"time": _now_iso(), "kind": kind, **_plain(data)}
        line = json.dumps(record, allow_nan=False) + "\n"
        with self._lock, naming(self.events_path):  # a full disk names the journal
            fd = os.open(self.events_path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
            try:
                torn = self._torn_tail_length(fd)
                if torn:
                    # Terminate the fragment a crash left so the new event gets its own line.
                    repair = {"time": _now_iso(), "kind": "journal_repaired", "torn_bytes": torn}
                    os.write(fd, b"\n" + (json.dumps(repair) + "\n").encode("utf-8"))
                os.write(fd, line.encode("utf-8"))
                if durable:
                    os.fsync(fd)
            finally:
                os.close(fd)

    @staticmethod
    def _torn_tail_length(fd: int) -> int:
        """Bytes after the last newline (0 when the file ends cleanly)."""
        size = os.fstat(fd).st_size
        if size == 0:
            return 0
        chunk = min(size, 1 << 16)
        tail = os.pread(fd, chunk, size - chunk)
        if tail.endswith(b"\n"):
            return 0
        nl = tail.rfind(b"\n")
        return len(tail) - (nl + 1)

    def events(self) -> list[dict[str, Any]]:
        """All journal events in order.

        A torn last line (a crash mid-append) is skipped. A broken line in the middle is
        accepted only when the next event is the ``journal_repaired`` that terminated it;
        anything else raises :class:`SessionError` naming the file and line.
        """
        return [dict(e) for e in self._journal()[1]]

    def _journal(self) -> tuple[tuple[int, int], list[dict[str, Any]]]:
        """``(key, events)``: the parsed journal, shared with the reader (callers only read
        it); ``key`` (reader generation, event count) changes whenever the events do."""
        with self._journal_lock:
            try:
                _, events = self._journal_reader.read()
            except FileNotFoundError as exc:
                raise SessionError(f"{self.events_path}: journal missing") from exc
            except JournalError as exc:
                raise SessionError(str(exc)) from None
            return (self._journal_reader.generation, len(events)), events

    # ------------------------------------------------------------------ steps
    def mark_step_completed(self, step_id: str, **summary: Any) -> None:
        """Journal that a step finished; :meth:`completed_steps` then includes it."""
        _check_name("step id", step_id)
        self.log_event("step_completed", step_id=step_id, **summary)

    def completed_steps(self) -> set[str]:
        """Step ids with a ``step_completed`` event."""
        return {
            str(ev["step_id"])
            for ev in self._journal()[1]
            if ev.get("kind") == "step_completed" and "step_id" in ev
        }

