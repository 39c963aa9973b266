"""Complete simulated MTF and radiometry runs through the UI, then the session on disk."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from test_tui_helpers import MTF_PARAMS, RADIOMETRY_PARAMS, connected, make_app, wait_until
from textual.widgets import DataTable

from benchlab.session import Session, read_results
from benchlab.tui.drawing.plot import CtfPlot, render_plot
from benchlab.tui.runner import STATUS_MARK, RunScreen


@pytest.mark.slow
@pytest.mark.asyncio
async def test_run_screen_is_readable_at_80x24_and_plots_the_readings(tmp_path: Path) -> None:
    app = make_app(tmp_path, mtf=MTF_PARAMS)
    async with app.run_test(size=(80, 24)) as pilot:
        await connected(pilot)
        await pilot.press("3")
        screen = app.screen
        assert isinstance(screen, RunScreen)
        await wait_until(pilot, lambda: len(screen.step_status) == 14, what="checklist")
        assert screen.query_one("#steps").border_title == "checklist (Table 4.10 steps)"
        plot = screen.query_one("#ctf-plot", CtfPlot)
        await wait_until(pilot, lambda: bool(plot.curves), what="simulated CTF band")
        assert set(plot.curves) == {"forward", "radial"}
        await pilot.press("s")
        shown: list[tuple[str, str]] = []
        table = screen.query_one("#results-table", DataTable)

        def done() -> bool:
            if screen.state == "running" and table.row_count:
                row = tuple(str(c) for c in table.get_row_at(table.row_count - 1))
                if len(row) == 2 and row not in shown:
                    shown.append(row)  # type: ignore[arg-type]
            return screen.state != "running"

        await wait_until(pilot, done, answer_prompts=True, what="run end")
        assert screen.state == "done", screen.message
        # Readings while the run goes: two short columns that fit the 80-column layout.
        readings = [r for r in shown if r[1].startswith("M ") or r[1] == "not resolved"]
        assert readings and all(len(w) <= 12 and len(v) <= 12 for w, v in readings)
        assert any(re.fullmatch(r"G2E[14] [ST]", w) for w, _ in readings)
        assert any(re.fullmatch(r"M 0\.\d{3}", v) for _, v in readings)
        # The plot follows the last view measured: the radial readings (2 frequencies x S/T).
        assert plot.view == "radial" and len(plot.points) == 4
        text = render_plot(plot.points, plot.curves["radial"], 40, 8, plot.x_max, plot.nyquist)
        lines = text.plain.splitlines()
        assert len(lines) == 8 and lines[0].startswith("1.0")
        assert "s" in text.plain and "t" in text.plain  # the S and T readings
        # the radial patterns' contrast is measured by the analysis, not known live: raw readings
        assert all(p.target_contrast is None for p in plot.points)
        assert "CTF" in str(plot.render()).splitlines()[0]
        assert any(0x2800 < ord(ch) <= 0x28FF for ch in text.plain)  # the simulated band
        # The final table puts the modulations where 80 columns show them.
        svg = app.export_screenshot()
        for header in ("element", "S mod.", "T mod."):
            assert header in svg.replace("&#160;", " ")


def _results_json(session: Session, table: str) -> list[dict]:
    latest = session.latest_results()
    assert latest is not None
    data = read_results(latest)[0][table]
    return data["rows"] if isinstance(data, dict) else data


@pytest.mark.slow
@pytest.mark.asyncio
async def test_mtf_run_through_the_ui_writes_a_complete_session(tmp_path: Path) -> None:
    app = make_app(tmp_path, mtf=MTF_PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        await pilot.press("3")
        screen = app.screen
        assert isinstance(screen, RunScreen)
        await wait_until(pilot, lambda: len(screen.step_status) > 0, what="checklist")
        # setup, thread, focus, forward, radial-setup, 2 x 2 x (roll, acquire), analysis
        assert len(screen.step_status) == 14
        await pilot.press("s")
        prompts = await wait_until(
            pilot, lambda: screen.state != "running", answer_prompts=True, what="run end"
        )
        assert screen.state == "done", screen.message
        assert prompts == 8  # setup, thread, focus, radial set-up, four rolls
        assert set(screen.step_status.values()) == {"done"}
        steps = screen.query_one("#steps", DataTable)
        assert all(steps.get_cell_at((r, 0)).startswith(STATUS_MARK["done"]) for r in range(14))

        session = Session.open(screen.session_path)
        assert session.status == "completed"
        assert session.completed_steps() == set(screen.step_status)
        assert len(list(session.frames_dir.glob("*.tiff"))) == 5  # forward + 4 radial
        forward = _results_json(session, "table_4_11")
        assert {str(r.get("element")) for r in forward} >= {"G2E1", "G2E4"}
        radial = _results_json(session, "table_4_12")
        assert len(radial) >= 2
        # what the UI shows at the end is the table on disk
        shown = screen.query_one("#results-table", DataTable)
        assert shown.row_count == len(forward)
        first = [str(c) for c in shown.get_row_at(0)]
        assert first[0] == str(forward[0]["element"])
        assert first[1] == f"{forward[0]['sagittal_modulation']:.3f}"  # S mod. second


@pytest.mark.slow
@pytest.mark.asyncio
async def test_radiometry_run_through_the_ui(tmp_path: Path) -> None:
    app = make_app(tmp_path, radiometry=RADIOMETRY_PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        await pilot.press("3", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "radiometry"
        await wait_until(pilot, lambda: len(screen.step_status) == 4, what="checklist")
        assert screen.query_one("#steps").border_title == "positions (section 4.4)"
        assert not screen.query_one("#ctf-plot").display  # bar contrast plot: MTF only
        await pilot.press("s")
        prompts = await wait_until(
            pilot, lambda: screen.state != "running", answer_prompts=True, what="run end"
        )
        assert screen.state == "done", screen.message
        assert prompts == 1
        session = Session.open(screen.session_path)
        assert session.status == "completed"
        rows = _results_json(session, "table_4_16")
        assert [r["position_mm"] for r in rows] == [15, 25]
        assert rows[0]["measured_normalised"] == pytest.approx(1.0)
        assert 0 < rows[1]["measured_normalised"] < 1.0  # fall-off towards the edge
        bench = app.bench
        assert all(bench.sim_led.channel_output_ma(ch) == 0
                   for ch in range(1, bench.sim_led.channel_count + 1))
        assert bench.sim_stage.position_mm == pytest.approx(25.0, abs=0.01)
