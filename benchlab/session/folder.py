"""A session folder's state and ``session.json``: the base every part of :class:`Session`
builds on."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

from benchlab.session.layout import (
    FRAMES_DIR,
    RESULTS_DIR,
    SESSION_FILE,
    _plain,
)
from benchlab.session.lock import (
    session_holder,
)
from benchlab.storage import (
    atomic_write_json,
)


class SessionFolder:
    """The folder, its metadata and whether this object holds the owner lock."""

    def __init__(self, path: Path, meta: dict[str, Any]) -> None:
        self.path = Path(path)
        self._meta = meta
        self._lock = threading.Lock()
        self._owner_fd: int | None = None

    @property
    def held(self) -> bool:
        """Whether this object holds the session's owner lock."""
        return self._owner_fd is not None

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
