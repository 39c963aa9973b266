"""Histogram-peak method: bar-centre selection from the quick geometry, and no reading without a
significant bar fundamental."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchlab.analysis.bars import histogram
from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.bars.roi import prepare_roi
from benchlab.benchmarks.bars.estimators import Case, benchmark_cases
from benchlab.synthetic.bars import BarCase, render


@lru_cache(maxsize=1)
def _cases() -> list[Case]:
    return benchmark_cases(1500, seed=0)


def _benchmark_roi(index: int) -> tuple[np.ndarray, Case, dict[str, object]]:
    """ROI ``index`` of ``benchlab benchmark analysis`` (seed 0), called as the benchmark does."""
    case = _cases()[index]
    roi = render(case.bar, np.random.default_rng(10_000 + index))
    orientation = (("horizontal" if case.bar.theta_rad < 0.1 else "vertical")
                   if case.axis_aligned else None)
    return roi, case, {"freq_cycles_per_px": case.bar.freq_cycles_per_px,
                       "orientation": orientation}


# Flat ROIs the method used to call resolved: a shading ramp (40 x 10, axis given) and two
# 5 x 5 ROIs of a few quantisation codes.
FLAT_CALLED_RESOLVED = (1236, 1299, 1335)


@pytest.mark.slow
@pytest.mark.parametrize("index", FLAT_CALLED_RESOLVED)
def test_flat_rois_are_not_resolved(index: int) -> None:
    roi, case, kwargs = _benchmark_roi(index)
    assert case.kind == "flat"
    r = estimate_modulation(roi, estimator="histogram", **kwargs)  # type: ignore[arg-type]
    assert not r.resolved and r.modulation == 0.0
    assert any("no bar pattern above the noise" in w for w in r.warnings)


@pytest.mark.slow
def test_the_significance_rule_is_what_rejects_them(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(histogram, "MIN_FUNDAMENTAL_Z", 0.0)
    called = []
    for index in FLAT_CALLED_RESOLVED:
        roi, _, kwargs = _benchmark_roi(index)
        called.append(estimate_modulation(roi, estimator="histogram", **kwargs).resolved)  # type: ignore[arg-type]
    assert all(called)


@pytest.mark.slow
@pytest.mark.parametrize("index", [834, 1118, 29])
def test_small_rois_with_real_bars_stay_resolved(index: int) -> None:
    """5 x 5 ROIs whose geometry smears the phase bins: the significance uses the least of the
    noise estimates, so real bars (truth 0.06-0.90) are still read."""
    roi, case, kwargs = _benchmark_roi(index)
    assert case.bar.shape == (5, 5) and case.kind == "bars"
    r = estimate_modulation(roi, estimator="histogram", **kwargs)  # type: ignore[arg-type]
    assert r.resolved


@pytest.mark.parametrize("angle", [12.0, 38.0, 63.0])
def test_quick_geometry_reads_like_the_spectral_search(
    angle: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    case = BarCase(shape=(40, 50), px_per_period=7.0, angle_deg=angle, noise_sigma=1.5,
                   electrons_per_dn=20.0, phase=0.2, psf_sigma_px=1.0)
    roi = render(case, np.random.default_rng(int(angle)))
    quick = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=1 / 7)
    monkeypatch.setattr(histogram, "quick_fundamental", lambda *a, **k: None)
    full = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=1 / 7)
    assert quick.resolved and full.resolved
    assert quick.modulation == pytest.approx(full.modulation, abs=0.005)
    assert quick.modulation == pytest.approx(case.truth, abs=0.03)


def test_bar_centre_bins_lie_within_the_phase_window() -> None:
    near, wide = histogram._phase_tables(histogram.NOISE_BINS)
    n = histogram.NOISE_BINS
    mids = (np.arange(n) + 0.5) / n % 1.0
    dist = np.minimum(np.abs(mids - np.rint(mids)), np.abs(mids - 0.5))
    assert np.all(dist[near] <= histogram.PHASE_WINDOW)
    assert np.all(dist[~near] > histogram.PHASE_WINDOW)
    assert np.all(near <= wide) and wide.sum() > near.sum()
    assert near[0] and near[n // 2] and not near[n // 4]  # bar and space centres, not edges
    assert n & (n - 1) == 0  # a power of two: the phase bin is a cell's low bits


def test_selected_pixels_are_bar_and_space_centres() -> None:
    """Sharp oblique bars: the selected pixels sit on the two plateaus, none on the edges."""
    case = BarCase(shape=(60, 60), px_per_period=12.0, angle_deg=30.0, noise_sigma=0.0,
                   psf_sigma_px=0.0, modulation=0.5, mean=100.0, phase=0.1)
    roi = render(case, np.random.default_rng(0)).astype(np.float64)
    prep = prepare_roi(roi, freq_cycles_per_px=1 / 12)
    selected, z = histogram._bar_centres(prep)
    values = selected.pixels.ravel()
    assert z is not None and z > 100
    assert values.size > 0.3 * roi.size * (1 - 12 / 60)
    # Levels 50 and 150 (pixel integration blurs only the pixels the edges cross).
    on_plateau = (np.abs(values - 50.0) < 1.0) | (np.abs(values - 150.0) < 1.0)
    assert on_plateau.mean() > 0.97
    assert math.isclose(selected.vmin, values.min()) and math.isclose(selected.vmax, values.max())


def test_a_chart_rotated_against_the_given_orientation_is_measured() -> None:
    """Bars at 45 deg called "horizontal": the line-averaged profile shows no bars, so the
    bars' own geometry locates the centres (not "no bar pattern")."""
    case = BarCase(shape=(48, 48), px_per_period=6.0, angle_deg=45.0, noise_sigma=1.0,
                   phase=0.3, psf_sigma_px=0.7)
    roi = render(case, np.random.default_rng(3))
    r = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=1 / 6,
                            orientation="horizontal")
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.03)


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(2, 70), cols=st.integers(2, 70), theta=st.floats(-1.6, 1.6),
       f=st.floats(0.02, 0.5), phase=st.floats(-0.5, 0.5))
