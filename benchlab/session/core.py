"""The :class:`Session` class: creating and opening a session folder and holding it."""

from __future__ import annotations

import json
import os
import shutil
import sys
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from benchlab.session.layout import (
    EVENTS_FILE,
    FRAMES_DIR,
    OWNER_FILE,
    RESULTS_DIR,
    SESSION_FILE,
    SESSION_FORMAT,
    SESSION_VERSION,
    SessionBusyError,
    SessionError,
    _check_name,
    _now_iso,
    _plain,
    check_sessions_root,
)
from benchlab.session.lock import (
    _lock_exclusive,
    describe_holder,
    session_holder,
)
from benchlab.session.results import SessionResults
from benchlab.storage import (
    atomic_write_json,
    atomic_write_text,
)

#: Fields session.json must have, with their JSON types (a wrong type is named, not a crash).
_META_TYPES: dict[str, type | tuple[type, ...]] = {
    "procedure": str, "params": dict, "status": str, "started_at": str,
}
_TYPE_WORDS: dict[type | tuple[type, ...], str] = {str: "a string", dict: "a table (object)"}




class Session(SessionResults):
    """An open session folder. Create with :meth:`create`, reopen with :meth:`open`."""

    # ------------------------------------------------------------------ create / open
    @classmethod
    def create(
        cls,
        root: Path,
        *,
        procedure: str,
        params: Mapping[str, Any],
        operator: str,
        devices: Mapping[str, Any],
        software_version: str,
        name: str | None = None,
        sample: str = "",
        lot: str = "",
    ) -> Session:
        """Create ``root/<timestamp>_<procedure>`` (or ``root/<name>``) with status "running".

        ``sample`` identifies the lens or sample under test - the unit's serial number -
        and ``lot`` its production lot (both optional; the catalogue's trends and
        ``benchlab units`` / ``lot`` group by them).

        A folder that already exists is never reused: a numeric suffix is added.
        """
        _check_name("procedure", procedure)
        root = check_sessions_root(root)
        started = datetime.now(UTC)
        base = name if name is not None else f"{started:%Y%m%d-%H%M%S}_{procedure}"
        _check_name("session name", base)
        folder = root / base
        n = 1
        while True:
            try:
                folder.mkdir()
                break
            except FileExistsError:
                n += 1
                folder = root / f"{base}-{n}"
            except OSError as exc:
                raise SessionError(f"{folder}: cannot create the session folder "
                                   f"({(exc.strerror or str(exc)).lower()})") from exc
        meta: dict[str, Any] = {
            "format": SESSION_FORMAT,
            "version": SESSION_VERSION,
            "procedure": procedure,
            "operator": operator,
            "sample": sample,
            "lot": lot,
            "devices": _plain(devices),
            "software_version": software_version,
            "params": _plain(params),
            "started_at": started.isoformat(timespec="microseconds"),
            "finished_at": None,
            "status": "running",
        }
        session = cls(folder, meta)
        try:
            (folder / FRAMES_DIR).mkdir()
            (folder / RESULTS_DIR).mkdir()
            atomic_write_text(folder / EVENTS_FILE, "", overwrite=False)
            session.hold()  # before session.json exists, so nobody ever sees it running unowned
            atomic_write_json(folder / SESSION_FILE, meta, overwrite=False)
            session.log_event("session_created", procedure=procedure)
        except OSError as exc:
            # A full disk (or a size limit) while the folder is made: it holds nothing
            # acquired yet, and a folder without a readable session file would be a stub
            # that neither `sessions list` nor `resume` can read. It goes.
            session.release()
            shutil.rmtree(folder, ignore_errors=True)
            what = exc.strerror or str(exc)
            raise SessionError(f"{exc.filename or folder}: cannot create the session "
                               f"({what.lower()}); nothing was acquired and the folder "
                               f"{folder} was removed") from exc
        return session

    @classmethod
    def open(cls, path: Path) -> Session:
        """Open an existing session folder.

        Frames found on disk without a ``frame_saved`` event (a crash between the flush and the
        journal line) are recorded with ``recovered=True`` so that nothing acquired is lost.

        Raises
        ------
        SessionError
            Naming ``session.json`` when it is missing, unreadable or not a benchlab session.
        """
        folder = Path(path)
        meta_path = folder / SESSION_FILE
        try:
            text = meta_path.read_text(encoding="utf-8")
        except FileNotFoundError as exc:
            raise SessionError(f"{meta_path}: no session file (is {folder} a session?)") from exc
        except OSError as exc:
            raise SessionError(f"{meta_path}: cannot read ({exc})") from exc
        try:
            meta = json.loads(text)
        except ValueError as exc:
            raise SessionError(f"{meta_path}: corrupt session file ({exc})") from exc
        if not isinstance(meta, dict) or meta.get("format") != SESSION_FORMAT:
            raise SessionError(f"{meta_path}: not a benchlab session file")
        for key, kind in _META_TYPES.items():
            if key not in meta:
                raise SessionError(f"{meta_path}: session file lacks {key!r}")
            if not isinstance(meta[key], kind):
                raise SessionError(f"{meta_path}: field {key!r} must be {_TYPE_WORDS[kind]}, "
                                   f"got {type(meta[key]).__name__} {meta[key]!r:.60}")
        session = cls(folder, meta)
        session._journal()  # fail now, naming the journal, if it is damaged beyond a torn tail
        return session

    # ------------------------------------------------------------------ ownership
    def hold(self, command: str | None = None) -> None:
        """Become the one process that writes this session (until :meth:`release` or exit).

        Raises
        ------
        SessionBusyError
            Naming the holder (pid, host, command) when another live process holds it.
        """
        if self._owner_fd is not None:
            return
        path = self.path / OWNER_FILE
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise SessionError(f"{path}: cannot take the session's owner lock "
                               f"({(exc.strerror or str(exc)).lower()}); is the session "
                               "folder read-only?") from exc
        if not _lock_exclusive(fd):
            holder = session_holder(self.path) or {}
            os.close(fd)
            raise SessionBusyError(f"{self.path}: session is in use by {describe_holder(holder)}"
                                   "; wait for it to end or stop that process") from None
        record = {"pid": os.getpid(), "host": os.uname().nodename, "since": _now_iso(),
                  "command": command or " ".join(["benchlab", *sys.argv[1:3]])}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(record) + "\n").encode("utf-8"), 0)
        self._owner_fd = fd
        # Frames a killed writer saved but never journalled: only the writer records them
        # (a reader writing the journal would race a resume that is just starting).
        self._recover_orphan_frames()

    def release(self) -> None:
        """Stop being the session's writer (the lock also goes when the process ends)."""
        self.stop_prefetch()
        fd, self._owner_fd = self._owner_fd, None
        if fd is not None:
            os.close(fd)  # closing drops the flock

    def __del__(self) -> None:
        fd = getattr(self, "_owner_fd", None)
        if fd is not None:
            try:
                os.close(fd)
            except (OSError, TypeError):  # TypeError: os already torn down at exit
                pass

    def remove_temporary_files(self) -> list[str]:
        """Delete what a kill in the middle of an atomic write left behind (``.*.tmp`` files
        beside frames and results, ``.v-*.tmp`` and ``.unwrap-*.tmp`` result folders) - never
        a real frame - and
        journal them. Only the holder may do this."""
        if not self.held:
            raise SessionError(f"{self.path}: only the session's writer removes temporary files")
        removed: list[str] = []
        for folder in (self.path, self.frames_dir, self.results_dir):
            if not folder.is_dir():
                continue
            for p in sorted(folder.glob(".*.tmp")):
                rel = p.relative_to(self.path).as_posix()
                if p.is_dir() and folder == self.results_dir and p.name.startswith(
                        (".v-", ".unwrap-")):
                    shutil.rmtree(p)
                elif p.is_file() and not p.is_symlink():
                    p.unlink()
                else:
                    continue
                removed.append(rel)
        if removed:
            self.log_event("temporary_files_removed", files=removed)
        return removed

