"""The depth report section for the radial view (rows per ROI, no slanted edges), and interval
cells in the terminal tables."""

from __future__ import annotations

import base64
import re
from typing import Any

import pytest

from benchlab.report.depth import depth_section
from benchlab.report.tables import cell


def _dof(fp: str, orientation: str, height: float, best: float | None) -> dict[str, Any]:
    near, far = (None, None) if best is None else (best - 2.0, best + 2.0)
    return {"view": "radial", "field_point": fp, "pattern": "2lp/mm", "orientation": orientation,
            "criterion": "modulation>=0.3", "freq_lp_per_mm": 2.0, "threshold": 0.3,
            "image_height_mm": height, "best_focus_mm": best,
            "best_focus_mm_ci95": [None, None] if best is None else [best - 0.01, best + 0.01],
            "near_mm": near, "far_mm": far}


def _curves(fp: str, orientation: str, peak: float) -> list[dict[str, Any]]:
    return [{"distance_mm": z, "segment": 0, "pattern": "2lp/mm", "field_point": fp,
             "orientation": orientation, "modulation": round(peak - 0.05 * (z - 6.0) ** 2, 4),
             "modulation_sigma": 0.002, "status": "ok"} for z in (3.0, 4.5, 6.0, 7.5, 9.0)]


@pytest.mark.slow
def test_a_radial_session_gets_its_curves_per_field_point() -> None:
    dof = [_dof("r330c895", "sagittal", 1.7962, 6.0), _dof("r330c895", "tangential", 1.7962, 5.9),
           _dof("r250c1000", "sagittal", 2.4827, 6.0), _dof("r250c1000", "tangential", 2.4827,
                                                             None)]
    curves = [row for fp in ("r330c895", "r250c1000") for o, peak in (("sagittal", 0.8),
              ("tangential", 0.35)) for row in _curves(fp, o, peak)]
    html = depth_section({"depth_of_field": dof, "depth_curves": curves},
                         {"analysis": {"design_half_range_mm": 5.0}})
    assert "rolled bar pattern's modulation (Eq. 2.9)" in html
    assert "slanted edges' MTF" not in html
    svgs = [base64.b64decode(b).decode() for b in
            re.findall(r"data:image/svg\+xml;base64,([^']+)", html)]
    assert len(svgs) == 2  # the curves, then best focus against image height
    assert "r330c895 (image height 1.80 mm)" in svgs[0]
    assert "r250c1000 (image height 2.48 mm)" in svgs[0]
    assert "distance from the side wall (mm)" in svgs[0]
    assert "design DOF: +-5 mm" in svgs[1]


@pytest.mark.slow
def test_with_the_prints_contrast_known_the_figure_draws_the_lens_share() -> None:
    share = {"threshold_on": "lens share (reading / target contrast)", "target_contrast": 0.81,
             "target_contrast_source": "measured: the 2 lp/mm pattern (sagittal)"}
    dof = [{**_dof("r330c895", "sagittal", 1.7962, 6.0), **share}]
    curves = [{**c, "lens_share": round(c["modulation"] / 0.81, 4)}
              for c in _curves("r330c895", "sagittal", 0.8)]
    html = depth_section({"depth_of_field": dof, "depth_curves": curves},
                         {"analysis": {"design_half_range_mm": 5.0}})
    assert "the lens's share of the print's contrast" in html and "0.810" in html
    svg = base64.b64decode(re.findall(r"data:image/svg\+xml;base64,([^']+)", html)[0]).decode()
    assert "lens share (Eq. 2.9 / target contrast)" in svg
    # raw rows (no threshold_on) keep the reading's axis
    raw = depth_section({"depth_of_field": [_dof("r330c895", "sagittal", 1.7962, 6.0)],
                         "depth_curves": curves}, {"analysis": {}})
    raw_svg = base64.b64decode(re.findall(r"data:image/svg\+xml;base64,([^']+)", raw)[0])
    assert b"bar modulation (Eq. 2.9)" in raw_svg and b"lens share" not in raw_svg


def test_intervals_print_as_numbers_or_na() -> None:
    assert cell([5.979, 5.995], "") == "[5.979, 5.995]"
    assert cell([None, 8.4], "") == "[N/A, 8.4]"
    assert cell([None, None], "") == "N/A"
    assert cell([1, 2], "") == "[1, 2]"
