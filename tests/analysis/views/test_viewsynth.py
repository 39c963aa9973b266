"""View synthesis maps: table at a cylinder, unwrap and perspective maps, remap, extremes, and
the figures on the simulated card and bar scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.views.metrics import dominant_period_px, scale_error
from benchlab.analysis.views.raytrace import (
    RayTraceError,
    RayTraceTable,
    parse_raytrace_csv,
    read_raytrace_table,
)
from benchlab.analysis.views.synthesis import (
    apply_maps,
    cylinder_map,
    perspective_maps,
    unwrap_maps,
    viewpoint,
)
from benchlab.benchmarks.viewsynth import bar_period_px, card_figures

TABLE = read_raytrace_table()
SHAPE = (1024, 1280)
CENTRE = (560.5, 646.0)
PITCH_MM = 5.2e-3


def _one_depth(radius_index: int = 4) -> RayTraceTable:
    return RayTraceTable(TABLE.depths_mm[[radius_index]], TABLE.object_radius_mm[[radius_index]],
                         (TABLE.object_z_mm[radius_index],), (TABLE.image_radius_mm[radius_index],),
                         "one-depth")


def _forward_px(radius_mm: float, z_mm: float, phi: float) -> tuple[float, float]:
    """Raw pixel of an object point, straight from the table's own spline at that depth."""
    cyl = cylinder_map(TABLE, radius_mm)
    rho_px = float(cyl.image_radius_mm(z_mm)) / PITCH_MM
    return CENTRE[0] + rho_px * math.sin(phi), CENTRE[1] + rho_px * math.cos(phi)


def test_cylinder_map_at_between_and_outside_the_depths() -> None:
    res = TABLE.resampled
    at = cylinder_map(TABLE, 19.88)
    assert np.allclose(at.z_mm, res.z_mm[4]) and not at.extrapolated
    mid = cylinder_map(TABLE, 20.38)  # halfway between depths 6 and 7: straight lines of sight
    assert np.allclose(mid.z_mm, (res.z_mm[4] + res.z_mm[5]) / 2, atol=1e-9)
    edge = cylinder_map(TABLE, 24.88)  # the last depth itself is inside
    assert np.allclose(edge.z_mm, res.z_mm[-1])
    for outside in (15.0, 26.0):
        with pytest.raises(RayTraceError, match=r"outside the table's 15.88-24.88 mm"):
            cylinder_map(TABLE, outside)
    flagged = cylinder_map(TABLE, 26.0, allow_extrapolation=True)
    assert flagged.extrapolated
    # straight lines of sight extrapolate along the line: z - z_view = R * slope
    assert np.allclose(flagged.z_mm, res.z_mm[-1] + (res.z_mm[-1] - res.z_mm[-2]) * 1.12)
    with pytest.raises(RayTraceError, match="object radius must be > 0"):
        cylinder_map(TABLE, -1.0)


def test_one_depth_table_maps_its_depth_only() -> None:
    one = _one_depth()
    rho = np.array([1.6, 2.0, 2.48, 2.8])
    assert np.allclose(cylinder_map(one, 19.88).axial_mm(rho),
                       cylinder_map(TABLE, 19.88).axial_mm(rho), atol=1e-9)
    maps = unwrap_maps(one, SHAPE, CENTRE, object_radius_mm=19.88, px_per_mm=5)
    assert maps.valid.any()
    with pytest.raises(RayTraceError, match="one depth .* not 20.88 mm"):
        unwrap_maps(one, SHAPE, CENTRE, object_radius_mm=20.88, px_per_mm=5)
    with pytest.raises(RayTraceError, match="at least two depths"):
        viewpoint(one)


