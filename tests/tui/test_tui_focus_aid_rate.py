"""The focus-aid rate command of the docs runs and counts what the panel showed."""

from __future__ import annotations

import pytest

from benchlab.tui.bench_rate import focus_aid_rate


@pytest.mark.slow
@pytest.mark.asyncio
async def test_focus_aid_rate_counts_readings_of_the_whole_chart() -> None:
    r = await focus_aid_rate(1.0, (100, 30))
    assert r["sets"] == 32  # every set of the simulated chart read
    # never more readings than frames (give or take one offered before the 1 s window)
    assert 0 < r["readings_per_s"] <= r["frames_per_s"] + 1.5
    assert 0.0 <= r["dropped_fraction"] < 1.0 and r["cpu_per_s"] > 0
