"""Abort a depth-of-field sweep from the keyboard mid-position, then retry: the stage is
stopped and the LEDs off, and no position is taken twice."""

from __future__ import annotations

import threading
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from sim_runs import events
from test_tui_depth import DEPTH_PARAMS
from test_tui_helpers import connected, make_app, wait_until

from benchlab.session import Session
from benchlab.tui.runner import RunScreen


@pytest.mark.slow
@pytest.mark.asyncio
async def test_abort_mid_sweep_then_retry_repeats_no_position(tmp_path: Path) -> None:
    app = make_app(tmp_path, depth=DEPTH_PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        bench = app.bench
        # Hold the runner inside the third position (56 mm: the stage at 56 - 51 mm, segment 0
        # mounted 51 mm out) until abort. Told by the stage, not by counting grabs: the set-up
        # prompt grabs frames for its live figure as long as it is up.
        in_position = threading.Event()
        real_grab = bench.grab

        def grab(**kwargs: Any) -> Any:
            frame = real_grab(**kwargs)
            if abs(bench.sim_stage.position_mm - 5.0) < 0.01 and not in_position.is_set():
                in_position.set()
                app.abort_event.wait(30)
            return frame

        bench.grab = grab
        await pilot.press("3", "p", "p", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "depth"
        await wait_until(pilot, lambda: len(screen.step_status) == 15, what="checklist")
        await pilot.press("s")
        await wait_until(pilot, in_position.is_set, answer_prompts=True, what="position 3")
        await pilot.press("a")
        await wait_until(pilot, lambda: screen.state != "running", what="abort")
        assert screen.state == "aborted", screen.message
        assert not bench.sim_stage.moving
        assert all(bench.sim_led.channel_output_ma(ch) == 0
                   for ch in range(1, bench.sim_led.channel_count + 1))
        session = Session.open(screen.session_path)
        assert session.status != "completed"
        # the held position had its one frame: it completes, the sweep stops after it
        assert session.completed_steps() == {"setup", "mount-0", "s0-z52", "s0-z54", "s0-z56"}
        assert len(list(session.frames_dir.glob("*.tiff"))) == 3

        bench.grab = real_grab
        await pilot.press("t")
        await wait_until(pilot, lambda: screen.state != "running", answer_prompts=True,
                         what="retry end")
        assert screen.state == "done", screen.message
        evs = events(screen.session_path)
        done = Counter(e["step_id"] for e in evs if e["kind"] == "step_completed")
        assert max(done.values()) == 1 and len(done) == 15
        saved = Counter(e["file"] for e in evs if e["kind"] == "frame_saved")
        assert len(saved) == 11 and max(saved.values()) == 1
        assert Session.open(screen.session_path).status == "completed"
