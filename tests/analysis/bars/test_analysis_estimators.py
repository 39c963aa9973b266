"""Estimators on synthetic bar ROIs with known truth, plus their labelled failure modes."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchlab.analysis import (
    DEFAULT_ESTIMATOR,
    ESTIMATORS,
    ModulationResult,
    compare_estimators,
    estimate_modulation,
)
from benchlab.analysis.bars import estimators
from benchlab.synthetic.bars import BarCase, bar_roi, render, true_modulation

WIDE = {"shape": (40, 50), "px_per_period": 16.0, "noise_sigma": 1.0, "psf_sigma_px": 1.0}


def test_registry_and_default() -> None:
    assert set(ESTIMATORS) == {"profilefit", "profilefit-fast", "histogram", "sinefit",
                               "variance"}
    assert DEFAULT_ESTIMATOR == "profilefit"
    assert estimators.resolve_estimator("auto") == estimators.resolve_estimator(None) == (
        DEFAULT_ESTIMATOR)
    roi, _ = bar_roi(0, **WIDE)
    assert estimate_modulation(roi, estimator="auto") == estimate_modulation(
        roi, estimator=DEFAULT_ESTIMATOR)


def test_truth_of_wide_bars_is_the_object_modulation() -> None:
    assert true_modulation(32.0, 0.6, 1.0) == pytest.approx(0.6, abs=1e-3)
    # A period of 4 px with sigma 1 px keeps only the fundamental: (4/pi) M MTF(f) sinc(f).
    expected = 4 / math.pi * 0.6 * math.exp(-2 * (math.pi * 0.25) ** 2) * np.sinc(0.25)
    assert true_modulation(4.0, 0.6, 1.0) == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
@pytest.mark.parametrize("period", [16.0, 8.0])
@pytest.mark.parametrize("orientation", ["horizontal", "vertical"])
def test_estimators_recover_truth(name: str, period: float, orientation: str) -> None:
    roi, case = bar_roi(3, **{**WIDE, "px_per_period": period, "orientation": orientation})
    r = estimate_modulation(
        roi, estimator=name, freq_cycles_per_px=1 / period, orientation=orientation
    )
    assert r.resolved and r.estimator == name
    # The histogram reads the sampled pixels' modes: at 8 px per period the samples sit 1/16
    # period off the profile's peak (sampling phase), which costs it 0.034 here.
    tol = (0.04 if period == 8.0 else 0.03) if name == "histogram" else 0.015
    assert r.modulation == pytest.approx(case.truth, abs=tol)
    assert r.dark is not None and r.bright is not None and r.dark < r.bright
    assert r.diagnostics.n_pixels == 2000
    assert r.diagnostics.noise_sigma == pytest.approx(1.0, rel=0.25)
    assert 0 < r.uncertainty < 0.05 and r.interval[0] <= r.modulation <= r.interval[1]


def test_histogram_levels_match_thesis_example() -> None:
    """Fig. 4.10-like ROI: plateaus at 41 and 174 -> 0.62 (G2E4 sagittal)."""
    mean, m = (41 + 174) / 2, (174 - 41) / (174 + 41)
    roi, _ = bar_roi(
        0,
        shape=(40, 64),
        px_per_period=32.0,
        modulation=m,
        mean=mean,
        psf_sigma_px=0.5,
        noise_sigma=2.0,
    )
    r = estimate_modulation(roi, estimator="histogram")
    assert r.dark == pytest.approx(41, abs=1.0) and r.bright == pytest.approx(174, abs=1.0)
    assert round(r.modulation, 2) == 0.62


def test_sinefit_near_limit_and_fundamental() -> None:
    roi, case = bar_roi(1, shape=(40, 60), px_per_period=3.0, noise_sigma=1.0, modulation=0.6)
    r = estimate_modulation(roi, estimator="sinefit", freq_cycles_per_px=1 / 3)
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.01)
    # Only the fundamental is below Nyquist: bar contrast == fundamental modulation.
    assert r.fundamental_modulation == pytest.approx(r.modulation, rel=1e-5)


def test_sinefit_corrects_a_two_percent_frequency_error() -> None:
    roi, case = bar_roi(2, shape=(40, 80), px_per_period=10.0, noise_sigma=1.0)
    r = estimate_modulation(roi, estimator="sinefit", freq_cycles_per_px=1.02 / 10.0)
    assert r.modulation == pytest.approx(case.truth, abs=0.005)
    assert r.diagnostics.px_per_period == pytest.approx(10.0, rel=0.002)


def test_sinefit_finds_frequency_when_not_given() -> None:
    roi, case = bar_roi(4, shape=(30, 90), px_per_period=9.0, noise_sigma=1.0)
    r = estimate_modulation(roi, estimator="sinefit")
    assert r.diagnostics.px_per_period == pytest.approx(9.0, rel=0.01)
    assert r.modulation == pytest.approx(case.truth, abs=0.01)


def test_histogram_twelve_bit_msb_aligned_has_no_comb() -> None:
    roi, case = bar_roi(5, **{**WIDE, "bits": 12, "msb_aligned": True, "noise_sigma": 2.0})
    assert roi.dtype == np.uint16 and np.all(roi % 16 == 0)
    r = estimate_modulation(roi, estimator="histogram")
    assert r.diagnostics.code_step == 16.0
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.03)


def test_unimodal_histogram_is_not_resolved() -> None:
    """A sine-like ROI with amplitude ~1 sigma: one mode, so N/A rather than a number (its
    fundamental is below the noise, which says so first)."""
    roi, _ = bar_roi(6, shape=(40, 50), px_per_period=3.0, modulation=0.03, noise_sigma=4.0)
    r = estimate_modulation(roi, estimator="histogram")
    assert not r.resolved and r.modulation == 0.0 and r.dark is None and r.bright is None
    assert any("no bar pattern above the noise" in w for w in r.warnings)


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_flat_field_is_not_resolved(name: str) -> None:
    roi, _ = bar_roi(7, shape=(40, 50), modulation=0.0, noise_sigma=3.0)
    r = estimate_modulation(roi, estimator=name, freq_cycles_per_px=1 / 8)
    assert not r.resolved and r.modulation == 0.0


def test_manual_peaks_override() -> None:
    roi, _ = bar_roi(8, **WIDE)
    r = estimate_modulation(roi, estimator="histogram", peaks=(174, 41))
    assert r.estimator == "manual" and (r.dark, r.bright) == (41.0, 174.0)
    assert r.modulation == pytest.approx(133 / 215)
    same = estimate_modulation(roi, peaks=(90, 90))
    assert not same.resolved and same.modulation == 0.0
    with pytest.raises(ValueError, match="positive"):
        estimate_modulation(roi, peaks=(-5, 3))


def test_saturation_is_counted_and_flagged() -> None:
    roi, _ = bar_roi(9, **{**WIDE, "exposure_scale": 1.8})
    r = estimate_modulation(roi, estimator="histogram")
    assert r.diagnostics.clipped_fraction > 0.2
    assert any("clipped" in w for w in r.warnings)


def test_aliasing_and_phase_flags() -> None:
    roi, _ = bar_roi(10, shape=(40, 50), px_per_period=2.5, noise_sigma=0.5)
    near = estimate_modulation(roi, estimator="sinefit", freq_cycles_per_px=0.4)
    assert near.diagnostics.phase_sensitive and not near.diagnostics.aliased
    above = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=0.6)
    assert above.diagnostics.aliased and any("aliased" in w for w in above.warnings)
    low = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=0.1)
    assert not low.diagnostics.aliased and not low.diagnostics.phase_sensitive


def test_frame_stack_is_averaged_and_noise_from_frames() -> None:
    case = BarCase(**{**WIDE, "noise_sigma": 4.0, "n_frames": 8})
    stack = render(case, np.random.default_rng(11))
    assert stack.shape == (8, 40, 50)
    r = estimate_modulation(stack, estimator="sinefit", freq_cycles_per_px=1 / 16)
    assert r.diagnostics.n_frames == 8
    assert r.diagnostics.noise_sigma == pytest.approx(4.0 / math.sqrt(8), rel=0.2)
    assert r.modulation == pytest.approx(case.truth, abs=0.01)
    h = estimate_modulation(stack, estimator="histogram")
    assert h.resolved and h.modulation == pytest.approx(case.truth, abs=0.03)


def test_compare_estimators_fills_disagreement() -> None:
    roi, _ = bar_roi(12, **WIDE)
    results = compare_estimators(roi, freq_cycles_per_px=1 / 16, orientation="horizontal")
    assert set(results) == set(ESTIMATORS)
    spread = max(r.modulation for r in results.values()) - min(
        r.modulation for r in results.values()
    )
    for r in results.values():
        assert r.diagnostics.disagreement == pytest.approx(spread)
    # Near the limit the histogram gives up while the fit still measures: a flagged split.
    roi, _ = bar_roi(13, shape=(40, 50), px_per_period=2.5, noise_sigma=0.5, modulation=0.6)
    split = compare_estimators(roi, freq_cycles_per_px=0.4, tolerance=0.01)
    mods = [r.modulation for r in split.values()]
    flagged = [any("disagree" in w for w in r.warnings) for r in split.values()]
    assert flagged == [max(mods) - min(mods) > 0.01] * len(split)


def test_bootstrap_uncertainty() -> None:
    roi, case = bar_roi(14, **{**WIDE, "noise_sigma": 3.0})
    r = estimate_modulation(
        roi,
        estimator="variance",
        freq_cycles_per_px=1 / 16,
        orientation="horizontal",
        bootstrap=50,
        seed=1,
    )
    assert r.uncertainty_method == "bootstrap"
    assert 0 < r.uncertainty < 0.05
    assert r.interval[0] <= case.truth + 0.03 and r.interval[1] >= case.truth - 0.03


def test_result_is_json_safe_and_guards_its_invariants() -> None:
    roi, _ = bar_roi(15, **WIDE)
    r = estimate_modulation(roi, estimator="sinefit", freq_cycles_per_px=1 / 16)
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    assert {"estimator", "dark", "bright", "modulation", "resolved"} <= set(d)
    with pytest.raises(ValueError):
        ModulationResult("x", None, None, float("nan"), False, r.diagnostics)
    with pytest.raises(ValueError):
        ModulationResult("x", 1.0, 2.0, 0.3, False, r.diagnostics)


def test_unknown_names_are_clear_errors() -> None:
    roi, _ = bar_roi(16, **WIDE)
    with pytest.raises(ValueError, match="unknown estimator"):
        estimate_modulation(roi, estimator="eyeball")
    with pytest.raises(ValueError, match="orientation"):
        estimate_modulation(roi, orientation="diagonal")


def test_histogram_looks_past_shading_bumps() -> None:
    """A 20 % illumination ramp spreads each plateau into a bumpy hump; the two humps read as
    two peaks (a technician's reading), not "unimodal". (With the bar centres located from the
    measured geometry the first smoothing already does; the whole-ROI histogram too.)"""
    roi, case = bar_roi(
        17, shape=(100, 128), px_per_period=32.0, noise_sigma=0.5, duty=0.4, shading=0.2
    )
    r = estimate_modulation(roi, estimator="histogram")
    assert r.resolved and r.modulation == pytest.approx(case.truth, abs=0.01)
    assert r.diagnostics.smoothing_codes is not None


@pytest.mark.parametrize("duty", [0.4, 0.6])
def test_sinefit_handles_uneven_duty(duty: float) -> None:
    """Printed lines come out thicker or thinner (thesis appendix C): even harmonics fit it."""
    roi, case = bar_roi(18, shape=(40, 64), px_per_period=16.0, noise_sigma=1.0, duty=duty)
    r = estimate_modulation(roi, estimator="sinefit", freq_cycles_per_px=1 / 16)
    assert r.modulation == pytest.approx(case.truth, abs=0.015)


def test_variance_uses_whole_periods() -> None:
    """32 px bars in a 50 px ROI: a partial period would skew mean and variance."""
    roi, case = bar_roi(19, shape=(40, 50), px_per_period=32.0, noise_sigma=1.0, phase=0.3)
    r = estimate_modulation(
        roi, estimator="variance", freq_cycles_per_px=1 / 32, orientation="horizontal"
    )
    assert r.modulation == pytest.approx(case.truth, abs=0.02)


def test_sinefit_sharp_bars_in_a_short_roi() -> None:
    """Pixel-sharp bars, 1.6 periods in the thesis's 41 x 51 radial ROI: the truncated series
    would overshoot (Gibbs); the fit is Lanczos-smoothed and held to the profile's extremes."""
    roi, case = bar_roi(
        20,
        shape=(41, 51),
        px_per_period=32.0,
        psf_sigma_px=0.0,
        noise_sigma=1.0,
        modulation=0.73,
        mean=110.0,
    )
    r = estimate_modulation(
        roi, estimator="sinefit", freq_cycles_per_px=1 / 32, orientation="horizontal"
    )
    assert r.modulation == pytest.approx(case.truth, abs=0.01)
    assert any("sharp bars" in w for w in r.warnings)


