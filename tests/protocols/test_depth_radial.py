"""The radial view's through-focus analysis on noise-free rendered frames: best focus from the
fundamental lands on the scene's truth (the Eq. 2.9 modulation's plateau does not), field points
and radial field curvature, rings that never reach the threshold."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchlab.analysis.chart.layout import RADIAL_ROI_BOX, box_centroid
from benchlab.drivers.sensor import SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX, rate_for_dn8
from benchlab.protocols.depth.params import DepthParams
from benchlab.protocols.depth.radial import analyze_radial
from benchlab.protocols.depth.radial_rois import read_rois, roi_height_mm, roi_name
from benchlab.protocols.depth.radial_truth import truth_rows
from benchlab.scenes.focus import RADIAL_LENS, defocused_radial
from benchlab.scenes.radial import RadialScene

WALL = 13.88


def _params(orientations: tuple[str, ...], rois: tuple[tuple[int, int, int, int], ...],
            **lens: float) -> DepthParams:
    return DepthParams(view="radial", near_mm=2.5, far_mm=10.5, step_mm=0.5, frames=1,
                       radial_orientations=orientations, radial_rois=rois,
                       design_half_range_mm=5.0, simulator=lens)


def _noise_free(params: DepthParams) -> list:
    """Positions read from noise-free 8-bit frames of the simulated scene."""
    lens = params.lens()
    out = []
    for pattern in params.patterns:
        assert pattern is not None
        template = RadialScene(pattern[0], "sagittal" if pattern[1] == "sagittal"
                               else "tangential")
        to_dn = 1.0 / float(rate_for_dn8(1.0, template.reference_exposure_ms,
                                         template.reference_gain))
        for z in params.distances_mm:
            scene = defocused_radial(template, lens, z + WALL)
            img = np.round(scene.render(SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX) * to_dn)
            out.append((pattern, z, 0, read_rois(img, params.radial_rois, 255.0)))
    return out


@pytest.mark.slow
def test_best_focus_of_a_noise_free_sweep_is_the_truth_within_0_02_mm() -> None:
    params = _params(("sagittal",), (RADIAL_ROI_BOX,))
    tables, summary = analyze_radial(_noise_free(params), params)
    row, = tables["depth_of_field"]
    truth, = truth_rows(params)
    # the lens focuses 19.88 mm from the axis: 6.0 mm from the wall; the spokes' magnification
    # moves the fundamental's peak by < 0.01 mm
    assert truth["best_focus_mm"] == pytest.approx(6.0, abs=0.01)
    # was 0.27 mm off (histogram peaks on the Eq. 2.9 plateau, truth searched on it)
    assert row["best_focus_mm"] == pytest.approx(truth["best_focus_mm"], abs=0.01)
    lo, hi = row["best_focus_mm_ci95"]  # the model term (0.004 mm, 1 sigma) covers the rest
    assert lo <= truth["best_focus_mm"] <= hi and hi - lo < 0.03
    assert row["near_mm"] == pytest.approx(truth["near_mm"], abs=0.1)
    assert row["far_mm"] == pytest.approx(truth["far_mm"], abs=0.1)
    assert row["field_point"] == "r250c1000" and row["image_height_mm"] == pytest.approx(2.483,
                                                                                         abs=1e-3)
    assert summary["estimator"] == "profilefit"


def test_the_eq29_modulation_is_flat_about_focus_but_the_fundamental_peaks() -> None:
    """Why best focus is read from the fundamental: the cause of the 0.27 mm."""
    from benchlab.protocols.depth.radial_truth import object_sigma_mm
    from benchlab.scenes.focus import ThroughFocusLens

    lens = ThroughFocusLens(**RADIAL_LENS)
    spokes = RadialScene(2.0, "sagittal")
    eq29 = [defocused_radial(spokes, lens, WALL + z).truth_modulation() for z in (5.5, 6.0, 6.5)]
    assert max(eq29) - min(eq29) < 1e-4  # the print's full contrast: a plateau
    sig = [object_sigma_mm(spokes, lens, WALL + z) for z in (5.5, 6.0, 6.5)]
    assert sig[1] < 0.7 * min(sig[0], sig[2])  # the blur (and so the fundamental) is not flat


@pytest.mark.slow
def test_field_points_give_radial_field_curvature_against_the_truth() -> None:
    rois = ((330, 895, 370, 945), RADIAL_ROI_BOX)
    params = _params(("sagittal",), rois, field_curvature_per_mm2=0.0005)
    tables, _ = analyze_radial(_noise_free(params), params)
    truth = {r["field_point"]: r for r in truth_rows(params)}
    rows = {r["field_point"]: r for r in tables["depth_of_field"]}
    assert set(rows) == {"r330c895", "r250c1000"}
    for name, r in rows.items():
        assert r["best_focus_mm"] == pytest.approx(truth[name]["best_focus_mm"], abs=0.03)
    # best focus moves toward the wall with image height (u_b grows with k h^2)
    assert truth["r250c1000"]["best_focus_mm"] < truth["r330c895"]["best_focus_mm"] - 0.4
    h = [roi_height_mm(b) for b in rois]
    b = [truth[roi_name(x)]["best_focus_mm"] for x in rois]
    k_true = (b[1] - b[0]) / (h[1] ** 2 - h[0] ** 2)
    curv, = tables["depth_field_curvature"]
    assert curv["orientation"] == "sagittal" and curv["field_points"] == 2
    assert curv["curvature_mm_per_mm2"] == pytest.approx(k_true, abs=0.02)
    lo, hi = curv["curvature_mm_per_mm2_ci95"]
    assert lo < curv["curvature_mm_per_mm2"] < hi


@pytest.mark.slow
def test_rings_below_the_threshold_get_best_focus_but_no_dof() -> None:
    params = _params(("tangential",), (RADIAL_ROI_BOX,))
    tables, _ = analyze_radial(_noise_free(params), params)
    row, = tables["depth_of_field"]
    truth, = truth_rows(params)
    # the rings' peak modulation (~0.18) never reaches 0.3: no ends, the criterion fails
    assert truth["near_mm"] is None and truth["far_mm"] is None
    assert row["near_mm"] is None and row["far_mm"] is None
    assert row["verdict"] == "fails (criterion never met)"
    assert row["peak_mtf"] == pytest.approx(0.18, abs=0.01)
    # their best focus, from the fundamental: the axial magnification shifts it ~0.17 mm
    assert truth["best_focus_mm"] == pytest.approx(5.83, abs=0.02)
    assert row["best_focus_mm"] == pytest.approx(truth["best_focus_mm"], abs=0.05)
    assert tables["depth_field_curvature"] == []  # one field point: no curvature


def test_truth_is_quoted_at_each_field_points_centroid() -> None:
    params = _params(("sagittal",), ((330, 895, 370, 945),), field_curvature_per_mm2=0.0005)
    truth, = truth_rows(params)
    template = dataclasses.replace(RadialScene(2.0, "sagittal"),
                                   reference_rc=box_centroid((330, 895, 370, 945)))
    lens = params.lens()
    at_best = defocused_radial(template, lens, WALL + truth["best_focus_mm"])
    h = roi_height_mm((330, 895, 370, 945))
    # at best focus the defocus there vanishes: the blur is the lens table's own
    assert float(at_best.across_bar_sigma_px(at_best.reference_radius_px)) == pytest.approx(
        float(template.blur.sagittal_px(h)), abs=0.01)
    assert truth["image_height_mm"] == pytest.approx(h, abs=1e-4)


@pytest.mark.slow
def test_a_sweep_that_misses_focus_is_not_measured_and_nothing_taken_is_refused() -> None:
    from benchlab.drivers.errors import BenchlabError

    # 7.5-10.5 mm from the wall: the spokes focus at 6.0 mm, outside the sweep
    params = dataclasses.replace(_params(("sagittal",), (RADIAL_ROI_BOX,)), near_mm=7.5)
    tables, _ = analyze_radial(_noise_free(params), params)
    row, = tables["depth_of_field"]
    assert row["best_focus_mm"] is None and row["verdict"] == "not measured"
    assert "no maximum inside the sweep" in row["note"]
    assert tables["depth_astigmatism"] == [] and tables["depth_field_curvature"] == []
    with pytest.raises(BenchlabError, match="no radial position taken yet"):
        analyze_radial([], params)
