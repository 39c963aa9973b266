"""What the catalogue knows about one session folder, read from the folder (the truth).

:func:`read_session_record` only reads: it never opens the session for writing (no journal
repair, no orphan-frame recovery), so indexing a session that a run is still writing is safe.
The status comes from :class:`benchlab.session.Session` so that however the session layer
decides it, the catalogue shows the same.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchlab.session import (
    SESSION_FILE,
    SESSION_FORMAT,
    VERDICTS_DIR,
    Session,
    SessionError,
    read_results,
)
from benchlab.table_4_15 import average_of

ORIENTATIONS = ("sagittal", "tangential")
#: Tables with no figure of merit: image heights (4.13), sampled SFR curves (the largest file
#: of a version: the catalogue does not read them at all).
NOT_FIGURES = frozenset({"table_4_13", "table_sfr_curves", "depth_curves", "depth_overlap",
                         "depth_chart"})
#: A table of another kind with more rows than this is a curve, not key figures.
MAX_GENERIC_ROWS = 100


@dataclass(frozen=True)
class Figure:
    """One key number of one results version (a modulation, a verdict, a radiometry value)."""

    version: int
    view: str
    element: str
    orientation: str
    freq_lp_per_mm: float | None
    quantity: str
    value: float | None
    text: str = ""


@dataclass(frozen=True)
class ResultsVersion:
    version: int
    estimator: str
    created_at: str


@dataclass(frozen=True)
class VerdictRow:
    """One stored acceptance verdict of the session (``verdicts/v<N>.json``)."""

    version: int
    created_at: str
    serial: str
    lot: str
    spec_name: str
    spec_revision: str
    spec_sha256: str
    decision_rule: str
    verdict: str
    #: Readings that disagree with another session of the unit (the record's list).
    disagreements: int = 0


@dataclass
class SessionRecord:
    """One ``sessions`` row plus its results versions and the key figures of the latest."""

    id: str
    path: str
    procedure: str
    status: str
    operator: str = ""
    sample: str = ""
    lot: str = ""
    devices: dict[str, Any] = field(default_factory=dict)
    started_at: str = ""
    finished_at: str | None = None
    software_version: str = ""
    report: str = ""
    error: str = ""
    #: The newest results version when it cannot be read (``error`` says why); ``latest`` is
    #: then the newest readable one, and no figures are listed (they would be of an old one).
    unreadable_version: int | None = None
    results: list[ResultsVersion] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    verdicts: list[VerdictRow] = field(default_factory=list)

    @property
    def serials(self) -> str:
        """``camera:SN led:SN stage:SN`` for searching and display."""
        return " ".join(
            f"{name}:{dev.get('serial', '')}"
            for name, dev in sorted(self.devices.items())
            if isinstance(dev, Mapping) and dev.get("serial")
        )

    @property
    def latest(self) -> ResultsVersion | None:
        return self.results[-1] if self.results else None


def is_session_folder(path: Path) -> bool:
    return (path / SESSION_FILE).is_file()


def read_session_record(path: Path) -> SessionRecord:
    """The catalogue record of the session folder ``path``.

    A folder whose ``session.json`` is unreadable still gets a record (status ``unreadable``,
    ``error`` saying why) so that the catalogue lists it like the folder listing does.
    """
    folder = Path(path)
    meta_path = folder / SESSION_FILE
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        if not isinstance(meta, dict) or meta.get("format") != SESSION_FORMAT:
            raise ValueError("not a benchlab session file")
        session = Session(folder, meta)
        status = session.status
        versions = session.result_versions()
    except (OSError, ValueError, KeyError, SessionError) as exc:
        return SessionRecord(id=folder.name, path=str(folder), procedure="?",
                             status="unreadable", error=f"{meta_path}: {exc}")
    devices = meta.get("devices")
    record = SessionRecord(
        id=folder.name, path=str(folder), procedure=str(meta.get("procedure", "?")),
        status=status, operator=str(meta.get("operator") or ""),
        sample=str(meta.get("sample") or ""), lot=str(meta.get("lot") or ""),
        devices=devices if isinstance(devices, dict) else {},
        started_at=str(meta.get("started_at") or ""), finished_at=meta.get("finished_at"),
        software_version=str(meta.get("software_version") or ""),
        report="report.html" if (folder / "report.html").is_file() else "",
    )
    for version in versions:
        folder_v = session.results_dir / f"v{version}"
        try:
            if version == versions[-1]:  # key figures: of the latest version only
                tables, summary = read_results(folder_v, skip=NOT_FIGURES)
                record.figures.extend(figures_of(version, tables))
            else:
                summary = json.loads((folder_v / "summary.json").read_text(encoding="utf-8"))
        except (OSError, ValueError, SessionError) as exc:
            record.error = f"{folder_v}: {exc}"
            if version == versions[-1]:
                record.unreadable_version = version
            continue
        record.results.append(ResultsVersion(version, str(summary.get("estimator", "")),
                                             str(summary.get("created_at", ""))))
    record.verdicts.extend(verdicts_of(folder))
    return record


def verdicts_of(folder: Path) -> Iterator[VerdictRow]:
    """The acceptance verdicts stored in the session folder (an unreadable one is skipped:
    ``benchlab certificate`` names it when asked for it)."""
    verdicts = folder / VERDICTS_DIR
    if not verdicts.is_dir():
        return
    for path in sorted(verdicts.glob("v*.json")):
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
            version = int(path.stem[1:])
            spec, unit = doc["spec"], doc["unit"]
            yield VerdictRow(version, str(doc.get("created_at", "")), str(unit["serial"]),
                             str(unit["lot"]), str(spec["name"]), str(spec.get("revision", "")),
                             str(spec.get("sha256", "")), str(spec.get("decision_rule", "")),
                             str(doc["verdict"]), len(doc.get("disagreements") or []))
        except (OSError, ValueError, KeyError, TypeError):
            continue


def figures_of(version: int, tables: Mapping[str, Any]) -> Iterator[Figure]:
    """The key figures of one results version's tables."""
    for name, rows in tables.items():
        if not isinstance(rows, list):
            continue
        rows = [r for r in rows if isinstance(r, Mapping)]
        if name == "table_4_11":
            yield from _bar_table(version, "forward", rows, lambda r: str(r.get("element", "")))
        elif name == "table_4_12":
            yield from _bar_table(version, "radial", rows,
                                  lambda r: f"{_num(r.get('object_lp_per_mm')) or 0:g}lp")
        elif name == "table_4_15":
            for r in rows:
                avg, missing = average_of(r)  # no average when a half is not resolved
                bound = r.get("averaged_modulation_lower_bound") is True
                yield Figure(version, str(r.get("view", "")), "", "averaged",
                             _num(r.get("mc_freq_lp_per_mm")), "modulation", _num(avg),
                             f"not available: {missing}" if missing
                             else ("lower bound: " if bound else "") + str(r.get("verdict", "")))
        elif name == "table_4_16":
            for r in rows:
                element = f"{_num(r.get('position_mm')) or 0:g}mm"
                clipped = _num(r.get("clipped_pixels"))
                # A clipped row's mean is only a lower bound: no number, and it says so.
                text = "clipped" if clipped else ""
                for q in ("measured_normalised", "difference", "measured_mean_gray"):
                    value = None if clipped else _num(r.get(q))
                    yield Figure(version, "radiometry", element, "", None, q, value, text)
                if clipped is not None:
                    yield Figure(version, "radiometry", element, "", None, "clipped_pixels",
                                 clipped, text)
        elif name == "table_sfr_edges":  # slanted-edge SFR per edge
            for r in rows:
                for q in ("mtf50_lp_per_mm", "mtf_nyquist", "contrast"):
                    yield Figure(version, "sfr", str(r.get("edge", "")),
                                 str(r.get("orientation", "")), None, q, _num(r.get(q)),
                                 str(r.get("status", "")))
        elif name == "table_sfr_vs_bars":  # edge SFR against the bars, per element
            for r in rows:
                for q in ("edge_mtf", "bar_mtf_coltman"):
                    yield Figure(version, "sfr_vs_bars", str(r.get("element", "")),
                                 str(r.get("orientation", "")), _num(r.get("image_lp_per_mm")),
                                 q, _num(r.get(q)), str(r.get("verdict", "")))
        elif name == "depth_of_field":  # best focus and DOF per field point and criterion
            for r in rows:
                text = f"{r.get('criterion', '')}: {r.get('verdict', '')}"
                for q in ("best_focus_mm", "near_mm", "far_mm", "dof_mm"):
                    yield Figure(version, f"depth {r.get('view', '')}".strip(),
                                 str(r.get("field_point", "")), str(r.get("orientation", "")),
                                 _num(r.get("freq_lp_per_mm")), q, _num(r.get(q)), text)
        elif name in NOT_FIGURES or len(rows) > MAX_GENERIC_ROWS:
            continue  # geometry or whole curves: not figures of merit
        else:
            yield from _generic_table(version, name, rows)


