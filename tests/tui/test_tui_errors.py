"""Errors become dialogs in plain words: a bad parameter file, a device fault mid-run."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_tui_helpers import RADIOMETRY_PARAMS, connected, make_app, wait_until
from textual.widgets import Static

from benchlab.session import Session
from benchlab.tui.dialogs import ErrorDialog, PromptDialog
from benchlab.tui.runner import RunScreen

BAD_MTF = """\
procedure = "mtf"
[camera]
exposure_ms = -5
[radial]
frequencies_lp_per_mm = [1, "two"]
"""


@pytest.mark.slow
@pytest.mark.asyncio
async def test_bad_parameter_file_lists_every_problem_and_starts_nothing(tmp_path: Path) -> None:
    app = make_app(tmp_path, mtf=BAD_MTF)
    async with app.run_test(size=(100, 30)) as pilot:
        await connected(pilot)
        await pilot.press("3")
        run = app.screen
        assert isinstance(run, RunScreen)
        await wait_until(pilot, lambda: "problem" in run.message, what="params message")
        assert "camera.exposure_ms" in run.message and "radial.frequencies" in run.message
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, ErrorDialog), what="dialog")
        text = str(app.screen.query_one("#error-text", Static).render())
        assert "camera.exposure_ms" in text and "radial.frequencies" in text
        assert run.state != "running" and run.session_path is None
        assert not (tmp_path / "sessions").exists() or not any((tmp_path / "sessions").iterdir())
        await pilot.press("enter")
        assert app.screen is run


@pytest.mark.slow
@pytest.mark.asyncio
async def test_device_fault_mid_run_shows_a_dialog_and_retry_completes(tmp_path: Path) -> None:
    app = make_app(tmp_path, radiometry=RADIOMETRY_PARAMS)
    async with app.run_test(size=(100, 30)) as pilot:
        await connected(pilot)
        bench = app.bench
        await pilot.press("3", "p")
        run = app.screen
        assert isinstance(run, RunScreen)
        await wait_until(pilot, lambda: len(run.step_status) == 4, what="checklist")
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, PromptDialog), what="prompt")
        bench.sim_led.faults.exec_error = 1  # the controller refuses the next command
        await pilot.press("y")
        await wait_until(pilot, lambda: run.state != "running", what="failure")
        assert run.state == "failed"
        failed = [sid for sid, st in run.step_status.items() if st == "failed"]
        assert len(failed) == 1 and failed[0] != "setup"  # the first position step
        await wait_until(pilot, lambda: isinstance(app.screen, ErrorDialog), what="dialog")
        text = str(app.screen.query_one("#error-text", Static).render())
        assert "unexpected reply" in text  # plain words first, then the detail
        assert bench.sim_led.channel_output_ma(1) == 0
        await pilot.press("enter")
        await pilot.press("t")
        await wait_until(pilot, lambda: run.state != "running", answer_prompts=True,
                         what="retry")
        assert run.state == "done", run.message
        session = Session.open(run.session_path)
        assert session.status == "completed"
        assert len(list(session.frames_dir.glob("*.tiff"))) == 4
