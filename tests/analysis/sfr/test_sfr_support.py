"""The data-driven LSF support (sfr.SUPPORT_*): the wide window follows a halo the 10-90 % rise
does not see, and neither noise nor an illumination slope stretches it."""

from __future__ import annotations

import math

import numpy as np
import pytest

import benchlab.analysis.sfr.measure as sfr
from benchlab.analysis.sfr.measure import measure_sfr
from benchlab.synthetic.edges import edge_truth_mtf, synthetic_edge

F_NYQ = np.linspace(0.0, 0.5, 101)
ANGLE = 5.0


def _halo_edge(noise: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A sharp core (0.5 px) with 10 % of the light in a 4 px halo (flare, veiling glare): the
    12-bit ROI and its truth MTF."""
    a = math.radians(ANGLE)
    clean = 0.9 * synthetic_edge((100, 100), ANGLE, 0.5) + 0.1 * synthetic_edge((100, 100),
                                                                                ANGLE, 4.0)
    img = clean + np.random.default_rng(seed).normal(0.0, noise, clean.shape) if noise else clean
    truth = 0.9 * edge_truth_mtf(F_NYQ, 0.5, a) + 0.1 * edge_truth_mtf(F_NYQ, 4.0, a)
    return np.clip(np.floor(img * 4095 + 0.5), 0, 4095).astype(np.uint16), truth


@pytest.mark.parametrize("noise", [0.0, 0.006])
def test_the_wide_window_follows_a_halo(noise: float, monkeypatch: pytest.MonkeyPatch) -> None:
    img, truth = _halo_edge(noise, 1)
    res = measure_sfr(img)
    assert float(np.max(np.abs(res.mtf_at(F_NYQ) - truth))) < 0.015
    assert res.lsf_windows[0].flat_half_px > 6.0  # the halo reaches ~2 sigma = 8 px
    # With the rise-based window alone (~4 px) the halo is cut: the MTF near 0.07 c/px reads
    # ~0.04 high.
    monkeypatch.setattr(sfr, "SUPPORT_SIGMAS", 0.0)
    cut = measure_sfr(img)
    assert cut.lsf_windows[0].flat_half_px < 4.5
    assert float(np.max(np.abs(cut.mtf_at(F_NYQ) - truth))) > 0.03


@pytest.mark.parametrize("snr", [math.inf, 100.0, 20.0])
@pytest.mark.parametrize("ramp", [0.0, 0.1])
def test_noise_and_an_illumination_slope_leave_a_gaussian_window_alone(
    snr: float, ramp: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A 10 % illumination slope across the ROI: the plateaus are lines, not a halo.
    clean = synthetic_edge((100, 100), 7.0, 1.0) * (1 + ramp * np.linspace(-0.5, 0.5, 100))
    noise = 0.0 if math.isinf(snr) else 0.6 / snr
    rng = np.random.default_rng(2)
    img = clean + rng.normal(0.0, noise, clean.shape) if noise else clean
    roi = np.clip(np.floor(img * 4095 + 0.5), 0, 4095).astype(np.uint16)
    wide = measure_sfr(roi).lsf_windows[0].flat_half_px
    monkeypatch.setattr(sfr, "SUPPORT_SIGMAS", 0.0)
    assert wide == pytest.approx(measure_sfr(roi).lsf_windows[0].flat_half_px, abs=0.5)


def test_benchmark_scores_non_gaussian_lsfs_against_their_own_truth() -> None:
    from benchlab.benchmarks.sfr.edges import (
        NON_GAUSSIAN,
        NON_GAUSSIAN_SNRS,
        format_non_gaussian,
        run_non_gaussian,
    )

    rows = run_non_gaussian(cases=1, seed=4, snrs=(math.inf, NON_GAUSSIAN_SNRS[-1]))
    assert len(rows) == len(NON_GAUSSIAN) * 2 * 2  # two SNRs, two methods
    noise_free = [r for r in rows if math.isinf(r.snr)]
    assert all(r.mtf_within == 1.0 and r.mtf50_within == 1.0 and r.mtf_err_p95 < 0.015
               for r in noise_free)
    text = format_non_gaussian(rows)
    assert "halo" in text and "box 3 px" in text and "defocus disc" in text
    assert text.count("\n") == len(rows) // 2 + 2  # one line per LSF and SNR


def test_wilson_interval_of_a_share() -> None:
    from benchlab.benchmarks.sfr.edges import wilson_interval

    # Reference values (Wilson 1927, z = 1.96): 47 of 50 -> [0.838, 0.979]; 50 of 50 ->
    # [0.929, 1]; 0 of 10 -> [0, 0.278].
    assert wilson_interval(47, 50) == pytest.approx((0.8378, 0.9794), abs=5e-4)
    lo, hi = wilson_interval(50, 50)
    assert lo == pytest.approx(0.9287, abs=5e-4) and hi == 1.0
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=5e-4)
    assert wilson_interval(0, 0) == (0.0, 1.0)


def test_a_bucket_passes_on_cases_within_both_tolerances_at_once() -> None:
    from benchlab.benchmarks.sfr.edges import Bucket, format_accuracy, pooled_share

    # 96 % within each tolerance, but the misses are different cases: 92 % within both.
    split = Bucket(3.0, 20.0, 100, 50, 0, 0.96, 0.96, 0.5, 0.01, 0.97, 0.97, "auto", 1.0,
                   both_within=0.92)
    assert not split.passed
    assert split.both_interval == pytest.approx((0.8116, 0.9685), abs=5e-4)
    line = format_accuracy([split]).splitlines()[1]
    assert "92% [81-97]" in line and "FAIL" in line
    ok = Bucket(3.0, 50.0, 100, 50, 0, 0.98, 1.0, 0.3, 0.01, 0.99, 1.0, "auto", 1.0,
                both_within=0.98)
    assert ok.passed
    not_judged = Bucket(3.0, 10.0, 100, 50, 0, 0.2, 0.2, 3.0, 0.1, 0.9, 0.9, both_within=0.1)
    share, n = pooled_share([split, ok, not_judged])
    assert n == 100 and share == pytest.approx(0.95)
