"""Chart geometry shared by the USAF scene and the MTF procedure."""

from __future__ import annotations

import itertools
import math

import pytest

from benchlab.analysis.chart import layout as chart
from benchlab.analysis.mtf.frequency import px_per_period, usaf_frequency_lp_per_mm

THESIS_ELEMENTS = [(1, 5), (1, 6), (2, 1), (2, 2), (2, 3), (2, 4), (2, 5), (2, 6), (3, 1)]
# Table 4.13 ROI centroids, thesis 1-based (row, col).
THESIS_CENTROIDS = {
    "G1E5S": (621, 528.5), "G1E6S": (600.5, 526.5), "G2E1S": (605.5, 587.5),
    "G2E2S": (652.5, 636), "G2E3S": (638, 636.5), "G2E4S": (625, 636),
    "G2E5S": (612.5, 635.5), "G2E6S": (602.5, 635.5), "G3E1S": (656, 587),
    "G1E5T": (621, 545.5), "G1E6T": (605.5, 542), "G2E1T": (605.5, 601.5),
    "G2E2T": (653, 624), "G2E3T": (638.5, 625.5), "G2E4T": (625, 626),
    "G2E5T": (613, 626.5), "G2E6T": (602.5, 627.5), "G3E1T": (656, 594),
}  # fmt: skip


def test_default_chart_holds_g1e5_to_g3e1() -> None:
    assert set(chart.ChartLayout().elements) >= set(THESIS_ELEMENTS)


@pytest.mark.parametrize("group,element", THESIS_ELEMENTS)
def test_bar_width_and_period_follow_usaf_and_magnification(group: int, element: int) -> None:
    bars = chart.usaf_bar_group(chart.ChartLayout(), group, element, "sagittal")
    f_obj = usaf_frequency_lp_per_mm(group, element)
    # bar width on the sensor = 0.5 / (f_obj * 16.3) mm over 5.2 um pixels
    assert bars.bar_width_px == pytest.approx(0.5 / (f_obj * 16.3) / 0.0052, rel=1e-12)
    assert bars.px_per_period == pytest.approx(2 * bars.bar_width_px, rel=1e-12)
    assert bars.px_per_period == pytest.approx(px_per_period(f_obj * 16.3))
    assert bars.bar_length_px == pytest.approx(5 * bars.bar_width_px)


def test_bar_rectangles_are_three_bars_two_widths_apart() -> None:
    s = chart.usaf_bar_group(chart.ChartLayout(), 2, 4, "sagittal")
    t = chart.usaf_bar_group(chart.ChartLayout(), 2, 4, "tangential")
    w = s.bar_width_px
    lefts = [b[1] for b in s.bars]
    assert [b - a for a, b in itertools.pairwise(lefts)] == pytest.approx([2 * w, 2 * w])
    for top, left, bottom, right in s.bars:  # vertical bars: tall and narrow
        assert bottom - top == pytest.approx(5 * w) and right - left == pytest.approx(w)
    for top, left, bottom, right in t.bars:  # horizontal bars: wide and short
        assert right - left == pytest.approx(5 * w) and bottom - top == pytest.approx(w)
    # G2E4: tangential set left of the sagittal set, centres 9 bar widths apart, same row
    assert s.centre_rc[1] - t.centre_rc[1] == pytest.approx(9 * w)
    assert s.centre_rc[0] == t.centre_rc[0]
    g1 = chart.usaf_bar_group(chart.ChartLayout(), 1, 5, "sagittal")
    g1t = chart.usaf_bar_group(chart.ChartLayout(), 1, 5, "tangential")
    assert g1t.centre_rc[1] - g1.centre_rc[1] == pytest.approx(9 * g1.bar_width_px)  # mirrored
    assert s.varies_along_axis == 1 and t.varies_along_axis == 0
    assert s.label == "G2E4S" and t.label == "G2E4T"


@pytest.mark.parametrize("label", sorted(THESIS_CENTROIDS))
def test_sets_sit_where_the_thesis_measured_them(label: str) -> None:
    g, e, o = int(label[1]), int(label[3]), "sagittal" if label[4] == "S" else "tangential"
    bars = chart.usaf_bar_group(chart.ChartLayout(), g, e, o)
    r1, c1 = THESIS_CENTROIDS[label]
    assert math.dist(bars.centre_rc, (r1 - 1, c1 - 1)) < 4.0  # hand-drawn ROIs


