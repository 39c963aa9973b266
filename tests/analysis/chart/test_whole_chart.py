"""The whole USAF 1951 chart (groups -2 to 7) and its finder at any scale and rotation: a
microscope's groups 4-7, a fifth and ten times that scale, the coarse groups from afar."""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np
import pytest

from benchlab.analysis.chart.finder import ChartNotFoundError
from benchlab.analysis.chart.layout import usaf_bar_groups
from benchlab.analysis.chart.pose import ChartPose
from benchlab.analysis.chart.whole import find_whole_chart
from benchlab.analysis.chart.whole_layout import (
    WHOLE_CHART_GROUPS,
    whole_chart_centres_mm,
    whole_chart_layout,
)
from benchlab.scenes.usaf import render_chart_image


def _frame(magnification: float, rot_deg: float, off_rc: tuple[float, float] = (0.0, 0.0),
           shape: tuple[int, int] = (600, 800), seed: int = 0, negative: bool = False
           ) -> np.ndarray:
    """An 8-bit frame of the whole chart, its centre at the frame centre + ``off_rc``."""
    lay = whole_chart_layout(magnification, origin_rc=((shape[0] - 1) / 2, (shape[1] - 1) / 2))
    img = render_chart_image(lay, ChartPose(off_rc, 1.0, rot_deg), *shape, blur_px=0.8)
    if negative:
        img = 1.0 - img
    img = img + np.random.default_rng(seed).normal(0.0, 0.01, img.shape)
    return np.clip(np.round(img * 255), 0, 255).astype(np.uint8)


def _rot_error(found_deg: float, true_deg: float) -> float:
    return abs((found_deg - true_deg + 45.0) % 90.0 - 45.0)


def test_the_whole_chart_holds_groups_minus_2_to_7_in_nested_quarter_size_layers() -> None:
    lay = whole_chart_layout(1.0)
    assert {g for g, _ in lay.elements} == set(range(-2, 8)) == set(WHOLE_CHART_GROUPS)
    assert len(lay.elements) == 60
    centres = whole_chart_centres_mm()
    for (g, e), (x, y) in centres.items():
        if g + 2 in WHOLE_CHART_GROUPS:  # each layer is the one outside it at a quarter size
            x2, y2 = centres[(g + 2, e)]
            assert (x2, y2) == pytest.approx((x / 4, y / 4), abs=1e-12)
    sets = usaf_bar_groups(lay)
    assert len(sets) == 120
    for b in sets:  # MIL-STD-150A: 2^(g + (e - 1) / 6) lp/mm, bars 5 widths long
        assert b.object_lp_per_mm == pytest.approx(2.0 ** (b.group + (b.element - 1) / 6))
        assert b.bar_length_px == pytest.approx(5 * b.bar_width_px)
    for a, b in combinations(sets, 2):  # no two sets overlap
        t1, l1, b1, r1 = a.extent
        t2, l2, b2, r2 = b.extent
        assert r1 < l2 or r2 < l1 or b1 < t2 or b2 < t1, (a.label, b.label)


@pytest.mark.slow
def test_a_microscope_view_of_groups_4_to_7_rotated_is_found_and_named() -> None:
    """The issue's captures: groups 4-7 under a microscope (image 4x the object), where the
    forward view's finder (groups 0-3, 0.5-2x of 16.3) says "no chart found"."""
    fit = find_whole_chart(_frame(0.25, 17.0), magnification=0.3)
    assert fit.groups_found == [4, 5, 6, 7]
    assert fit.implied_magnification == pytest.approx(0.25, rel=0.01)
    assert _rot_error(fit.pose.rotation_deg, 17.0) < 0.2
    assert len(fit.found) >= 30
    g5e3 = fit.element(5, 3, "sagittal")
    assert g5e3.found and g5e3.posed.object_lp_per_mm == pytest.approx(40.3175, abs=1e-3)


def test_at_a_fifth_of_the_microscope_scale_the_same_groups_are_found_with_coarser_ones(
) -> None:
    fit = find_whole_chart(_frame(1.25, -30.0), magnification=1.0)
    assert fit.implied_magnification == pytest.approx(1.25, rel=0.01)
    assert {3, 4, 5} <= set(fit.groups_found)
    assert _rot_error(fit.pose.rotation_deg, -30.0) < 0.2


def test_at_ten_times_the_microscope_scale_a_few_elements_of_groups_6_and_7() -> None:
    """Only a few elements of groups 6 and 7 in view (bars 15-60 px wide), rotated 12 deg."""
    m, rot = 0.025, 12.0
    mm_to_px = 1000.0 / m / 5.2
    (x6, y6), (x7, y7) = (whole_chart_centres_mm()[k] for k in ((6, 1), (7, 5)))
    x, y = 0.5 * (x6 + x7) * mm_to_px, 0.5 * (y6 + y7) * mm_to_px  # on the frame centre
    t = math.radians(rot)
    off = (-(x * math.sin(t) + y * math.cos(t)), -(x * math.cos(t) - y * math.sin(t)))
    fit = find_whole_chart(_frame(m, rot, off, shape=(1024, 1024)), magnification=0.03)
    assert fit.groups_found == [6, 7]
    assert fit.implied_magnification == pytest.approx(m, rel=0.01)
    assert {"G6E1", "G7E5", "G7E6"} <= {e.label[:4] for e in fit.found}


@pytest.mark.slow
def test_the_coarse_groups_from_afar_at_45_deg() -> None:
    fit = find_whole_chart(_frame(10.0, 45.0, shape=(768, 1024)), magnification=8.0)
    assert fit.implied_magnification == pytest.approx(10.0, rel=0.01)
    assert {-1, 0, 1, 2} <= set(fit.groups_found)


@pytest.mark.slow
def test_without_a_hint_a_negative_chart_is_found_and_the_ambiguity_said() -> None:
    """Self-similar every two groups: without a magnification the groups are named for the
    forward view's 16.3 (4^3 x 0.25 = 16), and a warning says so."""
    fit = find_whole_chart(_frame(0.25, -8.0, negative=True))
    assert fit.polarity == "negative"
    assert fit.implied_magnification == pytest.approx(16.0, rel=0.01)
    assert fit.groups_found == [-2, -1, 0, 1]
    assert any("no magnification given" in w for w in fit.warnings)
    assert any("repeats itself every two groups" in w for w in fit.warnings)


def test_a_frame_without_a_chart_is_refused() -> None:
    rng = np.random.default_rng(1)
    with pytest.raises(ChartNotFoundError, match="no chart found"):
        find_whole_chart(rng.normal(100, 3, (300, 400)), magnification=1.0)
