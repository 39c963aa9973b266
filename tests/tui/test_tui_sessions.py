"""Sessions browser: an interrupted run is listed, resumed, re-analysed and reported."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_tui_helpers import connected, make_app, wait_until
from textual.widgets import DataTable

from benchlab.session import Session
from benchlab.tui.dialogs import PromptDialog
from benchlab.tui.runner import RunScreen
from benchlab.tui.sessions import SessionsScreen

TINY_MTF = """\
procedure = "mtf"
[focus]
frames = 1
[forward]
elements = ["G2E1"]
[radial]
frequencies_lp_per_mm = [2]
"""


@pytest.mark.slow
@pytest.mark.asyncio
async def test_interrupted_run_resumed_reanalysed_and_reported(tmp_path: Path) -> None:
    app = make_app(tmp_path, mtf=TINY_MTF)
    async with app.run_test(size=(110, 32)) as pilot:
        await connected(pilot)
        await pilot.press("3")
        run = app.screen
        assert isinstance(run, RunScreen)
        await wait_until(pilot, lambda: len(run.step_status) == 10, what="checklist")
        await pilot.press("s")
        # confirm the set-up prompt, then abort at the second manual step ("thread the lens")
        await wait_until(pilot, lambda: isinstance(app.screen, PromptDialog), what="prompt 1")
        await pilot.press("y")
        await wait_until(
            pilot, lambda: isinstance(app.screen, PromptDialog) and "Thread" in str(
                app.screen.query_one("#prompt-text").render()), what="prompt 2",
        )
        await pilot.press("a")
        await wait_until(pilot, lambda: run.state == "aborted", what="abort")
        path = run.session_path
        assert path is not None and Session.open(path).completed_steps() == {"setup"}

        await pilot.press("4")
        sessions = app.screen
        assert isinstance(sessions, SessionsScreen)
        await wait_until(pilot, lambda: len(sessions.sessions) == 1, what="listing")
        listing = sessions.query_one("#session-list", DataTable)
        row = [str(c) for c in listing.get_row_at(0)]
        assert row[:2] == [path.name, "mtf"] and row[2] != "completed"
        assert row[2] == Session.open(path).status  # what the store says (aborted)

        await pilot.press("u")  # resume: back to the runner, from "thread"
        # (the runner screen shows the old "aborted" state for a moment while it switches)
        await wait_until(pilot, lambda: run.state in ("done", "failed"),
                         answer_prompts=True, what="resumed run")
        assert run.state == "done", run.message
        assert run.session_path == path
        assert Session.open(path).status == "completed"
        assert Session.open(path).result_versions() == [1]

        await pilot.press("4")
        await wait_until(pilot, lambda: "completed" in [s.status for s in sessions.sessions],
                         what="relisting")
        await pilot.press("enter")
        await wait_until(pilot, lambda: sessions.opened == path, what="open")
        detail = sessions.query_one("#session-table", DataTable)
        await wait_until(pilot, lambda: detail.row_count > 0, what="results table")

        first = sessions.estimator
        await pilot.press("m")
        assert sessions.estimator != first
        await pilot.press("n")
        await wait_until(pilot, lambda: Session.open(path).result_versions() == [1, 2],
                         what="re-analysis")
        summary = json.loads((path / "results" / "v2" / "summary.json").read_text())
        assert sessions.estimator in json.dumps(summary)

        await pilot.press("w")
        await wait_until(pilot, lambda: any(path.rglob("*.html")), what="report")
        html = next(path.rglob("*.html")).read_text(encoding="utf-8")
        assert "<html" in html.lower()
