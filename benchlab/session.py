"""A measurement session: one folder that holds everything a run acquired and concluded.

Layout::

    <root>/<YYYYmmdd-HHMMSS>_<procedure>/
        session.json      who, what, which devices, software version, parameters, start/end
        events.jsonl      append-only journal, one JSON object per line, fsync'd per line
        frames/           <step_id>__<name>.tiff, lossless, metadata inside, never overwritten;
                          <step_id>__<name>.take<N>.tiff: a later take (after rejected frames,
                          or ``resume --retake``), the earlier takes kept beside it
        results/v<N>/     one CSV + JSON per table and summary.json; a re-analysis adds v<N+1>
        verdicts/v<N>.json  acceptance verdicts (benchlab verify); a re-verification adds one

Every file is written atomically (:mod:`benchlab.storage`); frames are flushed to disk before
:meth:`Session.save_frame` returns, so analysis never runs on a frame that could still be lost.
The journal is the source of truth for resume: a step is done when its ``step_completed`` event
is on disk. A ``kill -9`` can tear the journal's last line; readers skip it, and the next append
terminates it and records a ``journal_repaired`` event so the damage stays visible.

Why one module of ~1,200 lines: the folder layout, the journal, frame files and result versions
are one data contract guarded by one lock file; split, the rules that keep a session truthful
(what is written before what, what is never overwritten) would be spread over several files.
"""

from __future__ import annotations

import csv
import errno
import fcntl
import hashlib
import io
import json
import math
import os
import re
import shutil
import stat
import sys
import threading
import time
from collections.abc import Collection, Mapping
from concurrent.futures import Future, ThreadPoolExecutor, wait
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.drivers.errors import BenchlabError
from benchlab.journal import JournalError, JournalReader, file_identity
from benchlab.storage import (
    FrameFileError,
    atomic_write_json,
    atomic_write_text,
    flush_folder,
    fsync_dir,
    fsync_tree,
    json_default,
    json_rows_text,
    load_frame_tiff,
    make_staging_dir,
    save_frame_tiff,
    sha256_file,
    write_new_file,
)

SESSION_FORMAT = "benchlab.session"
SESSION_VERSION = 1
SESSION_FILE = "session.json"
EVENTS_FILE = "events.jsonl"
FRAMES_DIR = "frames"
RESULTS_DIR = "results"
#: Acceptance verdicts (:mod:`benchlab.acceptance.store`), versioned like the results.
VERDICTS_DIR = "verdicts"
#: Held (``flock``) by the one process writing the session; the kernel drops it when that
#: process dies, so a session can never stay "running" for a dead process.
OWNER_FILE = "owner.lock"
#: Step ids, frame names and table names become file names: keep them plain.
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
_VERSION_DIR = re.compile(r"^v(\d+)$")
#: A frame taken again after its earlier takes were rejected, or by a retake (``resume
#: --retake``): ``<step>__<name>.take2.tiff``; the earlier takes keep their names.
_TAKE_MARK = ".take"
_TAKE_RE = re.compile(r"\.take\d+$")


def take_of(path: Path) -> int:
    """The take number of a frame file: N of ``<step>__<name>.take<N>.tiff``, else 1."""
    m = _TAKE_RE.search(path.stem)
    return int(m.group(0)[len(_TAKE_MARK):]) if m else 1


#: Journal events of a retake (``benchlab resume SESSION --retake STEP``).
RETAKE_STARTED = "retake_started"
RETAKE_ADOPTED = "retake_adopted"
RETAKE_STOPPED = "retake_stopped"
#: How a missing number (NaN) is written in results CSV files; JSON uses null.
CSV_MISSING = "NA"
#: Flush policy of a results version: "syncfs" (files written, then ONE flush of the file
#: system, syncfs(2), before the rename; falls back to "per-version" off Linux),
#: "per-version" (each file fsync'd once before the rename) or "per-file" (each file and its
#: folder fsync'd as it is written, the old behaviour). ``benchlab benchmark batch`` measures
#: all three. The journal lines resume depends on are fsync'd one by one whatever this says.
RESULTS_FSYNC = "syncfs"
#: Threads that load a session's frames (decoding releases the GIL; more buys nothing here).
FRAME_LOAD_THREADS = min(4, os.cpu_count() or 1)


class SessionError(BenchlabError):
    """A session folder or one of its files is missing, corrupt or misused."""


class FrameExistsError(SessionError):
    """A frame with this step and name is already saved; frames are never overwritten."""


class SessionBusyError(SessionError):
    """Another live process is writing this session (its owner lock is held)."""


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


#: Fields session.json must have, with their JSON types (a wrong type is named, not a crash).
_META_TYPES: dict[str, type | tuple[type, ...]] = {
    "procedure": str, "params": dict, "status": str, "started_at": str,
}
_TYPE_WORDS: dict[type | tuple[type, ...], str] = {str: "a string", dict: "a table (object)"}


def check_sessions_root(root: str | os.PathLike[str]) -> Path:
    """The folder that receives new session folders, made ready or refused in plain words.

    Only the last level is created: a missing parent is most likely a typo, and silently
    creating ``/data/sesions/...`` would hide it.

    Raises
    ------
    SessionError
        Naming the folder: it is a file, its parent is missing, or it is not writable.
    """
    folder = Path(root)
    if folder.exists() and not folder.is_dir():
        raise SessionError(f"{folder}: is a file, not a folder for sessions")
    if not folder.exists():
        parent = folder.parent
        if not parent.is_dir():
            raise SessionError(f"{folder}: parent folder {parent} does not exist (only the "
                               "last level is created; check the path for a typo)")
        try:
            folder.mkdir()
        except FileExistsError:
            pass
        except OSError as exc:
            raise SessionError(f"{folder}: cannot create the sessions folder "
                               f"({(exc.strerror or str(exc)).lower()})") from exc
    if not os.access(folder, os.W_OK | os.X_OK):
        raise SessionError(f"{folder}: sessions folder is not writable (read-only or no "
                           "permission); nothing was written")
    return folder


