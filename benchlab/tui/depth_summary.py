"""The Run screen's digest of a depth-of-field run: one line per criterion and orientation out
of the ``depth_of_field`` table (one row per field point there), short enough for 80 columns.

Display only: every number comes from the stored table; nothing is fitted or judged again.
Per criterion and orientation it shows the median best focus of the field points and the DOF
all of them share - the largest near end and the smallest far end - first, then the range of
best focus, each end's 95 % interval (of the field point that sets it) and how many field
points each verdict got.
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence
from typing import Any

ORIENTATION_SHORT = {"sagittal": "S", "tangential": "T"}


def _num(value: Any) -> str:
    return "N/A" if value is None else f"{float(value):.2f}"


def _ci(value: Any) -> str:
    if not isinstance(value, list | tuple) or len(value) != 2:
        return "N/A"
    return f"[{_num(value[0])}, {_num(value[1])}]"


def _verdicts(rows: Sequence[Mapping[str, Any]]) -> str:
    counts: dict[str, int] = {}
    for r in rows:
        word = str(r.get("verdict") or "-").split(" (")[0]
        counts[word] = counts.get(word, 0) + 1
    return ", ".join(f"{n} {w}" for w, n in sorted(counts.items()))


def depth_summary_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, str]]:
    """One display row per (criterion, frequency, orientation) of ``depth_of_field`` rows
    (module docstring); the values are strings ready for the table. A criterion read at more
    than one frequency (radial patterns) is named with its frequency (``"... @2"`` lp/mm)."""
    groups: dict[tuple[str, float, str], list[Mapping[str, Any]]] = {}
    for r in rows:
        freq = r.get("freq_lp_per_mm")
        key = (str(r.get("criterion", "?")), float(freq) if freq is not None else 0.0,
               str(r.get("orientation", "?")))
        groups.setdefault(key, []).append(r)
    out: list[dict[str, str]] = []
    criteria = list(dict.fromkeys(k[0] for k in groups))  # the table's order; S before T
    freqs: dict[str, set[float]] = {}
    for c, f, _ in groups:
        freqs.setdefault(c, set()).add(f)
    for (name, freq, orientation), group in sorted(
            groups.items(), key=lambda kv: (criteria.index(kv[0][0]), kv[0][1], kv[0][2])):
        criterion = name if len(freqs[name]) == 1 else f"{name} @{freq:g}"
        best = [float(r["best_focus_mm"]) for r in group if r.get("best_focus_mm") is not None]
        nears = [r for r in group if r.get("near_mm") is not None]
        fars = [r for r in group if r.get("far_mm") is not None]
        near = max(nears, key=lambda r: float(r["near_mm"])) if nears else None
        far = min(fars, key=lambda r: float(r["far_mm"])) if fars else None
        out.append({
            "criterion": criterion,
            "orient.": ORIENTATION_SHORT.get(orientation, orientation),
            # The result first (best focus and the DOF ends: what 80 columns show), then
            # how far the field points spread and the ends' intervals.
            "best mm": _num(statistics.median(best)) if best else "N/A",
            "near mm": _num(near["near_mm"]) if near else "N/A",
            "far mm": _num(far["far_mm"]) if far else "N/A",
            "best range": f"{min(best):.2f}-{max(best):.2f}" if best else "N/A",
            "near 95 %": _ci(near.get("near_mm_ci95")) if near else "N/A",
            "far 95 %": _ci(far.get("far_mm_ci95")) if far else "N/A",
            "verdicts": _verdicts(group),
            "points": str(len(group)),
        })
    return out
