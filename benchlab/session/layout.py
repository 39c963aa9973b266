"""The session folder's layout and names: file and folder names, errors, the rules for
step ids and frame names, and the JSON-safe copy every session file is written through."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from benchlab.drivers.errors import BenchlabError

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

class SessionError(BenchlabError):
    """A session folder or one of its files is missing, corrupt or misused."""


class FrameExistsError(SessionError):
    """A frame with this step and name is already saved; frames are never overwritten."""


class SessionBusyError(SessionError):
    """Another live process is writing this session (its owner lock is held)."""


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


