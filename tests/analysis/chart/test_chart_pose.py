"""Chart poses: posed bar sets, their rotated measurement ROIs, and the USAF scene's pose knobs
(closed-form rotated bars, negative target, vignetting, ``usaf:...`` scene specs)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ndtr

from benchlab.analysis.chart import layout as chart
from benchlab.analysis.chart.pose import ChartPose, posed_bar_set, posed_bar_set_roi
from benchlab.scenes.usaf import UsafScene, _rotated_bar, usaf_scene_from_spec

H, W = 1024, 1280


@pytest.mark.parametrize("shift", [(0.0, 0.0), (0.3, 0.7), (6.0, -9.0), (0.5, 0.5)])
def test_unrotated_roi_is_bar_set_roi(shift: tuple[float, float]) -> None:
    layout = chart.ChartLayout()
    for g, e in layout.elements:
        for o in ("sagittal", "tangential"):
            posed = posed_bar_set(layout, ChartPose(shift), g, e, o)  # type: ignore[arg-type]
            nominal = chart.usaf_bar_group(layout, g, e, o)  # type: ignore[arg-type]
            t, lft, b, r = nominal.extent
            moved = (t + shift[0], lft + shift[1], b + shift[0], r + shift[1])
            assert posed.roi == chart.bar_set_roi(moved, o)  # type: ignore[arg-type]


@pytest.mark.parametrize("theta", [7.0, 15.0, 33.0, 45.0, 90.0 + 12.0, -20.0])
@pytest.mark.parametrize("width", [1.2, 3.0, 7.5])
def test_rotated_roi_keeps_inside_the_set_and_off_the_bar_ends(theta: float, width: float) -> None:
    centre = (300.37, 411.81)
    r0, c0, r1, c1 = posed_bar_set_roi(centre, width, theta)
    assert r1 > r0 and c1 > c0
    t = math.radians(theta)
    reach = 0.5 * (abs(math.cos(t)) + abs(math.sin(t)))
    for r in range(r0, r1):
        for c in range(c0, c1):
            dy, dx = r - centre[0], c - centre[1]
            across = dx * math.cos(t) + dy * math.sin(t)
            along = -dx * math.sin(t) + dy * math.cos(t)
            assert abs(across) <= 2.5 * width + 1e-6
            assert abs(along) + reach <= 2.5 * width - chart.ROI_END_MARGIN_PX + 1e-6
    if width >= 3.0:  # not a sliver: at least half the inscribed square's pixels
        side = 5 * width / (abs(math.cos(t)) + abs(math.sin(t)))
        assert (r1 - r0) * (c1 - c0) >= 0.4 * side**2


def test_pose_moves_scales_and_rotates_about_the_origin() -> None:
    origin = (500.0, 600.0)
    pose = ChartPose((10.0, -20.0), 2.0, 90.0)
    # a point 5 px right of the origin goes 10 px down (clockwise on screen), then moves
    assert pose.apply((500.0, 605.0), origin) == pytest.approx((520.0, 580.0))
    assert ChartPose().is_identity and not pose.is_identity
    layout = chart.ChartLayout()
    a = posed_bar_set(layout, ChartPose(scale=1.25), 2, 2, "sagittal")
    b = chart.usaf_bar_group(layout, 2, 2, "sagittal")
    assert a.bar_width_px == pytest.approx(1.25 * b.bar_width_px)
    assert a.image_lp_per_mm == pytest.approx(b.image_lp_per_mm / 1.25)
    assert a.theta_deg == 0.0
    assert posed_bar_set(layout, ChartPose(rotation_deg=10), 2, 2, "tangential").theta_deg == 100
    with pytest.raises(ValueError, match="scale"):
        ChartPose(scale=0.0)
    with pytest.raises(ValueError, match="finite"):
        ChartPose(rotation_deg=math.inf)


def test_rotated_bar_is_the_blurred_pixel_integrated_rectangle() -> None:
    """Against brute force: an isotropic Gaussian-blurred rotated rectangle (exact as a product
    of erf differences) averaged over a 24 x 24 sub-pixel grid of each pixel aperture."""
    theta, sigma, half_len, half_w, centre = 17.0, 0.4, 6.0, 1.3, (20.3, 20.6)
    rows = np.arange(41, dtype=float)[:, None]
    cols = np.arange(41, dtype=float)[None, :]
    got = _rotated_bar(rows, cols, centre, half_len, half_w, theta, sigma, sigma)
    t = math.radians(theta)
    n = 24
    sub = (np.arange(n) + 0.5) / n - 0.5
    ref = np.zeros_like(got)
    for a in sub:
        for b in sub:
            dy, dx = rows + a - centre[0], cols + b - centre[1]
            u = dx * math.cos(t) + dy * math.sin(t)
            v = -dx * math.sin(t) + dy * math.cos(t)
            ref += ((ndtr((u + half_w) / sigma) - ndtr((u - half_w) / sigma))
                    * (ndtr((v + half_len) / sigma) - ndtr((v - half_len) / sigma)))
    ref /= n * n
    dy, dx = rows - centre[0], cols - centre[1]
    mid = np.abs(-dx * math.sin(t) + dy * math.cos(t)) < half_len - 2  # away from the bar ends
    assert np.abs(got - ref)[mid].max() < 2e-4
    assert np.abs(got - ref).max() < 2e-3  # corners: the separable approximation


def test_general_render_reduces_to_the_nominal_one() -> None:
    nominal = UsafScene().render(H, W)
    general = UsafScene(vignetting=1e-12).render(H, W)  # forces the posed path
    assert np.abs(general - nominal).max() < 1e-8 * nominal.max()
    tiny = UsafScene(pose=ChartPose(rotation_deg=1e-7)).render(H, W)
    assert np.abs(tiny - nominal).max() < 1e-5 * nominal.max()


def test_rotated_scene_truth_and_pixels() -> None:
    scene = UsafScene(pose=ChartPose((0.0, 0.0), 1.0, 20.0))
    img = scene.render(H, W)
    # the truth is the render's value at the set's centre pixel when that pixel is centred
    for g, e, o in [(0, 1, "sagittal"), (0, 2, "tangential")]:
        s = scene.bar_set(g, e, o)  # type: ignore[arg-type]
        dark, bright = scene.truth_levels(g, e, o)  # type: ignore[arg-type]
        assert 0.8 < scene.truth_modulation(g, e, o) < 0.82  # type: ignore[arg-type]
        r, c = round(s.centre_rc[0]), round(s.centre_rc[1])
        assert img[r, c] == pytest.approx(dark, rel=0.05)  # within a pixel of the bar centre
        assert dark < 0.15 * bright


def test_negative_and_vignetted_scene() -> None:
    pos = UsafScene()
    neg = UsafScene(negative=True)
    assert neg.truth_levels(0, 1, "sagittal") == pytest.approx(
        pos.truth_levels(0, 1, "sagittal"), rel=1e-6)  # same levels, bars and ground swapped
    s = neg.bar_set(0, 1, "sagittal")
    img = neg.render(H, W)
    assert img[round(s.centre_rc[0]), round(s.centre_rc[1])] > 5 * img[
        round(s.centre_rc[0]), round(s.centre_rc[1] + 1.0 * s.bar_width_px)]
    vig = UsafScene(vignetting=0.3).render(H, W)
    cr, cc = pos.circles.centre_rc
    edge = (round(cr), round(cc - 230))
    assert vig[edge] / pos.render(H, W)[edge] == pytest.approx(1 - 0.3 * (230 / 250) ** 2,
                                                                rel=1e-3)
    with pytest.raises(ValueError, match="vignetting"):
        UsafScene(vignetting=1.0)


def test_usaf_scene_specs() -> None:
    s = usaf_scene_from_spec("usaf:dx=12,dy=-4.5,scale=1.2,rot=-7,vignetting=0.2,negative=1")
    assert s.pose == ChartPose((-4.5, 12.0), 1.2, -7.0)
    assert s.vignetting == 0.2 and s.negative
    assert usaf_scene_from_spec("usaf:").pose.is_identity
    for bad, msg in [("usaf:foo=1", "unknown"), ("usaf:scale=0", "> 0"), ("usaf:rot", "value"),
                     ("usaf:dx=abc", "not a number"), ("usaf:negative=2", "0 or 1"),
                     ("usaf:vignetting=1.5", r"\[0, 1\)"), ("usaf:dx=nan", "finite")]:
        with pytest.raises(ValueError, match=msg):
            usaf_scene_from_spec(bad)
