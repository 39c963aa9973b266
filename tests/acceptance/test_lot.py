"""Lot statistics with known values: the binomial interval, Cpk and the control chart flags."""

from __future__ import annotations

import math

import pytest

from benchlab.acceptance.lot import D2_MOVING_RANGE, control_chart, cpk, yield_interval


def test_clopper_pearson_closed_forms() -> None:
    # x = 0 or x = n: the one-sided bounds have closed forms, (alpha/2)^(1/n)
    assert yield_interval(0, 20) == pytest.approx((0.0, 1 - 0.025 ** (1 / 20)))
    assert yield_interval(20, 20) == pytest.approx((0.025 ** (1 / 20), 1.0))
    low, high = yield_interval(5, 10)
    assert (low, high) == pytest.approx((0.187086, 0.812914), abs=1e-6)  # symmetric about 1/2
    assert yield_interval(0, 0) == (0.0, 1.0)


def test_cpk_and_its_interval() -> None:
    values = [0.60, 0.62, 0.64, 0.66, 0.68]
    mean, s = 0.64, math.sqrt(0.001)  # sample std of the five: sqrt(0.004 / 4)
    index, low, high = cpk(values, 0.55, 0.70)
    assert index == pytest.approx((0.70 - mean) / (3 * s))  # the nearer limit decides
    half = 1.959964 * math.sqrt(1 / 45 + index**2 / 8)
    assert (low, high) == pytest.approx((index - half, index + half), abs=1e-6)
    assert cpk(values, 0.55, None)[0] == pytest.approx((mean - 0.55) / (3 * s))
    assert cpk([0.6], 0.5, None) == (None, None, None)
    assert cpk([0.6, 0.6, 0.6], 0.5, None) == (None, None, None)  # no spread: undefined


def test_control_chart_limits_and_flags() -> None:
    values = [1.0, 1.2] * 6 + [2.0]  # alternating, then one far point
    chart = control_chart(values)
    assert chart is not None
    centre = sum(values) / len(values)
    moving = [abs(b - a) for a, b in zip(values, values[1:], strict=False)]
    sigma = sum(moving) / len(moving) / D2_MOVING_RANGE
    assert (chart.centre, chart.ucl, chart.lcl) == pytest.approx(
        (centre, centre + 3 * sigma, centre - 3 * sigma))
    assert chart.beyond == [12] and chart.runs == []
    shifted = [1.0, 1.1] * 3 + [1.3, 1.4] * 4 + [1.0]  # eight above the centre in a row
    flagged = control_chart(shifted)
    assert flagged is not None and flagged.runs == [(6, 13)] and flagged.beyond == []
    assert control_chart([1.0, 2.0]) is None
