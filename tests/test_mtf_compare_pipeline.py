"""The pipeline's Table 4.15 rows come from the one Monte Carlo comparison in analysis."""

from __future__ import annotations

import pytest

from benchlab.analysis.mtf_compare import compare_with_monte_carlo, load_monte_carlo_table
from benchlab.analysis.thesis_data import thesis_fixture_path
from benchlab.protocols.mtf_analysis import _monte_carlo_rows
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
    for r in rows:
        ref = compare_with_monte_carlo(r["view"], r["measured_freq_lp_per_mm"],
                                       r["sagittal_modulation"], r["tangential_modulation"],
                                       table)
        assert r["verdict"] == ref.percentile_band
        assert r["averaged_modulation"] == pytest.approx(ref.averaged.average)
        assert ref.row is not None and {k: r[k] for k in ref.row.columns()} == ref.row.columns()
    assert rows[0]["verdict"] == "above the 10% threshold (0.62)"
    assert rows[2]["verdict"] == "between the 80% and 50% thresholds (0.27 .. 0.45)"
    assert list(rows[0])[6:11] == ["p90", "p80", "p50", "p20", "p10"]