def test_boxes_lie_on_the_bars_inside_the_disc_and_do_not_overlap() -> None:
    groups = chart.usaf_bar_groups()
    circles = chart.RadialLayout()
    for g in groups:
        r0, c0, r1, c1 = g.box
        top, left, bottom, right = g.extent
        assert r1 > r0 and c1 > c0
        # every pixel centre of the box is inside the bar set's square
        assert top <= r0 and r1 - 1 <= bottom and left <= c0 and c1 - 1 <= right
        assert circles.radius_px(g.centre_rc) + 10 < circles.disc_radius_px
        if (g.group, g.element) in chart.THESIS_ELEMENT_CENTRES_MM:
            assert 0.15 < g.image_height_mm < 0.75  # Table 4.13: 0.22-0.69 mm
    for a, b in itertools.combinations(groups, 2):
        ar0, ac0, ar1, ac1 = a.box
        br0, bc0, br1, bc1 = b.box
        assert ar1 <= br0 or br1 <= ar0 or ac1 <= bc0 or bc1 <= ac0, (a.label, b.label)


def test_magnification_scales_sizes_and_positions() -> None:
    half = chart.ChartLayout(magnification=16.3 / 2)
    a = chart.usaf_bar_group(chart.ChartLayout(), 2, 2, "sagittal")
    b = chart.usaf_bar_group(half, 2, 2, "sagittal")
    assert b.bar_width_px == pytest.approx(2 * a.bar_width_px)
    c0 = chart.IMAGE_CENTRE_RC
    assert b.centre_rc[0] - c0[0] == pytest.approx(2 * (a.centre_rc[0] - c0[0]))
    assert b.image_lp_per_mm == pytest.approx(a.image_lp_per_mm / 2)


def test_unknown_element_and_orientation_are_refused() -> None:
    with pytest.raises(KeyError, match="G7E1"):
        chart.usaf_bar_group(chart.ChartLayout(), 7, 1, "sagittal")
    with pytest.raises(ValueError, match="orientation"):
        chart.usaf_bar_group(chart.ChartLayout(), 2, 2, "diagonal")  # type: ignore[arg-type]


def test_pixel_box_is_never_empty() -> None:
    assert chart.pixel_box((10.2, 20.1, 10.4, 20.3)) == (10, 20, 11, 21)
    assert chart.pixel_box((9.5, 19.5, 12.5, 22.5)) == (10, 20, 13, 23)


def test_radial_roi_is_in_the_annulus_at_the_thesis_image_height() -> None:
    circles = chart.RadialLayout()
    roi = chart.radial_roi_default()
    assert roi == (250, 1000, 290, 1050)  # 40 x 50 px
    assert circles.box_in_annulus(roi)
    # Table 4.13: ROI centroid (270.5, 1025.5) 1-based, 477.43 px = 2.48 mm from the centre
    assert chart.box_centroid(roi) == (269.5, 1024.5)
    assert circles.radius_px(chart.box_centroid(roi)) == pytest.approx(477.43, abs=0.1)
    assert chart.image_height_mm(chart.box_centroid(roi)) == pytest.approx(2.48, abs=0.005)


def test_field_of_view_circle_is_clipped_by_the_frame() -> None:
    circles = chart.RadialLayout()
    assert circles.fov_clipped()
    cr, _ = circles.centre_rc
    assert cr + circles.annulus_outer_radius_px > 1023  # runs off the bottom
    assert not chart.RadialLayout(
        centre_rc=(511.5, 639.5), annulus_outer_radius_px=400
    ).fov_clipped()


def test_measurement_roi_keeps_the_bar_profile_and_drops_the_bar_ends() -> None:
    for g in chart.usaf_bar_groups():
        r0, c0, r1, c1 = g.roi
        br0, bc0, br1, bc1 = g.box
        top, left, bottom, right = g.extent
        m = chart.ROI_END_MARGIN_PX
        assert r1 > r0 and c1 > c0
        if g.orientation == "sagittal":  # vertical bars: every column across, rows trimmed
            assert (c0, c1) == (bc0, bc1)
            if r1 - r0 > 1:
                assert r0 - 0.5 >= top + m and r1 - 0.5 <= bottom - m
        else:
            assert (r0, r1) == (br0, br1)
            if c1 - c0 > 1:
                assert c0 - 0.5 >= left + m and c1 - 0.5 <= right - m
    # G2E1 S: bar ends at rows 600.81 and 608.19, so rows 601 and 608 straddle them
    g = chart.usaf_bar_group(chart.ChartLayout(), 2, 1, "sagittal")
    assert g.box == (601, 584, 609, 591) and g.roi == (602, 584, 608, 591)


def test_measurement_roi_is_never_empty() -> None:
    assert chart.bar_set_roi((10.2, 20.1, 10.4, 20.3), "sagittal") == (10, 20, 11, 21)
    assert chart.bar_set_roi((10.2, 20.1, 10.4, 20.3), "tangential") == (10, 20, 11, 21)
