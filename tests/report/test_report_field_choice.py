"""The MTF report picks each test's simulated field point through the unit's measured
image-height mapping when an fov session of the same unit sits next to it, and says so;
otherwise the design's nearest in image height (the thesis's way)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from benchlab.report.field_choice import choose_fields, measured_angle
from benchlab.session import Session

#: A forward test at 0.70 mm: the design's nearest in height is 16 deg (0.79 mm) - 12 deg is
#: 0.60 mm - and a radial one at 2.48 mm: the thesis's -30 deg (2.49 mm).
TESTS = [{"view": "forward", "test": "G2E2", "image_height_mm": 0.70, "nearest_field_deg": 16.0},
         {"view": "radial", "test": "4 lp/mm", "image_height_mm": 2.48,
          "nearest_field_deg": -30.0}]
#: A lens that images more widely than the design: 0.70 mm is only 12.6 deg, and the radial
#: 2.48 mm is -39 deg.
MAPPING = [
    {"view": "forward", "field_angle_deg": a, "image_height_mm": h}
    for a, h in ((0.0, 0.0), (10.0, 0.55), (15.0, 0.84), (25.0, 1.45))
] + [
    {"view": "radial", "field_angle_deg": a, "image_height_mm": h}
    for a, h in ((-26.0, 2.83), (-35.0, 2.60), (-40.0, 2.44), (-57.5, 1.58))
] + [{"view": "radial", "field_angle_deg": -60.0, "image_height_mm": None}]


def _session(root: Path, name: str, procedure: str, serial: str,
             tables: dict[str, list[dict[str, Any]]]) -> Session:
    s = Session.create(root, procedure=procedure, params={}, operator="t", devices={},
                       software_version="test", name=name, sample=serial)
    s.write_results(tables, summary={}, estimator="test")
    s.finish("completed")
    s.release()
    return Session.open(s.path)


def test_the_measured_mapping_picks_the_field_points(tmp_path: Path) -> None:
    mtf = _session(tmp_path, "mtf", "mtf", "OBJ-7", {"table_4_13": TESTS})
    _session(tmp_path, "fov", "fov", "OBJ-7", {"image_height_mapping": MAPPING})
    _session(tmp_path, "fov-other", "fov", "OBJ-8", {"image_height_mapping": []})
    choice = choose_fields(mtf, {"table_4_13": TESTS})
    assert choice.source == tmp_path / "fov"
    assert choice.fields == {"forward": {12.0}, "radial": {-40.0}}
    text = "\n".join(choice.lines)
    assert "through the measured image-height mapping of fov (fov, unit OBJ-7)" in text
    assert "forward G2E2: 0.700 mm is 12.6 deg on this lens -> the 12 deg curve" in text
    assert "(design's nearest in height: 16 deg)" in text
    assert "radial 4 lp/mm: 2.480 mm is -38.8 deg on this lens -> the -40 deg curve" in text


def test_without_an_fov_session_of_the_unit_the_design_decides(tmp_path: Path) -> None:
    mtf = _session(tmp_path, "mtf", "mtf", "OBJ-7", {"table_4_13": TESTS})
    _session(tmp_path, "fov", "fov", "OBJ-8", {"image_height_mapping": MAPPING})
    choice = choose_fields(mtf, {"table_4_13": TESTS})
    assert choice.source is None
    assert choice.fields == {"forward": {16.0}, "radial": {-30.0}}
    assert "the design's (Table 4.14) nearest in image height" in choice.lines[0]


def test_a_height_outside_the_measured_mapping_is_not_guessed() -> None:
    assert measured_angle(MAPPING, "forward", 1.6) is None
    assert measured_angle(MAPPING, "radial", 2.60) == pytest.approx(-35.0)
