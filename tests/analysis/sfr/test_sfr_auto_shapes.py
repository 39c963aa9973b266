"""Method auto on LSFs the Gaussian mixture does not model (the flat-top gate and the
agreement allowance), and the oracle ceiling of ``benchlab benchmark sfr --oracle``."""

from __future__ import annotations

import math

import numpy as np
import pytest

import benchlab.analysis.sfr.measure as sfr
import benchlab.analysis.sfr.model as sfr_model
from benchlab.analysis.sfr.measure import measure_sfr
from benchlab.analysis.sfr.model import LsfModelFit
from benchlab.benchmarks.sfr.edges import (
    _F_CHECK,
    NON_GAUSSIAN,
    _non_gaussian_case,
    iter_cases,
    run_accuracy,
)
from benchlab.benchmarks.sfr.oracle import fit_true_model, format_oracle, run_oracle
from benchlab.cli.main import main
from benchlab.synthetic.edges import synthetic_edge


def _mixture(weights: list[float], centres: list[float], sigmas: list[float]) -> LsfModelFit:
    k = len(weights)
    return LsfModelFit(np.array(weights), np.array(centres), np.array(sigmas), 0.0, 1.0, 50,
                       np.eye(1 + 3 * k), 1.0, 0.0, np.zeros(50))


def test_excess_kurtosis_of_the_fitted_lsf() -> None:
    assert _mixture([1.0], [0.3], [1.2]).excess_kurtosis == pytest.approx(0.0, abs=1e-12)
    # A halo (a wide, weak component under the core) is heavy-tailed ...
    assert _mixture([0.9, 0.1], [0.0, 0.0], [0.5, 4.0]).excess_kurtosis > 10.0
    # ... a split into two (a flat top) is flatter than a Gaussian: two delta-like
    # components +-d apart have excess kurtosis -2.
    assert _mixture([1.0, 1.0], [-1.0, 1.0], [0.7, 0.7]).excess_kurtosis < -0.5
    assert _mixture([1.0, 1.0], [-1.0, 1.0], [1e-3, 1e-3]).excess_kurtosis == pytest.approx(
        -2.0, abs=1e-4)


def _disc_r2(seed: int) -> np.ndarray:
    parts = NON_GAUSSIAN["defocus disc R 2 px (+ 0.3 px Gaussian)"]
    img, _ = _non_gaussian_case(parts, 9.0, 0.3, 0.6 / 50, np.random.default_rng(seed))
    return img


