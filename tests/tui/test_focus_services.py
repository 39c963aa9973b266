"""services.read_focus on simulated frames: a reading, the chart not found, the chart gone from
a tracked pose (said at once, not read as bars for the frames until the next find)."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.bench import Bench, BenchConfig
from benchlab.tui import services


@pytest.fixture(scope="module")
def frames() -> dict[str, np.ndarray]:
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True, seed=3) as bench:
        out = {}
        for target in ("usaf", "dark"):
            bench.mount(target)
            out[target] = bench.grab(exposure_ms=300.0, gain=1.0, fresh=True)[0]
        return out


def test_read_focus_reads_says_not_found_and_drops_a_lost_tracked_chart(
        frames: dict[str, np.ndarray]) -> None:
    tracker = services.focus_tracker()
    reading, mean, why = services.read_focus(tracker, frames["usaf"])
    assert reading is not None and why == ""
    edges = [v for v in reading.edge_mtf50_lp_per_mm.values() if v is not None]
    assert mean == pytest.approx(sum(edges) / len(edges)) and 40.0 < mean < 120.0
    assert tracker.fit is not None  # tracked: the next frame is read at this pose
    reading, mean, why = services.read_focus(tracker, frames["dark"])
    assert reading is None and mean is None
    assert why.startswith("chart not found: nothing read")
    assert tracker.fit is None  # looked for again on the next frame
    reading, mean, why = services.read_focus(tracker, frames["dark"])
    assert reading is None and why.startswith("chart not found: no three-bar sets")
    reading, _, _ = services.read_focus(tracker, frames["usaf"])
    assert reading is not None  # back as soon as the chart is
