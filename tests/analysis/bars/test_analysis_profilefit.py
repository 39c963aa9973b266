"""The measurement engine v2: the imaged-bar generator's truth, ``profilefit`` (the default) in
every condition bucket and at the extremes, and the corrected histogram-peak rules."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis import DEFAULT_ESTIMATOR, ESTIMATORS, estimate_modulation
from benchlab.analysis.bars import histogram
from benchlab.analysis.bars.model import imaged_bars, truth_modulation
from benchlab.analysis.bars.roi import prepare_roi
from benchlab.scenes.optics import blurred_square_wave
from benchlab.synthetic.bars import bar_roi

NOISY = {"noise_sigma": 1.5, "electrons_per_dn": 20.0}  # read noise + Poisson shot noise


@pytest.mark.parametrize("angle_deg", [0.0, 30.0, 45.0, 72.0])
def test_generator_is_the_exact_pixel_integral(angle_deg: float) -> None:
    """The closed-form trapezoid footprint equals brute-force integration of the blurred bars
    over the unit pixel (64 x 64 sub-samples)."""
    t = math.radians(angle_deg)
    period, sigma = 5.3, 0.6
    centres = np.linspace(-3.0, 7.0, 23)
    sub = (np.arange(64) + 0.5) / 64 - 0.5
    dx, dy = np.meshgrid(sub, sub)
    brute = [
        float(blurred_square_wave(c + dx * math.cos(t) + dy * math.sin(t), period, sigma).mean())
        for c in centres
    ]
    closed = imaged_bars(centres, period, 0.5, sigma, t)
    assert np.allclose(closed, brute, atol=3e-4)
    # Truth: Eq. 2.9 of that profile's max and min over every phase, between levels 0.4, 1.6.
    w = np.linspace(0.0, period, 4000, endpoint=False)
    s = imaged_bars(w, period, 0.5, sigma, t)
    hi, lo = 0.4 + 1.2 * s.max(), 0.4 + 1.2 * s.min()
    assert truth_modulation(0.4, 1.6, period, 0.5, sigma, t) == pytest.approx(
        (hi - lo) / (hi + lo), abs=1e-6)


@pytest.mark.parametrize("angle", [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0])
def test_any_bar_angle(angle: float) -> None:
    roi, case = bar_roi(
        int(angle), shape=(40, 50), px_per_period=6.0, angle_deg=angle, psf_sigma_px=1.0,
        shading=0.2, duty=0.45, **NOISY,
    )
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 6)
    assert r.estimator == DEFAULT_ESTIMATOR and r.resolved
    assert r.modulation == pytest.approx(case.truth, abs=0.02)
    measured = r.diagnostics.bar_angle_deg
    assert measured is not None and abs((measured - angle + 90) % 180 - 90) < 0.5
    assert r.interval[0] - 0.01 <= case.truth <= r.interval[1] + 0.01
    assert r.diagnostics.noise_sigma < 2.5 * case.noise_at_mean  # angle-independent noise


@pytest.mark.parametrize("period", [2.2, 3.0, 5.0, 12.0, 30.0])
def test_period_buckets(period: float) -> None:
    roi, case = bar_roi(
        7, shape=(64, 64), px_per_period=period, angle_deg=35.0, psf_sigma_px=0.7, **NOISY
    )
    r = estimate_modulation(roi, freq_cycles_per_px=1 / period)
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.02)
    assert r.diagnostics.px_per_period == pytest.approx(period, rel=0.01)


@pytest.mark.parametrize(("snr", "tol"), [(5.0, 0.05), (200.0, 0.01)])
def test_snr_buckets(snr: float, tol: float) -> None:
    base = dict(shape=(40, 50), px_per_period=8.0, angle_deg=25.0, psf_sigma_px=1.0)
    _, clean = bar_roi(0, **base, noise_sigma=0.0)
    roi, case = bar_roi(3, **base, noise_sigma=100.0 * clean.truth / snr)
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 8)
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=tol)


@pytest.mark.parametrize(
    ("shape", "period", "angle", "tol"),
    [((10, 40), 5.0, 20.0, 0.03), ((200, 200), 9.0, 50.0, 0.005), ((40, 50), 16.0, 0.0, 0.01)],
)
def test_roi_size_buckets(shape: tuple[int, int], period: float, angle: float, tol: float) -> None:
    roi, case = bar_roi(5, shape=shape, px_per_period=period, angle_deg=angle, **NOISY)
    r = estimate_modulation(roi, freq_cycles_per_px=1 / period)
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=tol)


def test_flat_and_below_noise_are_never_resolved() -> None:
    rng = np.random.default_rng(0)
    flat = np.clip(np.rint(rng.normal(100, 3, (40, 50))), 0, 255).astype(np.uint8)
    weak, _ = bar_roi(1, shape=(40, 50), px_per_period=6.0, modulation=0.004, noise_sigma=3.0,
                      angle_deg=30.0)
    for roi in (flat, weak):
        for name in ("profilefit", "histogram"):
            r = estimate_modulation(roi, estimator=name, freq_cycles_per_px=1 / 6)
            assert not r.resolved and r.modulation == 0.0 and r.dark is None


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_all_zero_and_one_pixel_rois(name: str) -> None:
    for roi in (np.zeros((40, 50), np.uint8), np.full((1, 1), 77, np.uint8)):
        r = estimate_modulation(roi, estimator=name, freq_cycles_per_px=0.1)
        assert not r.resolved and r.modulation == 0.0


def test_five_by_five_roi() -> None:
    roi, case = bar_roi(2, shape=(5, 5), px_per_period=4.0, noise_sigma=0.5, psf_sigma_px=0.5,
                        orientation="vertical")
    r = estimate_modulation(roi, freq_cycles_per_px=0.25, orientation="vertical")
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.05)
    assert r.diagnostics.n_pixels == 25


def test_saturation_found_from_the_data() -> None:
    roi, case = bar_roi(4, shape=(40, 50), px_per_period=10.0, exposure_scale=2.2,
                        angle_deg=20.0, **NOISY)
    r = estimate_modulation(roi, freq_cycles_per_px=0.1)
    assert r.diagnostics.saturation_code == 255.0 and r.diagnostics.clipped_fraction > 0.2
    assert any("clipped" in w for w in r.warnings)
    # A plateau at a code no bit depth predicts (float data clipped at 180.5) is found too.
    clean, _ = bar_roi(4, shape=(40, 50), px_per_period=10.0, noise_sigma=1.0)
    clipped = np.minimum(clean.astype(np.float64) + 0.5, 120.5)
    prep = prepare_roi(clipped)
    assert prep.max_code == 120.5 and prep.clipped_fraction > 0.2


def test_near_and_above_nyquist() -> None:
    roi, case = bar_roi(6, shape=(64, 64), px_per_period=2.1, angle_deg=30.0,
                        psf_sigma_px=0.3, **NOISY)
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 2.1)
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.03)
    assert r.diagnostics.phase_sensitive
    alias, _ = bar_roi(6, shape=(64, 64), px_per_period=1.9, angle_deg=30.0, **NOISY)
    for name in ESTIMATORS:
        a = estimate_modulation(alias, estimator=name, freq_cycles_per_px=1 / 1.9)
        assert not a.resolved and a.modulation == 0.0
        assert any("not resolved (aliased)" in w for w in a.warnings)


def test_12bit_msb_aligned() -> None:
    roi, case = bar_roi(8, shape=(40, 50), px_per_period=7.0, angle_deg=40.0, bits=12,
                        msb_aligned=True, noise_sigma=0.5)
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 7)
    assert roi.dtype == np.uint16 and r.diagnostics.code_step == 16.0
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.01)


@pytest.mark.parametrize("seed", range(1, 5))
def test_levels_never_beyond_the_samples(seed: int) -> None:
    """Sharp bars sampled at many phases (oblique): no fitted level beyond the samples."""
    roi, case = bar_roi(seed, shape=(30, 40), px_per_period=3.0 + seed, angle_deg=10.0 * seed,
                        psf_sigma_px=0.0, noise_sigma=1.0)
    r = estimate_modulation(roi, freq_cycles_per_px=1 / (3.0 + seed))
    assert r.dark is not None and r.bright is not None
    sigma = r.diagnostics.noise_sigma
    assert r.dark >= float(roi.min()) - 3 * sigma and r.bright <= float(roi.max()) + 3 * sigma
    assert r.modulation == pytest.approx(case.truth, abs=0.02)


def test_levels_between_sampled_phases() -> None:
    """Axis-aligned sharp bars at exactly 3 px sample only three phases: the levels between
    them are the model's guess, so the reading may leave the samples (the true dark level lies
    below every sample) and the interval says how far it can be trusted."""
    for phase in (0.0, 0.1, 0.2, 0.3):
        roi, case = bar_roi(0, shape=(30, 40), px_per_period=3.0, psf_sigma_px=0.0,
                            noise_sigma=1.0, phase=phase)
        r = estimate_modulation(roi, freq_cycles_per_px=1 / 3, orientation="horizontal")
        assert r.interval[0] <= case.truth <= r.interval[1]
        assert r.modulation == pytest.approx(case.truth, abs=0.08)
        assert r.diagnostics.uncertainty_model is not None
        assert r.diagnostics.uncertainty_model > 0.05


def test_priors_are_cross_checked() -> None:
    roi, case = bar_roi(9, shape=(40, 50), px_per_period=8.0, angle_deg=20.0, **NOISY)
    wrong_f = estimate_modulation(roi, freq_cycles_per_px=1 / 8.8)
    assert any("disagrees with the given frequency" in w for w in wrong_f.warnings)
    assert wrong_f.diagnostics.px_per_period == pytest.approx(8.0, rel=0.01)
    assert wrong_f.modulation == pytest.approx(case.truth, abs=0.02)
    wrong_o = estimate_modulation(roi, freq_cycles_per_px=1 / 8, orientation="horizontal")
    assert any("disagrees with the given orientation" in w for w in wrong_o.warnings)
    assert wrong_o.modulation == pytest.approx(case.truth, abs=0.02)
    good = estimate_modulation(roi, freq_cycles_per_px=1 / 8)
    assert not any("disagrees" in w for w in good.warnings)


def test_uncertainty_includes_model_and_phase_terms() -> None:
    roi, _ = bar_roi(10, shape=(40, 50), px_per_period=8.0, orientation="vertical",
                     noise_sigma=0.5)
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 8, orientation="vertical")
    d = r.diagnostics
    assert d.uncertainty_noise is not None and d.uncertainty_model is not None
    assert d.uncertainty_model > d.uncertainty_noise  # 8 sampled phases: the model interpolates
    assert r.uncertainty == pytest.approx(math.hypot(d.uncertainty_noise, d.uncertainty_model))


def test_fast_mode_trades_accuracy_for_time() -> None:
    """The fast mode fits the duty too (fixed at 0.5 it read sharp bars of duty 0.42 0.04
    off); it saves the curvature, half the bins and the second refinement round."""
    roi, case = bar_roi(11, shape=(40, 50), px_per_period=16.0, angle_deg=33.0, duty=0.42,
                        psf_sigma_px=0.3, **NOISY)
    r = estimate_modulation(roi, estimator="profilefit-fast", freq_cycles_per_px=1 / 16)
    assert r.estimator == "profilefit-fast"
    assert r.diagnostics.duty == pytest.approx(0.42, abs=0.03)
    assert r.modulation == pytest.approx(case.truth, abs=0.015)


# -- histogram-peak rules ------------------------------------------------------------------


def _two_levels(low: float, high: float, period: float = 8.0) -> np.ndarray:
    x = np.arange(64)
    bright = np.mod(x / period, 1.0) < 0.5
    return np.broadcast_to(np.where(bright, high, low), (40, 64)).astype(np.float64)


def test_histogram_separation_rule(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two clean modes 1.5 noise sigmas apart are not two bar levels."""
    roi = _two_levels(100.0, 103.0)
    kwargs = {"freq_cycles_per_px": 1 / 8, "orientation": "horizontal", "noise_sigma": 2.0}
    r = estimate_modulation(roi, estimator="histogram", **kwargs)
    assert not r.resolved and any("noise sigma apart" in w for w in r.warnings)
    monkeypatch.setattr(histogram, "MIN_SEPARATION_SIGMA", 0.0)
    assert estimate_modulation(roi, estimator="histogram", **kwargs).resolved


