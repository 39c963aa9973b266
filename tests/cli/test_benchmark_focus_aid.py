"""``benchlab benchmark focus-aid`` at its smallest: every bit depth and estimator has a row, the
fast reading agrees with the full chart reading, and the table prints every row."""

from __future__ import annotations

import pytest

from benchlab.benchmarks.focus_aid import ESTIMATORS, format_benchmark, run_benchmark


@pytest.mark.slow
def test_focus_aid_rows_agree_with_the_full_chart_reading() -> None:
    rows = run_benchmark(seconds=0.05, frames=2)
    assert [(r["bits"], r["estimator"]) for r in rows] == [
        (bits, est) for bits in (8, 12) for est in ESTIMATORS]
    for r in rows:
        assert r["readings_per_s"] > 0.0
        assert r["sets"] >= 10  # the thesis's elements below Nyquist are found and read
    histogram = [r for r in rows if r["estimator"] == "histogram"]
    assert all(r["median_abs_diff"] < 0.05 for r in histogram), histogram
    text = format_benchmark(rows)
    assert text.count("\n") == 2 + len(rows)  # title, blank, header, one line per row
    assert "readings/s" in text
