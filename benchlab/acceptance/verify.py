"""One unit against a spec: the sessions of the unit, their latest results, a verdict per limit.

Sessions of the same unit (the same serial number, ``sample`` in ``session.json``) are
verified together: a spec may limit an MTF table and a camera table, measured in two
sessions. Each limit reads its table from the newest of the unit's sessions that has it.
When an older session of the unit read the same quantity and the two readings disagree
beyond their uncertainties (:mod:`benchlab.acceptance.agreement`), the row says so, naming
both sessions and readings, and is never a pass: the start time does not settle which
session is right. A session without a serial number is a unit of its own.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchlab.acceptance.agreement import Disagreement, disagreement
from benchlab.acceptance.decide import (
    INDETERMINATE,
    PASS,
    Reading,
    Verdict,
    combine,
    decide,
    missing,
    reading_of,
    row_matches,
)
from benchlab.acceptance.spec import Limit, Spec
from benchlab.session import RESULT_FILE_STEMS, Session, SessionError, read_results

#: Columns that name a row in a verdict (``element=G2E2 orientation=sagittal``), in order.
KEY_COLUMNS = ("view", "element", "edge", "orientation", "test", "object_lp_per_mm",
               "mc_freq_lp_per_mm", "position_mm", "gain", "bits", "freq_lp_per_mm")
_LABEL_OF_FILE = {stem: label for label, stem in RESULT_FILE_STEMS.items()}


@dataclass
class SessionResults:
    """What verification reads of one session: identity and its latest results version."""

    path: Path
    serial: str
    lot: str
    procedure: str
    status: str
    started_at: str
    software_version: str
    results_version: int | None
    partial: bool
    tables: dict[str, list[dict[str, Any]]]
    frames_sha256: dict[str, str]
    #: sha256 of each file of the results version (its ``files_sha256``), checked on reading.
    results_sha256: dict[str, str] = field(default_factory=dict)

    def identity(self) -> dict[str, Any]:
        return {"path": str(self.path), "id": self.path.name, "procedure": self.procedure,
                "status": self.status, "started_at": self.started_at,
                "results_version": self.results_version, "partial": self.partial,
                "software_version": self.software_version,
                "frames_sha256": self.frames_sha256, "results_sha256": self.results_sha256}


def read_session(path: str | Path) -> SessionResults:
    """The latest results of a session folder (only read; nothing is written).

    Raises
    ------
    SessionError
        Naming the folder or file when it is no session, or its results cannot be read.
    """
    session = Session.open(Path(path))
    meta = session.meta
    latest = session.latest_results()
    tables: dict[str, list[dict[str, Any]]] = {}
    summary: dict[str, Any] = {}
    if latest is not None:
        raw, summary = read_results(latest, skip=("table_sfr_curves",))
        tables = {k: v for k, v in raw.items() if isinstance(v, list)}
    frames = summary.get("frames_sha256")
    files = summary.get("files_sha256")
    return SessionResults(
        path=session.path, serial=str(meta.get("sample") or ""), lot=str(meta.get("lot") or ""),
        procedure=session.procedure, status=session.status,
        started_at=str(meta.get("started_at") or ""),
        software_version=str(meta.get("software_version") or ""),
        results_version=int(latest.name[1:]) if latest is not None else None,
        partial=bool(summary.get("partial", False)), tables=tables,
        frames_sha256=dict(frames) if isinstance(frames, dict) else {},
        results_sha256=dict(files) if isinstance(files, dict) else {})


def table_of(results: SessionResults, name: str) -> list[dict[str, Any]] | None:
    """Rows of the table ``name`` (file name, ``forward_view_modulation``, or label,
    ``table_4_11``), or None."""
    for key in (name, _LABEL_OF_FILE.get(name, name), RESULT_FILE_STEMS.get(name, name)):
        if key in results.tables:
            return results.tables[key]
    return None


def row_label(row: Mapping[str, Any], limit: Limit, index: int, several: bool = True) -> str:
    """``element=G2E2``: the row's ``where`` columns, and - when the limit matched several
    rows or has no ``where`` - its first key columns, so each row of a verdict is named."""
    names = [c for c in limit.where if c in row]
    if several or not names:
        keys = [c for c in KEY_COLUMNS if c in row and c not in limit.where]
        names += keys[:max(1, 2 - len(names))]
    parts = [f"{c}={_cell(row.get(c))}" for c in names]
    return " ".join(parts) or f"row {index + 1}"


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


@dataclass
class UnitResult:
    """The verdicts of one unit against one spec."""

    serial: str
    lot: str
    spec: Spec
    sessions: list[SessionResults]
    verdicts: list[Verdict] = field(default_factory=list)
    #: Readings of other sessions of the unit that disagree with the deciding one.
    disagreements: list[Disagreement] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        return combine(v.verdict for v in self.verdicts)

    def limit_verdicts(self) -> dict[str, str]:
        """limit id -> the limit's verdict (over its rows)."""
        out: dict[str, list[str]] = {}
        for v in self.verdicts:
            out.setdefault(v.limit_id, []).append(v.verdict)
        return {k: combine(vs) for k, vs in out.items()}


