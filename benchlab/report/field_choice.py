"""Which simulated field point (Table 4.14) each MTF test is compared with: through the unit's
*measured* image-height mapping when a ``benchlab run fov`` session of the same unit exists,
else (as the thesis did) the design's field point nearest in image height.

The thesis compared each reading with the simulated curve "nearest in image height", the
heights taken from the design (Table 4.14). With the lens's own mapping (issue 41), a test's
image height is turned into the field angle the lens really images there, and the field point
nearest in field angle is taken. The fov session is found next to the MTF session (the same
sessions folder) by the unit's serial (``--sample``); the newest one with a mapping is used,
and the report names it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchlab.analysis.geometry import field_points
from benchlab.session import Session, read_results


@dataclass(frozen=True)
class FieldChoice:
    """The field angles used per view, and how they were chosen (a sentence for the report;
    ``source`` the fov session's folder, or None for the design's heights)."""

    fields: dict[str, set[float]] = field(default_factory=dict)
    source: Path | None = None
    lines: tuple[str, ...] = ()


def fov_mapping(session: Session) -> tuple[Path, list[dict[str, Any]]] | None:
    """The newest fov session of the same unit next to ``session`` and its mapping rows
    (None: no serial, or no such session with results)."""
    serial = str(session.meta.get("sample") or "")
    if not serial:
        return None
    found: list[tuple[str, Path]] = []
    for meta_path in session.path.parent.glob("*/session.json"):
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue  # not a session this report can read: not a mapping either
        if (isinstance(meta, dict) and meta.get("procedure") == "fov"
                and str(meta.get("sample") or "") == serial):
            found.append((str(meta.get("started_at") or ""), meta_path.parent))
    for _, path in sorted(found, reverse=True):
        latest = Session.open(path).latest_results()
        if latest is None:
            continue
        tables, _ = read_results(latest)
        rows = tables.get("image_height_mapping") or []
        if rows:
            return path, rows
    return None


def measured_angle(rows: list[dict[str, Any]], view: str, height_mm: float) -> float | None:
    """The field angle the measured mapping images at ``height_mm`` (None: outside it)."""
    pts = sorted((float(r["image_height_mm"]), float(r["field_angle_deg"])) for r in rows
                 if r.get("view", "forward") == view and r.get("image_height_mm") is not None)
    if len(pts) < 2 or not pts[0][0] <= height_mm <= pts[-1][0]:
        return None
    h, a = np.array(pts).T
    return float(np.interp(height_mm, h, a))


def choose_fields(session: Session, tables: dict[str, list[dict[str, Any]]]) -> FieldChoice:
    """The field point of every test of ``table_4_13`` (module docstring)."""
    tests = tables.get("table_4_13", [])
    design = {v: {float(r["nearest_field_deg"]) for r in tests if r["view"] == v}
              for v in ("forward", "radial")}
    found = fov_mapping(session)
    if found is None:
        return FieldChoice(design, None, ("Field points: the design's (Table 4.14) nearest in "
                                          "image height - no fov session of this unit.",))
    path, rows = found
    chosen: dict[str, set[float]] = {"forward": set(), "radial": set()}
    lines = [f"Field points: through the measured image-height mapping of {path.name} (fov, "
             f"unit {session.meta.get('sample')}), the Table 4.14 point nearest in field "
             "angle."]
    for r in tests:
        view, h = str(r["view"]), float(r["image_height_mm"])
        angle = measured_angle(rows, view, h)
        if angle is None:
            chosen.setdefault(view, set()).add(float(r["nearest_field_deg"]))
            lines.append(f"{view} {r.get('test', '')}: {h:.3f} mm is outside the measured "
                         f"mapping; the design's {float(r['nearest_field_deg']):g} deg")
            continue
        point = min(field_points(view), key=lambda p: abs(p.field_angle_deg - angle))
        chosen.setdefault(view, set()).add(point.field_angle_deg)
        lines.append(f"{view} {r.get('test', '')}: {h:.3f} mm is {angle:.1f} deg on this "
                     f"lens -> the {point.field_angle_deg:g} deg curve (design's nearest in "
                     f"height: {float(r['nearest_field_deg']):g} deg)")
    return FieldChoice(chosen, path, tuple(lines))
