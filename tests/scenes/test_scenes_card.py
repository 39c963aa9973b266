"""The rolled card scene: imaged through the ray-trace table, mounted like any bench target."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.views.synthesis import cylinder_map
from benchlab.cli.devices.camera import simulated_snap_scene
from benchlab.drivers.errors import BenchlabError
from benchlab.drivers.sensor import AcquisitionState
from benchlab.scenes.card import CardScene
from benchlab.scenes.world import SimWorld, parse_target

H, W = 1024, 1280


def _pixel_of(card: CardScene, x_mm: float, y_mm: float) -> tuple[int, int]:
    phi, z = card.card_to_object(x_mm, y_mm)
    rho_px = float(cylinder_map(card.ray_table, card.object_radius_mm).image_radius_mm(z)) / 5.2e-3
    cr, cc = card.circles.centre_rc
    return round(cr + rho_px * math.sin(float(phi))), round(cc + rho_px * math.cos(float(phi)))


def test_grid_lines_fall_where_the_table_sends_them() -> None:
    card = CardScene()
    img = card.render(H, W)
    xs, ys = card.grid_lines_mm()
    y_mid = card.card_height_mm / 2 + card.grid_pitch_mm / 2  # mid-cell, away from text rows
    for x in xs[3:8]:
        r, c = _pixel_of(card, float(x), y_mid)
        on_line = img[r, c]
        beside = img[_pixel_of(card, float(x) + 0.6, y_mid)]
        assert on_line < 0.5 * beside  # ink on the line, paper 0.6 mm beside it
    assert img.max() == pytest.approx(card.paper_rate, rel=0.01)  # blank paper outside the card


@pytest.mark.slow
def test_card_depth_moves_it_and_off_table_depths_are_refused() -> None:
    near, far = CardScene(object_radius_mm=16.88), CardScene(object_radius_mm=23.88)
    assert not np.array_equal(near.render(H, W), far.render(H, W))
    with pytest.raises(ValueError, match="outside the table"):
        CardScene(object_radius_mm=40.0)
    with pytest.raises(ValueError, match="card width"):
        CardScene(card_width_mm=200.0)


def test_world_and_snap_accept_the_card() -> None:
    assert parse_target("card") == ("card", None)
    assert parse_target("card:18.5") == ("card", 18.5)
    with pytest.raises(ValueError, match="radius"):
        parse_target("card:abc")
    world = SimWorld("card:18.88")
    state = AcquisitionState(300.0, 1.0, 8, W, H, 0.0, 0, {})
    img = world(state)
    assert img.shape == (H, W) and img.max() > 0
    assert world.scene_for("card:18.88") is world.card_scene(18.88)
    with pytest.raises(ValueError, match="card at 40 mm"):
        SimWorld("card:40")
    with pytest.raises(BenchlabError, match="--scene card:40: card at 40 mm"):
        simulated_snap_scene("card:40")
    scene = simulated_snap_scene("card")
    assert scene(state).max() > 0
    with pytest.raises(BenchlabError, match="--scene card:x"):
        simulated_snap_scene("card:x")
