"""Abort from the keyboard mid-run: LEDs off, stage stopped, session resumable; then retry."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest
from test_tui_helpers import connected, make_app, wait_until
from textual.widgets import DataTable

from benchlab.session import Session
from benchlab.tui.dialogs import ConfirmDialog
from benchlab.tui.runner import RunScreen

PARAMS = """\
procedure = "radiometry"
[positions]
field_mm = [15, 20, 25]
[analysis]
simulated_irradiance_mw_per_mm2 = [22.48, 19.40, 14.34]
"""


@pytest.mark.slow
@pytest.mark.asyncio
async def test_abort_key_leaves_leds_off_and_stage_stopped_then_retry_completes(
    tmp_path: Path,
) -> None:
    app = make_app(tmp_path, radiometry=PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        bench = app.bench
        # Hold the runner inside the second position, with its LED lit, until abort is pressed.
        in_position = threading.Event()
        real_grab = bench.grab
        grabs = 0

        def grab(**kwargs: Any) -> Any:
            nonlocal grabs
            grabs += 1
            frame = real_grab(**kwargs)
            if grabs == 3:  # position 2, mask frame taken, LED on
                in_position.set()
                app.abort_event.wait(30)
            return frame

        bench.grab = grab
        await pilot.press("3", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen)
        await wait_until(pilot, lambda: len(screen.step_status) == 5, what="checklist")
        await pilot.press("s")
        await wait_until(pilot, in_position.is_set, answer_prompts=True, what="position 2")
        assert bench.sim_led.channel_output_ma(1) > 0  # the LED really is on now
        assert screen.step_status["setup"] == "done"
        await pilot.press("a")
        await wait_until(pilot, lambda: screen.state != "running", what="abort")

        assert screen.state == "aborted"
        assert all(bench.sim_led.channel_output_ma(ch) == 0
                   for ch in range(1, bench.sim_led.channel_count + 1))
        assert not bench.stage.status.is_moving
        assert "LEDs off" in screen.message
        session = Session.open(screen.session_path)
        assert session.status != "completed"  # not finished: resumable
        kinds = [e.get("kind") or e.get("event") for e in session.events()]
        assert "aborted" in kinds
        done = session.completed_steps()
        assert "setup" in done and len(done) == 2  # set-up and the first position
        assert len(list(session.frames_dir.glob("*.tiff"))) == 3  # nothing half-written

        # Retry continues from the first incomplete step; nothing is acquired twice.
        bench.grab = real_grab
        await pilot.press("t")
        await wait_until(pilot, lambda: screen.state != "running", answer_prompts=True,
                         what="retry end")
        assert screen.state == "done", screen.message
        session = Session.open(screen.session_path)
        assert session.status == "completed"
        assert len(list(session.frames_dir.glob("*.tiff"))) == 6
        table = screen.query_one("#results-table", DataTable)
        assert table.row_count == 3


@pytest.mark.slow
@pytest.mark.asyncio
async def test_quit_mid_run_stops_workers_and_leaves_the_bench_safe(tmp_path: Path) -> None:
    app = make_app(tmp_path, radiometry=PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        bench = app.bench
        in_position = threading.Event()
        real_grab = bench.grab

        def grab(**kwargs: Any) -> Any:
            frame = real_grab(**kwargs)
            in_position.set()  # first mask frame taken, LED lit
            app.abort_event.wait(30)
            return frame

        bench.grab = grab
        await pilot.press("3", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen)
        await wait_until(pilot, lambda: len(screen.step_status) == 5, what="checklist")
        await pilot.press("s")
        await wait_until(pilot, in_position.is_set, answer_prompts=True, what="LED on")
        assert bench.sim_led.channel_output_ma(1) > 0
        await pilot.press("q")  # a run is active: asks first, changes nothing yet
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="confirm")
        assert not app.abort_event.is_set() and app.bench is not None
        await pilot.press("n")  # keep running
        await wait_until(pilot, lambda: app.screen is screen, what="back to the run")
        assert not app.abort_event.is_set() and app.procedure_running
        assert bench.sim_led.channel_output_ma(1) > 0
        await pilot.press("q")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="confirm")
        await pilot.press("q")  # q again confirms
        await wait_until(pilot, lambda: app.bench is None, what="bench closed")
    assert app._active_threads == 0  # every device thread wound down before the bench closed
    assert bench.sim_led.channel_output_ma(1) == 0
    assert not any(w.is_running for w in app.workers)
    session = Session.open(screen.session_path)
    assert session.status != "completed" and "setup" in session.completed_steps()
