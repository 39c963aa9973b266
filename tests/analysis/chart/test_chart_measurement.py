"""What the chart finder hands the estimators: the measurement ROI (three whole periods, bar
ends trimmed, neighbours kept out), the priors (the axis only for bars on an axis), the sets
that are found but give no reliable reading (with the reason); the prior pose and the search
window that make it fast; the benchmark's truth in the frame's own codes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scene_frames import frame

from benchlab.analysis import estimate_modulation
from benchlab.analysis.chart.finder import (
    GENERIC_MIN_OBLIQUE_PX_PER_PERIOD,
    READING_END_PX,
    _measurement_roi,
    _reading_roi,
    find_chart,
)
from benchlab.analysis.chart.layout import ROI_END_MARGIN_PX, RadialLayout
from benchlab.analysis.chart.pose import ChartPose, PosedBarSet, posed_bar_set_roi
from benchlab.analysis.chart.reading import read_chart
from benchlab.benchmarks.chart import TRUNCATION_DN8, frame_truth_modulation
from benchlab.drivers.mightex.sim_sensor import FlatFieldScene, SensorModel
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes.usaf import UsafScene


def _posed(centre: tuple[float, float], width: float, theta: float, ppp: float = 4.0,
           orientation: str = "sagittal") -> PosedBarSet:
    return PosedBarSet(2, 1, orientation, centre, width, theta, 4.0, 65.0, ppp, 0.5)  # type: ignore[arg-type]


@pytest.mark.parametrize("theta", [0.0, 90.0, 7.0, -13.0, 30.0])
@pytest.mark.parametrize("width", [1.4, 2.7, 5.2])
def test_whole_period_roi_spans_three_periods_off_the_bar_ends(theta: float, width: float) -> None:
    centre = (400.37, 512.81)
    r0, c0, r1, c1 = posed_bar_set_roi(centre, width, theta, half_across_widths=3.0)
    inner = posed_bar_set_roi(centre, width, theta)
    assert (r1 - r0) * (c1 - c0) > (inner[2] - inner[0]) * (inner[3] - inner[1])
    t = math.radians(theta)
    reach = 0.5 * (abs(math.cos(t)) + abs(math.sin(t)))
    for r in (r0, r1 - 1):
        for c in (c0, c1 - 1):
            dy, dx = r - centre[0], c - centre[1]
            across = dx * math.cos(t) + dy * math.sin(t)
            along = -dx * math.sin(t) + dy * math.cos(t)
            assert abs(across) <= 3.0 * width + 1e-9  # centres within three whole periods
            assert abs(along) + reach <= 2.5 * width - ROI_END_MARGIN_PX + 1e-9  # off the ends
    if theta in (0.0, 90.0):  # on an axis: every line across the set plus half a space each side
        assert r0 <= inner[0] and c0 <= inner[1] and r1 >= inner[2] and c1 >= inner[3]
        lines = c1 - c0 if theta == 0.0 else r1 - r0
        lo = (centre[1] if theta == 0.0 else centre[0]) - 3.0 * width
        assert lines == math.floor(lo + 6.0 * width) - math.ceil(lo) + 1


def test_the_reading_roi_runs_past_the_bar_ends_unless_a_neighbour_is_there() -> None:
    me = _posed((300.0, 300.0), 2.0, 0.0)
    shape = (1024, 1280)
    box = me.whole_period_roi
    longer = _reading_roi(me, [me], shape, box)
    assert longer is not None
    # same columns (three whole periods across); the rows reach the bar ends (295 and 305),
    # the pixel apertures at most READING_END_PX past them
    assert (longer[1], longer[3]) == (box[1], box[3])
    assert longer[0] < box[0] and longer[2] > box[2]
    assert longer[0] <= 295 and longer[2] - 1 >= 305
    assert longer[0] - 0.5 >= 295.0 - READING_END_PX and longer[2] - 0.5 <= 305.0 + READING_END_PX
    # a set just beyond the bar ends: the measurement ROI
    below = _posed((300.0 + 5.0 + 5.6, 300.0), 2.0, 0.0)
    assert _reading_roi(me, [me, below], shape, box) is None
    # off the frame, or a measurement ROI that is not the whole-period one: none
    assert _reading_roi(_posed((3.0, 300.0), 2.0, 0.0), [], shape,
                        _posed((3.0, 300.0), 2.0, 0.0).whole_period_roi) is None
    assert _reading_roi(me, [me], shape, me.roi) is None


def test_priors_give_the_axis_only_for_bars_on_an_axis() -> None:
    on_axis = _posed((300.0, 300.0), 2.0, 90.3, 4.0, "tangential")
    oblique = _posed((300.0, 300.0), 2.0, 4.0, 4.0)
    scene = UsafScene()
    px = frame(scene)
    fit = find_chart(px)
    el = fit.found[0]
    for posed, orient in ((on_axis, "tangential"), (oblique, None)):
        priors = dataclasses.replace(el, posed=posed).estimator_priors()
        assert priors == {"freq_cycles_per_px": pytest.approx(0.25), "orientation": orient}


def test_a_neighbour_is_kept_out_of_the_roi() -> None:
    me = _posed((300.0, 300.0), 2.0, 0.0)
    shape = (1024, 1280)
    # nobody near: three whole periods
    assert _measurement_roi(me, [me], shape) == (me.whole_period_roi, None)
    # a set 6 bar widths to the right reaches into the wide box, not into the set's own
    near = _posed((300.0, 300.0 + 2.0 * 6.0), 2.0, 0.0)
    box, note = _measurement_roi(me, [me, near], shape)
    assert box == me.roi and note is None
    # overlapping sets: no reading
    on_top = _posed((300.0, 300.0 + 2.0 * 5.0), 2.0, 0.0)
    box, note = _measurement_roi(me, [me, on_top], shape)
    assert note is not None and "neighbouring bar set" in note
    # the wide box off the frame: the set's own
    edge = _posed((300.0, 4.6), 2.0, 0.0)
    assert _measurement_roi(edge, [edge], shape)[0] == edge.roi


@pytest.mark.slow
@pytest.mark.parametrize("pose", [ChartPose((10.0, -15.0), 1.1, 7.0),
                                  ChartPose((-20.0, 25.0), 0.9, -11.0)])
def test_rotated_chart_read_within_003_down_to_nyquist(pose: ChartPose) -> None:
    """Every found set is read at the pose's geometry within 0.03, the fine oblique ones too;
    the generic estimator is kept off the fine oblique sets (GENERIC_MIN_OBLIQUE_PX_PER_PERIOD)
    and still reads the others within 0.03."""
    scene = UsafScene(pose=pose, vignetting=0.2)
    px = frame(scene, 12, seed=3)
    fit = find_chart(px)
    within, generic_within, generic_read, fine = 0, 0, 0, 0
    for el, res in zip(fit.found, read_chart(px, fit), strict=True):
        p = el.posed
        assert el.unmeasurable is None, el.label
        truth = frame_truth_modulation(scene, scene.bar_set(p.group, p.element, p.orientation), 12)
        within += abs(res.modulation - truth) <= 0.03
        fine += p.px_per_period < GENERIC_MIN_OBLIQUE_PX_PER_PERIOD
        if p.px_per_period < GENERIC_MIN_OBLIQUE_PX_PER_PERIOD:
            assert el.generic_unreliable is not None and "px per period <" in el.generic_unreliable
            continue
        assert el.generic_unreliable is None, el.label
        r0, c0, r1, c1 = el.measurement_roi
        gen = estimate_modulation(px[r0:r1, c0:c1], **el.estimator_priors())
        generic_read += 1
        generic_within += abs(gen.modulation - truth) <= 0.03
    assert fine >= 2 and len(fit.found) >= 27
    assert within == len(fit.found)
    assert generic_within >= generic_read - 1


def test_fine_sets_on_the_axes_are_measured() -> None:
    fit = find_chart(frame(UsafScene(pose=ChartPose((0.0, 0.0), 1.0, 0.0))))
    fine = [e for e in fit.found if e.posed.px_per_period < GENERIC_MIN_OBLIQUE_PX_PER_PERIOD]
    assert fine and all(e.unmeasurable is None and e.generic_unreliable is None for e in fine)


def test_prior_pose_gives_the_searched_fit_and_a_wrong_prior_falls_back() -> None:
    scene = UsafScene(pose=ChartPose((4.0, -6.0), 1.0, 0.4))
    px = frame(scene)
    searched = find_chart(px, prior=None)
    for prior in (ChartPose(), ChartPose((180.0, -150.0), 0.8, 9.0)):
        fit = find_chart(px, prior=prior)
        assert fit.pose.offset_rc == pytest.approx(searched.pose.offset_rc, abs=1e-6)
        assert fit.pose.scale == pytest.approx(searched.pose.scale, rel=1e-9)
        assert fit.pose.rotation_deg == pytest.approx(searched.pose.rotation_deg, abs=1e-6)
        assert [e.label for e in fit.found] == [e.label for e in searched.found]
        assert fit.polarity == "positive"


def test_a_frame_lit_all_over_is_searched_whole() -> None:
    lit_everywhere = RadialLayout(centre_rc=(512.0, 640.0), disc_radius_px=3000.0)
    scene = UsafScene(circles=lit_everywhere, pose=ChartPose((-330.0, 480.0), 1.2, -6.0))
    fit = find_chart(frame(scene))  # the chart in a corner of a frame lit all over
    assert fit.pose.offset_rc == pytest.approx((-330.0, 480.0), abs=0.3)
    assert len(fit.found) >= 25


def test_eight_bit_codes_sit_15_32_below_the_twelve_bit_mean() -> None:
    state = AcquisitionState(300.0, 1.0, 8, 256, 256, 0.0, 0)
    flat = FlatFieldScene(float(rate_for_dn8(100.0, 300.0)))
    dn12 = SensorModel(1).render_dn12(flat, state).astype(np.float64)
    dn8 = np.floor(dn12 / 16.0)
    assert float(dn12.mean() / 16.0 - dn8.mean()) == pytest.approx(TRUNCATION_DN8, abs=0.02)
    scene = UsafScene()
    t = scene.bar_set(1, 5, "sagittal")
    assert frame_truth_modulation(scene, t, 8) > frame_truth_modulation(scene, t, 12)
    assert frame_truth_modulation(scene, t, 12) == pytest.approx(
        scene.truth_modulation(1, 5, "sagittal"), rel=1e-12)
