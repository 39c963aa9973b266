"""Decision rules: a reading, its interval, a limit -> pass / fail / indeterminate.

Two rules, after ISO 14253-1 (decision rules for conformity with specifications) and the
shared-risk "simple acceptance" of ILAC-G8 / JCGM 106:

``guarded``
    Conformity is proven only when the whole coverage interval (reading +- U) lies within
    the limits: **pass**. Non-conformity is proven only when the whole interval lies outside:
    **fail**. An interval that straddles a limit proves neither: **indeterminate**.
``simple``
    The reading alone is compared with the limits (the guard band is zero, so the risk of a
    wrong decision near a limit is shared by supplier and customer). Every row says whether
    the interval agreed or the reading decided alone.

Whatever the rule, a reading marked not resolved or aliased, a missing reading and a reading
of a partial results version are never a pass. Everything here is pure: rows in, verdicts out.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from statistics import NormalDist
from typing import Any

from benchlab.acceptance.spec import Limit

PASS, FAIL, INDETERMINATE = "pass", "fail", "indeterminate"
#: Exit status of ``benchlab verify`` per unit verdict (2 stays the usage error).
EXIT_STATUS = {PASS: 0, FAIL: 1, INDETERMINATE: 3}
#: The two-sided normal coverage factor a "*_ci95" column was built with.
K95 = NormalDist().inv_cdf(0.975)
_SIGMA_TAGS = ("uncertainty", "sigma")
_CI_TAG = "ci95"


def coverage_factor(coverage: float) -> float:
    """k of a two-sided normal interval holding ``coverage`` (1.96 for 0.95)."""
    return NormalDist().inv_cdf(0.5 + coverage / 2.0)


def _candidates(column: str, tag: str) -> list[str]:
    """Column names that would hold ``tag`` for ``column``, most specific first.

    ``sagittal_modulation`` -> ``sagittal_modulation_uncertainty``, ...,
    ``sagittal_uncertainty``; ``system_gain_dn_per_e`` -> ``system_gain_uncertainty_dn_per_e``;
    ``mtf50_lp_per_mm`` -> ``mtf50_sigma_lp_per_mm``; ``mtf`` -> ``mtf_sigma``: the naming
    conventions of benchlab's results tables.
    """
    parts = column.split("_")
    n = len(parts)
    inserted = ["_".join([*parts[:i], tag, *parts[i:]]) for i in range(n, 0, -1)]
    truncated = ["_".join([*parts[:i], tag]) for i in range(n - 1, 0, -1)]
    return [*inserted, *truncated]


def interval_columns(column: str, columns: Iterable[str]) -> tuple[str, str] | None:
    """``(kind, name)`` of the column holding ``column``'s interval: kind ``"ci95"`` (a 95 %
    interval) or ``"sigma"`` (one standard uncertainty); None when the table has neither."""
    present = set(columns)
    for name in _candidates(column, _CI_TAG):
        if name in present:
            return "ci95", name
    for tag in _SIGMA_TAGS:
        for name in _candidates(column, tag):
            if name in present:
                return "sigma", name
    return None


def _flag(row: Mapping[str, Any], column: str, tag: str) -> tuple[str, Any] | None:
    """The most specific flag column of ``column`` in ``row`` - ``<column>_<tag>``, then
    ``<prefix>_<tag>`` for shorter prefixes (``sagittal_resolved`` for
    ``sagittal_modulation``) - else the row's own ``tag`` column."""
    parts = column.split("_")
    names = ["_".join([*parts[:i], tag]) for i in range(len(parts), 0, -1)] + [tag]
    for name in names:
        if name in row:
            return name, row[name]
    return None


