"""Every procedure readable in an 80x24 terminal: what the screen shows, as text.

The checklist gives each step a unique number and its whole description (wrapped, never cut);
after a depth-of-field run the digest shows best focus and the DOF ends within the 80 columns;
the prompt buttons show their keys.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from screen_text import screen_text
from test_tui_depth import DEPTH_PARAMS
from test_tui_helpers import MTF_PARAMS, RADIOMETRY_PARAMS, connected, make_app, wait_until
from textual.pilot import Pilot
from textual.widgets import DataTable

from benchlab.tui.depth_summary import depth_summary_rows
from benchlab.tui.dialogs import PromptDialog
from benchlab.tui.runner import PROCEDURES, RunScreen
from benchlab.tui.services import procedure_checklist, table_rows

SIZE = (80, 24)


def _steps_panel(lines: list[str]) -> tuple[list[str], str]:
    """The checklist panel's rows (left of the first inner border) and its "what" column's
    text, its wrapped lines joined."""
    top = next(i for i, line in enumerate(lines) if line.startswith("\u256d"))
    right = lines[top].index("\u256e")
    rows = [line[1:right] for line in lines[top + 1:] if line.startswith("\u2502")]
    at = rows[0].index("what")
    what = " ".join(r[at:].strip() for r in rows[1:] if r[at:].strip())
    what = re.sub("[\u2580-\u259f]", " ", what)  # a scrollbar's blocks are not text
    return rows, re.sub(r"\s+", " ", what)


async def _checklist(pilot: Pilot[None], screen: RunScreen, n: int) -> None:
    await wait_until(pilot, lambda: len(screen.step_status) == n, what="checklist")
    await pilot.pause()
    await pilot.pause()


@pytest.mark.slow
@pytest.mark.asyncio
async def test_every_procedures_checklist_is_readable_at_80x24(tmp_path: Path) -> None:
    app = make_app(tmp_path, mtf=MTF_PARAMS, radiometry=RADIOMETRY_PARAMS, depth=DEPTH_PARAMS)
    async with app.run_test(size=SIZE) as pilot:
        await connected(pilot)
        await pilot.press("3")
        screen = app.screen
        assert isinstance(screen, RunScreen)
        for i, procedure in enumerate(PROCEDURES):
            if i:
                await pilot.press("p")
            assert screen.procedure == procedure
            steps = procedure_checklist(procedure, app.params_files.get(procedure))
            await _checklist(pilot, screen, len(steps))
            lines = screen_text(app)
            assert all(len(line) <= SIZE[0] for line in lines)
            rows, what = _steps_panel(lines)
            numbers = [m.group(1) for r in rows if (m := re.match(r"^ ..\s*(\d+) ", r))]
            assert numbers == [str(k) for k in range(1, len(numbers) + 1)], (procedure, rows)
            assert len(numbers) >= min(5, len(steps)), rows  # five steps in view, or all
            # every step in view has its whole description (the last may be scrolled off)
            for step in steps[: len(numbers) - 1]:
                assert step.title in what, (procedure, step.title, what)


@pytest.mark.slow
@pytest.mark.asyncio
async def test_depth_run_at_80x24_shows_the_dof_ends_and_keyed_buttons(tmp_path: Path) -> None:
    app = make_app(tmp_path, depth=DEPTH_PARAMS)
    async with app.run_test(size=SIZE) as pilot:
        await connected(pilot)
        await pilot.press("3", "p", "p", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "depth"
        await _checklist(pilot, screen, 15)
        with app.device_lock:
            app.bench.mount("usaf")
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, PromptDialog), what="prompt")
        await pilot.pause()
        shown = "\n".join(screen_text(app))
        assert "[y] Done" in shown and "[a] Abort run" in shown
        await wait_until(pilot, lambda: screen.state != "running", answer_prompts=True,
                         what="run end")
        assert screen.state == "done", screen.message
        await pilot.pause()
        await pilot.pause()
        lines = screen_text(app)
        assert all(len(line) <= SIZE[0] for line in lines)
        table = screen.query_one("#results-table", DataTable)
        header = [str(c.label) for c in table.ordered_columns]
        assert header[:5] == ["criterion", "orient.", "best mm", "near mm", "far mm"]
        data = screen.outcome.tables["depth_of_field"]
        digest = depth_summary_rows(table_rows(data)[1])
        text = "\n".join(lines)
        head = next(line for line in lines if "criterion" in line)
        for h in ("best mm", "near mm", "far mm"):
            assert h in head
        # each digest row in view: its criterion, best focus and both DOF ends on one line
        for d in digest:
            line = next(x for x in lines if d["criterion"] in x and f" {d['orient.']} " in x)
            cells = line.split()
            assert [d["best mm"], d["near mm"], d["far mm"]] == cells[cells.index(
                d["orient."]) + 1:cells.index(d["orient."]) + 4], line
        assert any(d["near mm"] != "N/A" for d in digest)
        # the checklist beside it still shows whole descriptions
        _, what = _steps_panel(lines)
        assert "Forward-view set-up and camera settings" in what, text


CHARACTERISE_PARAMS = (Path(__file__).resolve().parents[2] / "fixtures" / "params"
                       / "characterise-small.toml").read_text(encoding="utf-8")


@pytest.mark.slow
@pytest.mark.asyncio
async def test_characterise_results_at_80x24_footnote_the_repeated_reason(
        tmp_path: Path) -> None:
    app = make_app(tmp_path, characterise=CHARACTERISE_PARAMS)
    async with app.run_test(size=SIZE) as pilot:
        await connected(pilot)
        await pilot.press("3", "p", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "characterise"
        await _checklist(pilot, screen, 4)
        await pilot.press("s")
        await wait_until(pilot, lambda: screen.state != "running", answer_prompts=True,
                         what="run end")
        assert screen.state == "done", screen.message
        await pilot.pause()
        await pilot.pause()
        lines = screen_text(app)
        text = "\n".join(lines)
        assert all(len(line) <= SIZE[0] for line in lines)
        assert "n/a (unresolved" not in text
        # the 8-bit row: its unresolved figures point to one footnote, on the panel's border
        row = next(line for line in lines if " 8 " in line and "n/a [1]" in line)
        assert row.count("n/a [1]") >= 2
        assert "[1] n/a: unresolved: dark noise < 1 DN" in lines[-3]  # the bottom border
        table = screen.query_one("#results-table", DataTable)
        assert table.fixed_columns == 1
        # every step done, each with its whole description
        _, what = _steps_panel(lines)
        steps = procedure_checklist("characterise", app.params_files["characterise"])
        for step in steps:
            assert step.title.replace(" ", "") in what.replace(" ", ""), (step.title, what)
        assert text.count("\u2714") == len(steps)
