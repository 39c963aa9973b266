"""Noise-band pooling of the SFR's debiased power (sfr.NOISE_BAND_*): less noise where the MTF
is lost in it, no bias where it is not (noise-free sigma 0.3 px, a non-Gaussian box LSF); the
LSF windows the SFR reports."""

from __future__ import annotations

import math

import numpy as np
import pytest

import benchlab.analysis.sfr.measure as sfr
from benchlab.analysis.sfr.measure import measure_sfr
from benchlab.synthetic.edges import edge_truth_mtf, synthetic_edge

F_NYQ = np.linspace(0.0, 0.5, 101)


def _box_edge(angle_deg: float, width_px: float, noise: float, rng: np.random.Generator
              ) -> np.ndarray:
    """An edge blurred by a box PSF ``width_px`` wide (and 0.3 px Gaussian): the mean of
    shifted edges, trapezoid weights. Its MTF has a zero at 1 / width and a side lobe."""
    offsets = np.linspace(-width_px / 2, width_px / 2, 61)
    w = np.ones(offsets.size)
    w[0] = w[-1] = 0.5
    clean = np.average([synthetic_edge((100, 100), angle_deg, 0.3, offset_px=o)
                        for o in offsets], axis=0, weights=w)
    img = clean + rng.normal(0.0, noise, clean.shape) if noise else clean
    return np.clip(np.floor(img * 4095 + 0.5), 0, 4095).astype(np.uint16)


def _max_over_zero_band(seed: int) -> np.ndarray:
    """Max reading over 0.25-0.5 c/px (truth < 1e-3) of 16 sigma-3 px edges at SNR 50."""
    rng = np.random.default_rng(seed)
    f = np.linspace(0.25, 0.5, 51)
    out = []
    for i in range(16):
        img = synthetic_edge((100, 100), 8.0 + 2 * i, 3.0, noise_sigma=0.6 / 50, bits=12,
                             rng=rng)
        res = measure_sfr(img.astype(np.uint16), method="free")
        assert float(np.max(edge_truth_mtf(f, 3.0, math.radians(8.0 + 2 * i)))) < 1e-3
        out.append(float(np.max(res.mtf_at(f))))
    return np.asarray(out)


def test_pooling_keeps_noise_from_reading_as_mtf_where_the_truth_is_zero(
    monkeypatch: pytest.MonkeyPatch
) -> None:
    pooled = _max_over_zero_band(11)
    # Measured: 12/16 within 0.02 (90th percentile 0.023) pooled; 7/16 (0.034) without.
    assert np.mean(pooled <= 0.02) >= 0.7 and np.percentile(pooled, 90) < 0.028
    monkeypatch.setattr(sfr, "NOISE_BAND_CYCLES_PER_PX", 0.0)
    single = _max_over_zero_band(11)
    assert np.mean(single <= 0.02) < 0.6 and np.percentile(single, 90) > 0.03


@pytest.mark.parametrize("angle_deg", [3.0, 17.0, 33.0])
def test_pooling_leaves_a_sharp_noise_free_edge_alone(
    angle_deg: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    img = synthetic_edge((100, 100), angle_deg, 0.3, offset_px=0.2, bits=8).astype(np.uint8)
    truth = edge_truth_mtf(F_NYQ, 0.3, math.radians(angle_deg))
    pooled = measure_sfr(img, method="free").mtf_at(F_NYQ)
    assert float(np.max(np.abs(pooled - truth))) < 0.01
    monkeypatch.setattr(sfr, "NOISE_BAND_CYCLES_PER_PX", 0.0)
    assert float(np.max(np.abs(measure_sfr(img, method="free").mtf_at(F_NYQ) - pooled))) < 0.002


@pytest.mark.parametrize("noise", [0.0, 0.006])
def test_a_box_lsf_with_a_zero_below_nyquist_is_measured_unbiased(
    noise: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Box 3 px: MTF zero at 0.333 c/px, side lobe ~0.1 at 0.5: not a Gaussian, and the
    # pooling must neither fill the zero nor flatten the lobe.
    img = _box_edge(12.0, 3.0, noise, np.random.default_rng(4))
    truth = edge_truth_mtf(F_NYQ, 0.3, math.radians(12.0)) * np.abs(np.sinc(3.0 * F_NYQ))
    pooled = measure_sfr(img, method="free").mtf_at(F_NYQ)
    assert float(np.max(np.abs(pooled - truth))) < (0.002 if noise == 0 else 0.02)
    monkeypatch.setattr(sfr, "NOISE_BAND_CYCLES_PER_PX", 0.0)
    assert float(np.max(np.abs(measure_sfr(img, method="free").mtf_at(F_NYQ) - pooled))) < 0.005


@pytest.mark.parametrize("sigma", [0.3, 3.0])
def test_lsf_windows_are_reported_and_narrow_with_frequency(sigma: float) -> None:
    res = measure_sfr(synthetic_edge((100, 100), 7.0, sigma, noise_sigma=0.006, bits=12,
                                     rng=np.random.default_rng(2)).astype(np.uint16))
    wins = res.lsf_windows
    assert 2 <= len(wins) <= 3 and wins[0].from_cycles_per_px == 0.0
    # The widest window's flat top holds the Gaussian LSF to +-3 sigma (and the pixel).
    assert wins[0].flat_half_px >= 3.0 * sigma + 0.5
    for wide, narrow in zip(wins, wins[1:], strict=False):
        assert narrow.flat_half_px <= wide.flat_half_px
        assert wide.full_from_cycles_per_px <= narrow.from_cycles_per_px
        assert narrow.from_cycles_per_px < narrow.full_from_cycles_per_px
    assert res.to_dict()["lsf_windows"][0]["flat_half_px"] == pytest.approx(
        wins[0].flat_half_px, abs=1e-4)