def test_bar_centre_pixels_are_those_of_their_own_phase(
    rows: int, cols: int, theta: float, f: float, phase: float
) -> None:
    """The selection is each pixel's own phase: bin = floor(NOISE_BINS (phi mod 1)) in the
    window, and |phi - phase| <= half - 1/2 cycle for the inner bars (no whole-bin rounding
    of that limit: it moved readings by up to 0.04)."""
    kx, ky = f * math.cos(theta), f * math.sin(theta)
    half_f = 0.5 * f * (abs((cols - 1) * math.cos(theta)) + abs((rows - 1) * math.sin(theta)))
    _, bins, inner = histogram._phase_bins((rows, cols), kx, ky, phase, half_f)
    y = np.arange(rows)[:, None] - (rows - 1) / 2
    x = np.arange(cols)[None, :] - (cols - 1) / 2
    phi = ky * y + kx * x + phase
    frac = (phi - np.floor(phi)) * histogram.NOISE_BINS
    want_bins = np.minimum(frac.astype(int), histogram.NOISE_BINS - 1)
    # Pixels on a bin edge (to rounding) may fall either side.
    on_edge = np.abs(frac - np.rint(frac)) < 1e-9
    assert np.array_equal(bins[~on_edge], want_bins[~on_edge])
    if half_f >= 1.0:
        assert inner is not None
        dev = np.abs(phi - phase) - (half_f - 0.5)
        decided = np.abs(dev) > 1e-9
        assert np.array_equal(inner[decided], (dev <= 0)[decided])
    else:
        assert inner is None
    phases = histogram._Phases(bins, inner, 1.0, None)
    near = phases.centres("near")
    want = histogram._NEAR[bins] & (inner if inner is not None else True)
    assert np.array_equal(near, want)
    assert np.array_equal(phases.centres("all"), inner if inner is not None
                          else np.ones((rows, cols), bool))


@pytest.mark.parametrize("ratio", [0.7, 0.75])
def test_a_side_lobe_the_quick_geometry_settles_on_is_declined(
    ratio: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A frequency prior 25-30 % low: the quick geometry settles on a side lobe of the bars
    (about 0.65 of their frequency); the noise test with the noise about the bars' profile
    declines it (it carries little of the power), the spectral search runs, and the reading
    is the one an exact prior gives."""
    from benchlab.analysis.bars import geometry as bargeometry

    bar = BarCase(shape=(60, 80), px_per_period=8.0, angle_deg=25.0, noise_sigma=2.0,
                  phase=0.2)
    roi = render(bar, np.random.default_rng(1))
    f_prior = 0.125 * ratio
    lobe = bargeometry.quick_fundamental(prepare_roi(roi).pixels, None, f_prior, None, None)
    assert lobe is not None and abs(lobe.freq_cycles_per_px / 0.125 - 0.65) < 0.03
    searched: list[int] = []
    real = histogram.measure_geometry

    def spy(*args: object, **kw: object) -> object:
        searched.append(1)
        return real(*args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(histogram, "measure_geometry", spy)
    exact = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=0.125)
    assert not searched  # the exact prior: the quick geometry is accepted
    off = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=f_prior)
    assert searched == [1]
    assert off.resolved and off.modulation == exact.modulation
