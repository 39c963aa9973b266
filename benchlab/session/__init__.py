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

One class, :class:`Session`, built in layers, each module one job and each layer using only
the ones before it: :mod:`.layout` (names, errors) and :mod:`.lock` (the owner lock);
:mod:`.folder` (``session.json``) < :mod:`.journal` (``events.jsonl``, read incrementally by
:mod:`.journal_reader`) < :mod:`.frames` < :mod:`.retakes` < :mod:`.results` < :mod:`.core`
(create, open, hold). Import from ``benchlab.session``; the modules are its implementation.
"""


from __future__ import annotations

from benchlab.session.core import (  # noqa: F401 (re-exported)
    Session,
)
from benchlab.session.frames import (  # noqa: F401 (re-exported)
    FRAME_LOAD_THREADS,
)
from benchlab.session.layout import (  # noqa: F401 (re-exported)
    CSV_MISSING,
    EVENTS_FILE,
    FRAMES_DIR,
    OWNER_FILE,
    RESULTS_DIR,
    RETAKE_ADOPTED,
    RETAKE_STARTED,
    RETAKE_STOPPED,
    SESSION_FILE,
    SESSION_FORMAT,
    SESSION_VERSION,
    VERDICTS_DIR,
    FrameExistsError,
    SessionBusyError,
    SessionError,
    _plain,
    check_sessions_root,
    take_of,
)
from benchlab.session.lock import (  # noqa: F401 (re-exported)
    HOLD_RETRY_S,
    describe_holder,
    session_holder,
)
from benchlab.session.results import (  # noqa: F401 (re-exported)
    RESULT_FILE_STEMS,
    RESULTS_FSYNC,
    _csv_text,
    read_results,
    result_file_stem,
)

__all__ = [
    "CSV_MISSING",
    "EVENTS_FILE",
    "FRAMES_DIR",
    "FRAME_LOAD_THREADS",
    "FrameExistsError",
    "HOLD_RETRY_S",
    "OWNER_FILE",
    "RESULTS_DIR",
    "RESULTS_FSYNC",
    "RESULT_FILE_STEMS",
    "RETAKE_ADOPTED",
    "RETAKE_STARTED",
    "RETAKE_STOPPED",
    "SESSION_FILE",
    "SESSION_FORMAT",
    "SESSION_VERSION",
    "Session",
    "SessionBusyError",
    "SessionError",
    "VERDICTS_DIR",
    "check_sessions_root",
    "describe_holder",
    "read_results",
    "result_file_stem",
    "session_holder",
    "take_of",
]
