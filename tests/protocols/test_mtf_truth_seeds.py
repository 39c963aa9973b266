"""The MTF procedure's Tables 4.11/4.12 against the simulator's truth at several noise seeds
(issue 9's done-when: every element below Nyquist within 0.03, at any seed, not just seed 0)."""

from __future__ import annotations

import dataclasses

import pytest
from scene_frames import camera_frame

from benchlab.analysis.chart.pose import ChartPose
from benchlab.protocols.mtf.analysis import (
    CHART_READING,
    analyze_forward_frame,
    analyze_radial_frame,
)
from benchlab.protocols.params import load_params
from benchlab.report.tables import TABLE_VIEWS, format_table
from benchlab.scenes.radial import RadialScene
from benchlab.scenes.usaf import UsafScene

TOLERANCE = 0.03




def off_by(rows: list[dict[str, object]], scene: UsafScene) -> dict[str, float]:
    """|reading - truth| of every measured set below Nyquist."""
    out = {}
    for r in rows:
        if r["aliased"] or r["modulation"] is None:
            continue
        g, e = (int(x) for x in str(r["element"])[1:].split("E"))
        truth = scene.truth_modulation(g, e, r["orientation"])  # type: ignore[arg-type]
        out[f"{r['element']}{str(r['orientation'])[0].upper()}"] = abs(
            float(r["modulation"]) - truth)  # type: ignore[arg-type]
    return out


@pytest.mark.slow
@pytest.mark.parametrize("seed", [None, 2, 7, 8, 9])
def test_table_4_11_reads_every_set_within_003_of_truth_at_any_seed(seed: int | None) -> None:
    # Before: the small G1/G2 ROIs (< 100 px) were read by a harmonic series whose dark level
    # fell below every pixel: G1E5T 0.814 vs truth 0.782 even without noise, G2E4S up to 0.06
    # off at other seeds.
    params = load_params("mtf", None)  # the thesis's G1E5-G3E1
    scene = UsafScene()
    rows = analyze_forward_frame(camera_frame(scene, seed), params, None)
    errors = off_by(rows, scene)
    assert len(errors) == 12  # G1E5-G2E4 both orientations; G2E5 on are above Nyquist
    assert max(errors.values()) <= TOLERANCE, errors
    assert {r["estimator"] for r in rows if r["modulation"] is not None} == {CHART_READING}


@pytest.mark.slow
def test_defocused_chart_sets_are_read_not_called_unresolved() -> None:
    # Before: G2E1T/G2E2S/G2E2T "not resolved" vs truths 0.078/0.043/0.039 (the small-ROI
    # noise estimate held the bar ends' blur).
    params = load_params("mtf", None)
    scene = UsafScene(defocus_px=1.0)
    rows = analyze_forward_frame(camera_frame(scene, 2), params, None)
    errors = off_by(rows, scene)
    assert len(errors) == 8 and max(errors.values()) <= TOLERANCE, errors  # G1E5-G2E2
    assert all(r["resolved"] for r in rows if r["modulation"] is not None)
    # G2E3/G2E4 (truths 0.011-0.020) are too faint for the finder to confirm: said so
    for r in rows:
        if r["element"] in ("G2E3", "G2E4"):
            assert r["modulation"] is None and "ambiguous" in r["warnings"]


def test_wrong_configured_magnification_takes_the_found_frequencies() -> None:
    # 18.75 configured, 16.3 true: the configured magnification put G2E4 (92 lp/mm on the
    # sensor) above Nyquist as "aliased" and every frequency 15 % high.
    params = dataclasses.replace(load_params("mtf", None), forward_magnification=18.75)
    scene = UsafScene()
    rows = {(r["element"], r["orientation"]): r
            for r in analyze_forward_frame(camera_frame(scene, 1), params, None)}
    g2e4 = rows[("G2E4", "tangential")]
    assert g2e4["image_lp_per_mm"] == pytest.approx(2 ** (2 + 3 / 6) * 16.3, rel=5e-3)
    assert not g2e4["aliased"] and g2e4["modulation"] is not None
    assert abs(g2e4["modulation"] - scene.truth_modulation(2, 4, "tangential")) <= TOLERANCE
    assert rows[("G2E5", "sagittal")]["aliased"]  # 103 lp/mm: above Nyquist all the same
    warnings = g2e4["chart"]["warnings"]  # type: ignore[index]
    assert len(warnings) == 1 and "implied magnification 16.3 differs" in warnings[0]


