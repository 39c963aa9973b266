"""The run screen with a unit and a spec: serial and lot stored at the start, the verdicts
in the results panel and the unit verdict in the status when the run ends."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_tui_helpers import RADIOMETRY_PARAMS, connected, make_app, wait_until
from textual.widgets import DataTable, Input

from benchlab.acceptance.store import read_verdict
from benchlab.tui.dialogs import ErrorDialog, InputDialog
from benchlab.tui.runner import RunScreen

SPEC = """format = "benchlab.spec"
version = 1
name = "falloff spec"
decision_rule = "simple"

[[limit]]
id = "centre"
table = "relative_radiometry"
where = { position_mm = 15 }
column = "measured_normalised"
min = 0.9

[[limit]]
id = "edge"
table = "relative_radiometry"
where = { position_mm = 25 }
column = "measured_normalised"
min = 0.01
decision_rule = "guarded"
"""


async def _answer(pilot: object, text: str) -> None:
    app = pilot.app  # type: ignore[attr-defined]
    await wait_until(pilot, lambda: isinstance(app.screen, InputDialog),  # type: ignore[arg-type]
                     what="input dialog")
    app.screen.query_one("#value", Input).value = text
    await pilot.press("enter")  # type: ignore[attr-defined]


@pytest.mark.slow
@pytest.mark.asyncio
async def test_run_with_unit_and_spec_shows_the_verdicts(tmp_path: Path) -> None:
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC, encoding="utf-8")
    bad = tmp_path / "bad.toml"
    bad.write_text('format = "benchlab.spec"\nversion = 9\n', encoding="utf-8")
    app = make_app(tmp_path, radiometry=RADIOMETRY_PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        await pilot.press("3", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "radiometry"
        await wait_until(pilot, lambda: len(screen.step_status) == 4, what="checklist")
        await pilot.press("n")
        await _answer(pilot, "OBJ-7")
        await _answer(pilot, "W48")
        await pilot.press("k")
        await _answer(pilot, str(bad))  # refused with its problems; no spec chosen
        await wait_until(pilot, lambda: isinstance(app.screen, ErrorDialog), what="error")
        await pilot.press("escape")
        assert screen.spec_file is None
        await pilot.press("k")
        await _answer(pilot, str(spec))
        assert (screen.unit_serial, screen.unit_lot, screen.spec_file) == ("OBJ-7", "W48", spec)
        await pilot.press("s")
        await wait_until(pilot, lambda: screen.state != "running", answer_prompts=True,
                         what="run end")
        assert screen.state == "done", screen.message
        assert screen.session_path is not None
        meta = json.loads((screen.session_path / "session.json").read_text())
        assert (meta["sample"], meta["lot"]) == ("OBJ-7", "W48")
        record = read_verdict(screen.session_path)
        # the edge limit has no uncertainty column: guarded cannot decide it
        assert record["limits"] == {"centre": "pass", "edge": "indeterminate"}
        assert "Unit verdict: INDETERMINATE" in screen.message
        table = screen.query_one("#results-table", DataTable)
        assert screen.query_one("#results").border_title.startswith("acceptance")
        rows = [[str(c) for c in table.get_row_at(i)] for i in range(table.row_count)]
        assert [(r[0], r[-1]) for r in rows] == [("centre", "pass*"), ("edge", "indeterminate")]
