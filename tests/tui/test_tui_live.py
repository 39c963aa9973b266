"""Live view on the simulated camera: frames keep coming, keys move the ROI and settings."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_tui_helpers import make_app, open_live, wait_until
from textual.widgets import Static

from benchlab.tui.widgets import UPPER_HALF, FrameView


@pytest.mark.slow
@pytest.mark.asyncio
async def test_live_view_streams_and_obeys_keys(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        live = await open_live(pilot, 5)
        view = live.query_one(FrameView)
        lines = [view.render_line(y).text for y in range(view.size.height)]
        assert sum(line.count(UPPER_HALF) for line in lines) > 500
        assert live.exposure_ms == 300.0 and live.gain == 1.0

        start = live.roi
        # (each key costs the pilot up to 2 s here: it waits for an idle CPU, and the
        # stream keeps the CPU busy; in a terminal keys are handled at once)
        await pilot.press("right", "plus", "E", "G")
        assert live.roi != start and live.roi.height > start.height
        assert live.exposure_ms == 375.0 and live.gain == 2.0
        assert app.bench.mounted == "usaf"  # the simulated bench shows the forward chart
        # the newest frame carries the new settings and ROI (reading taken in the worker)
        shown = live.frames_displayed

        def caught_up() -> bool:
            r = live._latest
            return (live.frames_displayed > shown + 2 and r is not None
                    and r.exposure_ms == 375.0 and r.gain == 2.0 and r.roi == live.roi)

        await wait_until(pilot, caught_up, what="new settings in the stream")
        readout = str(live.query_one("#readout", Static).render())
        assert "exposure 375 ms  gain 2" in readout
        assert f"(r{live.roi.row}, c{live.roi.col})" in readout
        assert "sharpness" in readout and "clipped" in readout

        # leaving the screen stops acquisition; coming back resumes it
        await pilot.press("1")

        def stopped() -> bool:  # the display timer stopped and the acquisition thread ended
            return live._timer is None and not any(
                w.group == "live" and not w.is_finished for w in app.workers)

        await wait_until(pilot, stopped, what="acquisition stopped")
        stopped_at = live.frames_displayed
        await pilot.pause(0.3)  # an observation window: nothing is left to show a frame
        assert live.frames_displayed == stopped_at
        await pilot.press("2")
        await wait_until(pilot, lambda: live.frames_displayed > stopped_at + 2, what="resume")