def reading_flags(row: Mapping[str, Any], column: str) -> list[str]:
    """Why a reading may not be trusted: "not resolved", "aliased" (with the column that
    says so), from benchlab's ``*_resolved`` / ``*_unresolved`` / ``*_aliased`` columns."""
    out = []
    resolved = _flag(row, column, "resolved")
    if resolved is not None and resolved[1] is False:
        out.append(f"not resolved ({resolved[0]})")
    unresolved = _flag(row, column, "unresolved")
    if unresolved is not None and unresolved[1] not in (None, "", False) and not out:
        out.append(f"not resolved ({unresolved[0]}: {unresolved[1]})")
    aliased = _flag(row, column, "aliased")
    if aliased is not None and aliased[1] is True:
        out.append(f"aliased ({aliased[0]})")
    return out


@dataclass(frozen=True)
class Reading:
    """A value and its coverage interval (``low``/``high`` None when no interval is known)."""

    value: float | None
    low: float | None = None
    high: float | None = None
    source: str = ""
    flags: tuple[str, ...] = ()


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def reading_of(row: Mapping[str, Any], limit: Limit, coverage: float) -> Reading:
    """The reading of ``limit.column`` in ``row`` with its interval at ``coverage``.

    A 1-sigma column gives value +- k sigma; a ``*_ci95`` column (a half-width, or
    ``[low, high]``) is rescaled to ``coverage`` by k / 1.96 (normal), around the value.
    """
    value = _number(row.get(limit.column))
    flags = tuple(reading_flags(row, limit.column))
    if limit.uncertainty:
        found: tuple[str, str] | None = ("sigma", limit.uncertainty)
    elif limit.ci95:
        found = ("ci95", limit.ci95)
    else:
        found = interval_columns(limit.column, row.keys())
    if value is None or found is None:
        return Reading(value, source="" if found is None else found[1], flags=flags)
    kind, name = found
    k = coverage_factor(coverage)
    cell = row.get(name)
    if kind == "sigma":
        sigma = _number(cell)
        if sigma is None or sigma < 0:
            return Reading(value, source=f"{name} (no value)", flags=flags)
        return Reading(value, value - k * sigma, value + k * sigma,
                       f"{name} x {k:.3g} (1 sigma, {coverage:.0%})", flags)
    scale = k / K95
    if isinstance(cell, list | tuple) and len(cell) == 2:
        lo, hi = _number(cell[0]), _number(cell[1])
        if lo is None or hi is None or lo > hi:
            return Reading(value, source=f"{name} (no value)", flags=flags)
        low, high = value - (value - lo) * scale, value + (hi - value) * scale
    else:
        half = _number(cell)
        if half is None or half < 0:
            return Reading(value, source=f"{name} (no value)", flags=flags)
        low, high = value - half * scale, value + half * scale
    text = f"{name} (95 %)" if math.isclose(scale, 1.0) else \
        f"{name} (95 %) x {scale:.3g} ({coverage:.0%})"
    return Reading(value, low, high, text, flags)