def _now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds")


def _check_name(kind: str, value: str) -> str:
    if not isinstance(value, str) or not _SAFE_NAME.match(value) or "__" in value:
        raise ValueError(
            f"{kind} {value!r} must be letters, digits, '.', '_' or '-' "
            "(no '__', not starting with a symbol)"
        )
    return value


#: Types :func:`_plain` returns as they are, tested first: a results version has thousands of
#: such cells, and the ``Mapping`` check (an ABC) costs several times a type lookup.
_PLAIN_SCALARS = frozenset({str, int, bool, type(None)})


def _plain(obj: Any) -> Any:
    """JSON-safe copy: NaN/inf -> None, tuples -> lists, numpy scalars -> Python."""
    kind = type(obj)
    if kind in _PLAIN_SCALARS:
        return obj
    if kind is float:
        return obj if math.isfinite(obj) else None
    if kind is np.float64:  # most cells of the SFR curves: the np.generic case, tested first
        value = obj.item()
        return value if math.isfinite(value) else None
    if kind is dict:
        return {str(k): _plain(v) for k, v in obj.items()}
    if kind is list:
        return [_plain(v) for v in obj]
    if isinstance(obj, Mapping):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    return obj


class Session:
    """An open session folder. Create with :meth:`create`, reopen with :meth:`open`."""

    def __init__(self, path: Path, meta: dict[str, Any]) -> None:
        self.path = Path(path)
        self._meta = meta
        self._lock = threading.Lock()
        #: The journal, parsed as it grows (only appended bytes are read again).
        self._journal_reader = JournalReader(self.path / EVENTS_FILE)
        #: Guards the reader and the indexes below (frames are loaded from several threads).
        self._journal_lock = threading.RLock()
        #: :meth:`_frame_records` and the same records by step, built from the journal's
        #: events as they arrive: ``(reader generation, events seen, records, by step)``.
        self._records_index: tuple[int, int, dict[str, dict[str, Any]],
                                   dict[str, list[dict[str, Any]]]] | None = None
        #: :meth:`rejected_frames` and the frames retakes made current, likewise:
        #: ``(reader generation, events seen, rejected file -> reason, adopted files)``.
        self._set_aside_index: tuple[int, int, dict[str, str], set[str]] | None = None
        #: The retake this object is running (:meth:`begin_retake`): its id and steps.
        self._retake: tuple[str, frozenset[str]] | None = None
        self._owner_fd: int | None = None
        #: Set by :meth:`mark_results_partial`: written into every new results version.
        self._partial: dict[str, Any] | None = None
        #: Frames being loaded ahead by :meth:`prefetch_frames`: relative file -> load.
        self._prefetched: dict[str, Future[tuple[npt.NDArray[Any], dict[str, Any]]]] = {}
        self._prefetch_pool: ThreadPoolExecutor | None = None
        #: Frames this object has hashed and found as journalled: relative file ->
        #: (file identity when read, sha256); see :meth:`verify_frames`.
        self._verified: dict[str, tuple[tuple[int, ...], str]] = {}
        #: Set by a re-analysis: :meth:`write_results` first checks every recorded frame
        #: (:meth:`verify_frames`), so results are never written from changed frames - also
        #: when the analysis started before the last frames had finished loading.
        self.verify_frames_before_results = False
        #: Set by a re-analysis: :meth:`write_results` adds no version when an existing one
        #: has the same inputs (frames), settings, software version and byte-identical
        #: results; it returns that version and sets :attr:`matched_version`.
        self.reuse_identical_results = False
        #: The version the last :meth:`write_results` matched instead of writing (or None).
        self.matched_version: int | None = None

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
        (folder / FRAMES_DIR).mkdir()
        (folder / RESULTS_DIR).mkdir()
        atomic_write_text(folder / EVENTS_FILE, "", overwrite=False)
        session = cls(folder, meta)
        session.hold()  # before session.json exists, so nobody ever sees it running unowned
        atomic_write_json(folder / SESSION_FILE, meta, overwrite=False)
        session.log_event("session_created", procedure=procedure)
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

    @property
    def held(self) -> bool:
        """Whether this object holds the session's owner lock."""
        return self._owner_fd is not None

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

    # ------------------------------------------------------------------ metadata
    @property
    def meta(self) -> dict[str, Any]:
        """A copy of ``session.json``."""
        return json.loads(json.dumps(self._meta))

    @property
    def params(self) -> dict[str, Any]:
        """The parameter snapshot the run was started with."""
        return self.meta["params"]

    @property
    def procedure(self) -> str:
        """Procedure name ("mtf", "radiometry")."""
        return str(self._meta["procedure"])

    @property
    def status(self) -> str:
        """Run status: "running", "completed", "interrupted", "aborted", "failed".

        A session recorded as "running" whose writer is gone (kill -9, power loss: nobody
        holds its owner lock) is "interrupted" - which it is.
        """
        recorded = str(self._meta["status"])
        if recorded == "running" and not self.held and session_holder(self.path) is None:
            retake = self._meta.get("retake")
            if isinstance(retake, dict) and retake.get("previous_status") == "completed":
                # a retake of a completed session was killed: its frames are still whole
                # (the previous takes, or the retake's once adopted; see results_stale)
                return "completed"
            return "interrupted"
        return recorded

    @property
    def frames_dir(self) -> Path:
        """The raw frames folder."""
        return self.path / FRAMES_DIR

    @property
    def results_dir(self) -> Path:
        """The folder holding ``v1``, ``v2``, ... result versions."""
        return self.path / RESULTS_DIR

    def update_meta(self, **fields: Any) -> None:
        """Add or change top-level fields of ``session.json`` (atomic rewrite)."""
        reserved = {"format", "version", "started_at"} & set(fields)
        if reserved:
            raise ValueError(f"cannot change {sorted(reserved)} of a session")
        with self._lock:
            new = {**self._meta, **_plain(fields)}
            atomic_write_json(self.path / SESSION_FILE, new)
            self._meta = new

    def finish(self, status: str = "completed") -> None:
        """Record the end of the run: status and ``finished_at`` in ``session.json``."""
        self.log_event("session_finished", status=status)
        self.update_meta(status=status, finished_at=_now_iso())

    # ------------------------------------------------------------------ journal
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
        with self._lock:
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

    # ------------------------------------------------------------------ frames
    def frame_path(self, step_id: str, name: str, take: int = 1) -> Path:
        """Where the frame ``name`` of step ``step_id`` is (or would be) saved; ``take`` > 1:
        a frame taken again after the earlier ones were rejected (:meth:`reject_frames`)."""
        _check_name("step id", step_id)
        _check_name("frame name", name)
        suffix = f"{_TAKE_MARK}{take}" if take > 1 else ""
        return self.frames_dir / f"{step_id}__{name}{suffix}.tiff"

    def save_frame(
        self, step_id: str, name: str, pixels: npt.NDArray[Any], metadata: Mapping[str, Any]
    ) -> Path:
        """Save a raw frame losslessly, on disk and fsync'd before returning; journal its hash.

        Raises
        ------
        FrameExistsError
            If this step already saved a frame with this name; the saved one is untouched.
        """
        if name in self.step_frames(step_id):
            raise FrameExistsError(f"{self.frame_path(step_id, name)}: frame already saved; "
                                   "frames are never overwritten")
        take = 1  # the first file name no frame (rejected or not) has used
        records = self._indexed_records()[0]
        while (self.frame_path(step_id, name, take).exists()
               or self.frame_path(step_id, name, take).relative_to(self.path).as_posix()
               in records):
            take += 1
        path = self.frame_path(step_id, name, take)
        meta = {**_plain(metadata), "step_id": step_id, "frame_name": name}
        try:
            save_frame_tiff(path, pixels, meta, overwrite=False)
        except FileExistsError as exc:
            raise FrameExistsError(
                f"{path}: frame already saved; frames are never overwritten"
            ) from exc
        retake = self._retake
        if retake is not None and step_id in retake[1]:
            self._record_frame(path, step_id, name, retake=retake[0])
        else:
            self._record_frame(path, step_id, name)
        return path

    def _record_frame(self, path: Path, step_id: str, name: str, **extra: Any) -> None:
        self.log_event(
            "frame_saved",
            step_id=step_id,
            name=name,
            file=path.relative_to(self.path).as_posix(),
            sha256=sha256_file(path),
            **extra,
        )

    def _frame_records(self) -> dict[str, dict[str, Any]]:
        """``relative file -> frame_saved event`` (first record wins: it is the original hash).

        A copy: the events in it are shared with the journal (read them, never change them)."""
        return dict(self._indexed_records()[0])

    def _indexed_records(self) -> tuple[dict[str, dict[str, Any]],
                                        dict[str, list[dict[str, Any]]]]:
        """``(relative file -> frame_saved event, step id -> its events)``, shared (read
        only). Brought up to date with the events appended since the last call, so saving a
        frame costs the same whatever the number of frames before it."""
        with self._journal_lock:
            (generation, count), events = self._journal()
            index = self._records_index
            if index is None or index[0] != generation:
                index = (generation, 0, {}, {})
            _, seen, recs, by_step = index
            for ev in events[seen:count]:
                if ev.get("kind") == "frame_saved" and "file" in ev:
                    file = str(ev["file"])
                    if file not in recs:
                        recs[file] = ev
                        by_step.setdefault(str(ev.get("step_id")), []).append(ev)
            self._records_index = (generation, count, recs, by_step)
            return recs, by_step

    def _recover_orphan_frames(self) -> None:
        known = self._frame_records()
        if not self.frames_dir.is_dir():
            return
        for path in sorted(self.frames_dir.glob("*.tiff")):
            rel = path.relative_to(self.path).as_posix()
            if rel in known or "__" not in path.stem:
                continue
            step_id, name = path.stem.split("__", 1)
            name = _TAKE_RE.sub("", name)  # a take after rejected frames: the same frame name
            try:
                load_frame_tiff(path)
            except FrameFileError as exc:
                self.log_event("frame_unreadable", file=rel, error=str(exc))
                continue
            extra: dict[str, Any] = {}
            if name in self.step_frames(step_id):  # a new take beside a current one: a retake's
                extra["retake"] = self._last_retake_of(step_id) or "unknown"
            self._record_frame(path, step_id, name, recovered=True, **extra)

    def step_frames(self, step_id: str) -> dict[str, Path]:
        """Frames saved by a step and not rejected: ``name -> path`` (the current take).

        A frame taken by a retake (:meth:`begin_retake`) is current once the retake is adopted
        (:meth:`adopt_retake`); until then only the process running the retake sees it, in
        place of the step's previous take - an interrupted retake leaves that take current."""
        rejected, adopted = self._set_aside()
        active = self._retake if self._retake is not None and step_id in self._retake[1] \
            else None
        out: dict[str, Path] = {}
        with self._journal_lock:
            step_events = list(self._indexed_records()[1].get(step_id, ()))
        for ev in step_events:
            file = str(ev["file"])
            if file in rejected:
                continue
            tag = ev.get("retake")
            if (tag != active[0]) if active is not None else (tag is not None
                                                              and file not in adopted):
                continue
            out[str(ev["name"])] = self.path / file
        return out

    def rejected_frames(self) -> dict[str, str]:
        """Frames set aside by :meth:`reject_frames`: relative file -> reason. They stay on
        disk and in the hash checks; no analysis and no resume uses them."""
        return dict(self._rejected())

    def _rejected(self) -> dict[str, str]:
        return self._set_aside()[0]

    def _adopted(self) -> frozenset[str]:
        """Frames a retake made current (:meth:`adopt_retake`)."""
        return self._set_aside()[1]

    def _set_aside(self) -> tuple[dict[str, str], frozenset[str]]:
        """``(rejected file -> reason, adopted files)``: a retake's adoption rejects the takes
        it supersedes and adopts its own in one journal line. Kept up to date with the
        events appended since the last call, like :meth:`_indexed_records`."""
        with self._journal_lock:
            (generation, count), events = self._journal()
            index = self._set_aside_index
            if index is None or index[0] != generation:
                index = (generation, 0, {}, set())
            _, seen, found, adopted = index
            for ev in events[seen:count]:
                if ev.get("kind") in ("frames_rejected", RETAKE_ADOPTED):
                    for f in ev.get("files") or ():
                        found[str(f)] = str(ev.get("reason", ""))
                    adopted.update(str(f) for f in ev.get("adopted") or ())
            self._set_aside_index = (generation, count, found, adopted)
            return dict(found), frozenset(adopted)

    def reject_frames(self, step_id: str, names: Collection[str], reason: str) -> list[str]:
        """Set aside a step's current frames ``names`` (their content cannot be used, e.g. no
        LED in them): journalled, never deleted; the step then acquires new ones."""
        current = self.step_frames(step_id)
        files = [current[n].relative_to(self.path).as_posix() for n in names if n in current]
        if files:
            self.log_event("frames_rejected", step_id=step_id, files=files, reason=reason)
        return files

    # ------------------------------------------------------------------ retakes
    def retakes(self) -> list[dict[str, Any]]:
        """Every retake, oldest first: ``id``, ``steps``, ``reason``, ``started_at`` and
        ``status`` - "adopted" (its takes are current), "running" (a live process is taking
        them), "interrupted" (stopped before adoption: the previous takes stay current) - with
        ``current`` (step -> take number) once adopted."""
        out: dict[str, dict[str, Any]] = {}
        for ev in self._journal()[1]:
            rid = ev.get("retake")
            if not isinstance(rid, str):
                continue
            kind = ev.get("kind")
            if kind == RETAKE_STARTED:
                out[rid] = {"id": rid, "steps": list(ev.get("steps") or ()),
                            "reason": str(ev.get("reason") or ""),
                            "started_at": str(ev.get("time", "")), "status": "running"}
            elif kind == RETAKE_ADOPTED and rid in out:
                out[rid].update(status="adopted", current=dict(ev.get("takes") or {}),
                                adopted_at=str(ev.get("time", "")))
            elif kind == RETAKE_STOPPED and rid in out and out[rid]["status"] == "running":
                out[rid].update(status="interrupted", stopped=str(ev.get("status", "")))
        # Running: the retake this object runs, or the last one while another live process
        # writes the session; any other that never ended was stopped by a kill.
        live = self._retake[0] if self._retake is not None else None
        last = next(reversed(out), None)
        other = live is None and not self.held and session_holder(self.path) is not None
        for rec in out.values():
            if rec["status"] == "running" and not (rec["id"] == live
                                                   or (other and rec["id"] == last)):
                rec.update(status="interrupted", stopped="writer gone")
        return list(out.values())

    def _last_retake_of(self, step_id: str) -> str | None:
        found = None
        for ev in self._journal()[1]:
            if ev.get("kind") == RETAKE_STARTED and step_id in (ev.get("steps") or ()):
                found = str(ev.get("retake"))
        return found

    def current_take(self, step_id: str) -> int:
        """The take number of a step's current frames (1: never taken again; the highest
        ``.take<N>`` of its current frame files)."""
        return max(map(take_of, self.step_frames(step_id).values()), default=1)

    def begin_retake(self, step_ids: Collection[str], reason: str = "",
                     previous_status: str | None = None) -> str:
        """Start taking ``step_ids`` again (their frames so far are kept, never edited). Until
        :meth:`adopt_retake`, frames those steps save are the retake's: this object sees them
        in place of the current takes, every other reader still sees the current takes.
        Journalled (``retake_started``) and recorded in ``session.json`` (``retake``).
        ``previous_status``: the session's status before this run set it "running" (a
        retake of a completed session that is stopped leaves it completed). Only the
        session's writer may do this. Returns the retake's id."""
        if not self.held:
            raise SessionError(f"{self.path}: only the session's writer starts a retake")
        if self._retake is not None:
            raise SessionError(f"{self.path}: retake {self._retake[0]} is already running")
        steps = [_check_name("step id", s) for s in step_ids]
        rid = f"r{sum(1 for ev in self._journal()[1] if ev.get('kind') == RETAKE_STARTED) + 1}"
        previous = {s: self.current_take(s) for s in steps}
        self.log_event(RETAKE_STARTED, retake=rid, steps=steps, reason=reason,
                       previous_takes=previous,
                       previous_frames={s: sorted(p.relative_to(self.path).as_posix()
                                                  for p in self.step_frames(s).values())
                                        for s in steps})
        record = {"id": rid, "steps": steps, "reason": reason, "status": "running",
                  "started_at": _now_iso(), "previous_status": previous_status or self.status,
                  "previous_takes": previous}
        self._retake = (rid, frozenset(steps))
        self.update_meta(status="running", retake=record)
        return rid

    @property
    def retake_running(self) -> str | None:
        """The id of the retake this object runs (not yet adopted), else None."""
        return self._retake[0] if self._retake is not None else None

    def adopt_retake(self) -> dict[str, int]:
        """Make the running retake's frames current, in ONE journal line that also sets the
        takes they supersede aside (kept on disk and in the hash checks, never analysed).
        Results written before are stale from then on (:meth:`results_stale`). Returns
        step -> its current take number."""
        if self._retake is None:
            raise SessionError(f"{self.path}: no retake is running")
        rid, steps = self._retake
        new = {s: self.step_frames(s) for s in sorted(steps)}
        missing = sorted(s for s, frames in new.items() if not frames)
        if missing:
            raise SessionError(f"{self.path}: retake {rid} has no frames for "
                               f"{', '.join(missing)}; nothing adopted")
        self._retake = None
        old = {s: self.step_frames(s) for s in sorted(steps)}
        superseded = [p.relative_to(self.path).as_posix() for s in sorted(steps)
                      for n, p in old[s].items() if n in new[s]]
        adopted = [p.relative_to(self.path).as_posix() for s in sorted(steps)
                   for p in new[s].values()]
        reason = str(self._meta.get("retake", {}).get("reason") or "")
        takes = {s: max(map(take_of, new[s].values())) for s in sorted(steps)}
        self.log_event(RETAKE_ADOPTED, retake=rid, steps=sorted(steps), files=superseded,
                       adopted=adopted, takes=takes,
                       reason=f"superseded by retake {rid}" + (f": {reason}" if reason else ""))
        meta_takes = dict(self._meta.get("takes") or {})
        for s in sorted(steps):
            meta_takes[s] = {"take": takes[s], "retake": rid, "reason": reason,
                             "frames": sorted(f for f in adopted
                                              if f.startswith(f"{FRAMES_DIR}/{s}__"))}
        retake = {**dict(self._meta.get("retake") or {}), "status": "adopted",
                  "adopted_at": _now_iso(), "current_takes": takes}
        self.update_meta(takes=meta_takes, retake=retake)
        return takes

    def stop_retake(self, status: str) -> None:
        """The running retake ended before adoption (``status``: interrupted, aborted,
        failed): journalled and recorded; the previous takes stay current, the retake's frames
        stay on disk beside them, never current."""
        if self._retake is None:
            return
        rid, steps = self._retake
        self._retake = None
        self.log_event(RETAKE_STOPPED, retake=rid, steps=sorted(steps), status=status,
                       message="previous takes stay current")
        retake = {**dict(self._meta.get("retake") or {}), "status": status,
                  "stopped_at": _now_iso(), "note": "previous takes stay current"}
        self.update_meta(retake=retake)

    def results_stale(self) -> str | None:
        """Why the latest results no longer describe the current frames (a retake adopted
        after they were written), or None."""
        latest = self.latest_results()
        adopted = [r for r in self.retakes() if r["status"] == "adopted"]
        if latest is None or not adopted:
            return None
        try:
            created = str(json.loads((latest / "summary.json").read_text(encoding="utf-8"))
                          .get("created_at", ""))
        except (OSError, ValueError, AttributeError):
            created = ""
        later = [r for r in adopted if str(r.get("adopted_at", "")) > created]
        if not later:
            return None
        steps = sorted({s for r in later for s in r["steps"]})
        return (f"results {latest.name} predate retake {later[-1]['id']} of "
                f"{', '.join(steps)}; run benchlab analyze {self.path}")

    def current_frames(self) -> list[tuple[str, str, Path]]:
        """``(step_id, name, path)`` of every frame an analysis uses - each step's current
        take (:meth:`step_frames`) - in the order they were first recorded."""
        out: list[tuple[str, str, Path]] = []
        current: dict[str, dict[str, Path]] = {}
        for ev in self._frame_records().values():
            step_id, name = str(ev.get("step_id", "")), str(ev.get("name", ""))
            if step_id not in current:
                current[step_id] = self.step_frames(step_id)
            path = current[step_id].pop(name, None)  # once per name: its current take
            if path is not None:
                out.append((step_id, name, path))
        return out

    def frames(self) -> dict[str, str]:
        """Every recorded frame: relative file -> recorded sha256."""
        return {f: str(ev["sha256"]) for f, ev in self._frame_records().items()}

    def prefetch_frames(self, threads: int) -> None:
        """Start loading every recorded frame on ``threads`` threads, so that the reading,
        hashing and inflating (zlib and sha256 release the GIL) overlap whatever the caller
        does next (a re-analysis imports its analysis meanwhile). :meth:`load_frame` hands out
        each prefetched frame once, with the same hash check and errors as a direct load.
        Stopped by :meth:`stop_prefetch` (and :meth:`release`)."""
        self.stop_prefetch()
        pool = ThreadPoolExecutor(max_workers=max(1, threads),
                                  thread_name_prefix="benchlab-frames")
        self._prefetch_pool = pool
        for _, _, path in sorted(self.current_frames(), key=lambda f: f[2]):
            rel = path.relative_to(self.path).as_posix()  # the take load_frame hands out
            self._prefetched[rel] = pool.submit(self._load_frame_now, path, rel)

    @property
    def prefetching(self) -> bool:
        """Whether :meth:`prefetch_frames` is loading (or holds) frames ahead."""
        return self._prefetch_pool is not None

    def stop_prefetch(self) -> None:
        """Drop frames prefetched and not yet handed out; cancel loads not yet started."""
        pool, self._prefetch_pool = self._prefetch_pool, None
        self._prefetched = {}
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)

    def load_frame(self, step_id: str, name: str) -> tuple[npt.NDArray[Any], dict[str, Any]]:
        """Load a recorded frame after checking its hash against the journal.

        Raises
        ------
        SessionError
            If the frame was never recorded or its bytes changed since it was saved.
        FrameFileError
            If the file is unreadable.
        """
        current = self.step_frames(step_id).get(name)
        path = current or self.frame_path(step_id, name)
        rel = path.relative_to(self.path).as_posix()
        if current is None and rel in self._rejected():
            raise SessionError(f"{path}: frame was rejected ({self._rejected()[rel]}); "
                               "no analysis uses it")
        ahead = self._prefetched.pop(rel, None)
        if ahead is not None and not ahead.cancelled():
            return ahead.result()
        return self._load_frame_now(path, rel)

    def _load_frame_now(self, path: Path, rel: str) -> tuple[npt.NDArray[Any], dict[str, Any]]:
        rec = self._frame_records().get(rel)
        if rec is None:
            raise SessionError(f"{path}: no such frame recorded in {self.events_path}")
        try:
            with open(path, "rb") as fh:
                # identity before reading: a write after it changes the ctime seen later
                identity = file_identity(os.fstat(fh.fileno()))
                data = fh.read()  # read once: the bytes hashed are the bytes decoded
        except FileNotFoundError:
            raise SessionError(f"{path}: recorded frame is missing") from None
        expected = str(rec["sha256"])
        if hashlib.sha256(data).hexdigest() != expected:
            raise SessionError(f"{path}: frame modified since it was saved (sha256 mismatch)")
        self._verified[rel] = (identity, expected)
        return load_frame_tiff(path, data)

    def frame(self, name: str) -> npt.NDArray[Any]:
        """The pixels of one recorded frame, its hash checked against the journal first.

        Parameters
        ----------
        name : str
            The frame's file name in ``frames/`` (``"forward__forward.tiff"``), or its path in
            the session as :meth:`frames` lists it (``"frames/forward__forward.tiff"``).

        Returns
        -------
        numpy.ndarray
            2-D, the frame's own dtype (``uint8``, or ``uint16`` for 10/12-bit frames).
            :meth:`load_frame` also gives the metadata.

        Raises
        ------
        SessionError
            No such frame recorded (the message lists the recorded ones), the file missing,
            or its bytes changed since it was saved.
        """
        rel = name if name.startswith(f"{FRAMES_DIR}/") else f"{FRAMES_DIR}/{name}"
        if rel not in self._frame_records():
            known = ", ".join(Path(f).name for f in self.frames()) or "none"
            raise SessionError(f"{self.path}: no frame {name!r} in this session; its frames: "
                               f"{known}")
        return self._load_frame_now(self.path / rel, rel)[0]

    def verify_frames(self, *, trust_loads: bool = False) -> list[str]:
        """Relative paths of recorded frames that are missing or whose sha256 changed.

        A frame this object already hashed (a load, an earlier check) is not hashed again while
        its file identity - device, inode, size, modification and status-change times - is
        the one it had when read: any write to the file sets its status-change time (ctime),
        which no program can set back. So a re-analysis reads and hashes each frame once
        (its loads) and its checks before and after cost a ``stat`` per frame. Frames still
        being loaded ahead (:meth:`prefetch_frames`) are waited for (their loads hash them),
        or with ``trust_loads`` left to their loads, which raise on a mismatch (the analysis
        then starts while the last frames load).
        """
        records = sorted(self._frame_records().items())
        ahead = {rel: f for rel, f in ((rel, self._prefetched.get(rel)) for rel, _ in records)
                 if f is not None and not f.done()}
        if trust_loads:
            records = [(rel, ev) for rel, ev in records if rel not in ahead]
        elif ahead:
            wait(ahead.values())  # their outcome is read below, from what they verified
        bad = []
        for rel, ev in records:
            path = self.path / rel
            try:
                st = os.stat(path)
            except OSError:
                bad.append(rel)
                continue
            expected = str(ev["sha256"])
            identity = file_identity(st)
            if not stat.S_ISREG(st.st_mode):
                bad.append(rel)
            elif self._verified.get(rel) == (identity, expected):
                continue
            elif sha256_file(path) != expected:
                bad.append(rel)
            else:
                self._verified[rel] = (identity, expected)
        return bad

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

    # ------------------------------------------------------------------ results
    def mark_results_partial(self, status: str, steps_done: int, steps_total: int) -> None:
        """Results written from now on come from an incomplete session: ``summary.json`` says
        ``"partial": true`` with the session status and the steps done."""
        self._partial = {"partial": True, "session_status": status,
                         "steps_done": steps_done, "steps_total": steps_total}

    def result_versions(self) -> list[int]:
        """Existing results versions, ascending: ``results/v<N>`` folders holding their
        summary.json (an empty or partial folder - a crash of older software between
        claiming a number and filling it - is no version)."""
        if not self.results_dir.is_dir():
            return []
        found = []
        for p in self.results_dir.iterdir():
            m = _VERSION_DIR.match(p.name)
            if m and (p / "summary.json").is_file():
                found.append(int(m.group(1)))
        return sorted(found)

    def latest_results(self) -> Path | None:
        """The newest ``results/v<N>`` folder, or None before the first analysis."""
        versions = self.result_versions()
        return self.results_dir / f"v{versions[-1]}" if versions else None

    def tables(self) -> list[str]:
        """The tables of the latest results version, by file name (``forward_view_modulation``,
        ...), in the thesis' table order; empty before the first analysis."""
        latest = self.latest_results()
        return [] if latest is None else _table_names(read_results(latest, only=())[1])

    def table(self, name: str) -> list[dict[str, Any]]:
        """One table of the latest results version: a list of rows (column -> value).

        Parameters
        ----------
        name : str
            Its file name (``"forward_view_modulation"``, see :meth:`tables`) or its thesis
            label (``"table_4_11"``).

        Returns
        -------
        list of dict
            Read from the table's JSON file, so values keep their types (numbers, booleans,
            lists); a missing value (NaN when written) is ``None``.

        Raises
        ------
        SessionError
            No results yet, or no such table (the message lists the tables there are), or the
            file is damaged.
        """
        latest = self.latest_results()
        if latest is None:
            raise SessionError(f"{self.path}: no results yet (session {self.status}), so no "
                               f"table {name!r}")
        label = _LABEL_OF_FILE.get(name, name)
        tables, summary = read_results(latest, only=(label,))
        rows = tables.get(label)
        if label not in _table_labels(summary) or not isinstance(rows, list):
            raise SessionError(f"{latest}: no table {name!r}; its tables: "
                               f"{', '.join(_table_names(summary)) or 'none'}")
        return rows

    def _identical_version(self, staged: Path, same: Mapping[str, Any]) -> int | None:
        """The newest existing version with the summary ``same`` (inputs, settings, software
        version, summary) and byte-identical files to the ``staged`` folder; None if none."""
        staged_files: dict[str, bytes] | None = None
        for version in reversed(self.result_versions()):
            folder = self.results_dir / f"v{version}"
            if not _same_summary(folder, same):
                continue
            if staged_files is None:
                staged_files = _tree_bytes(staged)
            if _tree_bytes(folder) == staged_files:
                return version
        return None

    def write_results(
        self,
        tables: Mapping[str, list[dict[str, Any]]],
        *,
        summary: Mapping[str, Any],
        estimator: str,
        extra_dirs: Mapping[str, Path] | None = None,
    ) -> Path:
        """Write a new results version: ``<file>.csv`` + ``<file>.json`` per table (file names
        from :data:`RESULT_FILE_STEMS`, e.g. ``forward_view_modulation`` for ``table_4_11``),
        and summary.json (which maps each table label to its file). ``extra_dirs``: folders
        already written under ``results/`` (``name -> folder``), moved into the version as
        ``name`` before it appears, so the version never exists without them.

        The version folder is assembled under a temporary name and renamed into place, so a
        crash never leaves a half-written version; existing versions are never touched.
        NaN is written as ``null`` in JSON and ``NA`` in CSV. With :attr:`reuse_identical_results`
        (a re-analysis) a version whose summary differs only in its number and time and whose
        files are byte-identical is returned instead (:attr:`matched_version`; journal event
        ``results_matched``): fifty identical re-analyses leave one version, anything else
        still adds one. With :data:`RESULTS_FSYNC`
        ``"syncfs"`` (default) or ``"per-version"`` the files are flushed together just before
        the rename (one file-system flush, or one fsync per file), instead of a file and
        directory fsync per file; either way the version is on disk before this returns.
        """
        per_file = RESULTS_FSYNC == "per-file"
        for table in tables:
            _check_name("table name", table)
        if self.verify_frames_before_results:
            bad = self.verify_frames()
            if bad:
                raise SessionError(f"{self.path}: frames changed since acquisition: "
                                   f"{', '.join(bad)}; no results written")
        self.results_dir.mkdir(exist_ok=True)
        tmp = make_staging_dir(self.results_dir, ".v-")

        def write(path: Path, text: str) -> None:
            if per_file:
                atomic_write_text(path, text)
            else:  # the folder is private until its rename: no temporary file per file
                write_new_file(path, text.encode("utf-8"))

        try:
            for name, folder in (extra_dirs or {}).items():
                _check_name("folder name", name)
                os.replace(folder, tmp / name)  # same file system: a rename
            for table, rows in tables.items():
                plain_rows = [_plain(dict(r)) for r in rows]
                stem = result_file_stem(table)
                write(tmp / f"{stem}.json", json_rows_text(plain_rows))
                write(tmp / f"{stem}.csv", _csv_text(plain_rows))
            self.matched_version = None
            same = {
                "estimator": estimator,
                "software_version": _software_version(),
                "tables": sorted(tables),
                "table_files": {t: result_file_stem(t) for t in sorted(tables)},
                "frames_sha256": self.frames(),
                "summary": _plain(summary),
                **(self._partial or {"partial": False}),
            }
            if self.reuse_identical_results:
                matched = self._identical_version(tmp, same)
                if matched is not None:
                    shutil.rmtree(tmp, ignore_errors=True)
                    self.matched_version = matched
                    self.log_event("results_matched", durable=False, version=matched,
                                   estimator=estimator)
                    return self.results_dir / f"v{matched}"
            version = (self.result_versions() or [0])[-1] + 1
            while True:
                doc = {"version": version, "created_at": _now_iso(), **same}
                atomic_write_json(tmp / "summary.json", doc, durable=per_file)
                if RESULTS_FSYNC == "syncfs":
                    flush_folder(tmp)
                elif not per_file:
                    fsync_tree(tmp)
                target = self.results_dir / f"v{version}"
                try:
                    # Atomic, and only onto a free name (or an empty folder, left by a crash
                    # of older software): no moment where v<N> exists but is not complete.
                    os.rename(tmp, target)
                except OSError as exc:
                    if not (isinstance(exc, FileExistsError)
                            or exc.errno in (errno.EEXIST, errno.ENOTEMPTY)):
                        raise
                    # Another writer's version, or a folder that is none: the next number.
                    version = max(version + 1, (self.result_versions() or [0])[-1] + 1)
                    continue
                fsync_dir(self.results_dir)  # the rename itself
                break
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        # Not fsync'd: the version is already durable and resume does not read this line.
        self.log_event("results_written", durable=False, version=version, estimator=estimator)
        return target


