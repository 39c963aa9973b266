"""Issue 30: UI updates that race a dialog (or fail outright) never decide a step's outcome.

The run's thread sends the back-focus sharpness to the prompt dialog while the dialog may not
be composed yet or may have been dismissed a moment ago. These tests deliver the figure at
exactly those moments, through the runner's own path, and check the run completes.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from test_tui_helpers import (
    MTF_PARAMS,
    RADIOMETRY_PARAMS,
    connected,
    make_app,
    wait_until,
)
from textual.app import App
from textual.widgets import DataTable, Static

from benchlab.session import Session, read_results
from benchlab.tui import runner as runner_module
from benchlab.tui.dialogs import PromptDialog
from benchlab.tui.runner import RunScreen


def _figure_text(dialog: PromptDialog) -> str:
    return str(dialog.query_one("#live-figure", Static).render())


@pytest.mark.asyncio
async def test_live_figure_before_mount_is_kept_and_after_dismiss_dropped() -> None:
    app: App[None] = App()
    async with app.run_test() as pilot:
        answers: list[bool | None] = []
        dialog = PromptDialog("Step 3: focus", "Turn the back focus.")
        assert not dialog.set_live_figure("sharpness now: 1.5")  # not composed: kept
        app.push_screen(dialog, callback=answers.append)
        await wait_until(pilot, lambda: dialog.is_mounted, what="dialog mounted")
        assert _figure_text(dialog) == "sharpness now: 1.5"
        assert dialog.set_live_figure("sharpness now: 2.25")
        assert _figure_text(dialog) == "sharpness now: 2.25"
        await pilot.press("y")
        await wait_until(pilot, lambda: not dialog.is_attached, what="dialog removed")
        assert answers == [True]
        assert not dialog.set_live_figure("sharpness now: 3")  # dismissed: dropped, no error
        assert app.screen is not dialog


class _RacedPrompt(PromptDialog):
    """A prompt dialog that records each live figure sent to it and whether it was shown."""

    made: list[_RacedPrompt] = []
    #: Called with each new dialog, in the thread that makes it (the run's), before it is shown.
    on_create: Callable[[_RacedPrompt], None] | None = None

    def __init__(self, title: str, message: str) -> None:
        super().__init__(title, message)
        self.deliveries: list[tuple[str, bool]] = []
        self.shown_at_mount = ""
        self.before_mount: list[tuple[str, bool]] = []
        self.unmounted = threading.Event()
        _RacedPrompt.made.append(self)
        if _RacedPrompt.on_create is not None:
            _RacedPrompt.on_create(self)

    def on_mount(self) -> None:  # (Textual calls PromptDialog.on_mount as well)
        self.shown_at_mount = _figure_text(self)
        self.before_mount = list(self.deliveries)

    def on_unmount(self) -> None:
        self.unmounted.set()

    def set_live_figure(self, text: str) -> bool:
        shown = super().set_live_figure(text)
        self.deliveries.append((text, shown))
        return shown


@pytest.mark.slow
@pytest.mark.asyncio
async def test_focus_figure_before_mount_and_after_dismiss_the_run_completes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    _RacedPrompt.made = []
    monkeypatch.setattr(runner_module, "PromptDialog", _RacedPrompt)
    app = make_app(tmp_path, mtf=MTF_PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        await pilot.press("3")
        screen = app.screen
        assert isinstance(screen, RunScreen)
        await wait_until(pilot, lambda: len(screen.step_status) == 14, what="checklist")
        real_prompt = screen._prompt_operator
        focus_dialogs: list[_RacedPrompt] = []

        def racing_prompt(step: Any, message: str) -> bool:
            """The runner's prompt, with the sharpness sent (from the run's thread, as the
            runner sends it) before the dialog is shown and after it is gone."""
            if step.kind != "focus":
                return real_prompt(step, message)
            # the early figure: sent to the runner's dialog after it is made, before it is shown
            _RacedPrompt.on_create = screen._update_focus_figure
            try:
                answer = real_prompt(step, message)
            finally:
                _RacedPrompt.on_create = None
            dialog = _RacedPrompt.made[-1]
            assert dialog.unmounted.wait(30), "the dismissed dialog was never removed"
            screen._update_focus_figure(dialog)  # the late figure of issue 30
            focus_dialogs.append(dialog)
            return answer

        screen._prompt_operator = racing_prompt  # type: ignore[method-assign]
        await pilot.press("s")
        prompts = await wait_until(pilot, lambda: screen.state != "running",
                                   answer_prompts=True, what="run end")
        assert screen.state == "done", screen.message
        assert prompts == 8
        (dialog,) = focus_dialogs
        first, last = dialog.deliveries[0], dialog.deliveries[-1]
        assert first[0].startswith("sharpness now: ") and not first[1]  # before compose: kept
        # ... and shown once the dialog is (the newest figure by then: on a loaded CPU the
        # runner's own 4 Hz updates may also come before the mount)
        assert dialog.before_mount[0] == first
        assert dialog.shown_at_mount == dialog.before_mount[-1][0]
        assert last[0].startswith("sharpness now: ") and not last[1]  # after dismiss: dropped
        assert set(screen.step_status.values()) == {"done"}
        session = Session.open(screen.session_path)
        assert session.status == "completed"
        assert "focus" in session.completed_steps()
        latest = session.latest_results()
        assert latest is not None
        tables = read_results(latest)[0]
        forward = tables["table_4_11"]
        forward_rows = forward["rows"] if isinstance(forward, dict) else forward
        assert {str(r.get("element")) for r in forward_rows} >= {"G2E1", "G2E4"}
        shown = screen.query_one("#results-table", DataTable)
        assert shown.row_count == len(forward_rows)


@pytest.mark.slow
@pytest.mark.asyncio
async def test_a_failing_display_update_does_not_fail_the_step(
    tmp_path: Path, caplog: pytest.LogCaptureFixture,
) -> None:
    app = make_app(tmp_path, radiometry=RADIOMETRY_PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        await pilot.press("3", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "radiometry"
        await wait_until(pilot, lambda: len(screen.step_status) == 4, what="checklist")

        def broken_display(*_: Any) -> None:
            raise RuntimeError("the results panel is broken")

        screen._add_result = broken_display  # type: ignore[method-assign]
        with caplog.at_level(logging.WARNING, logger="benchlab.tui.ui_calls"):
            await pilot.press("s")
            await wait_until(pilot, lambda: screen.state != "running", answer_prompts=True,
                             what="run end")
        assert screen.state == "done", screen.message
        assert not app.procedure_running
        assert set(screen.step_status.values()) == {"done"}
        dropped = [r.getMessage() for r in caplog.records if "dropped" in r.getMessage()]
        assert len(dropped) == 2 and all("results panel is broken" in m for m in dropped)
        session = Session.open(screen.session_path)
        assert session.status == "completed"
        latest = session.latest_results()
        assert latest is not None
        rows = read_results(latest)[0]["table_4_16"]
        rows = rows["rows"] if isinstance(rows, dict) else rows
        assert [r["position_mm"] for r in rows] == [15, 25]
        # the final table is still shown: it does not depend on the broken live updates
        assert screen.query_one("#results-table", DataTable).row_count == 2
