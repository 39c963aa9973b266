"""DOF criteria as MTF thresholds; astigmatic difference and field curvature from draws."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.focus.criteria import Criterion, mtf_threshold, spot_threshold
from benchlab.analysis.focus.field import astigmatic_difference, field_curvature


def test_spot_threshold_is_the_gaussian_spot_mtf_times_the_pixel_aperture() -> None:
    f_um = 20.0 / 1000.0
    gauss = math.exp(-(math.pi * 12.0 * f_um) ** 2)
    x = f_um * 5.2
    assert spot_threshold(12.0, 20.0, 5.2) == pytest.approx(
        gauss * math.sin(math.pi * x) / (math.pi * x), rel=1e-12)
    # the same spot as a Gaussian of per-axis sigma r / sqrt 2
    sigma = 12.0 / math.sqrt(2)
    assert math.exp(-2 * (math.pi * sigma * f_um) ** 2) == pytest.approx(gauss, rel=1e-12)


def test_each_kind_reduces_to_a_threshold() -> None:
    assert mtf_threshold(Criterion("mtf", 70.0, threshold=0.46), 5.2) == 0.46
    assert mtf_threshold(Criterion("mtf50", 35.0), 5.2) == 0.5
    assert mtf_threshold(Criterion("spot", 20.0, rms_um=12.0), 5.2) == pytest.approx(
        spot_threshold(12.0, 20.0, 5.2))
    assert Criterion("spot", 20.0, rms_um=12.0).name == "spot<=12um@20"


def test_astigmatic_difference_is_s_minus_t_with_its_interval() -> None:
    rng = np.random.default_rng(0)
    s = [60.0 + rng.normal(0, 0.05, 4000) for _ in range(2)]
    t = [61.0 + rng.normal(0, 0.05, 4000) for _ in range(2)]
    value, ci = astigmatic_difference(s, t)
    assert value == pytest.approx(-1.0, abs=0.01)
    assert ci is not None and ci[0] < -1.0 < ci[1] and ci[1] < 0


def test_field_curvature_recovers_the_slope_in_h_squared() -> None:
    rng = np.random.default_rng(0)
    h = [0.2, 0.5, 0.8, 1.0]
    draws = [60.0 + 2.0 * x * x + rng.normal(0, 0.02, 4000) for x in h]
    k, b0, k_ci, b0_ci = field_curvature(h, draws)
    assert k == pytest.approx(2.0, abs=0.02) and b0 == pytest.approx(60.0, abs=0.02)
    assert k_ci is not None and k_ci[0] < 2.0 < k_ci[1]
    with pytest.raises(ValueError, match="two image heights"):
        field_curvature([0.5, 0.5], draws[:2])
