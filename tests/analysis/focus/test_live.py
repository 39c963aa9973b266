"""The live focus aid: the whole chart read per frame with the pose tracked; peak hold."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.analysis.chart.finder import ChartNotFoundError
from benchlab.analysis.focus.live import ChartTracker, PeakHold
from benchlab.bench import Bench, BenchConfig
from benchlab.scenes.usaf import UsafScene


@pytest.fixture(scope="module")
def frame() -> np.ndarray:
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True, seed=1) as bench:
        bench.configure_camera(bits=8)
        bench.mount("usaf")
        return bench.grab(exposure_ms=300.0, gain=1.0)[0]


@pytest.mark.slow
def test_the_chart_is_found_once_then_tracked(frame: np.ndarray) -> None:
    tracker = ChartTracker(refind_every=3)
    found = [tracker.read(frame).refound for _ in range(7)]
    assert found == [True, False, False, True, False, False, True]
    r = tracker.read(frame)
    # a coarse set (many pixels per period): the histogram peaks read it as the scene made it
    truth = UsafScene().truth_modulation(0, 1, "sagittal")
    assert len(r.modulation) == 32 and r.modulation["G0E1S"] == pytest.approx(truth, abs=0.02)
    assert len(r.edge_mtf50_lp_per_mm) == 12
    assert all(v is not None and 40 < v < 192 for v in r.edge_mtf50_lp_per_mm.values())


def test_a_frame_without_the_chart_is_an_error_and_forgets_the_pose() -> None:
    tracker = ChartTracker()
    with pytest.raises(ChartNotFoundError):
        tracker.read(np.full((1024, 1280), 20, np.uint8))
    assert tracker.fit is None
    with pytest.raises(ValueError, match="refind_every"):
        ChartTracker(refind_every=0)


def test_peak_hold_keeps_the_best_and_the_history() -> None:
    hold = PeakHold(history=3)
    for v in (0.2, 0.6, 0.5, None, 0.4):
        hold.update({"G2E4S": v})
    assert hold.peaks["G2E4S"] == 0.6
    assert list(hold.series["G2E4S"]) == [0.6, 0.5, 0.4]
    assert hold.fraction_of_peak("G2E4S") == pytest.approx(0.4 / 0.6)
    assert hold.fraction_of_peak("G3E1T") is None


def test_mean_edge_mtf50_leaves_out_refused_edges_and_says_none_when_all_are() -> None:
    from benchlab.analysis.focus.live import LiveReading, mean_edge_mtf50

    reading = LiveReading({}, {"E0L": 60.0, "E0R": None, "E0T": 90.0}, False, 0.0)
    assert mean_edge_mtf50(reading) == 75.0
    assert mean_edge_mtf50(LiveReading({}, {"E0L": None}, False, 0.0)) is None


def test_nothing_read_only_when_no_set_and_no_edge_gave_a_value() -> None:
    from benchlab.analysis.focus.live import LiveReading, nothing_read

    assert nothing_read(LiveReading({"G0E1S": None}, {"E0L": None}, False, 0.0))
    assert not nothing_read(LiveReading({"G0E1S": 0.2}, {"E0L": None}, False, 0.0))
    assert not nothing_read(LiveReading({"G0E1S": None}, {"E0L": 12.0}, False, 0.0))