def test_histogram_side_fraction_rule(monkeypatch: pytest.MonkeyPatch) -> None:
    """A minor mode holding 5 % of the pixels is a mode (by mass) but not a bar level."""
    rng = np.random.default_rng(3)
    values = rng.normal(100.0, 1.0, 2000)
    values[rng.permutation(2000)[:100]] = rng.normal(140.0, 1.0, 100)
    prep = prepare_roi(values.reshape(40, 50))
    r = histogram._histogram_peak(prep)
    assert not r.resolved and any("minor mode holds only 5.0%" in w for w in r.warnings)
    monkeypatch.setattr(histogram, "MIN_SIDE_FRACTION", 0.0)
    r0 = histogram._histogram_peak(prep)
    assert r0.resolved and r0.dark == pytest.approx(100, abs=1) and r0.bright == pytest.approx(
        140, abs=1)


def test_histogram_modes_by_mass_not_height() -> None:
    """A narrow, tall dark mode beside a broad bright one; a small saturation spike above the
    bright mode does not become the bright level."""
    rng = np.random.default_rng(4)
    dark = rng.normal(20.0, 0.5, 700)
    bright = rng.normal(175.0, 12.0, 1260)
    spike = np.full(40, 255.0)
    prep = prepare_roi(np.concatenate([dark, bright, spike]).reshape(40, 50))
    r = histogram._histogram_peak(prep)
    assert r.resolved and r.dark == pytest.approx(20, abs=1)
    assert r.bright == pytest.approx(175, abs=8)


