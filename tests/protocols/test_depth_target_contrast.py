"""The depth sweep's target contrast: measured on the plateau through focus (or from the
certificate), and the radial DOF bounded on the lens's share of the print's contrast, checked
against the simulated print's own contrast."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.analysis.chart.layout import RADIAL_ROI_BOX
from benchlab.drivers.sensor import SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX, rate_for_dn8
from benchlab.protocols.depth.params import DepthParams
from benchlab.protocols.depth.radial import READING_BASIS, SHARE_BASIS, analyze_radial
from benchlab.protocols.depth.radial_rois import read_rois
from benchlab.protocols.depth.radial_truth import truth_focus, truth_rows
from benchlab.protocols.depth.targets import plateau, target_contrast
from benchlab.protocols.target_contrast import TargetSetting, TargetSettings
from benchlab.scenes.focus import defocused_radial
from benchlab.scenes.radial import RadialScene

WALL = 13.88
#: A paler print than the packaged one (20 / 190 DN, 0.81): 60 / 190 DN, 0.52.
PALE = RadialScene(2.0, "sagittal", dark_dn8=60.0)


def _params(**kw: object) -> DepthParams:
    return DepthParams(view="radial", near_mm=2.5, far_mm=10.5, step_mm=0.5, frames=1,
                       radial_orientations=("sagittal",), radial_rois=(RADIAL_ROI_BOX,),
                       design_half_range_mm=5.0, **kw)  # type: ignore[arg-type]


def _sweep(params: DepthParams, template: RadialScene) -> list:
    """Positions read from noise-free 8-bit frames of ``template`` through focus."""
    lens = params.lens()
    to_dn = 1.0 / float(rate_for_dn8(1.0, template.reference_exposure_ms,
                                     template.reference_gain))
    out = []
    for z in params.distances_mm:
        img = np.round(defocused_radial(template, lens, z + WALL).render(
            SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX) * to_dn)
        out.append(((2.0, "sagittal"), z, 0, read_rois(img, params.radial_rois, 255.0)))
    return out


def test_a_plateau_needs_three_neighbouring_readings_within_1_percent() -> None:
    flat = [(z, 0.81 - 0.03 * abs(z - 6.0) * (abs(z - 6.0) > 0.6), 0.001)
            for z in (4.5, 5.0, 5.5, 6.0, 6.5, 7.0)]
    ref = plateau(flat, "sagittal")
    assert ref is not None and ref.modulation == pytest.approx(0.81) and ref.lens_ctf == 1.0
    peak = [(z, 0.81 - 0.05 * abs(z - 6.0), 0.001) for z in (5.0, 5.5, 6.0, 6.5, 7.0)]
    assert plateau(peak, "sagittal") is None  # 0.785 at +-0.5 mm: a peak, no plateau
    got = target_contrast(TargetSetting(), [("sagittal", peak)], "the 2 lp/mm pattern")
    assert got.value is None and got.source.startswith("not measured: the 2 lp/mm pattern")
    cert = target_contrast(TargetSetting((0.6, 0.5), 0.01), [("sagittal", flat)], "x", index=1)
    assert (cert.value, cert.uncertainty) == (0.5, 0.01) and cert.source.startswith("certificate")


@pytest.mark.slow
def test_radial_dof_is_bounded_on_the_lens_share_of_the_prints_own_contrast() -> None:
    params = _params()
    tables, summary = analyze_radial(_sweep(params, PALE), params)
    row, = tables["depth_of_field"]
    # measured on the plateau: the simulated print's own contrast
    assert PALE.contrast == pytest.approx(0.52)
    assert row["target_contrast"] == pytest.approx(PALE.contrast, abs=0.003)
    assert row["target_contrast_source"].startswith("measured: the 2 lp/mm pattern (sagittal)")
    assert summary["target_contrast"]["2lp/mm sagittal"]["value"] == row["target_contrast"]
    assert row["threshold_on"] == SHARE_BASIS and row["threshold"] == 0.3
    assert row["reading_threshold"] == pytest.approx(0.3 * row["target_contrast"], abs=1e-4)
    # the ends are the lens's: where reading / 0.52 crosses 0.3, as the scene's closed form says
    bounds = (2.0 + WALL, 11.0 + WALL)
    lens_t = truth_focus(PALE, params.lens(), 0.3 * PALE.contrast, bounds)
    raw_t = truth_focus(PALE, params.lens(), 0.3, bounds)
    assert lens_t["near"] is not None and lens_t["far"] is not None
    assert row["near_mm"] == pytest.approx(lens_t["near"] - WALL, abs=0.05)
    assert row["far_mm"] == pytest.approx(lens_t["far"] - WALL, abs=0.05)
    # bounding the raw reading (print and lens together) would have given a narrower DOF
    assert raw_t["near"] is not None and raw_t["far"] is not None
    assert (raw_t["far"] - raw_t["near"]) < row["dof_mm"] - 0.5
    # the raw reading stays beside the share
    assert row["peak_lens_share"] == pytest.approx(row["peak_mtf"] / row["target_contrast"],
                                                   abs=2e-4)
    curve = max(tables["depth_curves"], key=lambda c: c["modulation"] or 0.0)
    assert curve["lens_share"] == pytest.approx(curve["modulation"] / row["target_contrast"],
                                                abs=2e-4)


@pytest.mark.slow
def test_a_certificate_value_sets_the_share_and_the_truth_carries_the_scene_contrast() -> None:
    cert = _params(targets=TargetSettings(radial=TargetSetting((0.81,), 0.005)))
    tables, _ = analyze_radial(_sweep(cert, RadialScene(2.0, "sagittal")), cert)
    row, = tables["depth_of_field"]
    truth, = truth_rows(cert)
    assert row["target_contrast"] == 0.81 and row["target_contrast_uncertainty"] == 0.005
    assert row["target_contrast_source"].startswith("certificate")
    assert truth["target_contrast"] == pytest.approx(RadialScene(2.0, "sagittal").contrast)
    assert row["near_mm"] == pytest.approx(truth["near_mm"], abs=0.1)
    assert row["far_mm"] == pytest.approx(truth["far_mm"], abs=0.1)
    assert READING_BASIS.startswith("reading")  # the basis named when no contrast is known


def test_targets_are_read_as_in_the_mtf_test_and_kept_in_the_session() -> None:
    from benchlab.protocols.params import ParamsError, params_to_dict, parse_params

    data = {"procedure": "depth", "sweep": {"view": "radial"},
            "radial": {"frequencies_lp_per_mm": [2.0, 3.0]},
            "targets": {"radial_contrast": [0.8, 0.78], "radial_contrast_uncertainty": 0.01,
                        "usaf_contrast": 0.95}}
    p = parse_params("depth", data, "t.toml")
    assert p.targets.radial == TargetSetting((0.8, 0.78), 0.01)
    assert p.targets.usaf == TargetSetting((0.95,), 0.0)
    assert parse_params("depth", params_to_dict(p), "snapshot").targets == p.targets
    bad = {**data, "targets": {"radial_contrast": [0.8]}}
    with pytest.raises(ParamsError,
                       match=r"(?s)t\.toml.*targets\.radial_contrast: has 1 values for 2"):
        parse_params("depth", bad, "t.toml")
