"""The USAF chart finder against the simulated scene's known pose and truth: any offset, scale
and rotation, positive and negative, 8 and 12-bit, vignetting and dust, partly off the frame,
no chart at all."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scene_frames import H, W, frame

from benchlab.analysis.chart import layout as chart
from benchlab.analysis.chart.finder import ChartFit, ChartNotFoundError, find_chart
from benchlab.analysis.chart.pose import ChartPose, PosedBarSet
from benchlab.scenes.usaf import UsafScene


def truth_sets(scene: UsafScene) -> list[PosedBarSet]:
    return [scene.bar_set(g, e, o)  # type: ignore[arg-type]
            for g, e in scene.layout.elements for o in ("sagittal", "tangential")]


def imaged(scene: UsafScene, s: PosedBarSet, margin: float = 3.0) -> bool:
    """The set lies wholly inside the frame and the lit disc."""
    cr, cc = scene.circles.centre_rc
    return all(math.hypot(r - cr, c - cc) <= scene.circles.disc_radius_px - margin
               and -0.5 <= r <= H - 0.5 and -0.5 <= c <= W - 0.5 for r, c in s.corners())


def assert_matches(fit: ChartFit, scene: UsafScene, *, pose_px: float = 0.3) -> None:
    """Pose as rendered; every imaged set with bars >= 2 px found at its true place; no found
    set away from its label's true place."""
    p, q = fit.pose, scene.pose
    assert p.offset_rc == pytest.approx(q.offset_rc, abs=pose_px)
    assert p.scale == pytest.approx(q.scale, rel=2e-3)
    assert p.rotation_deg == pytest.approx(q.rotation_deg, abs=0.15)
    found = {e.label: e for e in fit.found}
    for t in truth_sets(scene):
        el = found.get(t.label)
        if el is not None:
            assert math.dist(el.posed.centre_rc, t.centre_rc) < 0.3, t.label
            # box edges move by at most a pixel when a bar end sits on a pixel boundary
            assert np.abs(np.subtract(el.roi, t.roi)).max() <= 1, t.label
            assert 0.5 <= el.confidence <= 1.0
            if t.px_per_period >= 3.0:  # nearer Nyquist the period fit is phase-sensitive
                assert el.measured_px_per_period == pytest.approx(t.px_per_period, rel=0.03)
        elif t.bar_width_px >= 2.0 and imaged(scene, t):
            pytest.fail(f"{t.label} ({t.bar_width_px:.2f} px bars) imaged but not found")


def test_nominal_chart_is_found_where_the_layout_puts_it() -> None:
    scene = UsafScene()
    fit = find_chart(frame(scene))
    assert_matches(fit, scene, pose_px=0.1)
    assert fit.polarity == "positive" and fit.warnings == ()
    assert fit.offset_px == (0, 0)
    # at the nominal pose the ROIs are exactly the layout's bar_set_roi boxes
    for g, e in chart.THESIS_ELEMENT_CENTRES_MM:
        for o in ("sagittal", "tangential"):
            nominal = chart.usaf_bar_group(chart.ChartLayout(), g, e, o)  # type: ignore[arg-type]
            assert fit.element(g, e, o).roi == nominal.roi  # type: ignore[arg-type]
    reasons = {e.label: e.reason for e in fit.rejected}
    # 2.1 px per period at G2E4: above Nyquist from G2E6 (1.6 px) on, not before
    assert reasons["G2E6S"] is not None and "above Nyquist" in reasons["G2E6S"]
    assert reasons["G3E1T"] is not None and "above Nyquist" in reasons["G3E1T"]
    assert "G2E4S" not in reasons and "G2E4T" not in reasons


@pytest.mark.parametrize("pose", [
    ChartPose((40.0, -60.0), 1.3, 12.0),
    ChartPose((-30.0, 70.0), 0.7, -15.0),
    ChartPose((12.5, 8.25), 1.1, 4.0),
])
@pytest.mark.slow
def test_any_offset_scale_and_rotation_with_vignetting_and_dust(pose: ChartPose) -> None:
    scene = UsafScene(pose=pose, vignetting=0.3)
    rng = np.random.default_rng(3)
    dust = np.ones((H, W))
    rows, cols = np.mgrid[0:H, 0:W]
    for _ in range(8):  # dark spots over the disc, some on bars
        y, x = rng.uniform(400, 720), rng.uniform(480, 820)
        dust *= 1 - 0.7 * np.exp(-((rows - y) ** 2 + (cols - x) ** 2) / (2 * 2.5**2))
    fit = find_chart(frame(scene, transmission=dust))
    tainted = set()
    for t in truth_sets(scene):  # sets under a dust spot may be rejected as ambiguous
        r0, c0, r1, c1 = (math.floor(min(r for r, _ in t.corners())),
                          math.floor(min(c for _, c in t.corners())),
                          math.ceil(max(r for r, _ in t.corners())) + 1,
                          math.ceil(max(c for _, c in t.corners())) + 1)
        if dust[max(r0, 0):r1, max(c0, 0):c1].min() < 0.97:
            tainted.add(t.label)
    clean = dataclasses.replace(fit, elements=tuple(
        e for e in fit.elements if e.label not in tainted or e.found))
    assert_matches(clean, scene)
    implied = 16.3 / pose.scale
    assert fit.implied_magnification == pytest.approx(implied, rel=2e-3)
    assert any("implied magnification" in w for w in fit.warnings)  # 10-43 % off


