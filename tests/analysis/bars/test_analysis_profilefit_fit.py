"""``profilefit``'s fit itself: analytic derivatives, convergence from a poor start, the choice
between a given and a measured period, and honest intervals where the fit is hard."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from benchlab.analysis import estimate_modulation
from benchlab.analysis.bars.profilefit import _Model, _phasors, _scaled_pinv
from benchlab.synthetic.bars import bar_roi


@pytest.mark.parametrize("theta", [0.0, 0.5])
def test_model_derivatives_match_finite_differences(theta: float) -> None:
    """The phase, duty and blur derivatives of the model (the phase one had the wrong sign, so
    Levenberg-Marquardt could never move the phase off the spectral estimate)."""
    w = np.linspace(0.0, 1.0, 50, endpoint=False)
    model = _Model(w, 0.1, theta, 20)
    p = (0.1, 0.45, 1.0)
    value, deriv = model.eval(*p)
    assert deriv is not None
    h = 1e-6
    for j in range(3):
        q = list(p)
        q[j] += h
        numeric = (model.eval(*q, derivatives=False)[0] - value) / h
        assert np.abs(numeric - deriv[:, j]).max() < 1e-4 * max(np.abs(numeric).max(), 1.0)


@pytest.mark.parametrize(
    ("shape", "period", "angle", "sigma", "duty", "shading", "seed"),
    [
        ((40, 50), 32.15, 90.0, 0.39, 0.42, 0.22, 1),  # 1.25 periods: spectral phase off
        ((10, 40), 23.5, 61.9, 0.0, 0.52, 0.0, 2),
        ((20, 100), 17.5, 90.0, 0.78, 0.42, 0.0, 4),
    ],
)
def test_few_periods_fit_converges(
    shape: tuple[int, int], period: float, angle: float, sigma: float, duty: float,
    shading: float, seed: int,
) -> None:
    """One to three periods across the ROI: the fundamental's phase from the spectrum is pulled
    by its side lobes, and the fit must move it (before the fix: errors of 0.1-0.2)."""
    roi, case = bar_roi(
        seed, shape=shape, px_per_period=period, angle_deg=angle, psf_sigma_px=sigma,
        duty=duty, shading=shading, noise_sigma=0.4, electrons_per_dn=200.0,
    )
    axis = angle in (0.0, 90.0)
    r = estimate_modulation(
        roi, freq_cycles_per_px=1 / period,
        orientation=("vertical" if angle == 90.0 else "horizontal") if axis else None,
    )
    assert r.resolved
    assert r.modulation == pytest.approx(case.truth, abs=0.02)
    assert r.interval[0] <= case.truth <= r.interval[1]
    assert math.isfinite(r.uncertainty)


@pytest.mark.parametrize(
    ("shape", "period", "angle", "sigma", "exposure", "noise"),
    [
        ((64, 64), 8.1, 12.8, 2.0, 2.2, 0.5),  # blurred: 9 % of the pixels at the top code
        ((40, 50), 13.7, 80.0, 0.0, 2.3, 2.0),  # sharp bars: half the ROI saturated
    ],
)
def test_saturated_bars_read_against_the_unclipped_truth(
    shape: tuple[int, int], period: float, angle: float, sigma: float, exposure: float,
    noise: float,
) -> None:
    """Saturated pixels are censored, not data: the fit leaves the saturated phases out and
    the model carries the bright level beyond the top code (before: -0.13 and -0.16, interval
    missing the truth)."""
    roi, case = bar_roi(
        7, shape=shape, px_per_period=period, angle_deg=angle, psf_sigma_px=sigma,
        exposure_scale=exposure, mean=100.0, modulation=0.45, noise_sigma=noise,
        electrons_per_dn=5.0, bits=12, msb_aligned=True,
    )
    assert case.clipped and int(np.count_nonzero(roi == 65520)) > roi.size // 20
    r = estimate_modulation(roi, freq_cycles_per_px=1 / period)
    assert r.resolved
    assert r.modulation == pytest.approx(case.truth, abs=0.03)
    assert r.interval[0] <= case.truth <= r.interval[1]
    assert any("censored" in w for w in r.warnings)


def test_noise_clipping_does_not_bias_the_bright_level() -> None:
    """Bars whose noiseless bright level sits just under the top code: only the noise's upper
    tail is clipped (16 % of the pixels), and a saturated pixel stands for the tail's mean
    (read as the top code, the bright level came out low: -0.008 on average)."""
    errors = []
    for seed in range(6):
        roi, case = bar_roi(
            seed, shape=(100, 20), px_per_period=34.8, angle_deg=90.0, psf_sigma_px=0.66,
            duty=0.43, exposure_scale=1.8, mean=100.0, modulation=0.4, noise_sigma=6.0,
            electrons_per_dn=1.0, bits=12, msb_aligned=True,
        )
        assert not case.clipped and 0 < int(np.count_nonzero(roi == 65520)) < roi.size // 4
        r = estimate_modulation(roi, freq_cycles_per_px=1 / 34.8, orientation="vertical")
        assert r.interval[0] <= case.truth <= r.interval[1]
        errors.append(r.modulation - case.truth)
    assert abs(float(np.mean(errors))) < 0.003


def test_direction_refined_from_the_residuals() -> None:
    """Long bars across a short ROI: the spectral direction was 1.4 deg off, which moves the
    bar phase by 0.14 cycles at the ROI's ends (before: 0.527 against 0.602, outside its
    interval); Gauss-Newton on the per-pixel residuals corrects it."""
    roi, case = bar_roi(
        5, shape=(20, 100), px_per_period=8.62, angle_deg=76.3, psf_sigma_px=1.42, duty=0.49,
        mean=100.0, modulation=0.6, noise_sigma=0.5, electrons_per_dn=100.0,
    )
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 8.62)
    assert r.modulation == pytest.approx(case.truth, abs=0.01)
    assert r.interval[0] <= case.truth <= r.interval[1]
    angle = r.diagnostics.bar_angle_deg
    assert angle is not None and abs(angle - 76.3) < 0.4
    # The noise is the residual scatter, not the misfit (before: 20x the true noise).
    assert r.diagnostics.noise_sigma < 1.5 * case.noise_at_mean


def test_refined_period_agrees_with_the_given_one() -> None:
    """Three periods across a 20 x 100 ROI: the spectral peak put the period at 29.8 px and
    overruled the given 31.3 px (reading 0.525 against 0.639); the refined period agrees with
    the given one, and no disagreement is reported."""
    roi, case = bar_roi(
        6, shape=(20, 100), px_per_period=31.33, angle_deg=29.6, psf_sigma_px=3.71, duty=0.6,
        modulation=0.7, noise_sigma=1.0, electrons_per_dn=20.0,
    )
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 31.33)
    assert r.modulation == pytest.approx(case.truth, abs=0.02)
    period = r.diagnostics.px_per_period
    assert period is not None and abs(period - 31.33) < 0.3
    assert not any("disagrees" in w for w in r.warnings)


def test_one_period_across_with_the_spectral_direction_off() -> None:
    """1.1 periods across a 40 x 10 ROI at 15 deg: the spectral direction said under one
    period fits, so the bars were "not resolved" (truth 0.485); the refined one spans one."""
    roi, case = bar_roi(
        7, shape=(40, 10), px_per_period=18.32, angle_deg=15.4, psf_sigma_px=0.93, duty=0.45,
        modulation=0.5, noise_sigma=0.6, electrons_per_dn=50.0, phase=0.65,
    )
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 18.32)
    assert r.resolved
    assert r.modulation == pytest.approx(case.truth, abs=0.03)
    assert r.interval[0] <= case.truth <= r.interval[1]


@pytest.mark.slow
def test_benchmark_lists_the_worst_cases() -> None:
    """``benchlab benchmark analysis --worst N``: the N largest errors, largest first, each
    with the reading, interval and case parameters."""
    from benchlab.benchmarks.bars.estimators import (
        Row,
        format_worst,
        is_clipped_measurable,
        is_measurable,
        run_benchmark,
    )

    rows: list[Row] = []
    cases, _ = run_benchmark(n_cases=30, seed=2, workers=1, estimators=("profilefit",),
                             rows_out=rows)
    assert len(rows) == 30
    text = format_worst(cases, rows, 3).splitlines()
    assert text[0].startswith("profilefit: 3 worst of")
    errors = [abs(float(re.findall(r"[+-]\d+\.\d{3}", line)[0])) for line in text[1:]]
    assert len(errors) == 3 and errors == sorted(errors, reverse=True)
    scored = [r for r in rows if is_measurable(cases[r[0]]) or is_clipped_measurable(cases[r[0]])]
    assert errors[0] == pytest.approx(
        max(abs(r[2] - cases[r[0]].bar.truth) for r in scored), abs=1e-3)
    assert "period" in text[1] and "SNR" in text[1]


def test_bootstrap_keeps_the_model_term_and_skips_oblique_bars() -> None:
    """The bootstrap resamples lines of an image axis: it sees the noise only, so the model
    and sampling-phase term is added; on oblique bars a resampled line lands at another bar
    phase (the audit's 25 % coverage), so the analytic interval is kept and said so."""
    roi, case = bar_roi(8, shape=(40, 50), px_per_period=7.3, angle_deg=0.0, **{
        "noise_sigma": 1.5, "electrons_per_dn": 20.0})
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 7.3, orientation="horizontal",
                            bootstrap=20, seed=1)
    model = r.diagnostics.uncertainty_model
    assert r.uncertainty_method == "bootstrap" and model is not None and model > 0
    assert r.uncertainty >= model
    assert r.interval[1] - r.interval[0] >= 2 * 1.96 * model - 1e-9
    assert r.interval[0] <= case.truth <= r.interval[1]

    roi, case = bar_roi(9, shape=(40, 50), px_per_period=7.3, angle_deg=30.0, **{
        "noise_sigma": 1.5, "electrons_per_dn": 20.0})
    r = estimate_modulation(roi, freq_cycles_per_px=1 / 7.3, bootstrap=20, seed=1)
    assert r.uncertainty_method == "analytic"
    assert any("analytic uncertainty kept" in w for w in r.warnings)
    assert r.interval[0] <= case.truth <= r.interval[1]


