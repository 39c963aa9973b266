"""Through focus in the simulated scene: defocus blur and magnification from object distance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.drivers.sensor import AcquisitionState
from benchlab.scenes.edge import EdgeScene
from benchlab.scenes.focus import ThroughFocusLens, scenes_at
from benchlab.scenes.usaf import UsafScene
from benchlab.scenes.world import SimWorld


def test_thin_lens_geometry() -> None:
    lens = ThroughFocusLens(focal_length_mm=2.8, pupil_diameter_mm=1.34, best_focus_mm=60.0)
    v = 1.0 / (1.0 / 2.8 - 1.0 / 60.0)
    assert lens.sensor_distance_mm == pytest.approx(v)
    assert lens.reference_distance_mm == pytest.approx(16.3 * v)
    assert lens.scale_at(lens.reference_distance_mm) == pytest.approx(1.0)
    assert lens.scale_at(30.0) == pytest.approx(2 * lens.scale_at(60.0))
    assert lens.defocus_sigma_px(60.0, 0.0, 0.0, "sagittal") == 0.0
    # blur disc diameter D v |1/z - 1/z0|, Gaussian of the same variance: c / 4
    c_mm = 1.34 * v * abs(1 / 40.0 - 1 / 60.0)
    assert lens.defocus_sigma_px(40.0, 0.0, 0.0, "tangential") == pytest.approx(
        c_mm / 4 * 1000 / 5.2)


def test_astigmatism_and_field_curvature_move_best_focus_per_orientation() -> None:
    lens = ThroughFocusLens(axial_astigmatism_per_mm=0.002, field_curvature_per_mm2=0.001)
    u0 = 1 / 60.0
    assert lens.best_vergence_per_mm(0, 0, "sagittal") == pytest.approx(u0 + 0.001)
    assert lens.best_vergence_per_mm(0, 0, "tangential") == pytest.approx(u0 - 0.001)
    assert lens.best_vergence_per_mm(1.0, 0, "sagittal") == pytest.approx(u0 + 0.002)
    with pytest.raises(ValueError, match="best_focus_mm"):
        ThroughFocusLens(best_focus_mm=2.0)


def test_edge_truth_is_sharpest_at_best_focus_and_scales_with_distance() -> None:
    lens = ThroughFocusLens()
    f = [35 * 5.2e-3]
    near = scenes_at(lens, 45.0, UsafScene(), EdgeScene())[1]
    best = scenes_at(lens, 60.0, UsafScene(), EdgeScene())[1]
    far = scenes_at(lens, 80.0, UsafScene(), EdgeScene())[1]
    m = [s.truth_mtf_at("E0L", f)[0] for s in (near, best, far)]
    assert m[1] > m[0] and m[1] > m[2]
    assert near.squares[0].side_px / far.squares[0].side_px == pytest.approx(80 / 45)


def test_world_images_a_stage_carried_chart_at_its_distance() -> None:
    world = SimWorld("usaf", through_focus=ThroughFocusLens())

    def render(bench: dict[str, object]) -> np.ndarray:
        st = AcquisitionState(exposure_ms=300.0, gain=1.0, bits=8, width=1280, height=1024,
                              time_s=0.0, frame_index=0, bench=bench)
        return world(st)

    plain = render({})
    at_ref = render({"object_offset_mm": world.through_focus.reference_distance_mm,  # type: ignore[union-attr]
                     "stage_position_mm": 0.0})
    moved = render({"object_offset_mm": 40.0, "stage_position_mm": 5.0})
    # at the reference distance only the defocus differs (blurrier: lower variance)
    assert not np.allclose(plain, moved)
    assert math.isfinite(float(at_ref.sum()))
    assert np.var(np.diff(moved, axis=1)) != pytest.approx(np.var(np.diff(plain, axis=1)))
    # without the lens model a carried chart is imaged as before
    assert np.array_equal(SimWorld("usaf")(AcquisitionState(
        exposure_ms=300.0, gain=1.0, bits=8, width=1280, height=1024, time_s=0.0,
        frame_index=0, bench={"object_offset_mm": 40.0})), plain)


def test_mounting_another_target_takes_the_chart_off_the_carriage() -> None:
    from benchlab.bench import Bench, BenchConfig

    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        bench.mount("usaf")
        bench.carry_target(40.0)
        assert bench.state()["object_offset_mm"] == 40.0
        bench.mount("usaf")  # e.g. the MTF procedure's set-up after a depth run
        assert "object_offset_mm" not in bench.state()


def test_defocused_radial_follows_field_curvature_between_the_blur_table_rows() -> None:
    """The defocus is added at every 0.05 mm of image height, not only at the table's rows
    (1.5, 2.48, 3.0 mm): the blur at 2.0 mm is exactly table (interpolated) (+) defocus."""
    from benchlab.scenes.focus import RADIAL_LENS, defocused_radial
    from benchlab.scenes.radial import RadialScene

    lens = ThroughFocusLens(**{**RADIAL_LENS, "field_curvature_per_mm2": 0.001})
    spokes = RadialScene(2.0, "sagittal")
    scene = defocused_radial(spokes, lens, 18.0)
    for h in (1.75, 2.0, 2.8):
        want = math.hypot(float(spokes.blur.sagittal_px(h)),
                          lens.defocus_sigma_px(18.0, h, 0.0, "sagittal"))
        assert float(scene.blur.sagittal_px(h)) == pytest.approx(want, rel=1e-9)
    # focused where 1/R = u0 + k h^2: at that radius the defocus at h vanishes
    h = 2.0
    radius = 1.0 / (1.0 / 19.88 + 0.001 * h * h)
    sharp = defocused_radial(spokes, lens, radius)
    assert float(sharp.blur.sagittal_px(h)) == pytest.approx(float(spokes.blur.sagittal_px(h)),
                                                            rel=1e-9)
    assert sharp.object_radius_mm == pytest.approx(radius)
