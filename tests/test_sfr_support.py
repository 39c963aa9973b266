"""The data-driven LSF support (sfr.SUPPORT_*): the wide window follows a halo the 10-90 % rise
does not see, and neither noise nor an illumination slope stretches it."""

from __future__ import annotations

import math

import numpy as np
import pytest

import benchlab.analysis.sfr as sfr
from benchlab.analysis.sfr import measure_sfr
from benchlab.analysis.sfr_synthetic import edge_truth_mtf, synthetic_edge

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
    from benchlab.analysis.sfr_benchmark import (
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