def test_geometry_refinement_takes_small_steps_only() -> None:
    """Bars blurred away (PSF sigma 3.6 px at a 6.3 px period, truth 0.001): the spectrum finds
    an 18 px shading pattern, and unbounded Gauss-Newton steps chased the noise to a 31 px
    period (reading 0.006); steps over 6 deg or 15 % of the frequency are refused."""
    from benchlab.synthetic.bars import BarCase, render

    bar = BarCase(  # the benchmark's case 704 (seed 0), with its noise
        shape=(20, 100), px_per_period=6.301938037517345, modulation=0.41749896895793737,
        mean=93.34976734783896, psf_sigma_px=3.5734908380353363,
        noise_sigma=0.008171887116916394, phase=0.3805941186572196, duty=0.501135981673537,
        shading=0.021578291274496095, angle_deg=90.0, electrons_per_dn=907905.4398475882,
        pedestal=8.0,
    )
    roi = render(bar, np.random.default_rng(10_704))
    r = estimate_modulation(roi, freq_cycles_per_px=bar.freq_cycles_per_px,
                            orientation="vertical")
    period = r.diagnostics.px_per_period
    assert bar.truth < 0.002 and r.modulation < 0.004
    assert period is not None and period < 25.0


@pytest.mark.parametrize("rank", [9, 7])
def test_scaled_pinv_matches_the_svd_pseudo_inverse(rank: int) -> None:
    """The covariance's pseudo-inverse (eigen-decomposition of the scaled symmetric ``J^T J``)
    equals numpy's SVD one, also when directions are unconstrained (rank-deficient)."""
    rng = np.random.default_rng(rank)
    jac = rng.normal(size=(60, rank)) @ rng.normal(size=(rank, 9))
    jac *= np.logspace(-3, 3, 9)  # parameters of very different units
    jtj = jac.T @ jac
    d = np.sqrt(np.diag(jtj))
    expected = np.linalg.pinv(jtj / np.outer(d, d), rcond=1e-10) / np.outer(d, d)
    got = _scaled_pinv(jtj)
    assert np.allclose(got, expected, rtol=1e-6, atol=1e-9 * float(np.abs(expected).max()))
    if rank < 9:  # a plain inverse would blow up along the null space
        assert float(np.abs(got).max()) < 1e6 * float(np.abs(expected).max())


