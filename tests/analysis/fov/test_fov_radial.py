"""The radial view of ``benchlab run fov``: the annulus, the rings and their indices, the
mapping and the field's ends against the ring tube's exact mapping (noise-free renders, so
the errors are the method's own), and the refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.fov import radial as rad
from benchlab.analysis.fov.annulus import (
    AnnulusNotFoundError,
    find_annulus,
    median_annulus,
    refine_annulus,
)
from benchlab.analysis.fov.model import PIXEL_MM
from benchlab.analysis.fov.rings import find_rings, profile
from benchlab.protocols.fov.radial_analysis import (
    clean_positions,
    fit_rings,
    radial_angles,
    rings_of,
)
from benchlab.protocols.fov.radial_params import RadialPlan
from benchlab.scenes.rings import RingTube, RingTubeScene

POSITIONS = RadialPlan().positions_mm


def _frames(scene: RingTubeScene) -> dict[float, np.ndarray]:
    return {p: np.asarray(scene.render(p, 1024, 1280)) for p in POSITIONS}


@pytest.mark.slow
def test_rings_mapping_and_field_ends_match_the_tube() -> None:
    scene = RingTubeScene()
    frames = _frames(scene)
    first = median_annulus([find_annulus(f) for f in frames.values()])
    profiles = {p: profile(f, first, 6.0) for p, f in frames.items()}
    base = np.max(np.stack([pr.level for pr in profiles.values()]), axis=0)
    plan = RadialPlan()
    zs, rhos = [], []
    for p, pr in profiles.items():
        rings = rings_of(pr, base, plan)
        k = rings.indices(-1)  # the far end of the field images innermost
        z = p + k * plan.pitch_mm
        # each ring where the tube's exact mapping puts it: within 0.01 px
        true = scene.image_radius_mm(z) / PIXEL_MM
        assert np.abs(rings.radius_px - true).max() < 0.01
        zs += list(z[k != 0])
        rhos += list(rings.radius_px[k != 0] * PIXEL_MM)
    fit = rad.fit_mapping(zs, rhos, plan.tube_radius_mm, plan.viewpoint_z_mm, plan.ring_mm)
    inner, outer = clean_positions(fit, first, plan, list(frames))
    assert inner and outer and len(inner) < len(frames) and len(outer) < len(frames)
    annulus = refine_annulus([frames[p] for p in inner], [frames[p] for p in outer], first)
    cr, cc = scene.circles.centre_rc
    assert annulus.centre_col == pytest.approx(cc, abs=0.002)
    assert annulus.centre_row == pytest.approx(cr, abs=0.002)
    assert annulus.inner_px == pytest.approx(scene.circles.annulus_inner_radius_px, abs=0.002)
    assert annulus.outer_px == pytest.approx(scene.circles.annulus_outer_radius_px, abs=0.002)
    # read on every position instead, the rings next to the edges pull them by ~0.1-3 px
    every = refine_annulus(list(frames.values()), list(frames.values()), first)
    assert abs(every.inner_px - scene.circles.annulus_inner_radius_px) > 0.01
    start, end = rad.field_end(fit, annulus, True), rad.field_end(fit, annulus, False)
    true_start, true_end = scene.field_ends_mm()
    assert start.value == pytest.approx(true_start, abs=0.002)  # target 0.2 mm
    assert end.value == pytest.approx(true_end, abs=0.002)
    for a in (-30.0, -40.0, -49.0):
        z = fit.z_of_angle(a)
        assert rad.height_at_z(fit, z).value == pytest.approx(
            float(scene.image_radius_mm(np.array([z]))[0]), abs=1e-5)
    fov = rad.field_of_view_deg(fit, annulus)
    assert fov.value == pytest.approx(fit.angle_of_z(true_start) - fit.angle_of_z(true_end),
                                      abs=0.002)
    assert fov.value > 15.0  # Table 3.1


@pytest.mark.slow
def test_a_tube_without_its_wide_ring_is_refused() -> None:
    scene = RingTubeScene(tube=RingTube(fiducial_scale=1.0))
    frames = _frames(scene)
    annulus = find_annulus(frames[POSITIONS[0]])
    profiles = [profile(f, annulus, 6.0) for f in frames.values()]
    base = np.max(np.stack([pr.level for pr in profiles]), axis=0)
    assert find_rings(profiles[0], base).fiducial is None
    with pytest.raises(ValueError, match="fiducial"):
        rings_of(profiles[0], base, RadialPlan())
    with pytest.raises(ValueError, match="only .* rings found; analysis.radial_min_rings is 40"):
        rings_of(profiles[0], base, RadialPlan(min_rings=40))


def test_a_dark_frame_has_no_annulus() -> None:
    with pytest.raises(AnnulusNotFoundError, match="no lit annulus"):
        find_annulus(np.random.default_rng(0).normal(3.0, 1.0, (1024, 1280)))


def test_a_ring_is_fitted_as_the_midpoint_of_its_edges() -> None:
    # a curved mapping: a ring 1 mm wide images 0.01 * 1 / 8 = 1.25 um inside rho(z)
    def rho(z: np.ndarray) -> np.ndarray:
        return 3.0 - 0.05 * z - 0.01 * z ** 2 / 2.0

    z = np.linspace(0.0, 10.0, 40)
    seen = (rho(z - 0.5) + rho(z + 0.5)) / 2.0
    exact = rad.fit_mapping(z, seen, 19.88, -6.4, ring_mm=1.0)
    naive = rad.fit_mapping(z, seen, 19.88, -6.4)
    assert exact.height_mm(5.0) == pytest.approx(float(rho(np.array(5.0))), abs=1e-12)
    assert naive.height_mm(5.0) - float(rho(np.array(5.0))) == pytest.approx(-0.01 / 8, rel=1e-6)


def test_radial_angles_are_multiples_of_the_step_inside_the_field() -> None:
    assert radial_angles(2.5, -25.94, -57.75) == [-57.5 + 2.5 * k for k in range(13)]
    assert all(math.isclose(a % 2.5, 0.0, abs_tol=1e-9) for a in radial_angles(2.5, -26, -31))


@pytest.mark.slow
def test_intervals_hold_the_methods_own_error_on_noise_free_renders() -> None:
    # Without noise the statistical intervals shrink to ~0.1-0.4 nm, but the ring centres'
    # and the annulus edges' estimators are off by up to ~2 nm (smooth along the field, so
    # the residuals cannot show it): the intervals must hold that modelling error, or it
    # is all the error there is on a quiet bench and the intervals miss the truth.
    scene = RingTubeScene()
    frames = _frames(scene)
    plan = RadialPlan()
    first = median_annulus([find_annulus(f) for f in frames.values()])
    profiles = {p: profile(f, first, plan.margin_px) for p, f in frames.items()}
    base = np.max(np.stack([pr.level for pr in profiles.values()]), axis=0)
    zs: list[float] = []
    rhos: list[float] = []
    for p, pr in profiles.items():
        rings = rings_of(pr, base, plan)
        k = rings.indices(-1)
        zs += list(p + k[k != 0] * plan.pitch_mm)
        rhos += list(rings.radius_px[k != 0] * PIXEL_MM)
    fit = fit_rings(zs, rhos, plan)
    inner, outer = clean_positions(fit, first, plan, list(frames))
    annulus = refine_annulus([frames[p] for p in inner], [frames[p] for p in outer], first)
    for a in (-26.0, -30.0, -35.0, -40.0, -45.0, -49.0, -55.0, -57.5):
        z = fit.z_of_angle(a)
        h = rad.height_at_z(fit, z)
        true = float(scene.image_radius_mm(np.array([z]))[0])
        assert h.low <= true <= h.high, (a, (h.value - true) * 1e6, h.sigma * 1e6)
        assert h.high - h.low < 6e-6  # a few nm: the floor, not a blanket
    true_start, true_end = scene.field_ends_mm()
    start, end = rad.field_end(fit, annulus, True), rad.field_end(fit, annulus, False)
    assert start.low <= true_start <= start.high
    assert end.low <= true_end <= end.high
    c = scene.circles
    for which, true_px in ((2, c.annulus_inner_radius_px), (3, c.annulus_outer_radius_px)):
        px = annulus.inner_px if which == 2 else annulus.outer_px
        assert abs(px - true_px) <= 1.96 * annulus.sigma[which], (which, px - true_px)


def test_a_clipped_dark_side_does_not_move_the_edge() -> None:
    # A camera clips its dark side at 0: the noise there is 0 on most pixels and a few codes
    # on the rest. Its median pixel is the level (0); the median of interpolated samples,
    # which mix clipped pixels, sits above it and pulled the edge towards the light.
    from scipy.special import ndtr

    from benchlab.analysis.fov.edges import clean_edge_points

    rows, cols = np.mgrid[0:240, 0:240].astype(np.float64)
    r = np.hypot(rows - 120.3, cols - 119.6)
    clean = 3000.0 * ndtr((90.0 - r) / 1.5)  # lit inside, dark 0 outside
    clipped = np.where(np.random.default_rng(1).random(r.shape) < 0.4, 6.0, 0.0)
    noisy = clean + np.where(r > 95.0, clipped, 0.0)  # only where the dark level is read
    none = np.empty((0, 2))
    want = clean_edge_points(clean, (119.6, 120.3), 90.0, 180, True, none, 0.0)
    got = clean_edge_points(noisy, (119.6, 120.3), 90.0, 180, True, none, 0.0)
    assert len(got) == len(want) == 180
    assert np.abs(got - want).max() < 1e-4  # it was 0.0036 px
