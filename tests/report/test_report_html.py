"""The HTML report and the simulated MTF curves it draws."""

from __future__ import annotations

import base64
import math
import re
from pathlib import Path

import numpy as np
import pytest
from sim_runs import MTF_SMALL, RAD_SMALL, run_sim

from benchlab.bench import Bench, BenchConfig
from benchlab.protocols import start_run
from benchlab.protocols.mtf.curves import (
    default_curves_path,
    gaussian_mtf,
    load_curves,
    simulated_curves_json,
    simulated_curves_toml,
)
from benchlab.report.render import ReportError, render_report, write_report
from benchlab.session import Session


@pytest.mark.slow
def test_mtf_report_is_self_contained_with_tables_plots_and_frames(tmp_path: Path) -> None:
    outcome = run_sim("mtf", tmp_path, MTF_SMALL)
    hashes = Session.open(outcome.session_path).frames()
    out = write_report(outcome.session_path)
    assert out == outcome.session_path / "report.html"
    text = out.read_text()
    for title in ("Table 4.11", "Table 4.12", "Tables 4.13-4.14", "Table 4.15",
                  "Measured vs simulated bar contrast", "Table 4.15 verdict", "Frames with ROIs",
                  "Evidence per ROI", "G1E5", "SIM-130001", "The USAF chart as found"):
        assert title in text
    # Plots: CTF, Monte Carlo bands, the slanted-edge MTF; frames: forward overview + zoom + 4
    # radial crops, the found chart (frame + zoom, SVG-annotated); evidence: one crop per ROI
    # (2 elements x S/T + 2 radial frequencies x S/T).
    assert text.count("class='plot'") == 3
    assert text.count("class='roi-panel'") == 8
    assert text.count("class='crop'") == 8
    assert text.count("alt='frame with the found chart'") == 1
    assert text.count("alt='zoom on the chart'") == 1
    assert text.count("<polygon") >= 4 * 2  # the 4 elements' sets, drawn in both images
    assert text.count("data:image/png;base64,") == 6 + 2 + 8  # frames and crops: pixels
    plots = re.findall(r"data:image/svg\+xml;base64,([^']*)'", text)
    assert len(plots) == 3  # plots: vectors, their labels kept as text (sharp at any zoom)
    ctf_svg = base64.b64decode(plots[0]).decode("utf-8")
    assert "<text" in ctf_svg and "lens share of the bar contrast (CTF)" in ctf_svg
    assert "Slanted-edge MTF" in text and "bar readings compared" in text
    visible = re.sub(r"base64,[^']*'", "", text)
    assert not re.search(r"\bnan\b", visible, re.IGNORECASE)  # N/A, never NaN
    assert "src='http" not in text and "<script" not in text  # nothing fetched from outside
    assert Session.open(outcome.session_path).frames() == hashes
    assert Session.open(outcome.session_path).verify_frames() == []


@pytest.mark.slow
def test_radiometry_report_has_the_fall_off(tmp_path: Path) -> None:
    outcome = run_sim("radiometry", tmp_path, RAD_SMALL)
    text = render_report(outcome.session_path)
    assert "Table 4.16" in text and "fig. 4.21" in text
    assert text.count("class='plot'") == 1  # the fall-off
    # one measurement frame per position, mask outlined
    n_positions = text.count("alt='LED at")
    assert n_positions == 3  # radiometry-small.toml's three positions
    assert text.count("data:image/png;base64,") == n_positions
    assert text.count("data:image/svg+xml;base64,") == 1


def test_report_of_a_session_without_results_says_so(tmp_path: Path) -> None:
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        runner = start_run("mtf", bench=bench, params=MTF_SMALL, root=tmp_path)
    with pytest.raises(ReportError, match="no results yet"):
        write_report(runner.session.path)


def test_shipped_curves_are_the_simulated_optics(tmp_path: Path) -> None:
    assert default_curves_path().read_text() == simulated_curves_json()
    curves = load_curves()
    toml = tmp_path / "curves.toml"  # the same curves written as TOML read back the same
    toml.write_text(simulated_curves_toml(), encoding="utf-8")
    for a, b in zip(load_curves(toml), curves, strict=True):
        assert (a.view, a.field_angle_deg, a.direction) == (b.view, b.field_angle_deg,
                                                            b.direction)
        assert np.array_equal(a.freqs_lp_per_mm, b.freqs_lp_per_mm)
        assert np.array_equal(a.mtf, b.mtf)
    assert len(curves) == 16  # 8 field points x S/T
    radial_t = next(c for c in curves if c.view == "radial" and c.field_angle_deg == -30
                    and c.direction == "T")
    radial_s = next(c for c in curves if c.view == "radial" and c.field_angle_deg == -30
                    and c.direction == "S")
    assert radial_t.at(35.0) < radial_s.at(35.0)  # tangential worse, as in the thesis
    assert gaussian_mtf(0.0, 0.0) == 1.0
    nu = 50 * 5.2e-3
    assert gaussian_mtf(1.0, 50.0) == pytest.approx(
        math.exp(-2 * math.pi**2 * (1 + 1 / 12) * nu**2))


def test_forward_curves_are_the_forward_scenes_truth() -> None:
    # The forward view integrates the exact 1-px box: the curve is Gaussian x |sinc| (the
    # edge scene's truth along a pixel axis), not the Gaussian stand-in for the aperture
    # (0.024 high at Nyquist, 0.146 against 0.001 at 192 lp/mm). The radial view renders the
    # Gaussian stand-in, and its curves keep it.
    import json

    from benchlab.synthetic.edges import edge_truth_mtf

    records = json.loads(default_curves_path().read_text())["curve"]
    for rec in records:
        nu = np.asarray(rec["freq_lp_per_mm"]) * 5.2e-3
        if rec["view"] == "forward":
            want = edge_truth_mtf(nu, rec["sigma_px"], 0.0)
        else:
            want = np.exp(-2 * math.pi**2 * (rec["sigma_px"] ** 2 + 1 / 12) * nu**2)
        np.testing.assert_allclose(rec["mtf"], want, atol=1e-4)  # sigma_px has 4 decimals
    assert gaussian_mtf(0.3, 96.15, aperture="box") == pytest.approx(
        math.exp(-2 * math.pi**2 * 0.09 * (96.15 * 5.2e-3) ** 2)
        * math.sin(math.pi * 0.49998) / (math.pi * 0.49998), rel=1e-4)
    with pytest.raises(ValueError, match="aperture"):
        gaussian_mtf(0.3, 10.0, aperture="disc")


@pytest.mark.slow
def test_a_csv_curve_file_from_the_params_is_used(tmp_path: Path) -> None:
    csv = tmp_path / "zemax.csv"
    csv.write_text("view,field_angle_deg,direction,freq_lp_per_mm,mtf\n"
                   "forward,0,S,0,1.0\nforward,0,S,100,0.5\n")
    params = tmp_path / "mtf.toml"
    params.write_text(MTF_SMALL.read_text().replace(
        'estimator = "histogram"', f'estimator = "histogram"\nsimulated_mtf_file = "{csv}"'))
    outcome = run_sim("mtf", tmp_path / "s", params)
    assert [c.view for c in load_curves(csv)] == ["forward"]
    assert "No simulated curves" not in render_report(outcome.session_path)