def test_unwrap_maps_send_object_points_to_their_raw_pixels() -> None:
    px_per_mm = 20.0
    maps = unwrap_maps(TABLE, SHAPE, CENTRE, object_radius_mm=19.88, px_per_mm=px_per_mm)
    z_top = maps.meta["z_top_mm"]
    for row, col in ((100, 300), (250, 1700), (400, 50)):
        z = z_top - row / px_per_mm
        phi = col / (19.88 * px_per_mm)
        want = _forward_px(19.88, z, phi)
        assert maps.valid[row, col]
        assert maps.map_row[row, col] == pytest.approx(want[0], abs=1e-3)
        assert maps.map_col[row, col] == pytest.approx(want[1], abs=1e-3)
    assert maps.meta["table_sha256"] == TABLE.sha256 and maps.meta["centre_rc"] == list(CENTRE)
    assert maps.shape == (int((z_top - cylinder_map(TABLE, 19.88).z_range_mm[0]) * 20) + 1,
                          round(2 * math.pi * 19.88 * 20))


def test_clipped_annulus_is_marked_not_invented() -> None:
    """Centre near the top edge: most of the annulus is off the frame. Those output pixels
    are invalid and 0; every valid one reads a real raw pixel."""
    centre = (40.0, 640.0)
    maps = unwrap_maps(TABLE, SHAPE, centre, object_radius_mm=19.88, px_per_mm=10)
    assert 0.3 < maps.valid_fraction < 0.7
    frame = np.full(SHAPE, 200, np.uint8)
    out = apply_maps(frame, maps)
    assert np.all(out[~maps.valid] == 0)
    assert np.all(out[maps.valid] == 200)  # bilinear never mixes in the border
    rows, cols = maps.map_row[maps.valid], maps.map_col[maps.valid]
    assert rows.min() >= 0 and rows.max() <= SHAPE[0] - 1 and cols.max() <= SHAPE[1] - 1
    for name in ("nearest", "cubic", "lanczos"):
        assert np.all(apply_maps(frame, maps, name)[~maps.valid] == 0)


def test_apply_maps_refuses_bad_inputs() -> None:
    maps = unwrap_maps(TABLE, SHAPE, CENTRE, object_radius_mm=19.88, px_per_mm=4)
    with pytest.raises(ValueError, match="interpolation must be one of"):
        apply_maps(np.zeros(SHAPE, np.uint8), maps, "bicubic-ish")
    with pytest.raises(ValueError, match=r"frame shape \(10, 10\) differs"):
        apply_maps(np.zeros((10, 10), np.uint8), maps)
    with pytest.raises(ValueError, match="azimuth range"):
        unwrap_maps(TABLE, SHAPE, CENTRE, object_radius_mm=19.88, azimuth_deg=(10, 10))
    with pytest.raises(ValueError, match="px per mm"):
        unwrap_maps(TABLE, SHAPE, CENTRE, object_radius_mm=19.88, px_per_mm=0)


def test_perspective_centre_ray_meets_the_cylinder_where_it_points() -> None:
    vp = viewpoint(TABLE).effective_viewpoint_z_mm
    yaw, pitch = -40.0, 45.0
    maps = perspective_maps(TABLE, SHAPE, CENTRE, object_radius_mm=19.88, yaw_deg=yaw,
                            pitch_deg=pitch, fov_deg=60, size_wh=(101, 81))
    z = vp + 19.88 * math.tan(math.radians(pitch))
    want = _forward_px(19.88, z, math.radians(yaw))
    assert maps.map_row[40, 50] == pytest.approx(want[0], abs=1e-3)
    assert maps.map_col[40, 50] == pytest.approx(want[1], abs=1e-3)
    # looking up the axis (pitch 90) the central rays never meet the cylinder
    up = perspective_maps(TABLE, SHAPE, CENTRE, object_radius_mm=19.88, yaw_deg=0,
                          pitch_deg=90, fov_deg=10, size_wh=(11, 11))
    assert not up.valid[5, 5]
    with pytest.raises(ValueError, match="field of view"):
        perspective_maps(TABLE, SHAPE, CENTRE, object_radius_mm=19.88, yaw_deg=0,
                         pitch_deg=0, fov_deg=180, size_wh=(10, 10))


def test_unwrapped_card_is_straight_and_to_scale() -> None:
    along, around, extra = card_figures(TABLE)
    assert len(along) == 19 and len(around) >= 4
    assert max(ln.rms_px for ln in along + around) < 0.5
    assert abs(scale_error(along)) < 0.01 and abs(scale_error(around)) < 0.01
    assert extra["centre_error_px"] < 1.0