def test_auto_gives_the_model_free_reading_on_a_defocus_disc(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    img = _disc_r2(2)
    res = measure_sfr(img)
    free = measure_sfr(img, method="free")
    assert res.estimator == "model-free"
    assert any("flat-topped LSF" in w for w in res.warnings)
    assert res.lsf_model is not None and res.lsf_model["components"] >= 2
    assert np.array_equal(res.mtf, free.mtf)
    # Without the flat-top gate the Gaussians read it (what the benchmark saw: 42 % within
    # 0.02 against the model-free 83 %).
    monkeypatch.setattr(sfr_model, "FLAT_TOP_KURTOSIS", -math.inf)
    assert measure_sfr(img).estimator == "LSF model"


def test_flat_top_gate_leaves_gaussian_and_halo_edges_to_the_model() -> None:
    rng = np.random.default_rng(8)
    for sigma in (0.3, 1.0, 3.0):
        img = synthetic_edge((100, 100), float(rng.uniform(2, 40)), sigma,
                             noise_sigma=0.6 / 20, bits=12, rng=rng).astype(np.uint16)
        assert measure_sfr(img).estimator == "LSF model"
    parts = NON_GAUSSIAN["halo: 0.5 px core + 10 % in a 4 px halo"]
    img, _ = _non_gaussian_case(parts, 11.0, 0.2, 0.6 / 50, rng)
    res = measure_sfr(img)
    assert res.estimator == "LSF model" and res.lsf_model is not None
    assert res.lsf_model["components"] == 2


def test_agreement_allowance() -> None:
    n = sfr.FREQS_CYCLES_PER_PX.size
    m = np.linspace(1.0, 0.0, n)
    sig = np.full(n, 0.01)
    assert np.array_equal(sfr._agreement_allowance(m, m, sig), np.zeros(n))
    # Within the allowed share of the noise: nothing; a steady 0.05 apart: ~0.05.
    assert np.max(sfr._agreement_allowance(m + 0.003, m, sig)) == 0.0
    got = sfr._agreement_allowance(m + 0.05, m, sig)
    assert np.allclose(got, math.sqrt(0.05**2 - (sfr.AGREEMENT_NOISE_FRACTION * 0.01) ** 2))


def test_agreement_allowance_covers_a_disc_read_as_one_gaussian(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A disc R 1.5 px blurred by 1 px passes every gate as one Gaussian, slightly wrong: its
    # intervals cover the truth once they allow for the model-free reading's disagreement.
    parts = NON_GAUSSIAN["disc R 1.5 px + 1 px Gaussian"]
    rng = np.random.default_rng(21)
    cover_on, cover_off = [], []
    for _ in range(6):
        img, truth = _non_gaussian_case(parts, float(rng.uniform(2, 40)),
                                        float(rng.uniform(-2, 2)), 0.6 / 50, rng)
        for fraction, cover in ((0.4, cover_on), (1e6, cover_off)):
            monkeypatch.setattr(sfr, "AGREEMENT_NOISE_FRACTION", fraction)
            r = measure_sfr(img)
            sig = r.sigma_at(_F_CHECK)
            assert sig is not None
            cover.extend((np.abs(r.mtf_at(_F_CHECK) - truth) <= 1.96 * sig)[1:].tolist())
    assert np.mean(cover_on) >= 0.95 > np.mean(cover_off)


def test_oracle_recovers_the_blur_of_a_noiseless_edge() -> None:
    img = synthetic_edge((100, 100), 7.0, 0.6, offset_px=0.4)  # fractions of full scale
    fit = fit_true_model(img, 1.0, angle_deg=9.0, offset_px=0.0, sigma_px=1.0, dark=0.25,
                         bright=0.7)
    assert fit.sigma_px == pytest.approx(0.6, abs=1e-6)
    assert fit.angle_deg == pytest.approx(7.0, abs=1e-6)
    assert fit.offset_px == pytest.approx(0.4, abs=1e-6)
    assert (fit.dark, fit.bright) == pytest.approx((0.2, 0.8), abs=1e-7)


@pytest.mark.slow
def test_oracle_reads_the_benchmarks_own_cases() -> None:
    # iter_cases replays run_accuracy's random stream: the very images it scores.
    drawn = [(s, snr, c) for s, snr, c in iter_cases(1, 3, sigmas_px=(0.6,), snrs=(20.0, 50.0))]
    assert [(s, snr) for s, snr, _ in drawn] == [(0.6, 20.0)] * 2 + [(0.6, 50.0)] * 2
    acc = run_accuracy(1, 3, sigmas_px=(0.6,), snrs=(20.0,), method="auto")[0]
    res = [measure_sfr(c.image, method="auto") for _, snr, c in drawn if snr == 20.0]
    assert acc.cases == len(res) == 2
    buckets = run_oracle(cases_per_cell=1, seed=0, sigmas_px=(0.6, 1.0))
    assert [b.sigma_px for b in buckets] == [0.6, 1.0] and all(b.cases == 2 for b in buckets)
    auto = run_accuracy(1, 0, sigmas_px=(0.3, 0.6, 1.0, 2.0, 3.0), method="auto")
    by_sigma = {b.sigma_px: b for b in auto if b.snr == 20.0}
    for b in buckets:
        assert b.auto_mtf == by_sigma[b.sigma_px].mtf_within
        assert b.auto_mtf50 == by_sigma[b.sigma_px].mtf50_within
        assert 0.0 <= b.oracle_both <= min(b.oracle_mtf, b.oracle_mtf50) <= 1.0
    text = format_oracle(buckets)
    assert "oracle: MTF50<=2%" in text and len(text.splitlines()) == 5
    # Each line ends with the right model's floor over what 95 % needs (0.6 px: 1.64x).
    assert text.splitlines()[2].endswith("1.64x") and text.splitlines()[3].endswith("1.32x")


@pytest.mark.slow
def test_cli_oracle_prints_its_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["benchmark", "sfr", "--oracle", "--quick", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "oracle ceiling, SNR 20, 100-row edges" in out
    sigmas = ["0.3", "0.6", "1.0", "2.0", "3.0"]
    rows = [ln.split() for ln in out.splitlines() if ln.strip()[:3] in sigmas]
    # Every blur, on the judged table's cases (--quick: 12 per bit depth), with its floor.
    assert [r[0] for r in rows] == sigmas and all(r[1] == "24" for r in rows)
    assert [r[-1] for r in rows] == ["2.03x", "1.64x", "1.32x", "0.99x", "0.83x"]
    assert "method free" not in out  # the oracle alone
