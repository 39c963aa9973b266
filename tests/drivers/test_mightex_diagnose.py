"""The doctor's frame checks: each names the pattern a depth or packing error leaves."""

from __future__ import annotations

import numpy as np

from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.diagnose import depth_findings, period_finding, ratio_finding

RNG = np.random.default_rng(4)


def _noisy(mean: float, sigma: float, top: int) -> np.ndarray:
    return np.clip(RNG.normal(mean, sigma, (64, 64)).round(), 0, top).astype(np.uint16)


def test_plausible_frames_have_no_findings() -> None:
    assert depth_findings(_noisy(100, 5, 255).astype(np.uint8), 8) == []
    assert depth_findings(_noisy(400, 20, 1023), 10) == []
    assert depth_findings(_noisy(1600, 40, 4095), 12) == []


def test_10bit_data_read_with_the_12bit_rule_is_named() -> None:
    ten = _noisy(700, 60, 1023)
    words = np.empty_like(ten)
    p.pack_10bit(ten, words)
    as12 = p.unpack_12bit_inplace(words.copy())
    [finding] = depth_findings(as12, 12)
    assert "bits 2 and 3 are never set" in finding


def test_msb_aligned_data_and_missing_codes_are_named() -> None:
    [aligned] = depth_findings(_noisy(400, 30, 1023) << 2, 12)
    assert "lowest 2 bits never change" in aligned and "10 significant bits" in aligned
    sparse = (_noisy(60, 15, 255) * 3).astype(np.uint16)  # every third code only
    assert any("missing codes" in f for f in depth_findings(sparse, 10))
    assert "saturated" in depth_findings(np.full((8, 8), 255, np.uint8), 8)[0]


def test_period_and_ratio_findings() -> None:
    assert period_finding(100.0, 104.0) is None
    assert "2 x the profile's" in (period_finding(100.0, 200.0) or "")
    assert ratio_finding(10.0, 60.0, 110.0, 2.0) is None
    assert "ratio 1.5" in (ratio_finding(10.0, 60.0, 85.0, 2.0) or "")
    assert "no signal" in (ratio_finding(10.0, 9.0, 9.0, 2.0) or "")