def test_wrong_assumed_depth_shows_as_a_scale_error() -> None:
    """The figure can fail: the card at 19.88 mm unwrapped as if at 22.88 mm is 15 % wide."""
    from benchlab.analysis.views.metrics import find_line
    from benchlab.analysis.views.synthesis import fov_centre_of_frame
    from benchlab.benchmarks.viewsynth import PX_PER_MM, _render, expose_dn8
    from benchlab.scenes.card import CardScene

    card = CardScene()
    frame = expose_dn8(_render(card), 5)
    centre, _ = fov_centre_of_frame(frame)
    maps = unwrap_maps(TABLE, SHAPE, centre, object_radius_mm=22.88, px_per_mm=PX_PER_MM)
    view = apply_maps(frame, maps)
    xs, _ = card.grid_lines_mm()
    phi, _ = card.card_to_object(xs, np.zeros_like(xs))
    cols = np.mod(phi, 2 * np.pi) * 22.88 * PX_PER_MM
    lines = [find_line(view, maps.valid, c, axis=1, half_window_px=12) for c in cols]
    found = [ln for ln in lines if ln is not None]
    assert len(found) > 10
    # the truth on a 19.88 mm cylinder: spacing 5 mm * 20 px/mm; found 22.88 / 19.88 times it
    spacing = np.median(np.diff([ln.mean_px for ln in found]))
    assert spacing / (5.0 * PX_PER_MM) == pytest.approx(22.88 / 19.88, rel=0.01)


@pytest.mark.parametrize("orientation", ["sagittal", "tangential"])
def test_half_lp_per_mm_bars_unwrap_to_40_px_at_20_px_per_mm(orientation: str) -> None:
    assert bar_period_px(TABLE, orientation, seed=1) == pytest.approx(40.0, rel=0.02)


def test_dominant_period_and_its_bad_inputs() -> None:
    x = np.arange(400)
    assert dominant_period_px(np.sin(2 * np.pi * x / 37.0)) == pytest.approx(37.0, rel=2e-3)
    with pytest.raises(ValueError):
        dominant_period_px(np.ones(50))


def test_table_that_is_not_invertible_at_a_depth_is_refused() -> None:
    text = ("depth_mm,object_radius_mm,object_z_mm,image_radius_mm\n"
            + "".join(f"2,15.88,{10 + 2 * k},{2.0 + 0.2 * k}\n" for k in range(5))
            + "".join(f"4,17.88,{30 - 2 * k},{2.0 + 0.2 * k}\n" for k in range(5)))
    table = parse_raytrace_csv(text, "fold.csv")
    with pytest.raises(RayTraceError, match="not monotonic in image radius at 16.88 mm"):
        cylinder_map(table, 16.88)


def test_curved_lines_of_sight_are_followed_between_depths() -> None:
    """Lines of sight bent as z = a + b R + c R^2: the spline across depths finds the point on
    the curve at any radius; straight-line interpolation between depths would miss it."""
    radii = np.arange(15.88, 25.0, 1.0)
    rho = np.linspace(1.5, 2.9, 12)
    lines = []
    for r in radii:
        z = -6.4 + r * (2.0 - 0.8 * rho) + 0.01 * (r - 15.0) ** 2
        lines += [f"{r - 13.88:.2f},{r:.2f},{zz:.9f},{rr:.6f}\n"
                  for zz, rr in zip(z, rho, strict=True)]
    table = parse_raytrace_csv("depth_mm,object_radius_mm,object_z_mm,image_radius_mm\n"
                               + "".join(lines), "curved.csv")
    r = 20.38
    cyl = cylinder_map(table, r)
    probe = np.array([1.7, 2.2, 2.6])
    want = -6.4 + r * (2.0 - 0.8 * probe) + 0.01 * (r - 15.0) ** 2
    assert np.allclose(cyl.axial_mm(probe), want, atol=1e-4)
    linear_error = 0.01 * 0.25  # c * (dR/2)^2 halfway between depths 1 mm apart
    assert linear_error > 10 * np.max(np.abs(cyl.axial_mm(probe) - want))
