"""The one robust noise scale (benchlab.analysis.noise)."""

from __future__ import annotations

import numpy as np

from benchlab.analysis.noise import MAD_TO_SIGMA, robust_sigma


def test_robust_sigma_of_normal_noise_is_its_sigma_and_ignores_outliers() -> None:
    x = np.random.default_rng(0).normal(10.0, 2.0, 200_000)
    assert abs(robust_sigma(x) - 2.0) < 0.02
    x[:1000] = 1e6  # 0.5 % wild pixels
    assert abs(robust_sigma(x) - 2.0) < 0.05
    assert robust_sigma(np.full(10, 7.0)) == 0.0
    assert robust_sigma([0.0, 1.0, 2.0]) == MAD_TO_SIGMA  # median |x - 1| = 1
