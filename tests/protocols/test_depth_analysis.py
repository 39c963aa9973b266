"""The depth_of_field verdict against Table 4.1's design DOF (best focus +- 40 mm)."""

from __future__ import annotations

from typing import Any

from benchlab.analysis.focus.through_focus import FocusEstimate
from benchlab.protocols.depth.analysis import verdict


def _est(near: Any, near_ci: Any, far: Any, far_ci: Any, peak: float = 0.9) -> FocusEstimate:
    return FocusEstimate(best_focus_mm=60.0, best_focus_ci95=(59.9, 60.1), peak_mtf=peak,
                         near_mm=near, near_ci95=near_ci, far_mm=far, far_ci95=far_ci,
                         near_extrapolated=False, far_extrapolated=False)


def test_meets_only_when_both_intervals_clear_the_design_range() -> None:
    assert verdict(_est(15.0, (14.0, 16.0), 110.0, (105.0, 115.0)), 0.5, 40.0) == "meets"
    assert verdict(_est(19.0, (18.0, 21.0), 110.0, (105.0, 115.0)), 0.5, 40.0) == "undecided"


def test_fails_when_an_interval_misses_it_or_the_criterion_is_never_met() -> None:
    assert verdict(_est(45.0, (44.0, 46.0), 110.0, (105.0, 115.0)), 0.5, 40.0) == "fails"
    assert verdict(_est(15.0, (14.0, 16.0), 80.0, (79.0, 81.0)), 0.5, 40.0) == "fails"
    assert verdict(_est(None, (None, None), None, (None, None), peak=0.4), 0.5,
                   40.0) == "fails (criterion never met)"


def test_an_end_beyond_the_sweep_is_undecided_not_failed() -> None:
    assert verdict(_est(15.0, (14.0, 16.0), None, (None, None)), 0.5,
                   40.0) == "undecided (a DOF end beyond the sweep)"


def test_catalogue_keeps_best_focus_and_dof_per_field_point_and_criterion() -> None:
    from benchlab.catalog.extract import figures_of

    row = {"view": "forward", "field_point": "E0L", "orientation": "sagittal",
           "criterion": "MTF50>=35", "freq_lp_per_mm": 35.0, "best_focus_mm": 60.1,
           "near_mm": 46.0, "far_mm": 87.0, "dof_mm": 41.0, "verdict": "undecided"}
    figs = list(figures_of(1, {"depth_of_field": [row], "depth_curves": [row] * 3}))
    assert {f.quantity for f in figs} == {"best_focus_mm", "near_mm", "far_mm", "dof_mm"}
    near = next(f for f in figs if f.quantity == "near_mm")
    assert (near.view, near.element, near.orientation, near.freq_lp_per_mm, near.value) == (
        "depth forward", "E0L", "sagittal", 35.0, 46.0)
    assert near.text == "MTF50>=35: undecided"
