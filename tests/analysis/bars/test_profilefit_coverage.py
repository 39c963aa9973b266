"""Honest ``profilefit`` intervals (issue 9: 95 % intervals covering 90-98 % in every bucket of
``benchlab benchmark analysis``): the tiny-ROI model term, the few-periods widening on
axis-aligned bars and the model term shrinking where every phase is sampled many times."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis import estimate_modulation
from benchlab.analysis.bars.estimators import FEW_PERIODS, _series_starved, sine_fit
from benchlab.analysis.bars.profilefit import (
    DENSE_PIXELS_PER_BIN,
    MODEL_REL_SD,
    _model_sd,
    profile_fit,
)
from benchlab.analysis.bars.roi import prepare_roi
from benchlab.synthetic.bars import BarCase, render


def _read(bar: BarCase, seed: int, orientation: str | None = "horizontal"):  # type: ignore[no-untyped-def]
    roi = render(bar, np.random.default_rng(seed))
    prep = prepare_roi(roi, freq_cycles_per_px=bar.freq_cycles_per_px, orientation=orientation)
    r = estimate_modulation(
        roi, estimator="profilefit", freq_cycles_per_px=bar.freq_cycles_per_px,
        orientation=orientation,
    )
    return prep, r


def test_tiny_roi_interval_holds_the_bar_model_disagreement() -> None:
    # Benchmark case 957: 5 lines across at 2.36 px per period. The harmonic series reads 0.158
    # (before: [0.130, 0.186]), the bar model 0.255, truth 0.195.
    bar = BarCase(shape=(5, 5), px_per_period=2.35897, modulation=0.68958, mean=58.714,
                  psf_sigma_px=0.52432, noise_sigma=0.13271, phase=0.025691, duty=0.55886,
                  shading=0.12980, angle_deg=0.0, electrons_per_dn=1572.24, pedestal=8.0)
    prep, r = _read(bar, 10_957)
    series, bars = sine_fit(prep), profile_fit(prep)
    assert any("harmonic-series" in w for w in r.warnings)
    assert r.modulation == pytest.approx(series.modulation)  # reading unchanged: interval only
    assert abs(series.modulation - bars.modulation) > 0.05
    assert r.uncertainty >= abs(series.modulation - bars.modulation)
    lo, hi = r.interval
    assert lo <= bar.truth <= hi
    # The bootstrap resamples the noise only and adds the model term back from diagnostics.
    assert r.diagnostics.uncertainty_model == pytest.approx(
        math.sqrt(r.uncertainty**2 - series.uncertainty**2))
    roi = render(bar, np.random.default_rng(10_957))
    boot = estimate_modulation(roi, estimator="profilefit", bootstrap=50,
                               freq_cycles_per_px=bar.freq_cycles_per_px, orientation="horizontal")
    assert boot.uncertainty_method == "bootstrap"
    assert boot.uncertainty >= abs(series.modulation - bars.modulation)
    assert boot.interval[0] <= bar.truth <= boot.interval[1]


def test_tiny_roi_too_few_lines_for_the_harmonics_reads_the_bar_model() -> None:
    # Benchmark case 384: 5 lines across at 4.74 px per period: the 2nd harmonic is below
    # Nyquist but 5 lines cannot hold it, the series falls back to a sine and reads sharp bars
    # 0.425 (truth 0.280). The bar model reads them.
    bar = BarCase(shape=(5, 5), px_per_period=4.7438, modulation=0.3097, mean=76.3,
                  psf_sigma_px=0.0, noise_sigma=1.10, phase=0.0727, duty=0.428, shading=0.0294,
                  angle_deg=90.0, bits=12, msb_aligned=True, electrons_per_dn=13187.0, pedestal=8.0)
    prep, r = _read(bar, 10_384, "vertical")
    assert _series_starved(prep)
    assert not any("harmonic-series" in w for w in r.warnings)
    assert sine_fit(prep).modulation - bar.truth > 0.1
    assert r.modulation == pytest.approx(bar.truth, abs=0.03)
    lo, hi = r.interval
    assert lo <= bar.truth <= hi
    # Wider lines hold the 2nd harmonic: not starved (the forward view's elements).
    wide = prepare_roi(np.ones((8, 5)), freq_cycles_per_px=bar.freq_cycles_per_px,
                       orientation="vertical")
    assert not _series_starved(wide)


def test_few_periods_axis_aligned_widens_the_model_term() -> None:
    # Benchmark case 906: 40 px across at 39.3 px per period (one period), sharp bars, shading.
    # Before: 0.548 in [0.537, 0.560], truth 0.535.
    bar = BarCase(shape=(40, 50), px_per_period=39.2624, modulation=0.53476, mean=78.29,
                  psf_sigma_px=0.0, noise_sigma=1.1017, phase=0.2525, duty=0.49127,
                  shading=0.062493, angle_deg=90.0, electrons_per_dn=210.287)
    prep, r = _read(bar, 10_906, "vertical")
    plain = profile_fit(prep)
    periods = 40 / bar.px_per_period
    assert periods < FEW_PERIODS
    model = plain.diagnostics.uncertainty_model
    assert model is not None
    assert r.diagnostics.uncertainty_model == pytest.approx(model * FEW_PERIODS / periods, rel=1e-3)
    assert r.uncertainty == pytest.approx(
        math.hypot(plain.diagnostics.uncertainty_noise or 0.0, model * FEW_PERIODS / periods),
        rel=1e-3)
    assert r.modulation == plain.modulation
    lo, hi = r.interval
    assert lo <= bar.truth <= hi


def test_many_periods_and_oblique_bars_keep_the_model_term() -> None:
    many = BarCase(shape=(40, 50), px_per_period=8.0, modulation=0.5, psf_sigma_px=1.0)
    prep, r = _read(many, 1)
    assert r.uncertainty == pytest.approx(profile_fit(prep).uncertainty)
    oblique = BarCase(shape=(40, 50), px_per_period=33.0, modulation=0.5, psf_sigma_px=1.0,
                      angle_deg=30.0)
    prep, r = _read(oblique, 2, None)
    assert r.uncertainty == pytest.approx(profile_fit(prep).uncertainty)


@pytest.mark.parametrize("n_pixels", [None, 2000, int(DENSE_PIXELS_PER_BIN * 64)])
def test_model_sd_unchanged_up_to_dense_sampling(n_pixels: int | None) -> None:
    assert _model_sd(0.5, 0.02, 64, n_pixels=n_pixels) == pytest.approx(_model_sd(0.5, 0.02, 64))


def test_model_sd_shrinks_as_phase_sampling_gets_dense() -> None:
    base = _model_sd(0.5, 0.02, 64)
    for n_pixels in (40_000, 1_000_000):
        expected = base * math.sqrt(DENSE_PIXELS_PER_BIN * 64 / n_pixels)
        assert _model_sd(0.5, 0.02, 64, n_pixels=n_pixels) == pytest.approx(expected)
    assert _model_sd(0.5, 0.02, 64, n_pixels=10**9) < 0.01 * base  # vanishes when dense


def test_large_oblique_roi_interval_narrower_than_relative_model_term() -> None:
    bar = BarCase(shape=(200, 200), px_per_period=12.0, modulation=0.5, psf_sigma_px=1.5,
                  noise_sigma=1.0, angle_deg=37.0)
    _, r = _read(bar, 3, None)
    model = r.diagnostics.uncertainty_model
    assert model is not None
    assert model < 0.7 * MODEL_REL_SD * r.modulation
    lo, hi = r.interval
    assert lo <= bar.truth <= hi
