"""The TUI Run screen offers the characterisation and runs it on the simulated bench."""

from __future__ import annotations

import pytest
from sim_runs import TINY
from test_tui_helpers import connected, make_app, wait_until

from benchlab.session import Session
from benchlab.tui.runner import RunScreen


@pytest.mark.slow
@pytest.mark.asyncio
async def test_characterise_run_through_the_ui(tmp_path) -> None:
    app = make_app(tmp_path, characterise=TINY)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        await pilot.press("3", "p", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "characterise"
        await wait_until(pilot, lambda: len(screen.step_status) == 3, what="checklist")
        await pilot.press("s")
        prompts = await wait_until(
            pilot, lambda: screen.state != "running", answer_prompts=True, what="run end"
        )
        assert screen.state == "done", screen.message
        assert prompts == 1  # the uniform-illumination set-up
        session = Session.open(screen.session_path)
        assert session.status == "completed"
        assert "sweep-g1-b12" in session.completed_steps()
        bench = app.bench
        assert all(bench.sim_led.channel_output_ma(ch) == 0
                   for ch in range(1, bench.sim_led.channel_count + 1))
