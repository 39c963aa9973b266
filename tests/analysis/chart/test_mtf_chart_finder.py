"""The MTF procedure's forward view finds a chart mounted off position, scaled and rotated, and
the report draws the found chart."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from sim_runs import MTF_SMALL, events, yes

from benchlab.analysis.chart.pose import ChartPose
from benchlab.bench import Bench, BenchConfig
from benchlab.protocols import start_run
from benchlab.protocols.mtf.analysis import analyze_forward_frame
from benchlab.protocols.params import load_params
from benchlab.report.render import render_report
from benchlab.scenes.usaf import UsafScene


@pytest.mark.slow
def test_rotated_scaled_chart_gets_its_rois_and_the_report_shows_it(tmp_path: Path) -> None:
    pose = ChartPose((14.0, -22.0), 1.15, 9.0)
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        bench.world.usaf = dataclasses.replace(bench.world.usaf, pose=pose)
        outcome = start_run("mtf", bench=bench, params=MTF_SMALL, root=tmp_path,
                            prompt=yes).run()
    scene = UsafScene(pose=pose)
    chart = outcome.summary["summary"]["chart"]
    assert chart["pose"]["scale"] == pytest.approx(1.15, abs=3e-3)
    assert chart["pose"]["rotation_deg"] == pytest.approx(9.0, abs=0.15)
    assert chart["implied_magnification"] == pytest.approx(16.3 / 1.15, rel=3e-3)
    assert outcome.summary["summary"]["chart_offset_px"] == [14, -22]
    params = load_params("mtf", MTF_SMALL)
    for row, el in zip(outcome.tables["table_4_11"], params.forward_elements, strict=True):
        for orient in ("sagittal", "tangential"):
            truth = scene.bar_set(el.group, el.element, orient)  # type: ignore[arg-type]
            assert np.abs(np.subtract(row[f"{orient}_roi"], truth.whole_period_roi)).max() <= 1
            assert row[f"{orient}_resolved"]  # on the bars, not beside them
    located = [e for e in events(outcome.session_path) if e["kind"] == "chart_located"]
    assert len(located) == 1 and located[0]["offset_px"] == [14, -22]
    assert "implied magnification" in located[0]["chart"]["warnings"][0]  # 16.3 / 1.15
    html = render_report(outcome.session_path)
    assert "The USAF chart as found" in html and "rotation +9.0" in html


def test_no_chart_keeps_the_configured_rois_and_says_so() -> None:
    params = load_params("mtf", MTF_SMALL)
    rows = analyze_forward_frame(np.full((1024, 1280), 120, np.uint8), params, "histogram")
    assert rows and all("chart not found: configured ROI" in r["warnings"] for r in rows)
    assert all(r["chart"] is None and r["chart_offset_px"] == [0, 0] for r in rows)


def test_rois_off_the_frame_are_reported_not_measured() -> None:
    from scene_frames import frame

    from benchlab.analysis.chart.layout import RadialLayout

    params = load_params("mtf", MTF_SMALL)  # G1E5 and G2E1
    lit = RadialLayout(centre_rc=(512.0, 640.0))
    scene = UsafScene(circles=dataclasses.replace(lit, disc_radius_px=2000.0),
                      pose=ChartPose((0.0, -545.0), 1.0, 2.0))  # G1E5 beyond the left edge
    rows = {(r["element"], r["orientation"]): r
            for r in analyze_forward_frame(frame(scene), params, "histogram")}
    for orient in ("sagittal", "tangential"):
        g1e5, g2e1 = rows[("G1E5", orient)], rows[("G2E1", orient)]
        assert g1e5["modulation"] is None and g1e5["resolved"] is False
        # the chart finder's reason (it rejected the set)
        assert g1e5["warnings"] == "not measured: clipped by the FOV (runs off the frame)"
        assert g2e1["resolved"] and g2e1["modulation"] > 0.1  # measured (2 deg oblique)


def test_rotated_chart_oblique_fine_sets_say_why_and_the_rest_use_the_found_frequency() -> None:
    from scene_frames import frame

    params = load_params("mtf", None)  # the thesis's G1E5-G3E1
    scene = UsafScene(pose=ChartPose((10.0, -12.0), 1.05, 6.0))
    rows = {(r["element"], r["orientation"]): r
            for r in analyze_forward_frame(frame(scene, 12), params, "profilefit")}
    for orient in ("sagittal", "tangential"):
        fine = rows[("G2E4", orient)]  # 2.19 px per period, 6 deg off the axes
        assert fine["modulation"] is None and fine["resolved"] is False
        assert fine["warnings"].startswith("not measurable: 2.19 px per period < 2.5")
        coarse = rows[("G1E6", orient)]
        truth = scene.truth_modulation(1, 6, orient)  # type: ignore[arg-type]
        assert coarse["resolved"] and abs(coarse["modulation"] - truth) <= 0.03
        # the found (scaled, rotated) set's whole-period ROI, not the configured box
        assert coarse["roi"] == list(scene.bar_set(1, 6, orient).whole_period_roi)  # type: ignore[arg-type]
