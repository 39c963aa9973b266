"""The depth benchmark's comparison for the radial view: a field point carries an S and a T
pattern, each compared with its own truth; the S - T sign and the field curvature likewise."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from benchlab.benchmarks.depth import (
    RADIAL_VARIANTS,
    astig_signs,
    compare,
    curvature_checks,
)


def _row(fp: str, orient: str, best: float, h: float, ci: float = 0.01) -> dict[str, Any]:
    return {"view": "radial", "field_point": fp, "orientation": orient, "freq_lp_per_mm": 2.0,
            "criterion": "modulation>=0.3", "image_height_mm": h, "best_focus_mm": best,
            "best_focus_mm_ci95": [best - ci, best + ci], "near_mm": None,
            "near_mm_ci95": [None, None], "far_mm": None, "far_mm_ci95": [None, None],
            "note": ""}


def _write(tmp: Path, **tables: list[dict[str, Any]]) -> Path:
    for name, rows in tables.items():
        (tmp / f"{name}.json").write_text(json.dumps(rows))
    return tmp


def test_sagittal_and_tangential_of_one_field_point_meet_their_own_truth(tmp_path: Path
                                                                         ) -> None:
    measured = [_row("r250c1000", "sagittal", 5.23, 2.48),
                _row("r250c1000", "tangential", 6.80, 2.48)]
    truth = [_row("r250c1000", "sagittal", 5.232, 2.48),
             _row("r250c1000", "tangential", 6.79, 2.48)]
    res = _write(tmp_path, depth_of_field=measured, simulator_truth=truth,
                 depth_astigmatism=[{"field_point": "r250c1000", "freq_lp_per_mm": 2.0,
                                     "s_minus_t_mm": -1.57,
                                     "s_minus_t_mm_ci95": [-1.6, -1.54]}],
                 depth_field_curvature=[])
    best = [c for c in compare(res, 0.1) if c["quantity"] == "best_focus_mm"]
    # before, both rows were keyed (field point, criterion): S met T's truth, 1.56 mm off
    assert [round(c["error_mm"], 3) for c in best] == [-0.002, 0.01]
    assert all(c["covered"] for c in best)
    sign, = astig_signs(res)
    assert sign == {"significant": True, "sign_right": True, "covered": True}


def test_radial_field_curvature_is_checked_against_the_truths_heights(tmp_path: Path) -> None:
    heights = (1.8, 2.13, 2.48)
    k = -0.25
    truth = [_row(f"p{i}", "sagittal", 6.0 + k * h * h, h) for i, h in enumerate(heights)]
    res = _write(tmp_path, simulator_truth=truth, depth_field_curvature=[
        {"orientation": "sagittal", "freq_lp_per_mm": 2.0, "curvature_mm_per_mm2": -0.26,
         "curvature_mm_per_mm2_ci95": [-0.27, -0.24]}])
    check, = curvature_checks(res)
    assert check["covered"] and check["error"] == pytest.approx(-0.01, abs=1e-9)


def test_the_curved_variant_has_field_curvature() -> None:
    assert RADIAL_VARIANTS["radial-curved"] == {"field_curvature_per_mm2": 0.0005}
