"""A session's raw frames: saving them (never overwritten), which take is current, loading
them ahead and checking them against the hashes the journal recorded."""

from __future__ import annotations

import hashlib
import os
import stat
from collections.abc import Collection, Mapping
from concurrent.futures import Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any

import numpy.typing as npt

from benchlab.session.journal import SessionJournal
from benchlab.session.journal_reader import file_identity
from benchlab.session.layout import (
    _TAKE_MARK,
    _TAKE_RE,
    FRAMES_DIR,
    RETAKE_ADOPTED,
    RETAKE_STARTED,
    FrameExistsError,
    SessionError,
    _check_name,
    _plain,
)
from benchlab.storage import (
    FrameFileError,
    load_frame_tiff,
    save_frame_tiff,
    sha256_file,
)

#: Threads that load a session's frames (decoding releases the GIL; more buys nothing here).
FRAME_LOAD_THREADS = min(4, os.cpu_count() or 1)




class SessionFrames(SessionJournal):
    """Saves, lists, loads and verifies frames."""

    def __init__(self, path: Path, meta: dict[str, Any]) -> None:
        super().__init__(path, meta)
        #: :meth:`_frame_records` and the same records by step, built from the journal's
        #: events as they arrive: ``(reader generation, events seen, records, by step)``.
        self._records_index: tuple[int, int, dict[str, dict[str, Any]],
                                   dict[str, list[dict[str, Any]]]] | None = None
        #: :meth:`rejected_frames` and the frames retakes made current, likewise:
        #: ``(reader generation, events seen, rejected file -> reason, adopted files)``.
        self._set_aside_index: tuple[int, int, dict[str, str], set[str]] | None = None
        #: The retake this object is running (:meth:`begin_retake`): its id and steps.
        self._retake: tuple[str, frozenset[str]] | None = None
        #: Frames being loaded ahead by :meth:`prefetch_frames`: relative file -> load.
        self._prefetched: dict[str, Future[tuple[npt.NDArray[Any], dict[str, Any]]]] = {}
        self._prefetch_pool: ThreadPoolExecutor | None = None
        #: Frames this object has hashed and found as journalled: relative file ->
        #: (file identity when read, sha256); see :meth:`verify_frames`.
        self._verified: dict[str, tuple[tuple[int, ...], str]] = {}

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

    def _last_retake_of(self, step_id: str) -> str | None:
        found = None
        for ev in self._journal()[1]:
            if ev.get("kind") == RETAKE_STARTED and step_id in (ev.get("steps") or ()):
                found = str(ev.get("retake"))
        return found

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