def test_a_set_the_finder_rejected_is_not_measured_with_its_reason() -> None:
    # Before: G2E4T of a chart rotated 8 deg was read 0.284 +- 0.027 (truth 0.553) on a
    # 6 x 2 px ROI the finder had rejected as too small.
    params = load_params("mtf", None)
    scene = UsafScene(pose=ChartPose((0.0, 0.0), 1.0, 8.0))
    rows = {(r["element"], r["orientation"]): r
            for r in analyze_forward_frame(camera_frame(scene, 0), params, "profilefit")}
    g2e4t = rows[("G2E4", "tangential")]
    assert g2e4t["modulation"] is None and g2e4t["resolved"] is False
    assert g2e4t["warnings"].startswith("not measured: too small")
    assert g2e4t["estimator"] is None
    row = {"element": "G2E4", "image_lp_per_mm": 92.2, "tangential_modulation": None,
           "tangential_resolved": False, "tangential_aliased": False}
    assert "not measurable" in format_table([row], TABLE_VIEWS["table_4_11"].columns)


def test_radial_roi_under_one_period_is_not_measurable_never_a_zero() -> None:
    # The 0.5 lp/mm spokes image at ~48 px per period; a 50 px wide ROI placed so the bars
    # run along its short side spans under one period across them.
    roi = (540, 1099, 580, 1149)
    params = dataclasses.replace(load_params("mtf", None), radial_roi=roi)
    scene = RadialScene(0.5, "sagittal", reference_rc=((540 + 579) / 2, (1099 + 1148) / 2))
    pixels = camera_frame(scene, 4)
    row = analyze_radial_frame(pixels, 0.5, "sagittal", params, None)
    assert row["modulation"] is None and row["resolved"] is False
    assert row["warnings"].startswith("not measurable (ROI spans < 1 bar period)")
    t412 = {"object_lp_per_mm": 0.5, "sagittal_modulation": None, "sagittal_resolved": False,
            "sagittal_aliased": False, "tangential_aliased": True}
    text = format_table([t412], TABLE_VIEWS["table_4_12"].columns)
    assert "not measurable" in text and "not resolved" not in text
    assert text.splitlines()[1].split()[-2:] == ["no", "yes"]  # aliased per orientation


def test_report_and_catalogue_say_not_measurable_never_a_zero() -> None:
    from benchlab.catalog.extract import _bar_table
    from benchlab.report.roi import RoiReading, reading_text

    row = {"object_lp_per_mm": 0.5, "image_lp_per_mm": 8.75, "sagittal_modulation": None,
           "sagittal_resolved": False, "sagittal_aliased": False,
           "sagittal_warnings": "not measurable (ROI spans < 1 bar period); less than one "
                                "bar period across the ROI (40.1 px)",
           "tangential_modulation": 0.0, "tangential_resolved": False,
           "tangential_aliased": False, "tangential_warnings": ""}
    s = RoiReading.from_row(row, "sagittal", label="radial 0.5 sagittal", view="radial",
                            roi=[540, 1099, 580, 1149], estimator="profilefit")
    assert s.state == "not-measurable"
    assert reading_text(s).startswith("not measurable (ROI spans < 1 bar period)")
    t = RoiReading.from_row(row, "tangential", label="radial 0.5 tangential", view="radial",
                            roi=[540, 1099, 580, 1149], estimator="profilefit")
    assert t.state == "unresolved" and reading_text(t) == "not resolved"
    figures = {f.orientation: (f.value, f.text)
               for f in _bar_table(1, "radial", [row], lambda r: "0.5")}
    assert figures == {"sagittal": (None, "not measurable"),
                       "tangential": (None, "unresolved")}
