"""Statistics of a lot: yield, per-limit distributions, capability (Cpk) and drift.

* **Yield**: units passing / units verified, with the Clopper-Pearson ("exact") binomial
  interval, which never claims more than the counts show (a 20/20 lot is not "100 %").
* **Capability**: ``Cpk = min(USL - mean, mean - LSL) / (3 s)`` of each limited quantity,
  with Bissell's normal approximation of its interval,
  ``Cpk +- z sqrt(1 / (9 n) + Cpk^2 / (2 (n - 1)))``; needs >= 2 readings.
* **Drift**: an individuals control chart in the order the units were measured (centre the
  mean, limits +- 3 sigma estimated from the mean moving range / 1.128), flagging points
  beyond the limits and runs of :data:`RUN_LENGTH` on one side of the centre (Western
  Electric rules 1 and 4).

Readings that are missing, not resolved or aliased are counted but enter no statistic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from scipy import stats

from benchlab.acceptance.decide import FAIL, INDETERMINATE, PASS
from benchlab.acceptance.verify import UnitResult

#: Individuals chart: d2 of a moving range of two (sigma = mean moving range / d2).
D2_MOVING_RANGE = 1.128
#: Consecutive points on one side of the centre line that flag a shift.
RUN_LENGTH = 8
#: A spread this small relative to the mean is rounding, not variation.
_NO_SPREAD = 1e-12


def yield_interval(passed: int, total: int, confidence: float = 0.95) -> tuple[float, float]:
    """Clopper-Pearson interval of a pass fraction ``passed / total`` (0, 1 when total = 0)."""
    if total <= 0:
        return 0.0, 1.0
    alpha = 1.0 - confidence
    low = 0.0 if passed == 0 else float(stats.beta.ppf(alpha / 2, passed, total - passed + 1))
    high = 1.0 if passed == total else float(stats.beta.ppf(1 - alpha / 2, passed + 1,
                                                             total - passed))
    return low, high


def cpk(values: Sequence[float], lsl: float | None, usl: float | None,
        confidence: float = 0.95) -> tuple[float | None, float | None, float | None]:
    """``(Cpk, low, high)`` of ``values`` against the limits (None where undefined)."""
    n = len(values)
    if n < 2 or (lsl is None and usl is None):
        return None, None, None
    mean = math.fsum(values) / n
    s = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1))
    if s <= _NO_SPREAD * max(1.0, abs(mean)):  # identical readings (rounding aside)
        return None, None, None
    sides = [(usl - mean) if usl is not None else math.inf,
             (mean - lsl) if lsl is not None else math.inf]
    index = min(sides) / (3 * s)
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    half = z * math.sqrt(1 / (9 * n) + index**2 / (2 * (n - 1)))
    return index, index - half, index + half


@dataclass
class ControlChart:
    """Individuals chart of one quantity, in measurement order."""

    centre: float
    lcl: float
    ucl: float
    beyond: list[int] = field(default_factory=list)
    runs: list[tuple[int, int]] = field(default_factory=list)


def control_chart(values: Sequence[float]) -> ControlChart | None:
    """Centre, limits and the flagged points of ``values`` (None below 3 values)."""
    n = len(values)
    if n < 3:
        return None
    centre = math.fsum(values) / n
    moving = [abs(b - a) for a, b in zip(values, values[1:], strict=False)]
    sigma = (math.fsum(moving) / len(moving)) / D2_MOVING_RANGE
    if sigma <= _NO_SPREAD * max(1.0, abs(centre)):  # identical readings: nothing drifts
        return ControlChart(centre, centre, centre)
    chart = ControlChart(centre, centre - 3 * sigma, centre + 3 * sigma)
    chart.beyond = [i for i, v in enumerate(values) if v < chart.lcl or v > chart.ucl]
    start, side = 0, 0
    for i, v in enumerate([*values, centre]):  # the centre ends the last run
        s = (v > centre) - (v < centre)
        if s != side or s == 0:
            if side != 0 and i - start >= RUN_LENGTH:
                chart.runs.append((start, i - 1))
            start, side = i, s
    return chart


@dataclass
class QuantityStats:
    """One limited quantity over the lot (one limit, one row label)."""

    limit_id: str
    row: str
    column: str
    min: float | None
    max: float | None
    unit: str
    serials: list[str] = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=lambda: {PASS: 0, FAIL: 0,
                                                            INDETERMINATE: 0})
    no_value: int = 0

    def summary(self) -> dict[str, Any]:
        v = sorted(self.values)
        n = len(v)
        index, low, high = cpk(self.values, self.min, self.max)
        chart = control_chart(self.values)
        mean = math.fsum(v) / n if n else None
        return {
            "limit_id": self.limit_id, "row": self.row, "column": self.column,
            "min": self.min, "max": self.max, "unit": self.unit, "n": n,
            "no_value": self.no_value, "verdicts": dict(self.counts),
            "mean": mean,
            "std": (math.sqrt(math.fsum((x - mean) ** 2 for x in v) / (n - 1))
                    if n > 1 and mean is not None else None),
            "minimum": v[0] if n else None, "maximum": v[-1] if n else None,
            "p05": _quantile(v, 0.05), "p50": _quantile(v, 0.5), "p95": _quantile(v, 0.95),
            "cpk": index, "cpk_low": low, "cpk_high": high,
            "drift": None if chart is None else {
                "centre": chart.centre, "lcl": chart.lcl, "ucl": chart.ucl,
                "beyond_limits": [self.serials[i] for i in chart.beyond],
                "runs": [[self.serials[a], self.serials[b]] for a, b in chart.runs]},
        }


def _quantile(sorted_values: Sequence[float], q: float) -> float | None:
    if not sorted_values:
        return None
    pos = q * (len(sorted_values) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(sorted_values) - 1)
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * (pos - lo)


def lot_statistics(units: Sequence[UnitResult], confidence: float = 0.95) -> dict[str, Any]:
    """Yield, per-quantity distributions, Cpk and drift of ``units`` (in measurement order:
    the units are sorted by their newest session's start)."""
    ordered = sorted(units, key=lambda u: u.sessions[0].started_at if u.sessions else "")
    counts = {PASS: 0, FAIL: 0, INDETERMINATE: 0}
    quantities: dict[tuple[str, str], QuantityStats] = {}
    for unit in ordered:
        counts[unit.verdict] += 1
        for v in unit.verdicts:
            q = quantities.setdefault((v.limit_id, v.row), QuantityStats(
                v.limit_id, v.row, v.column, v.min, v.max, v.unit))
            q.counts[v.verdict] += 1
            flagged = any(("not resolved" in n or "aliased" in n) for n in v.notes)
            if v.reading is None or flagged:
                q.no_value += 1
            else:
                q.values.append(v.reading)
                q.serials.append(unit.serial or unit.sessions[0].path.name)
    total = len(ordered)
    low, high = yield_interval(counts[PASS], total, confidence)
    return {
        "units": total, "verdicts": counts,
        "yield": counts[PASS] / total if total else None,
        "yield_low": low, "yield_high": high, "confidence": confidence,
        "quantities": [q.summary() for q in quantities.values()],
        "order": [u.serial or u.sessions[0].path.name for u in ordered],
        "readings": {f"{q.limit_id} {q.row}".strip(): q.values for q in quantities.values()},
    }