def _software_version() -> str:
    import benchlab

    return str(benchlab.__version__)


def _tree_bytes(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes), ``summary.json`` left out."""
    files = {p.relative_to(folder).as_posix(): p for p in folder.rglob("*") if p.is_file()}
    return {rel: p.read_bytes() for rel, p in sorted(files.items()) if rel != "summary.json"}


def _same_summary(folder: Path, same: Mapping[str, Any]) -> bool:
    """Whether ``folder``'s summary.json is ``same`` but for its version number and time."""
    try:
        doc = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if not isinstance(doc, dict):
        return False
    doc.pop("version", None)
    doc.pop("created_at", None)
    try:  # through JSON: the stored document's types (lists for tuples, str keys)
        want = json.loads(json.dumps(same, allow_nan=False, default=json_default))
    except (TypeError, ValueError):
        return False
    return bool(doc == want)


#: Result files are named after what they hold; the thesis table stays the table's label
#: (the key in ``tables``, the report's caption). Labels not listed are their own file names.
RESULT_FILE_STEMS: dict[str, str] = {
    "table_4_11": "forward_view_modulation",
    "table_4_12": "radial_view_modulation",
    "table_4_13": "image_heights_field_points",
    "table_4_15": "averaged_mtf_vs_monte_carlo",
    "table_4_16": "relative_radiometry",
}
_LABEL_OF_FILE = {stem: label for label, stem in RESULT_FILE_STEMS.items()}


