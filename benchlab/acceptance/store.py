"""Verdicts stored in the session folder: ``verdicts/v<N>.json``, one file per verification.

A re-verification (a new spec revision, a re-analysis) adds ``v<N+1>``; a written version is
never edited or replaced (created with ``link(2)``, which refuses an existing name). A
verification whose record equals the newest version's (all but its time) adds nothing: fifty
identical verifies leave one version, as fifty identical re-analyses leave one results
version. The journal line names the version and the spec by file and SHA-256; the spec's
content lives in the verdict file only. The
record holds everything a certificate shows - unit, spec (name, revision, sha256 of the
file), rule, every row, the sessions with their results version and frame hashes, and the
software version that decided - so a certificate is rendered from the stored record, not
from a second verification.
"""

from __future__ import annotations

import json
import re
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from benchlab.acceptance.verify import UnitResult
from benchlab.session import VERDICTS_DIR, Session, SessionError
from benchlab.storage import atomic_write_json

VERDICT_FORMAT = "benchlab.verdict"
VERDICT_FORMAT_VERSION = 1
_VERSION_FILE = re.compile(r"^v(\d+)\.json$")


def record_of(unit: UnitResult, software_version: str) -> dict[str, Any]:
    """The JSON record of one unit's verification (without its version number)."""
    return {
        "format": VERDICT_FORMAT,
        "format_version": VERDICT_FORMAT_VERSION,
        "created_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "software_version": software_version,
        "unit": {"serial": unit.serial, "lot": unit.lot},
        "spec": unit.spec.header(),
        "verdict": unit.verdict,
        "limits": unit.limit_verdicts(),
        "sessions": [s.identity() for s in unit.sessions],
        "rows": [v.as_dict() for v in unit.verdicts],
        "disagreements": [d.as_dict() for d in unit.disagreements],
    }


def verdict_versions(session_path: str | Path) -> list[int]:
    """The session's verdict versions, ascending."""
    folder = Path(session_path) / VERDICTS_DIR
    if not folder.is_dir():
        return []
    return sorted(int(m.group(1)) for p in folder.iterdir()
                  if (m := _VERSION_FILE.match(p.name)))


def read_verdict(session_path: str | Path, version: int | None = None) -> dict[str, Any]:
    """One stored verdict record (the newest by default).

    Raises
    ------
    SessionError
        Naming the file when there is none, or it is not a verdict record.
    """
    if not (Path(session_path) / "session.json").is_file():
        raise SessionError(f"{session_path}: not a session folder (no session.json)")
    versions = verdict_versions(session_path)
    if not versions:
        raise SessionError(f"{session_path}: no verdict stored (run benchlab verify first)")
    version = versions[-1] if version is None else version
    path = Path(session_path) / VERDICTS_DIR / f"v{version}.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SessionError(f"{path}: no verdict version {version} (versions: "
                           f"{', '.join(map(str, versions))})") from None
    except (OSError, ValueError) as exc:
        raise SessionError(f"{path}: unreadable verdict ({exc})") from exc
    if not isinstance(doc, dict) or doc.get("format") != VERDICT_FORMAT:
        raise SessionError(f"{path}: not a benchlab verdict record")
    return doc


#: Keys of a record that may differ between two verifications that decided the same.
_VOLATILE_KEYS = ("created_at", "version", "stored")


def same_verdict(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether two records decided the same (everything but their time and version)."""
    def strip(r: dict[str, Any]) -> str:
        return json.dumps({k: v for k, v in r.items() if k not in _VOLATILE_KEYS},
                          sort_keys=True, default=str)

    return strip(a) == strip(b)


def store_verdict(session_path: str | Path, record: dict[str, Any]
                  ) -> tuple[Path, int, bool]:
    """Write ``record`` as the session's next verdict version and journal it, unless the
    newest version holds the same verdict.

    The writer takes the session's owner lock for the write, so a verification never mixes
    into a run or a re-analysis in progress (:class:`~benchlab.session.SessionBusyError`).
    Returns the file, its version and whether it was written (False: the newest version
    already held this verdict; nothing written, nothing journalled).
    """
    session = Session.open(Path(session_path))
    session.hold(command="benchlab verify")
    try:
        folder = session.path / VERDICTS_DIR
        versions = verdict_versions(session.path)
        if versions:
            try:
                newest = read_verdict(session.path, versions[-1])
            except SessionError:
                newest = None  # unreadable: a new version is written beside it
            if newest is not None and same_verdict(newest, record):
                return folder / f"v{versions[-1]}.json", versions[-1], False
        folder.mkdir(exist_ok=True)
        version = (versions or [0])[-1] + 1
        while True:
            path = folder / f"v{version}.json"
            try:
                atomic_write_json(path, {**record, "version": version}, overwrite=False)
                break
            except FileExistsError:
                version += 1
        spec = record["spec"]
        session.log_event("verdict_written", version=version, spec_file=spec.get("file"),
                          spec_sha256=spec.get("sha256"), verdict=record["verdict"])
    finally:
        session.release()
    return path, version, True
