"""``find-chart`` and ``analyze --chart usaf`` on a microscope's JPEG of groups 4-7: found by
the whole-chart finder, its groups named, its elements read (was "no chart found")."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from benchlab.analysis.chart.pose import ChartPose
from benchlab.analysis.chart.whole_layout import whole_chart_layout
from benchlab.cli.main import main
from benchlab.scenes.usaf import render_chart_image


@pytest.fixture(scope="module")
def scope_jpeg(tmp_path_factory: pytest.TempPathFactory) -> Path:
    shape = (600, 800)
    lay = whole_chart_layout(0.25, origin_rc=((shape[0] - 1) / 2, (shape[1] - 1) / 2))
    img = render_chart_image(lay, ChartPose((10.0, -20.0), 1.0, 23.0), *shape, blur_px=0.8)
    img = img + np.random.default_rng(0).normal(0.0, 0.01, img.shape)
    out = tmp_path_factory.mktemp("scope") / "scope.jpg"
    Image.fromarray(np.clip(np.round(img * 255), 0, 255).astype(np.uint8)).save(out, quality=85)
    return out


@pytest.mark.slow
def test_find_chart_names_the_groups_of_a_microscope_jpeg(
    scope_jpeg: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["find-chart", str(scope_jpeg), "--magnification", "0.3"]) == 0
    out = capsys.readouterr().out
    assert "groups in view: 4, 5, 6, 7 (whole chart, groups -2 to 7)" in out
    assert "implied magnification 0.25" in out
    assert main(["find-chart", str(scope_jpeg), "--json", "--magnification", "0.3"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["groups_found"] == [4, 5, 6, 7]
    assert doc["pose"]["rotation_deg"] == pytest.approx(23.0, abs=0.2)


@pytest.mark.slow
def test_analyze_reads_the_elements_of_a_microscope_jpeg(
    scope_jpeg: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["analyze", str(scope_jpeg), "--chart", "usaf", "--magnification", "0.3",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rows = {r["label"]: r for r in doc["rows"]}
    # Bars at 0.1 / 0.9 of full scale (modulation 0.8), 0.8 px blur: wide bars read 0.8.
    assert rows["G5E3S"]["result"]["modulation"] == pytest.approx(0.8, abs=0.02)
    fine = rows["G7E6S"]["result"]["modulation"]
    assert 0.1 < fine < rows["G6E1S"]["result"]["modulation"]
    assert main(["analyze", str(scope_jpeg), "--magnification", "0.3", "--roi", "0,0,9,9"]) == 2
    assert "--magnification applies with --chart only" in capsys.readouterr().err


@pytest.mark.slow
def test_the_simulated_bench_shows_the_whole_chart_and_find_chart_finds_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``usaf:whole=0.25``: a microscope's view of groups 4-7 over the whole frame. Without a
    hint the forward view's finder fits a few sets by coincidence; the whole chart fits ~40 and
    is taken (its groups then named for 16.3 - 64x the truth, six groups coarser - with the
    other readings in a warning)."""
    frame = tmp_path / "scope.tiff"
    assert main(["snap", "--simulate", "--seed", "1", "--exposure-ms", "300", "--gain", "1",
                 "--scene", "usaf:whole=0.25,rot=20", str(frame)]) == 0
    capsys.readouterr()
    assert main(["find-chart", str(frame), "--json", "--magnification", "0.3"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert {4, 5, 6, 7} <= set(doc["groups_found"]) <= {3, 4, 5, 6, 7}  # a corner of group 3
    assert doc["implied_magnification"] == pytest.approx(0.25, rel=0.01)
    assert main(["find-chart", str(frame)]) == 0
    out = capsys.readouterr().out
    assert "groups in view: -2, -1, 0, 1" in out and "(whole chart, groups -2 to 7)" in out
    assert "implied magnification 16 " in out and "no magnification given" in out
