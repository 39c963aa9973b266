"""depth.toml checked in full before any device moves; the stage segments it plans."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from sim_runs import FIXTURES

from benchlab.checks import BenchLimits
from benchlab.protocols.depth.params import DepthParams
from benchlab.protocols.params import ParamsError, load_params, params_to_dict, parse_params

TRAVEL = BenchLimits(led_ceilings_ma=None, stage_travel_mm=(0.0, 50.0))


def _parse(data: dict[str, Any], limits: BenchLimits | None = TRAVEL) -> Any:
    return parse_params("depth", {"procedure": "depth", **data}, "t.toml", limits)


def test_packaged_defaults_load_and_round_trip() -> None:
    p = load_params("depth", None, TRAVEL)
    assert isinstance(p, DepthParams)
    assert p.segment_mm == 49.0  # resolved from the travel (stage_start 1 mm)
    assert [c.name for c in p.criteria] == ["MTF50>=35", "MTF(70)>=0.46", "spot<=12um@20"]
    again = parse_params("depth", params_to_dict(p), "snapshot")
    assert again == p or params_to_dict(again) == params_to_dict(p)


def test_a_range_longer_than_the_travel_is_taken_in_overlapping_segments() -> None:
    p = load_params("depth", None, TRAVEL)
    segs = p.segments()
    assert len(segs) == 2
    assert segs[0].distances_mm[0] == 40.0 and segs[1].distances_mm[-1] == 94.0
    overlap = set(segs[0].distances_mm) & set(segs[1].distances_mm)
    assert max(overlap) - min(overlap) >= p.overlap_mm
    for s in segs:  # every stage target inside the travel
        assert all(0.0 <= s.stage_mm(z) <= 50.0 for z in s.distances_mm)
    small = load_params("depth", FIXTURES / "depth-small.toml", TRAVEL)
    assert [s.distances_mm for s in small.segments()] == [
        (52.0, 54.0, 56.0, 58.0, 60.0, 62.0), (60.0, 62.0, 64.0, 66.0, 68.0)]


@pytest.mark.parametrize(("data", "message"), [
    ({"sweep": {"step_mm": 0}}, "sweep.step_mm: must be in (0.0, 1000.0]"),
    ({"sweep": {"near_mm": 80, "far_mm": 60}}, "sweep.far_mm: 60 mm must be beyond"),
    ({"sweep": {"stage_start_mm": 60}}, "sweep.stage_start_mm: 60 mm is outside the stage travel"),
    ({"sweep": {"segment_mm": 55}}, "sweep.segment_mm: 55 mm from sweep.stage_start_mm 1 runs "
                                    "past the stage travel"),
    ({"sweep": {"overlap_mm": 48}}, "sweep.overlap_mm: 48 mm leaves no new distance"),
    ({"criteria": [{"kind": "mtf", "frequency_lp_per_mm": 120, "threshold": 0.3}]},
     "criteria[0].frequency_lp_per_mm: 120 lp/mm is at or above Nyquist"),
    ({"criteria": [{"kind": "mtf", "frequency_lp_per_mm": 50}]}, "criteria[0].threshold: is "
                                                                 "required"),
    ({"criteria": [{"kind": "mtf50", "frequency_lp_per_mm": 35, "threshold": 0.3}]},
     "criteria[0].threshold: only a kind = \"mtf\" criterion takes a threshold"),
    ({"criteria": [{"kind": "blur", "frequency_lp_per_mm": 35}]}, "criteria[0].kind: must be"),
    ({"simulator": {"pupil_mm": 1.0}}, "simulator.pupil_mm: unknown parameter"),
    ({"sweep": {"stepmm": 2}}, "sweep.stepmm: unknown parameter"),
])
def test_bad_parameters_are_named(data: dict[str, Any], message: str) -> None:
    with pytest.raises(ParamsError) as err:
        _parse(data)
    assert message in str(err.value)


def test_every_problem_is_listed_at_once(tmp_path: Path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text('procedure = "depth"\n[sweep]\nstep_mm = 0\nstage_start_mm = 70\n'
                 '[[criteria]]\nkind = "mtf50"\nfrequency_lp_per_mm = 100\n')
    with pytest.raises(ParamsError) as err:
        load_params("depth", f, TRAVEL)
    text = str(err.value)
    assert str(f) in text
    for field in ("sweep.step_mm", "sweep.stage_start_mm", "criteria[0].frequency_lp_per_mm"):
        assert field in text


def test_depth_procedure_is_made_on_demand_and_mtf_never_loads_it() -> None:
    import subprocess
    import sys

    from benchlab.protocols.depth.steps import DepthProcedure
    from benchlab.protocols.runs import make_procedure

    assert isinstance(make_procedure(load_params("depth")), DepthProcedure)
    code = ("from benchlab.protocols.runs import make_procedure; "
            "from benchlab.protocols.params import load_params; "
            "make_procedure(load_params('mtf')); import sys; print('\\n'.join(sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout.split()
    assert not [m for m in loaded if m.startswith("benchlab.protocols.depth")]


def test_radial_view_sweeps_the_wall_distance_with_its_own_defaults() -> None:
    p = _parse({"sweep": {"view": "radial"}})
    assert (p.near_mm, p.far_mm, p.step_mm) == (2.5, 10.5, 0.5)
    assert p.design_half_range_mm == 5.0  # Table 4.1 radial: +-5 mm
    assert p.patterns == ((2.0, "sagittal"), (2.0, "tangential"))
    assert p.object_distance_mm(3.0) == pytest.approx(16.88)  # + the endoscope radius
    assert p.lens().pupil_diameter_mm == 1.68 and p.lens().best_focus_mm == 19.88
    assert parse_params("depth", params_to_dict(p), "snapshot").patterns == p.patterns
    with pytest.raises(ParamsError, match="criteria: apply to the forward view"):
        _parse({"sweep": {"view": "radial"},
                "criteria": [{"kind": "mtf50", "frequency_lp_per_mm": 35}]})
    with pytest.raises(ParamsError, match="radial.orientations: must be a list"):
        _parse({"sweep": {"view": "radial"}, "radial": {"orientations": ["sideways"]}})


def test_radial_field_points_default_and_round_trip() -> None:
    p = _parse({"sweep": {"view": "radial"}})
    assert p.radial_rois == ((330, 895, 370, 945), (291, 946, 331, 996), (250, 1000, 290, 1050))
    q = _parse({"sweep": {"view": "radial"}, "radial": {"rois": [[300, 960, 330, 990]]}})
    assert q.radial_rois == ((300, 960, 330, 990),)
    assert parse_params("depth", params_to_dict(q), "snapshot").radial_rois == q.radial_rois


@pytest.mark.parametrize(("rois", "message"), [
    ([[1000, 1200, 1040, 1290]], r"radial.rois\[0\]: columns 1200..1290 must satisfy"),
    ([[540, 620, 580, 670]], r"radial.rois\[0\]: \[540, 620, 580, 670\] lies outside the "
                             r"radial annulus"),
    ([[250, 1000, 260, 1050]], r"radial.rois\[0\]: \[250, 1000, 260, 1050\] 10 x 50 px is too "
                               r"small"),
    ([[250, 1000, 290, 1050], [250, 1000, 290, 1050]], r"radial.rois\[1\]: repeats"),
    ([[250, 1000, 290]], r"radial.rois\[0\]: must be 4 integers"),
    ([], r"radial.rois: must be a non-empty list"),
    ("r250c1000", r"radial.rois: must be a non-empty list"),
])
def test_bad_radial_field_points_are_refused_by_name(rois: Any, message: str) -> None:
    with pytest.raises(ParamsError, match=message):
        _parse({"sweep": {"view": "radial"}, "radial": {"rois": rois}})