def test_rotation_45_degrees() -> None:
    scene = UsafScene(pose=ChartPose((0.0, 20.0), 1.0, 45.0))
    fit = find_chart(frame(scene, seed=4))
    assert_matches(fit, scene)
    assert len(fit.found) >= 24
    # at 45 deg the box inscribed in a G2E3 set (1.3 px bars) is 3 x 3 px: too small
    small = {e.label: e.reason for e in fit.rejected if (e.reason or "").startswith("too small")}
    assert "G2E3S" in small and "G1E1S" not in small
    for label in small:
        r0, c0, r1, c1 = fit.element(int(label[1]), int(label[3]),
                                     "sagittal" if label[4] == "S" else "tangential").roi
        assert min(r1 - r0, c1 - c0) < 4


def test_negative_target() -> None:
    scene = UsafScene(pose=ChartPose((-20.0, 15.0), 1.2, -8.0), negative=True)
    fit = find_chart(frame(scene, seed=5))
    assert fit.polarity == "negative"
    assert_matches(fit, scene)
    with pytest.raises(ChartNotFoundError):  # the wrong polarity alone finds nothing
        find_chart(frame(scene, seed=5), polarity="positive")


def test_twelve_bit_frame() -> None:
    scene = UsafScene(pose=ChartPose((5.0, -5.0), 0.9, 7.0))
    px = frame(scene, bits=12, seed=6)
    assert px.dtype == np.uint16 and px.max() > 255
    fit = find_chart(px)
    assert_matches(fit, scene)
    assert find_chart(px << 4).pose.offset_rc == pytest.approx(fit.pose.offset_rc, abs=0.05)


def test_chart_partly_outside_the_frame() -> None:
    # The whole frame lit; the chart pushed so that group 0 runs off the right edge.
    scene = UsafScene(circles=chart.RadialLayout(centre_rc=(512.0, 640.0)),
                      pose=ChartPose((-100.0, 560.0), 1.0, 3.0))
    scene = dataclasses.replace(scene, circles=dataclasses.replace(
        scene.circles, disc_radius_px=2000.0))
    fit = find_chart(frame(scene, seed=7))
    off_frame = [t for t in truth_sets(scene)
                 if any(not (-0.5 <= c <= W - 0.5) for _, c in t.corners())]
    assert len(off_frame) >= 4
    for t in off_frame:
        el = fit.element(t.group, t.element, t.orientation)
        assert not el.found and el.reason == "clipped by the FOV (runs off the frame)"
    assert_matches(fit, scene)


def test_a_set_without_its_bars_is_rejected_as_ambiguous() -> None:
    scene = UsafScene()
    px = frame(scene, seed=8)
    victim = scene.bar_set(1, 2, "tangential")
    r0, c0, r1, c1 = chart.pixel_box((victim.centre_rc[0] - 8, victim.centre_rc[1] - 8,
                                      victim.centre_rc[0] + 8, victim.centre_rc[1] + 8))
    px[r0:r1, c0:c1] = 190  # painted over: clear glass where the bars were
    fit = find_chart(px)
    el = fit.element(1, 2, "tangential")
    assert not el.found and el.reason is not None and el.reason.startswith("ambiguous")
    assert fit.element(1, 2, "sagittal").found


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["flat", "dark", "noise", "disc"])
def test_no_chart_found(kind: str) -> None:
    rng = np.random.default_rng(9)
    if kind == "flat":
        px = np.full((H, W), 180, np.uint8)
    elif kind == "dark":
        px = np.zeros((H, W), np.uint8)
    elif kind == "noise":
        px = rng.integers(0, 256, (H, W)).astype(np.uint8)
    else:  # the lit disc with dust, but no chart in it
        px = frame(dataclasses.replace(UsafScene(), layout=chart.ChartLayout(
            element_centres_mm={})), seed=9)
    with pytest.raises(ChartNotFoundError, match="no chart found"):
        find_chart(px)


def test_bad_frames_and_options_are_refused() -> None:
    with pytest.raises(ValueError, match="2-D"):
        find_chart(np.zeros(10))
    with pytest.raises(ValueError, match="non-finite"):
        find_chart(np.full((20, 20), np.nan))
    with pytest.raises(ValueError, match="scale_range"):
        find_chart(np.zeros((20, 20)), scale_range=(2.0, 1.0))
    with pytest.raises(ValueError, match="polarity"):
        find_chart(np.zeros((20, 20)), polarity="inverted")  # type: ignore[arg-type]


def test_fit_to_dict_is_json_ready() -> None:
    import json

    fit = find_chart(frame(UsafScene(pose=ChartPose((3.0, 4.0), 1.05, 2.0))))
    d = json.loads(json.dumps(fit.to_dict(), allow_nan=False))
    assert d["pose"]["scale"] == pytest.approx(1.05, abs=2e-3)
    assert d["found"] + d["rejected"] == len(d["elements"]) == 2 * len(fit.layout.elements)
    g1e5 = next(e for e in d["elements"] if e["label"] == "G1E5S")
    assert g1e5["object_lp_per_mm"] == pytest.approx(2 ** (1 + 4 / 6))
    assert g1e5["image_lp_per_mm"] == pytest.approx(2 ** (1 + 4 / 6) * 16.3 / 1.05, rel=2e-3)


def test_thesis_elements_alone_are_enough() -> None:
    """A chart model of only the thesis's G1E5-G3E1 (bars 0.7-1.9 px at 16.3x): the three
    coarsest elements' sets still give the pose."""
    layout = chart.ChartLayout(element_centres_mm=dict(chart.THESIS_ELEMENT_CENTRES_MM),
                               sagittal_left=chart.THESIS_SAGITTAL_LEFT)
    scene = UsafScene(layout=layout, pose=ChartPose((5.0, -7.0), 1.0, 0.0))
    fit = find_chart(frame(scene, seed=10), layout)
    assert fit.pose.offset_rc == pytest.approx((5.0, -7.0), abs=0.15)
    assert {e.label for e in fit.found} >= {"G1E5S", "G1E5T", "G2E1S", "G2E4T"}