def result_file_stem(label: str) -> str:
    """The file name (without ``.csv`` / ``.json``) a results table is written under."""
    return RESULT_FILE_STEMS.get(label, label)


def read_results(folder: str | os.PathLike[str], only: Collection[str] | None = None,
                 skip: Collection[str] = ()) -> tuple[dict[str, Any], dict[str, Any]]:
    """Tables (``label -> rows``) and ``summary.json`` of one ``results/vN`` folder; with
    ``only``, just the tables of those labels; tables labelled in ``skip`` are not read (the
    catalogue skips the SFR curves, the largest file of a version).

    Reads both the descriptive file names and the older thesis-table file names
    (``table_4_11.json``), so sessions written before the rename still load.
    Raises :class:`SessionError` naming the file when a JSON file is unreadable, when
    ``summary.json`` is not an object, or when a table it lists (and that was asked for) is
    missing or is not a list of row objects: a damaged version is an error, never a report or
    a listing with a table silently left out.
    """
    tables: dict[str, Any] = {}
    summary: dict[str, Any] = {}
    for p in sorted(Path(folder).glob("*.json")):
        label = _LABEL_OF_FILE.get(p.stem, p.stem)
        if p.stem != "summary" and ((only is not None and label not in only) or label in skip):
            continue
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise SessionError(f"{p}: unreadable results file ({exc})") from exc
        if p.stem == "summary":
            if not isinstance(data, dict):
                raise SessionError(f"{p}: not a results summary (a JSON object expected, "
                                   f"found {type(data).__name__})")
            summary = data
        else:
            tables[label] = data
    listed = summary.get("tables")
    named = summary.get("table_files")
    files: dict[str, Any] = named if isinstance(named, dict) else {}
    for label in listed if isinstance(listed, list) else []:
        if not isinstance(label, str) or (only is not None and label not in only) \
                or label in skip:
            continue
        path = Path(folder) / f"{files.get(label) or result_file_stem(label)}.json"
        if label not in tables:
            raise SessionError(f"{path}: missing (summary.json lists table {label})")
        rows = tables[label]
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise SessionError(f"{path}: not a table (a JSON list of row objects expected, "
                               f"found {_json_kind(rows)})")
    return dict(sorted(tables.items())), summary  # in label order, as the thesis numbers them