def _bar_table(version: int, view: str, rows: list[Mapping[str, Any]], element: Any
               ) -> Iterator[Figure]:
    for r in rows:
        for o in ORIENTATIONS:
            resolved = r.get(f"{o}_resolved")
            aliased = r.get(f"{o}_aliased", r.get("aliased")) is True  # 4.11: one per row
            freq = r.get(f"{o}_image_lp_per_mm", r.get("image_lp_per_mm"))  # radial: per roll
            value = _num(r.get(f"{o}_modulation"))
            measured = value is not None  # None and not resolved: no reading was possible
            if aliased or resolved is False:
                value = None  # the 0 stored for it is no measurement: NULL, and say why
            text = ("aliased" if aliased else "" if resolved is None
                    else ("lower bound" if r.get(f"{o}_lower_bound") is True else "resolved")
                    if resolved else "unresolved" if measured else "not measurable")
            yield Figure(version, view, element(r), o, _num(freq), "modulation", value, text)


def _generic_table(version: int, name: str, rows: list[Mapping[str, Any]]) -> Iterator[Figure]:
    """Any other table (e.g. characterisation numbers): every numeric cell, keyed by the row's
    first text cell (or its index)."""
    for i, r in enumerate(rows):
        label = next((str(v) for v in r.values() if isinstance(v, str) and v), str(i))
        for key, value in r.items():
            number = _num(value)
            if number is not None and not isinstance(value, bool):
                yield Figure(version, name, label, "", None, str(key), number)


def _num(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    number = float(value)
    return number if math.isfinite(number) else None
