"""The pipeline's Table 4.15 rows come from the one Monte Carlo comparison in analysis."""

from __future__ import annotations

import pytest

from benchlab.analysis.mtf.compare import compare_with_monte_carlo, load_monte_carlo_table
from benchlab.analysis.thesis_data import thesis_fixture_path
from benchlab.protocols.mtf.analysis import _monte_carlo_rows
from benchlab.protocols.params import parse_params


def _row(f_img: float, s: float | None, t: float | None, aliased: bool = False) -> dict:
    return {"image_lp_per_mm": f_img, "sagittal_modulation": s, "tangential_modulation": t,
            "aliased": aliased}


def test_pipeline_rows_match_the_analysis_comparison() -> None:
    params = parse_params("mtf", {}, "<test>")
    forward = [_row(73.187, 0.76, 0.69), _row(92.0, 0.5, 0.5, aliased=True)]
    radial = [_row(35.0, 0.66, 0.18), _row(52.5, 0.60, 0.0), _row(200.0, None, None)]
    rows = _monte_carlo_rows(forward, radial, params)
    table = load_monte_carlo_table(thesis_fixture_path("table_4_15_monte_carlo"))
    assert [(r["view"], r["mc_freq_lp_per_mm"], r["measured_freq_lp_per_mm"]) for r in rows] == [
        ("forward", 70.0, 73.187), ("radial", 30.0, 35.0), ("radial", 60.0, 52.5)]
    for r in rows[:2]:  # both readings resolved
        ref = compare_with_monte_carlo(r["view"], r["measured_freq_lp_per_mm"],
                                       r["sagittal_modulation"], r["tangential_modulation"],
                                       table)
        assert r["verdict"] == ref.percentile_band
        assert r["averaged_modulation"] == pytest.approx(ref.averaged.average)
        assert ref.row is not None and {k: r[k] for k in ref.row.columns()} == ref.row.columns()
    assert rows[0]["verdict"] == "above the 10% threshold (0.62)"
    # 52.5 lp/mm: T stored as 0 without a flag is not resolved (an Eq. 2.9 contrast that is
    # found is never exactly 0): no number, no average, no verdict built on a 0.
    assert rows[2]["tangential_modulation"] is None and rows[2]["tangential_resolved"] is False
    assert rows[2]["averaged_modulation"] is None
    assert rows[2]["averaged_lower_bound"] == pytest.approx(0.30)
    assert rows[2]["verdict"] == "not available: T not resolved"
    assert list(rows[0])[6:11] == ["p90", "p80", "p50", "p20", "p10"]


def _radial_row(f_obj: float, s: float, t: float) -> dict:
    """A Table 4.12 row as the procedure writes it: rings (T) at Eq. 4.1's 17.5x, spokes (S)
    at object radius / image radius (about 8.0x) - the two orientations' own frequencies."""
    f_t, f_s = 17.5 * f_obj, 8.007 * f_obj
    return {"object_lp_per_mm": f_obj, "image_lp_per_mm": f_t, "aliased": f_t > 100.0,
            "sagittal_modulation": s, "tangential_modulation": t,
            "sagittal_image_lp_per_mm": f_s, "sagittal_aliased": f_s > 100.0,
            "tangential_image_lp_per_mm": f_t, "tangential_aliased": f_t > 100.0}


def test_radial_average_takes_each_orientation_at_its_own_frequency() -> None:
    params = parse_params("mtf", {}, "<test>")
    # S readings fall with their own frequency; a row's S is ~2x lower in frequency than its T.
    radial = [_radial_row(f, s, t) for f, s, t in
              ((2, 0.90, 0.20), (3, 0.85, 0.05), (4, 0.70, 0.0), (6, 0.55, 0.0))]
    rows = {r["mc_freq_lp_per_mm"]: r for r in _monte_carlo_rows([], radial, params)}
    # 30 lp/mm: T from the 35 lp/mm rings (object 2), S from the 32 lp/mm spokes (object 4),
    # not the 16 lp/mm spokes of the same row.
    r30 = rows[30.0]
    assert (r30["tangential_modulation"], r30["sagittal_modulation"]) == (0.20, 0.70)
    assert r30["sagittal_freq_lp_per_mm"] == pytest.approx(32.028)
    assert r30["tangential_freq_lp_per_mm"] == r30["measured_freq_lp_per_mm"] == 35.0
    assert r30["averaged_modulation"] == pytest.approx(0.45)
    # 60 lp/mm: T from the 52.5 lp/mm rings; S from the 48 lp/mm spokes (object 6, whose
    # rings alias at 105 lp/mm: the spokes of that row are still a reading).
    r60 = rows[60.0]
    assert (r60["tangential_modulation"], r60["sagittal_modulation"]) == (0.05, 0.55)
    assert r60["sagittal_freq_lp_per_mm"] == pytest.approx(48.042)


def test_no_row_when_one_orientation_has_nothing_near() -> None:
    params = parse_params("mtf", {}, "<test>")
    # Spokes at 48 lp/mm are near 60, but the rings are at 17.5 and 105 lp/mm (aliased):
    # no tangential reading near 30 or 60 lp/mm, so no row.
    radial = [_radial_row(1, 0.9, 0.6), _radial_row(6, 0.6, 0.0)]
    rows = _monte_carlo_rows([], radial, params)
    assert [r["mc_freq_lp_per_mm"] for r in rows] == []