def _table_labels(summary: Mapping[str, Any]) -> list[str]:
    """The table labels a results ``summary.json`` lists."""
    listed = summary.get("tables")
    return [t for t in listed if isinstance(t, str)] if isinstance(listed, list) else []


def _table_names(summary: Mapping[str, Any]) -> list[str]:
    """The file names of the tables a results ``summary.json`` lists."""
    named = summary.get("table_files")
    files: Mapping[str, Any] = named if isinstance(named, Mapping) else {}
    return [str(files.get(t) or result_file_stem(t)) for t in _table_labels(summary)]


def _json_kind(value: Any) -> str:
    if isinstance(value, list):
        bad = next(v for v in value if not isinstance(v, dict))
        return f"a list holding {'null' if bad is None else type(bad).__name__}"
    return "null" if value is None else type(value).__name__


def _csv_text(rows: list[dict[str, Any]]) -> str:
    columns: list[str] = []
    seen: set[str] = set()
    for row in rows:
        for k in row:
            if k not in seen:
                seen.add(k)
                columns.append(k)
    buf = io.StringIO()
    # csv.writer with lists: the text DictWriter writes, without its per-row key checks (a
    # results version has ~700 rows, most of them the SFR curves).
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    # a cell: NA for a missing value, JSON for a list or table, else the value (inline: a
    # function call per cell was a third of the time)
    writer.writerows([CSV_MISSING if v is None else json.dumps(v) if isinstance(v, dict | list)
                      else v for v in map(row.get, columns)] for row in rows)
    return buf.getvalue()