def _sinefit_errors(f: float, n: int) -> np.ndarray:
    """sinefit minus truth on near-square bars (PSF sigma 0.3 px) at 8 sampling phases."""
    errs = []
    for i, phase in enumerate(np.linspace(0.0, 1.0, 8, endpoint=False)):
        roi, case = bar_roi(
            30 + i,
            shape=(20, n),
            px_per_period=1 / f,
            psf_sigma_px=0.3,
            noise_sigma=1.0,
            phase=float(phase),
        )
        r = estimate_modulation(
            roi, estimator="sinefit", freq_cycles_per_px=f, orientation="horizontal"
        )
        errs.append(r.modulation - case.truth)
    return np.asarray(errs)


@pytest.mark.parametrize("f", [0.23, 0.27, 0.29, 0.31])
def test_sinefit_aliased_third_harmonic_removes_square_wave_over_read(
    f: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Between ~0.225 and 1/3 cycles/px only the fundamental fits below Nyquist; alone it
    over-reads square-ish bars by up to (4/pi) sinc(f). The 3rd harmonic, fitted at its alias
    |3f - 1|, brings the reading back to the truth."""
    with_third = _sinefit_errors(f, 40)
    monkeypatch.setattr(estimators, "ALIASED_THIRD_MIN_SEPARATION", math.inf)
    fundamental_only = _sinefit_errors(f, 40)
    assert np.mean(fundamental_only) > 0.002  # the over-read being fixed
    assert np.mean(np.abs(with_third)) < 0.5 * np.mean(np.abs(fundamental_only))
    assert np.max(np.abs(with_third)) < 0.005


@pytest.mark.parametrize(
    ("f", "n"),
    [
        (0.2, 40),  # two harmonics fit below Nyquist: the 2nd absorbs the aliased 3rd
        (0.25, 40),  # alias |3f - 1| = f: indistinguishable from the fundamental
        (0.252, 40),  # alias 0.32 / n from f
        (0.32, 12),  # alias 0.04 = 0.48 / n from 0 (mean and shading)
        (0.33, 40),  # above 1/3 - 0.01
    ],
)
def test_sinefit_aliased_third_harmonic_guard_leaves_fit_unchanged(
    f: float, n: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert estimators._harmonic_orders(f, n, estimators._harmonics(f)).size <= 2
    if estimators._harmonics(f) == 1:
        assert list(estimators._harmonic_orders(f, n, 1)) == [1.0]
    roi, _ = bar_roi(41, shape=(20, n), px_per_period=1 / f, psf_sigma_px=0.3, noise_sigma=1.0)
    kwargs = {"estimator": "sinefit", "freq_cycles_per_px": f, "orientation": "horizontal"}
    before = estimate_modulation(roi, **kwargs)  # type: ignore[arg-type]
    monkeypatch.setattr(estimators, "ALIASED_THIRD_MIN_SEPARATION", math.inf)
    after = estimate_modulation(roi, **kwargs)  # type: ignore[arg-type]
    assert (before.modulation, before.dark, before.bright) == (
        after.modulation,
        after.dark,
        after.bright,
    )


def test_harmonic_orders_adds_the_aliased_third_only_where_it_is_separable() -> None:
    assert list(estimators._harmonic_orders(0.27, 40, 1)) == [1.0, 3.0]
    assert list(estimators._harmonic_orders(0.27, 10, 1)) == [1.0, 3.0]  # 0.76 / n from f
    assert list(estimators._harmonic_orders(0.27, 7, 1)) == [1.0]  # too few samples
    assert list(estimators._harmonic_orders(0.25, 40, 1)) == [1.0]
    assert list(estimators._harmonic_orders(0.1, 40, 4)) == [1.0, 2.0, 3.0, 4.0]