def test_phasors_by_running_product_match_cos_and_sin() -> None:
    """The phasors are powers of the fundamental (a running product, with the bins' damping
    folded in): equal to cos and sin of every harmonic to rounding, up to 48 harmonics."""
    w = np.random.default_rng(5).uniform(0.0, 1.0, 70)
    k = np.arange(1, 49, dtype=np.float64)
    arg = 2.0 * math.pi * np.outer(w, k)
    damp = np.exp(-np.outer(np.full(70, 1e-4), k * k))
    assert np.abs(_phasors(w, 48) - np.hstack([np.cos(arg), np.sin(arg)])).max() < 1e-12
    damped = np.hstack([np.cos(arg) * damp, np.sin(arg) * damp])
    assert np.abs(_phasors(w, 48, damp) - damped).max() < 1e-12


def test_profilefit_starts_from_the_quick_geometry(monkeypatch: pytest.MonkeyPatch) -> None:
    """With the frequency given, clear bars on a 2,000-pixel ROI are read without the 2-D
    spectrum (the structure-tensor start settles), within 0.02 of the truth."""
    from benchlab.analysis.bars import geometry as bargeometry

    roi, case = bar_roi(3, shape=(40, 50), px_per_period=8.0, angle_deg=27.0, noise_sigma=2.0,
                        electrons_per_dn=20.0, phase=0.4)

    def no_spectrum(resid: np.ndarray) -> None:
        raise AssertionError("the 2-D spectrum was computed")

    monkeypatch.setattr(bargeometry, "_spectrum", no_spectrum)
    got = estimate_modulation(roi, estimator="profilefit", freq_cycles_per_px=0.125)
    assert got.modulation == pytest.approx(case.truth, abs=0.02)
    assert got.interval[0] <= case.truth <= got.interval[1]
