"""The focus aid's drawing (bars with a peak mark, edges, sparkline) and its frame slot."""

from __future__ import annotations

import threading

import numpy as np

from benchlab.tui.drawing.focus_bars import (
    PEAK_MARK,
    FocusAidView,
    bar,
    element_rows,
    render_focus_aid,
    sparkline,
)
from benchlab.tui.focus_aid import FrameSlot


def test_bar_fills_eighths_and_marks_the_peak_in_its_cell() -> None:
    assert bar(0.5, None, 1.0, 4).plain == "\u2588\u2588  "
    assert bar(0.5625, None, 1.0, 4).plain == "\u2588\u2588\u258e "  # 2.25 cells: 2 + 2/8
    marked = bar(0.25, 0.8, 1.0, 10)
    assert marked.plain.index(PEAK_MARK) == 7  # the peak's cell: ceil(8) - 1
    assert bar(None, 0.5, 1.0, 4).plain == " " + PEAK_MARK + "  "  # no value: the peak alone
    assert bar(2.0, 3.0, 1.0, 3).plain == "\u2588\u2588" + PEAK_MARK  # clipped at full


def test_sparkline_spans_the_range_but_keeps_steady_noise_a_ripple() -> None:
    assert sparkline([0.0, 50.0, 100.0], 10) == "\u2581\u2585\u2588"
    steady = sparkline([80.0, 80.4, 79.8, 80.1], 10)
    assert set(steady) <= set("\u2581\u2582")  # 0.6 lp/mm of 80: under a tenth of the height
    assert sparkline(list(range(50)), 5) == sparkline([45.0, 46.0, 47.0, 48.0, 49.0], 5)
    assert sparkline([], 5) == "" and sparkline([float("nan")], 5) == ""


def test_render_lists_elements_coarsest_first_and_the_edges_per_square() -> None:
    assert element_rows(["G2E4T", "G0E1S", "G2E4S", "G1E6S", "E0L"]) == ["G0E1", "G1E6", "G2E4"]
    view = FocusAidView(
        modulation={"G0E1S": 0.8, "G0E1T": None, "G2E4S": 0.4, "G2E4T": 0.5},
        mtf50_lp_per_mm={"E0L": 91.4, "E0R": None, "E0T": 88.0, "E0B": 90.0},
        peaks={"G0E1S": 0.8, "G2E4S": 0.6}, history=[60.0, 80.0],
        status="4 sets, 20.0 readings/s", summary_now=80.0, summary_peak=82.5)
    lines = render_focus_aid(view, 30).plain.splitlines()
    assert lines[0] == "4 sets, 20.0 readings/s"
    assert lines[1].startswith("G0E1 S") and lines[2].startswith("G2E4 S")
    assert " T" in lines[1] and all(len(line) <= 30 for line in lines)
    assert lines[4] == "E0 L 91 R  - T 88 B 90"
    assert lines[5] == "mean MTF50 80.0 peak 82.5"
    assert lines[6] == "\u2581\u2588"
    # no current reading: the status and the history only, never bars of an older frame
    gone = FocusAidView({}, {}, peaks={"G0E1S": 0.8}, history=[60.0, 80.0],
                        status="chart not found")
    assert render_focus_aid(gone, 30).plain.splitlines() == ["chart not found", "\u2581\u2588"]


def test_frame_slot_keeps_the_newest_frame_and_counts_the_dropped() -> None:
    slot = FrameSlot()
    assert slot.take(timeout_s=0.01) is None
    for k in range(3):
        slot.offer(np.full((2, 2), k))
    frame = slot.take(timeout_s=0.01)
    assert frame is not None and frame[0, 0] == 2
    assert slot.offered == 3 and slot.dropped == 2
    assert slot.take(timeout_s=0.01) is None  # taken: nothing queued behind it
    got: list[object] = []
    reader = threading.Thread(target=lambda: got.append(slot.take(timeout_s=5.0)))
    reader.start()
    slot.offer(np.zeros((1, 1)))  # wakes a waiting reader
    reader.join(5.0)
    assert got and got[0] is not None
