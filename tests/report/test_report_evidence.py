"""The report's building blocks: per-ROI evidence, CTF against CTF, verdicts, readability."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from benchlab.analysis.mtf.coltman import mtf_to_ctf
from benchlab.analysis.mtf.compare import SimulatedCurve
from benchlab.report.html import downsample, flatten, local_time, svg_plot
from benchlab.report.mtf import _state, extended_mtf, simulated_ctf, verdict_section
from benchlab.report.roi import RoiReading, bar_direction_rad, reading_text, roi_panel


def _bars(theta_deg: float, period_px: float = 8.0, size: int = 40) -> np.ndarray:
    t = math.radians(theta_deg)
    r, c = np.mgrid[0:size, 0:size].astype(float)
    u = c * math.cos(t) + r * math.sin(t)
    return np.where(np.sin(2 * math.pi * u / period_px) >= 0, 200, 20).astype(np.uint8)


def _reading(**kw: object) -> RoiReading:
    base: dict[str, object] = dict(
        label="G2E1 sagittal", roi=(0, 0, 40, 40), orientation="sagittal", view="radial",
        modulation=0.8, dark=20.0, bright=180.0, resolved=True, aliased=False,
        uncertainty=0.01, warnings="clipped 2 %; near Nyquist", estimator="profilefit")
    base.update(kw)
    return RoiReading(**base)  # type: ignore[arg-type]


@pytest.mark.parametrize("theta_deg", [0.0, 30.0, 45.0, 90.0, 120.0])
def test_structure_tensor_finds_the_bar_direction(theta_deg: float) -> None:
    got = math.degrees(bar_direction_rad(_bars(theta_deg).astype(float)))
    diff = (got - theta_deg + 90.0) % 180.0 - 90.0  # a direction, modulo 180 deg
    assert abs(diff) < 3.0


def test_panel_shows_levels_interval_estimator_and_each_warning() -> None:
    html = roi_panel(_bars(30.0), _reading())
    assert "data-state='resolved'" in html
    assert "modulation 0.800 (95 % interval 0.780-0.820)" in html
    assert "profilefit" in html and "20.0 / 180.0" in html
    assert "<li>clipped 2 %</li>" in html and "<li>near Nyquist</li>" in html
    assert html.count("<svg class='mini-plot'") == 2  # histogram and profile
    assert html.count(">D</text>") == 2 and html.count(">B</text>") == 2  # levels on both
    assert "(30 deg)" in html  # profile taken across the bars at their own angle


def test_unresolved_and_aliased_are_labelled_never_a_number() -> None:
    unres = roi_panel(_bars(0.0), _reading(modulation=0.0, dark=None, bright=None,
                                           resolved=False, warnings=""))
    assert "data-state='unresolved'" in unres and "not resolved" in unres
    assert "modulation 0.000" not in unres and ">D</text>" not in unres
    alias = roi_panel(_bars(0.0), _reading(aliased=True))
    assert "data-state='aliased'" in alias and "aliased: above Nyquist" in alias
    assert reading_text(_reading(aliased=True, resolved=True)).startswith("not resolved")
    assert _state({"aliased": True, "sagittal_resolved": True}, "sagittal") == "aliased"
    assert _state({"sagittal_resolved": False, "sagittal_modulation": 0.0},
                  "sagittal") == "unresolved"
    assert _state({"sagittal_modulation": 0.31}, "sagittal") == "resolved"


def test_interval_is_clamped_to_0_1_and_panel_survives_an_roi_off_the_frame() -> None:
    assert "0.951-1.000" in reading_text(_reading(modulation=0.99, uncertainty=0.02))
    html = roi_panel(_bars(0.0), _reading(roi=(100, 100, 120, 120)))
    assert "ROI outside the frame" in html


def test_one_pixel_and_flat_rois_render() -> None:
    one = roi_panel(np.full((1, 1), 7, np.uint16), _reading(roi=(0, 0, 1, 1)))
    flat = roi_panel(np.zeros((10, 10), np.uint8), _reading(roi=(0, 0, 10, 10)))
    assert "1 x 1" in one and "10 x 10" in flat


def _gaussian_curve(sigma: float, f_max: float) -> SimulatedCurve:
    f = np.arange(0.0, f_max + 1e-9, 2.0)
    return SimulatedCurve("forward", 0.0, "S", f, np.exp(-(f / sigma) ** 2))


def test_simulated_ctf_is_coltman_of_the_mtf() -> None:
    full = _gaussian_curve(60.0, 600.0)
    grid = np.array([5.0, 20.0, 50.0, 90.0])
    exact = mtf_to_ctf(lambda x: np.exp(-(np.asarray(x) / 60.0) ** 2), grid)
    np.testing.assert_allclose(simulated_ctf(full, grid), exact, atol=2e-3)
    assert simulated_ctf(full, np.array([5.0]))[0] > 1.0 - 1e-3  # square wave -> 1 at low f


def test_a_curve_cut_at_nyquist_gets_its_tail_extrapolated() -> None:
    cut = _gaussian_curve(60.0, 100.0)  # ends at MTF 0.06: the series needs MTF(3f), ...
    mtf_at, extrapolated = extended_mtf(cut)
    assert extrapolated
    assert float(mtf_at(150.0)) == pytest.approx(math.exp(-(150 / 60) ** 2), rel=0.05)
    grid = np.array([20.0, 40.0, 60.0])
    exact = mtf_to_ctf(lambda x: np.exp(-(np.asarray(x) / 60.0) ** 2), grid)
    np.testing.assert_allclose(simulated_ctf(cut, grid), exact, atol=5e-3)
    # Without the extrapolation (tail = 0) the CTF at 40 lp/mm would be off by 0.03.
    _, vanished = extended_mtf(_gaussian_curve(20.0, 100.0))
    assert not vanished


MC_ROW = {"view": "radial", "mc_freq_lp_per_mm": 60.0, "measured_freq_lp_per_mm": 52.5,
          "sagittal_modulation": 0.706, "tangential_modulation": 0.12,
          "averaged_modulation": 0.413, "p90": 0.21, "p80": 0.27, "p50": 0.45, "p20": 0.61,
          "p10": 0.63, "verdict": "exceeds the 80 % threshold (0.27)"}


def test_verdict_shows_every_threshold_it_may_cite_and_the_frequency_mismatch() -> None:
    html = verdict_section([MC_ROW])
    assert "exceeds the 80 % threshold (0.27)" in html
    for header in ("90 % exceed", "80 % exceed", "50 % exceed", "20 % exceed", "10 % exceed"):
        assert header in html
    assert ">0.27<" in html  # the 80 % column's value, which the verdict cites
    assert "measured at 52.5 lp/mm against the prediction at 60 lp/mm (12 % apart" in html
    assert "class='plot'" in html  # the bands
    same = verdict_section([{**MC_ROW, "measured_freq_lp_per_mm": 60.0}])
    assert "apart" not in same
    # The radial spokes' own frequency differs from the rings': both are named.
    both = verdict_section([{**MC_ROW, "sagittal_freq_lp_per_mm": 48.04,
                             "tangential_freq_lp_per_mm": 52.5}])
    assert ("measured sagittal at 48.0 lp/mm and tangential at 52.5 lp/mm against the "
            "prediction at 60 lp/mm (up to 20 % apart") in both
    assert ">48.04<" in both  # the S lp/mm column
    assert "No Monte Carlo comparison" in verdict_section([])


def test_downsample_uses_an_area_filter_not_decimation() -> None:
    stripes = np.tile(np.array([0, 255], np.uint8), (64, 320))  # 1 px period, 640 wide
    small, scale = downsample(stripes, 320)
    assert scale == 0.5 and small.shape == (32, 320)
    assert np.all(np.abs(small.astype(int) - 128) <= 1)  # averaged grey, no moire
    same, one = downsample(stripes, 1000)
    assert one == 1.0 and same is stripes


def test_parameters_flatten_and_times_are_local_and_readable() -> None:
    rows = flatten({"camera": {"exposure_ms": 300.0, "gain": 1}, "forward": {"elements": ["G1E5"]},
                    "positions": [{"mm": 1}, {"mm": 2}]})
    assert ("camera.exposure_ms", 300.0) in rows and ("forward.elements", ["G1E5"]) in rows
    assert ("positions[1].mm", 2) in rows
    text = local_time("2026-11-23T01:22:59.713394+00:00")
    assert re.fullmatch(r"2026-11-2[23] \d\d:\d\d:59( \S+)?", text)
    assert local_time(None) == "-" and local_time("garbage") == "garbage"


def test_svg_plot_breaks_lines_at_nan_and_handles_empty_input() -> None:
    svg = svg_plot([([0, 1, 2, 3], [1.0, float("nan"), 2.0, 3.0], "#000", "p")])
    assert svg.count("<polyline") == 2
    assert "plot-empty" in svg_plot([([], [], "#000", "p")])
