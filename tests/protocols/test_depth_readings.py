"""One sweep position read at its own magnification: edges placed by the found chart, or by the
scale the other positions give when the chart is not found."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.drivers.sensor import AcquisitionState
from benchlab.protocols.depth.readings import read_position
from benchlab.scenes.focus import ThroughFocusLens
from benchlab.scenes.world import SimWorld

LENS = ThroughFocusLens()


def _frame(target: str, distance_mm: float) -> np.ndarray:
    world = SimWorld(target, through_focus=LENS)
    st = AcquisitionState(exposure_ms=300.0, gain=1.0, bits=8, width=1280, height=1024,
                          time_s=0.0, frame_index=0,
                          bench={"object_offset_mm": distance_mm, "stage_position_mm": 0.0})
    rate = world(st)
    noise = np.random.default_rng(3).normal(0.0, 1.0, rate.shape)  # ~1 DN, as the camera's
    return np.round(20.0 + 170.0 * rate / rate.max() + noise)  # the chart's 20 / 190 levels


@pytest.mark.slow
def test_edges_are_read_where_the_found_chart_puts_them() -> None:
    z = 70.0
    r = read_position(_frame("usaf", z), (35.0,), full_scale=255.0, read_bars=True)
    assert r.scale == pytest.approx(LENS.scale_at(z), rel=0.01)
    ok = [e for e in r.edges if e.status == "ok"]
    # E0T's side is ~25 px long at this scale, 5 deg off the axis: the SFR may refuse it
    assert len(r.edges) == 12 and len(ok) >= 11
    assert r.chart and all(c["image_lp_per_mm"] > 0 for c in r.chart)


def test_without_a_chart_the_edges_follow_the_fallback_scale() -> None:
    z = 70.0
    frame = _frame("edge", z)  # the slanted-edge squares alone: nothing for the finder
    r = read_position(frame, (35.0,), full_scale=255.0, read_bars=False)
    assert r.scale is None and not r.edges and r.chart_status.startswith("chart not found")
    r = read_position(frame, (35.0,), full_scale=255.0, read_bars=False,
                      fallback_scale=LENS.scale_at(z))
    assert len(r.edges) == 12 and sum(e.status == "ok" for e in r.edges) >= 11