def verify_unit(sessions: Sequence[SessionResults], spec: Spec) -> UnitResult:
    """Every limit of ``spec`` against the newest of ``sessions`` that has its table."""
    ordered = sorted(sessions, key=lambda s: s.started_at, reverse=True)
    first = ordered[0]
    unit = UnitResult(serial=first.serial, lot=first.lot, spec=spec, sessions=ordered)
    for limit in spec.limits:
        rule = limit.decision_rule or spec.decision_rule
        source = next((s for s in ordered if table_of(s, limit.table) is not None), None)
        if source is None:
            why = (f"table {limit.table!r} is in no results of "
                   + ", ".join(s.path.name for s in ordered)
                   + ("" if any(s.results_version for s in ordered) else " (not analysed)"))
            unit.verdicts.append(missing(limit, rule, why))
            continue
        rows = table_of(source, limit.table) or []
        matched = [(i, r) for i, r in enumerate(rows) if row_matches(r, limit.where)]
        if not matched:
            where = ", ".join(f"{k} = {list(v) if len(v) > 1 else v[0]!r}"
                              for k, v in limit.where.items())
            unit.verdicts.append(missing(limit, rule, f"no row of {limit.table} in "
                                         f"{source.path.name} matches {where}"))
            continue
        for index, row in matched:
            if limit.column not in row:
                unit.verdicts.append(missing(limit, rule, f"{limit.table} has no column "
                                             f"{limit.column!r}"))
                break
            reading = reading_of(row, limit, spec.coverage)
            label = row_label(row, limit, index, len(matched) > 1)
            verdict = decide(reading, limit, rule, table=limit.table, row=label,
                             partial=source.partial)
            found = [d for other in ordered if other is not source
                     if (d := _disagreement(limit, spec.coverage, label, row, reading, source,
                                            other)) is not None]
            unit.disagreements += found
            unit.verdicts.append(_flag_disagreements(verdict, found))
    return unit


def _row_key(row: Mapping[str, Any]) -> tuple[tuple[str, str], ...]:
    """What names a row across sessions: its key columns' values."""
    return tuple((c, _cell(row[c])) for c in KEY_COLUMNS if c in row)


def _disagreement(limit: Limit, coverage: float, label: str, row: Mapping[str, Any],
                  reading: Reading, source: SessionResults, other: SessionResults
                  ) -> Disagreement | None:
    """``other``'s reading of the same table, row and column, if it disagrees with
    ``reading`` (``source``'s) beyond their uncertainties."""
    rows = table_of(other, limit.table) or []
    key = _row_key(row)
    same = [r for r in rows if row_matches(r, limit.where) and _row_key(r) == key
            and limit.column in r]
    if len(same) != 1:  # not measured there, or no one row to compare with
        return None
    return disagreement(reading, reading_of(same[0], limit, coverage), limit_id=limit.id,
                        table=limit.table, row=label, column=limit.column,
                        decided_session=source.path.name, other_session=other.path.name)


def _flag_disagreements(verdict: Verdict, found: Sequence[Disagreement]) -> Verdict:
    """The row's verdict with the disagreements in its notes; never a pass with one."""
    if not found:
        return verdict
    notes = [*verdict.notes, *(d.text() for d in found)]
    if verdict.verdict == PASS:
        notes.append("sessions of the unit disagree: never a pass (find which is wrong; "
                     "verify the right one alone, or relabel the other with benchlab unit)")
        return dataclasses.replace(verdict, verdict=INDETERMINATE, notes=notes)
    return dataclasses.replace(verdict, notes=notes)


def group_units(sessions: Iterable[SessionResults]) -> list[list[SessionResults]]:
    """Sessions grouped by serial number (in the order first seen); no serial: alone."""
    groups: dict[str, list[SessionResults]] = {}
    for s in sessions:
        groups.setdefault(s.serial or f"\0{s.path}", []).append(s)
    return list(groups.values())


def format_number(value: float | None, digits: int = 4) -> str:
    """A reading for people: 4 significant digits, "-" for none."""
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.{digits}g}"


def check_sessions(paths: Sequence[str | Path]) -> list[SessionResults]:
    """Read every session, collecting the problems of all of them into one error."""
    out, problems = [], []
    for p in paths:
        try:
            out.append(read_session(p))
        except SessionError as exc:
            problems.append(str(exc))
    if problems:
        raise SessionError("; ".join(problems))
    return out
