"""Radiometry LED spot and the SimWorld dispatcher."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.chart.layout import RadialLayout
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes import LedFalloff, LedScene, SimWorld, UsafScene, parse_target

H, W = 1024, 1280
POSITIONS = (15.0, 18.0, 20.0, 25.0, 32.0)


def _state(exposure_ms: float = 375.0, gain: float = 1.0, **bench: object) -> AcquisitionState:
    return AcquisitionState(exposure_ms, gain, 8, W, H, 0.0, 0, dict(bench))


@pytest.mark.parametrize("position", POSITIONS)
def test_plateau_follows_the_falloff_table(position: float) -> None:
    scene = LedScene()
    img = scene.render(position, 20.0, H, W)
    plateau_dn8 = img.max() / float(rate_for_dn8(1.0, 375.0))
    expected = dict(zip(POSITIONS, (0.78, 1.00, 0.92, 0.77, 0.50), strict=True))[position]
    assert plateau_dn8 == pytest.approx(110.0 * expected, rel=1e-6)
    assert scene.expected_plateau_dn8(position, 20.0, 375.0) == pytest.approx(plateau_dn8)


def test_known_truth_falloff_current_and_gain_scale_linearly() -> None:
    scene = LedScene(falloff=LedFalloff((15.0, 32.0), (1.0, 0.25)), peak_dn8=80.0)
    assert scene.falloff.at(23.5) == pytest.approx(0.625)
    full = scene.render(23.5, 20.0, H, W)
    half = scene.render(23.5, 10.0, H, W)
    assert half.max() == pytest.approx(0.5 * full.max())
    assert full.max() / float(rate_for_dn8(1.0, 375.0)) == pytest.approx(80 * 0.625)
    assert scene.expected_plateau_dn8(23.5, 20.0, 375.0, gain=5) == pytest.approx(5 * 80 * 0.625)
    assert not scene.render(23.5, 0.0, H, W).any()


def test_spot_moves_inward_along_the_field_and_has_the_led_size() -> None:
    scene = LedScene()
    circles = RadialLayout()
    radii = []
    for pos in POSITIONS:
        img = scene.render(pos, 20.0, H, W)
        rr, cc = np.nonzero(img)
        wts = img[rr, cc]
        centroid = (np.average(rr, weights=wts), np.average(cc, weights=wts))
        assert math.dist(centroid, scene.centre_rc(pos)) < 0.5
        radii.append(circles.radius_px(centroid))
        inside = img > 0.5 * img.max()
        assert circles.annulus_inner_radius_px < min(radii) and max(radii) < 545
        a_rad, a_tan = scene.semi_axes_px  # 3 mm x 2 mm at 1/17.5
        assert inside.sum() == pytest.approx(math.pi * a_rad * a_tan, rel=0.05)
    assert all(b < a for a, b in zip(radii, radii[1:], strict=False))
    assert scene.semi_axes_px == pytest.approx((3 / 17.5 / 0.0052 / 2, 2 / 17.5 / 0.0052 / 2))


def test_expected_mean_in_a_mask_is_the_noise_free_reading() -> None:
    scene = LedScene()
    img = scene.render(20.0, 20.0, H, W)
    mask = img > 0.2 * img.max()
    per_dn8 = float(rate_for_dn8(1.0, 375.0))
    direct = (img[mask] / per_dn8).mean()
    assert scene.expected_mean_dn8(mask, 20.0, 20.0, 375.0) == pytest.approx(direct)
    assert direct < scene.expected_plateau_dn8(20.0, 20.0, 375.0)  # soft edges inside the mask
    # at gain 5 the plateau saturates: the expected reading clips like the camera
    assert scene.expected_mean_dn8(mask, 20.0, 20.0, 375.0, gain=5.0) <= 255.0
    with pytest.raises(ValueError):
        scene.expected_mean_dn8(np.zeros((H, W), bool), 20.0, 20.0, 375.0)


def test_parse_target_forms() -> None:
    assert parse_target("usaf") == ("usaf",)
    assert parse_target(("radial", 4, "sagittal")) == ("radial", 4.0, "sagittal")
    assert parse_target(["radial", "0.5", "tangential"]) == ("radial", 0.5, "tangential")
    assert parse_target("radial:2:sagittal") == ("radial", 2.0, "sagittal")
    for bad in ("usa", ("radial", 4, "diag"), ("radial", -1, "sagittal"), 3, ("radial", "x", "s")):
        with pytest.raises(ValueError):
            parse_target(bad)


def test_world_dispatches_on_the_mounted_target() -> None:
    world = SimWorld()
    assert not world(_state()).any()  # dark by default
    world.target = "usaf"
    # the forward view: the USAF chart with the slanted-edge target beside it
    forward = np.maximum(UsafScene().render(H, W) - world.edges.darkening(_state(300.0)), 0.0)
    assert np.array_equal(world(_state(300.0)), forward)
    world.mount(("radial", 4, "tangential"))
    radial = world(_state(300.0))
    assert np.array_equal(radial, world.radial_scene(4.0, "tangential").render(H, W))
    assert world.radial_scene(4.0, "tangential") is world.radial_scene(4, "tangential")
    # the bench state's target overrides the mounted one for that exposure
    assert np.array_equal(world(_state(target="usaf")), forward)
    with pytest.raises(ValueError):
        world.target = "mirror"


def test_world_led_reads_current_and_stage_from_the_bench() -> None:
    world = SimWorld("led")
    led = world.led
    assert not world(_state()).any()  # no current: LED off
    img = world(_state(led_current_ma=20.0, stage_position_mm=25.0))
    assert np.array_equal(img, led.render(25.0, 20.0, H, W))
    per_channel = world(_state(led_current_ma={1: 20.0, 2: 0.0}, stage_position_mm=25.0))
    assert np.array_equal(per_channel, img)
    world.led_channel = 2
    assert not world(_state(led_current_ma={1: 20.0, 2: 0.0}, stage_position_mm=25.0)).any()
    world.led_channel = None
    off = world(_state(led_current_ma=20.0, led_on=False, stage_position_mm=25.0))
    assert not off.any()
    world.led_position_mm = 18.0  # no stage: positioned by hand
    assert np.array_equal(world(_state(led_current_ma=20.0)), led.render(18.0, 20.0, H, W))
