"""The Run screen's depth-of-field digest and position rows (pure functions)."""

from __future__ import annotations

from benchlab.tui.depth_summary import depth_summary_rows
from benchlab.tui.runner import result_row


def _row(fp: str, orient: str, crit: str, best: float | None, near: float | None,
         far: float | None, verdict: str) -> dict[str, object]:
    return {"field_point": fp, "orientation": orient, "criterion": crit,
            "best_focus_mm": best, "near_mm": near, "far_mm": far,
            "near_mm_ci95": [None, None] if near is None else [near - 1, near + 1],
            "far_mm_ci95": [None, None] if far is None else [far - 2, far + 2],
            "verdict": verdict}


def test_digest_takes_the_shared_range_and_the_interval_of_the_point_that_sets_each_end(
) -> None:
    rows = [
        _row("E0T", "tangential", "MTF50>=35", 61.0, 45.0, 85.0, "meets"),
        _row("E0L", "sagittal", "MTF50>=35", 60.0, 46.0, 86.0, "meets"),
        _row("E1L", "sagittal", "MTF50>=35", 62.0, 48.0, 84.0, "fails"),
        _row("E2L", "sagittal", "MTF50>=35", 59.0, None, 90.0,
             "undecided (a DOF end beyond the sweep)"),
        _row("E0L", "sagittal", "spot", None, None, None, "not measured"),
    ]
    digest = depth_summary_rows(rows)
    assert [(d["criterion"], d["orient."]) for d in digest] == [
        ("MTF50>=35", "S"), ("MTF50>=35", "T"), ("spot", "S")]
    s = digest[0]
    assert s["best mm"] == "60.00" and s["best range"] == "59.00-62.00"  # median of 59, 60, 62
    assert s["near mm"] == "48.00" and s["near 95 %"] == "[47.00, 49.00]"  # E1L: the near end
    assert s["far mm"] == "84.00" and s["far 95 %"] == "[82.00, 86.00]"
    assert s["verdicts"] == "1 fails, 1 meets, 1 undecided" and s["points"] == "3"
    spot = digest[2]
    assert spot["best mm"] == spot["near mm"] == spot["far 95 %"] == "N/A"
    assert spot["verdicts"] == "1 not measured"


def test_a_depth_position_reads_as_its_distance_and_the_edges_mtf50() -> None:
    data = {"distance_mm": 52.0, "scale": 0.41, "mtf50_sagittal_lp_per_mm": 61.26,
            "mtf50_tangential_lp_per_mm": None}
    assert result_row(data) == ("52 mm", "S 61 T -")
    what, value = result_row({**data, "mtf50_tangential_lp_per_mm": 58.7})
    assert value == "S 61 T 59" and len(what) <= 12 and len(value) <= 12


def test_a_criterion_read_at_two_frequencies_gets_a_row_per_frequency() -> None:
    rows = [{**_row(fp, "sagittal", "modulation>=0.3", best, 3.5, 8.4, "fails"),
             "freq_lp_per_mm": f}
            for fp, best, f in (("r330c895", 6.0, 2.0), ("r291c946", 6.1, 2.0),
                                ("r330c895", 5.5, 4.0))]
    digest = depth_summary_rows(rows)
    assert [(d["criterion"], d["best mm"], d["points"]) for d in digest] == [
        ("modulation>=0.3 @2", "6.05", "2"), ("modulation>=0.3 @4", "5.50", "1")]