def test_histogram_levels_from_inner_bars_not_background() -> None:
    """Dark background beyond the outer bars (a USAF element's surround) does not become the
    dark level: only the inner bar and space centres make the histogram."""
    roi, case = bar_roi(12, shape=(40, 64), px_per_period=16.0, noise_sigma=1.0,
                        psf_sigma_px=0.5)
    framed = roi.astype(np.float64)
    framed[:, :6] = 5.0  # a dark surround at both ends
    framed[:, -6:] = 5.0
    r = estimate_modulation(framed, estimator="histogram", freq_cycles_per_px=1 / 16,
                            orientation="horizontal")
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.02)


@pytest.mark.slow
def test_benchmark_scores_clipped_cases_in_their_own_bucket() -> None:
    from benchlab.benchmarks.bars.estimators import (
        benchmark_cases,
        is_clipped_measurable,
        is_measurable,
        score,
    )

    cases = benchmark_cases(300, seed=0)
    clipped = [i for i, c in enumerate(cases) if is_clipped_measurable(c)]
    plain = [i for i, c in enumerate(cases) if is_measurable(c)]
    assert clipped and not set(clipped) & set(plain)
    # Synthetic rows: every reading 0.1 above the truth, resolved, interval around it.
    rows = [(i, "x", cases[i].bar.truth + 0.1, True, cases[i].bar.truth, 1.0, 1e-4)
            for i in clipped + plain]
    by_bucket = {s.bucket: s for s in score(cases, rows, ("x",))}
    assert by_bucket["clipped"].n == len(clipped)
    assert by_bucket["all"].n == len(plain)  # clipped cases stay out of "all"
    assert by_bucket["clipped"].bias == pytest.approx(0.1)
    assert by_bucket["clipped"].coverage == 1.0
