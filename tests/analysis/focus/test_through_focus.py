"""Through-focus fit: best focus and DOF ends with 95 % intervals (benchlab.analysis.focus)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.focus.through_focus import (
    FocusFitError,
    best_focus_draws,
    fit_through_focus,
    focus_estimate,
)

Z = np.arange(40.0, 96.0, 2.0)
BEST = 60.0
K = 22000.0  # ln MTF = ln 0.9 - K (1/z - 1/best)^2


def curve(z: np.ndarray) -> np.ndarray:
    return 0.9 * np.exp(-K * (1.0 / z - 1.0 / BEST) ** 2)


def ends(threshold: float) -> tuple[float, float]:
    du = math.sqrt(math.log(0.9 / threshold) / K)
    return 1.0 / (1.0 / BEST + du), 1.0 / (1.0 / BEST - du)


def test_noise_free_curve_gives_the_closed_form_best_focus_and_ends() -> None:
    fit = fit_through_focus(Z, curve(Z), np.full(Z.size, 0.003))
    est = focus_estimate(fit, 0.5)
    near, far = ends(0.5)
    assert est.best_focus_mm == pytest.approx(BEST, abs=0.02)
    assert est.near_mm == pytest.approx(near, abs=0.02)
    assert est.far_mm == pytest.approx(far, abs=0.02)
    assert est.peak_mtf == pytest.approx(0.9, abs=1e-3)
    assert not est.near_extrapolated and not est.far_extrapolated


@pytest.mark.slow
def test_intervals_cover_the_truth_about_95_percent_of_noisy_sweeps() -> None:
    rng = np.random.default_rng(5)
    near, far = ends(0.5)
    hits = {"best": 0, "near": 0, "far": 0}
    n = 60
    for _ in range(n):
        m = curve(Z) + rng.normal(0, 0.004, Z.size)
        est = focus_estimate(fit_through_focus(Z, m, np.full(Z.size, 0.004)), 0.5, draws=800)
        for key, value, (lo, hi) in (("best", BEST, est.best_focus_ci95),
                                     ("near", near, est.near_ci95),
                                     ("far", far, est.far_ci95)):
            assert lo is not None and hi is not None
            hits[key] += lo <= value <= hi
    for key, h in hits.items():
        assert 0.85 <= h / n <= 1.0, (key, h / n)


def test_threshold_above_the_peak_gives_no_ends() -> None:
    est = focus_estimate(fit_through_focus(Z, curve(Z), np.full(Z.size, 0.003)), 0.95)
    assert est.near_mm is None and est.far_mm is None


def test_a_sweep_without_a_peak_is_refused() -> None:
    z = np.arange(40.0, 56.0, 2.0)  # all below best focus: the curve rises to the end
    with pytest.raises(FocusFitError, match="no maximum inside the sweep"):
        fit_through_focus(z, curve(z), np.full(z.size, 0.003))


def test_too_few_readings_above_min_mtf_are_refused() -> None:
    m = curve(Z)
    m[m > 0.3] = 0.01
    with pytest.raises(FocusFitError, match="readings at or above MTF"):
        fit_through_focus(Z, m, np.full(Z.size, 0.003), min_mtf=0.05)


def test_far_end_beyond_the_sweep_is_flagged_extrapolated() -> None:
    fit = fit_through_focus(Z, curve(Z), np.full(Z.size, 0.003))
    est = focus_estimate(fit, 0.2)
    assert est.far_mm is not None and est.far_mm > Z.max() and est.far_extrapolated


def test_best_focus_draws_spread_like_the_interval() -> None:
    rng = np.random.default_rng(1)
    fit = fit_through_focus(Z, curve(Z) + rng.normal(0, 0.004, Z.size), np.full(Z.size, 0.004))
    d = best_focus_draws(fit, draws=2000)
    lo, hi = focus_estimate(fit, 0.5, draws=2000).best_focus_ci95
    assert np.nanpercentile(d, 2.5) == pytest.approx(lo, abs=1e-9)
    assert np.nanpercentile(d, 97.5) == pytest.approx(hi, abs=1e-9)