@dataclass(frozen=True)
class Verdict:
    """One limit against one row: the figures a quality engineer checks, and the decision."""

    limit_id: str
    table: str
    row: str
    column: str
    rule: str
    verdict: str
    reading: float | None = None
    low: float | None = None
    high: float | None = None
    min: float | None = None
    max: float | None = None
    unit: str = ""
    #: How far the reading is inside the limits (negative: outside), in the column's unit.
    margin: float | None = None
    #: The same for the whole interval: positive means the interval is inside (guarded pass).
    interval_margin: float | None = None
    interval_source: str = ""
    #: "interval" (the interval alone decided) or "reading (shared risk)".
    decided_by: str = ""
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def decide(reading: Reading, limit: Limit, rule: str, *, table: str = "", row: str = "",
           partial: bool = False) -> Verdict:
    """The verdict of one reading against one limit under ``rule`` ("guarded"/"simple")."""
    notes: list[str] = []
    base = dict(limit_id=limit.id, table=table or limit.table, row=row, column=limit.column,
                rule=rule, reading=reading.value, low=reading.low, high=reading.high,
                min=limit.min, max=limit.max, unit=limit.unit,
                interval_source=reading.source)
    if reading.value is None:
        notes.append("no reading" + (f" ({'; '.join(reading.flags)})" if reading.flags else ""))
        return Verdict(**base, verdict=INDETERMINATE, decided_by="no reading",  # type: ignore[arg-type]
                       notes=notes)
    value = reading.value
    lo_lim = -math.inf if limit.min is None else limit.min
    hi_lim = math.inf if limit.max is None else limit.max
    margin = min(value - lo_lim, hi_lim - value)
    has_interval = reading.low is not None and reading.high is not None
    interval_margin = None
    inside = outside = straddles = False
    if has_interval:
        assert reading.low is not None and reading.high is not None
        interval_margin = min(reading.low - lo_lim, hi_lim - reading.high)
        inside = reading.low >= lo_lim and reading.high <= hi_lim
        outside = reading.high < lo_lim or reading.low > hi_lim
        straddles = not inside and not outside
    if rule == "guarded":
        if not has_interval:
            verdict, decided_by = INDETERMINATE, "no interval"
            notes.append("no uncertainty for this reading: the guarded rule cannot decide "
                         "(name its column with 'uncertainty' / 'ci95', or use the simple rule)")
        elif inside:
            verdict, decided_by = PASS, "interval"
        elif outside:
            verdict, decided_by = FAIL, "interval"
        else:
            verdict, decided_by = INDETERMINATE, "interval"
            notes.append("the interval straddles a limit")
    else:
        verdict = PASS if lo_lim <= value <= hi_lim else FAIL
        if has_interval and not straddles:
            decided_by = "interval"
        else:
            decided_by = "reading (shared risk)"
            notes.append("simple acceptance: " + ("the interval straddles the limit, "
                                                   if straddles else "no interval known, ")
                         + "the reading decides (risk shared)")
    if verdict == PASS and reading.flags:
        verdict = INDETERMINATE
        notes.append(f"{'; '.join(reading.flags)}: never a pass")
    elif reading.flags:
        notes.append("; ".join(reading.flags))
    if verdict == PASS and partial:
        verdict = INDETERMINATE
        notes.append("results of an incomplete session: never a pass")
    return Verdict(**base, verdict=verdict, margin=_r(margin),  # type: ignore[arg-type]
                   interval_margin=_r(interval_margin), decided_by=decided_by, notes=notes)


def _r(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else x


def missing(limit: Limit, rule: str, why: str, table: str = "") -> Verdict:
    """An indeterminate verdict for a limit that found nothing to decide on."""
    return Verdict(limit_id=limit.id, table=table or limit.table, row="", column=limit.column,
                   rule=rule, verdict=INDETERMINATE, min=limit.min, max=limit.max,
                   unit=limit.unit, decided_by="no reading", notes=[why])


def row_matches(row: Mapping[str, Any], where: Mapping[str, Sequence[Any]]) -> bool:
    """Whether every ``where`` column of ``row`` equals one of its values (numbers compare
    as numbers, so ``30`` matches ``30.0``; a boolean only matches a boolean)."""
    for column, values in where.items():
        cell = row.get(column)
        if not any(_same(cell, v) for v in values):
            return False
    return True


def _same(cell: Any, value: Any) -> bool:
    if isinstance(cell, bool) or isinstance(value, bool):
        return cell is value
    if isinstance(cell, int | float) and isinstance(value, int | float):
        return math.isclose(float(cell), float(value), rel_tol=1e-9, abs_tol=1e-12)
    return isinstance(cell, str) and isinstance(value, str) and cell == value


def combine(verdicts: Iterable[str]) -> str:
    """The unit's verdict: any fail -> fail; else any indeterminate -> indeterminate; else
    pass (an empty list is indeterminate: nothing was decided)."""
    seen = set(verdicts)
    if FAIL in seen:
        return FAIL
    if INDETERMINATE in seen or not seen:
        return INDETERMINATE
    return PASS
