"""Decision rules with values: limits below, above and at a reading, both rules, the flags."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from benchlab.acceptance.decide import (
    FAIL,
    INDETERMINATE,
    PASS,
    Reading,
    Verdict,
    combine,
    coverage_factor,
    decide,
    interval_columns,
    reading_flags,
    reading_of,
    row_matches,
)
from benchlab.acceptance.spec import Limit

K = coverage_factor(0.95)  # 1.95996...
ROW = {"element": "G2E2", "sagittal_modulation": 0.60, "sagittal_uncertainty": 0.01,
       "sagittal_resolved": True, "sagittal_aliased": False, "aliased": False}


def verdict(min_: float | None = None, max_: float | None = None, rule: str = "guarded",
            row: dict[str, object] | None = None, column: str = "sagittal_modulation") -> Verdict:
    limit = Limit(id="L", table="t", column=column, min=min_, max=max_)
    return decide(reading_of(row or ROW, limit, 0.95), limit, rule)


def test_coverage_factor_is_the_normal_quantile() -> None:
    assert K == pytest.approx(1.959964, abs=1e-6)
    assert coverage_factor(0.6827) == pytest.approx(1.0, abs=1e-3)


def test_interval_from_a_one_sigma_column() -> None:
    limit = Limit(id="L", table="t", column="sagittal_modulation", min=0.5)
    r = reading_of(ROW, limit, 0.95)
    assert (r.value, r.low, r.high) == pytest.approx((0.60, 0.60 - 0.01 * K, 0.60 + 0.01 * K))
    assert "sagittal_uncertainty" in r.source


@pytest.mark.parametrize(("min_", "expected", "margin"), [
    (0.55, PASS, 0.05),           # limit below the whole interval
    (0.65, FAIL, -0.05),          # limit above the whole interval
    (0.60, INDETERMINATE, 0.0),   # limit at the reading: the interval straddles it
    (0.60 - 0.01 * K, PASS, 0.01 * K),  # limit at the interval's low end: inside, inclusive
    (0.61, INDETERMINATE, -0.01),  # the reading below, the interval's top above
])
def test_guarded_min(min_: float, expected: str, margin: float) -> None:
    v = verdict(min_)
    assert v.verdict == expected
    assert v.margin == pytest.approx(margin)
    assert v.interval_margin == pytest.approx(margin - 0.01 * K)


@pytest.mark.parametrize(("max_", "expected"), [(0.65, PASS), (0.55, FAIL), (0.60, INDETERMINATE)])
def test_guarded_max(max_: float, expected: str) -> None:
    assert verdict(max_=max_).verdict == expected


def test_two_sided_limit_margin_is_to_the_nearer_limit() -> None:
    v = verdict(0.5, 0.61)  # the interval's top, 0.6196, is above 0.61
    assert v.verdict == INDETERMINATE
    assert v.margin == pytest.approx(0.01)
    v2 = verdict(0.5, 0.63)
    assert v2.verdict == PASS
    assert v2.margin == pytest.approx(0.03)


def test_simple_rule_the_reading_decides_and_says_so() -> None:
    at = verdict(0.60, rule="simple")
    assert at.verdict == PASS
    assert at.decided_by == "reading (shared risk)"
    above = verdict(0.605, rule="simple")
    assert above.verdict == FAIL
    assert above.decided_by == "reading (shared risk)"
    clear = verdict(0.50, rule="simple")
    assert (clear.verdict, clear.decided_by) == (PASS, "interval")


def test_not_resolved_or_aliased_is_never_a_pass() -> None:
    for flag in ({"sagittal_resolved": False}, {"sagittal_aliased": True}):
        row = {**ROW, **flag}
        for rule in ("guarded", "simple"):
            v = verdict(0.10, row=row, rule=rule)
            assert v.verdict == INDETERMINATE, (flag, rule)
            assert "never a pass" in " ".join(v.notes)
    # a not-resolved reading clearly below a min limit still fails
    assert verdict(0.9, row={**ROW, "sagittal_resolved": False}).verdict == FAIL


def test_missing_reading_is_indeterminate() -> None:
    row = {**ROW, "sagittal_modulation": None, "sagittal_resolved": False}
    v = verdict(0.1, row=row, rule="simple")
    assert v.verdict == INDETERMINATE
    assert "not resolved" in v.notes[0]


def test_guarded_without_interval_cannot_pass() -> None:
    row = {"averaged_modulation": 0.9}
    assert verdict(0.1, row=row, column="averaged_modulation").verdict == INDETERMINATE
    assert verdict(0.1, row=row, column="averaged_modulation",
                   rule="simple").verdict == PASS


def test_partial_results_never_pass() -> None:
    limit = Limit(id="L", table="t", column="x", min=0.0)
    v = decide(Reading(1.0, 0.9, 1.1), limit, "guarded", partial=True)
    assert v.verdict == INDETERMINATE


@pytest.mark.parametrize(("column", "columns", "expected"), [
    ("sagittal_modulation", ["sagittal_uncertainty", "tangential_uncertainty"],
     ("sigma", "sagittal_uncertainty")),
    ("system_gain_dn_per_e", ["system_gain_uncertainty_dn_per_e"],
     ("sigma", "system_gain_uncertainty_dn_per_e")),
    ("mtf50_lp_per_mm", ["mtf50_sigma_lp_per_mm"], ("sigma", "mtf50_sigma_lp_per_mm")),
    ("edge_mtf", ["edge_mtf_sigma"], ("sigma", "edge_mtf_sigma")),
    ("mtf50_lp_per_mm", ["mtf50_sigma_lp_per_mm", "mtf50_ci95"], ("ci95", "mtf50_ci95")),
    ("averaged_modulation", ["verdict"], None),
])
def test_interval_column_found_by_benchlab_names(column: str, columns: list[str],
                                                 expected: tuple[str, str] | None) -> None:
    assert interval_columns(column, columns) == expected


def test_ci95_column_half_width_and_bounds_rescaled_to_coverage() -> None:
    limit = Limit(id="L", table="t", column="mtf50", min=0.0)
    half = reading_of({"mtf50": 100.0, "mtf50_ci95": 4.0}, limit, 0.95)
    assert (half.low, half.high) == pytest.approx((96.0, 104.0))
    bounds = reading_of({"mtf50": 100.0, "mtf50_ci95": [97.0, 106.0]}, limit, 0.95)
    assert (bounds.low, bounds.high) == pytest.approx((97.0, 106.0))
    wide = reading_of({"mtf50": 100.0, "mtf50_ci95": 4.0}, limit, 0.99)
    assert wide.high == pytest.approx(100 + 4.0 * coverage_factor(0.99) / K)


def test_flags_read_from_benchlab_columns() -> None:
    row = {"read_noise_dn": None, "read_noise_resolved": False,
           "read_noise_unresolved": "dark noise < 1 DN"}
    assert reading_flags(row, "read_noise_dn") == ["not resolved (read_noise_resolved)"]
    assert reading_flags({"aliased": True, "x": 1}, "x") == ["aliased (aliased)"]


def test_where_matches_numbers_as_numbers_and_lists_as_any() -> None:
    assert row_matches({"freq": 30.0}, {"freq": (30,)})
    assert row_matches({"e": "G2E2"}, {"e": ("G2E1", "G2E2")})
    assert not row_matches({"e": True}, {"e": (1,)})
    assert not row_matches({"e": "G2E3"}, {"e": ("G2E2",)})


def test_unit_verdict_combines_worst_first() -> None:
    assert combine([PASS, INDETERMINATE, FAIL]) == FAIL
    assert combine([PASS, INDETERMINATE]) == INDETERMINATE
    assert combine([PASS, PASS]) == PASS
    assert combine([]) == INDETERMINATE
    assert math.isfinite(K)


@given(reading=st.floats(-10, 10), sigma=st.floats(0, 3), lo=st.floats(-10, 10),
       width=st.floats(0, 10), two_sided=st.booleans())
def test_guarded_decisions_are_a_refinement_of_simple(reading: float, sigma: float, lo: float,
                                                      width: float, two_sided: bool) -> None:
    """Whatever guarded decides, simple decides the same; and a guarded pass keeps the whole
    interval inside (a fail keeps it wholly outside)."""
    limit = Limit(id="L", table="t", column="x", min=lo, max=lo + width if two_sided else None)
    r = reading_of({"x": reading, "x_uncertainty": sigma}, limit, 0.95)
    guarded, simple = decide(r, limit, "guarded"), decide(r, limit, "simple")
    assert r.low is not None and r.high is not None
    if guarded.verdict != INDETERMINATE:
        assert simple.verdict == guarded.verdict
    hi = math.inf if limit.max is None else limit.max
    if guarded.verdict == PASS:
        assert lo <= r.low and r.high <= hi
    if guarded.verdict == FAIL:
        assert r.high < lo or r.low > hi
    assert (simple.verdict == PASS) == (lo <= reading <= hi)
