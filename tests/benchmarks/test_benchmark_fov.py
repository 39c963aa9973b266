"""benchmark fov: each figure compared with the truth, bias / RMSE / coverage / target."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from benchlab.benchmarks.fov import VARIANTS, compare, format_benchmark, seed_of, summarise


def _write(folder: Path, **tables: list[dict[str, Any]]) -> Path:
    folder.mkdir()
    for name, rows in tables.items():
        (folder / f"{name}.json").write_text(json.dumps(rows))
    return folder


def _results(tmp_path: Path, fov: float, lo: float, hi: float) -> Path:
    return _write(
        tmp_path / f"r{fov}",
        field_of_view=[{"quantity": "full_fov_deg", "value": fov, "value_ci95": [lo, hi]},
                       {"quantity": "entrance_pupil_mm", "value": 2.5, "value_ci95": [2.4, 2.6]}],
        image_height_mapping=[
            {"field_angle_deg": 0.0, "image_height_mm": 0.0, "image_height_mm_ci95": [0, 0]},
            {"field_angle_deg": 12.0, "image_height_mm": 0.593,
             "image_height_mm_ci95": [0.592, 0.594]},
            {"field_angle_deg": 30.0, "image_height_mm": 1.5,  # beyond the edge: not judged
             "image_height_mm_ci95": [1.4, 1.6]},
            {"view": "radial", "field_angle_deg": -40.0, "image_height_mm": 2.4383,
             "image_height_mm_ci95": [2.4382, 2.4384]}],
        distortion=[{"field_angle_deg": 12.0, "rectilinear_pct": -1.4,
                     "rectilinear_pct_ci95": [-1.5, -1.3], "equidistant_pct": 0.0,
                     "equidistant_pct_ci95": [-0.1, 0.1]}],
        simulator_truth=[
            {"table": "field_of_view", "key": "full_fov_deg", "value": 52.6},
            {"table": "field_of_view", "key": "entrance_pupil_mm", "value": 2.0},
            {"table": "image_height_mapping", "key": "12", "value": 0.5927},
            {"table": "image_height_mapping", "key": "30", "value": 1.5},
            {"table": "distortion_rectilinear", "key": "12", "value": -1.467},
            {"table": "distortion_equidistant", "key": "12", "value": 0.0},
            {"table": "radial_image_height_mapping", "key": "-40", "value": 2.4381}])


def test_figures_are_compared_with_the_truth(tmp_path: Path) -> None:
    comps = compare(_results(tmp_path, 52.7, 52.65, 52.75))
    by = {(c["figure"], c["key"]): c for c in comps}
    assert by[("full_fov_deg", "")]["error"] == pytest.approx(0.1)
    assert by[("full_fov_deg", "")]["covered"] is False
    assert by[("entrance_pupil_mm", "")]["error"] == pytest.approx(0.5)
    assert by[("image_height_mm", 12.0)]["covered"] is True
    assert ("image_height_mm", 30.0) not in by and ("image_height_mm", 0.0) not in by
    assert by[("distortion_rectilinear_pct", 12.0)]["covered"] is True
    # the radial view's heights against the ring tube's truth (negative angles)
    assert by[("radial_image_height_mm", -40.0)]["error"] == pytest.approx(0.0002)
    assert by[("radial_image_height_mm", -40.0)]["covered"] is False


def test_summary_says_bias_rmse_coverage_and_the_target(tmp_path: Path) -> None:
    comps = compare(_results(tmp_path, 52.7, 52.65, 52.75)) + \
        compare(_results(tmp_path, 52.4, 52.3, 52.7))
    s = summarise(comps)
    fov = s["full_fov_deg"]
    assert fov["n"] == 2 and fov["bias"] == pytest.approx(-0.05)
    assert fov["rmse"] == pytest.approx((0.1 ** 2 / 2 + 0.2 ** 2 / 2) ** 0.5)
    assert fov["coverage"] == 0.5 and fov["within_target"] is True
    assert s["entrance_pupil_mm"]["within_target"] is False  # 0.5 mm off, target 0.3 mm
    text = format_benchmark({"seeds": 2, "variants": {"nominal": {
        "figures": s, "median_wall_s": 8.0, "frames_per_distance": 2,
        "distances_mm": [15.0, 25.0, 35.0], "stage_travel_mm": 20.0}}, "all": s})
    assert "2 frames at each of [15.0, 25.0, 35.0] mm, stage travel 20 mm" in text
    assert "entrance_pupil_mm" in text and " NO " in text


def test_an_unknown_variant_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    from benchlab.cli.main import main

    assert main(["benchmark", "fov", "--variants", "nominal,bent"]) == 2
    err = capsys.readouterr().err
    assert "benchlab: error: --variants: unknown bent; known: nominal, no-distortion" in err


def test_every_variant_takes_its_own_seeds() -> None:
    # the radial view is the same in every variant: only distinct seeds make its rows over
    # all variants independent runs
    seeds = [seed_of(v, k) for v in VARIANTS for k in range(100)]
    assert len(set(seeds)) == len(seeds)
    assert seed_of("tilted", 3) == seed_of("tilted", 3)
