"""The radial DOF ends' intervals carry the target contrast's own 1 sigma: the threshold on the
lens's share is ``threshold x target``, so each draw of the through-focus fit finds its ends at
its own draw of the target (:func:`benchlab.analysis.focus.through_focus.focus_estimate`,
``threshold_sd``). Synthetic readings (a Gaussian through focus, known slope at the ends) keep
the test fast and the expected widening in closed form."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from benchlab.analysis.chart.layout import RADIAL_ROI_BOX
from benchlab.analysis.focus.through_focus import fit_through_focus, focus_estimate
from benchlab.protocols.depth.params import DepthParams
from benchlab.protocols.depth.radial import SHARE_BASIS, analyze_radial
from benchlab.protocols.depth.radial_rois import RadialReading
from benchlab.protocols.target_contrast import TargetSetting, TargetSettings

#: The synthetic print's contrast and the reading through focus: PEAK exp(-((z - 6) / 3)^2).
PEAK, BEST_MM, WIDTH_MM, NOISE = 0.6, 6.0, 3.0, 0.003


def _row(sigma: float) -> dict[str, Any]:
    params = DepthParams(view="radial", near_mm=2.5, far_mm=10.5, step_mm=0.25, frames=1,
                         radial_orientations=("sagittal",), radial_rois=(RADIAL_ROI_BOX,),
                         design_half_range_mm=5.0,
                         targets=TargetSettings(radial=TargetSetting((PEAK,), sigma)))
    rng = np.random.default_rng(3)
    pos = []
    for z in params.distances_mm:
        m = PEAK * math.exp(-(((z - BEST_MM) / WIDTH_MM) ** 2)) + rng.normal(0.0, NOISE)
        pos.append(((2.0, "sagittal"), z, 0, (RadialReading(m, 1.1 * m, NOISE),)))
    row, = analyze_radial(pos, params)[0]["depth_of_field"]
    assert row["threshold_on"] == SHARE_BASIS and row["target_contrast_uncertainty"] == sigma
    return row


def test_a_target_sigma_of_zero_leaves_the_ends_and_their_intervals_as_before() -> None:
    row = _row(0.0)
    # pinned from the code before the target's sigma was carried (commit fe614e1), same input
    assert (row["near_mm"], row["near_mm_ci95"]) == (2.713, [2.684, 2.741])
    assert (row["far_mm"], row["far_mm_ci95"]) == (9.299, [9.28, 9.32])
    assert row["best_focus_mm_ci95"] == _row(0.05)["best_focus_mm_ci95"]


def test_a_large_target_sigma_widens_the_ends_intervals_by_its_crossing_shift() -> None:
    sigma = 0.05  # a certificate's 1 sigma: 8 % of the print's 0.6
    plain, wide = _row(0.0), _row(sigma)
    assert (wide["near_mm"], wide["far_mm"]) == (plain["near_mm"], plain["far_mm"])
    # the share's threshold 0.3 is the reading's 0.3 x target: its 1 sigma 0.3 sigma moves an
    # end by 0.3 sigma / |slope| (1 sigma), the slope of the reading where it crosses 0.18
    x = math.sqrt(-math.log(0.3))
    slope = 0.3 * PEAK * 2 * x / WIDTH_MM  # per mm
    shift = 1.96 * 0.3 * sigma / slope
    assert shift == pytest.approx(0.223, abs=0.001)
    for end in ("near_mm", "far_mm"):
        value = wide[end]
        lo0, hi0 = plain[end + "_ci95"]
        lo, hi = wide[end + "_ci95"]
        assert hi0 - lo0 < 0.07  # the fit's and the model term's alone
        # the target's draws and the fit's in the same draws: about their quadrature sum
        for half, half0 in ((value - lo, value - lo0), (hi - value, hi0 - value)):
            assert half == pytest.approx(math.hypot(half0, shift), rel=0.15)


def test_the_threshold_draws_leave_the_coefficient_draws_alone() -> None:
    z = np.arange(2.5, 10.51, 0.25) + 13.88
    m = PEAK * np.exp(-(((z - 13.88 - BEST_MM) / WIDTH_MM) ** 2))
    m = m + np.random.default_rng(5).normal(0.0, NOISE, z.size)
    fit = fit_through_focus(z, m, np.full(z.size, NOISE))
    a = focus_estimate(fit, 0.18, seed=7)
    b = focus_estimate(fit, 0.18, seed=7, threshold_sd=0.0)
    c = focus_estimate(fit, 0.18, seed=7, threshold_sd=0.015)
    assert a == b and np.array_equal(a.best_focus_draws, b.best_focus_draws)
    assert c.best_focus_ci95 == a.best_focus_ci95 and (c.near_mm, c.far_mm) == (a.near_mm, a.far_mm)
    assert c.near_ci95[0] < a.near_ci95[0] and c.far_ci95[1] > a.far_ci95[1]  # type: ignore[operator]
    with pytest.raises(ValueError, match="threshold_sd"):
        focus_estimate(fit, 0.18, threshold_sd=-0.01)
