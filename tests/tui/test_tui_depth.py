"""The depth-of-field procedure through the Run screen on the simulated bench: the re-mount
prompt between the segments, each position's edge MTF50, the digest and the stored table."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from test_tui_helpers import connected, make_app, wait_until
from textual.widgets import DataTable

from benchlab.session import Session, read_results
from benchlab.tui.dialogs import PromptDialog
from benchlab.tui.runner import RunScreen

#: Nine distances in two overlapping stage segments, one frame each (the protocol's test file).
DEPTH_PARAMS = (Path(__file__).resolve().parents[2] / "fixtures" / "params"
                / "depth-small.toml").read_text(encoding="utf-8")


def _rows(table: DataTable) -> list[tuple[str, ...]]:
    return [tuple(str(c) for c in table.get_row_at(r)) for r in range(table.row_count)]


@pytest.mark.slow
@pytest.mark.asyncio
async def test_depth_run_through_the_ui_shows_positions_prompts_and_the_digest(
        tmp_path: Path) -> None:
    app = make_app(tmp_path, depth=DEPTH_PARAMS)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        await pilot.press("3", "p", "p", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "depth"
        # setup, 2 mounts, 6 + 5 positions (60 mm taken in both segments), analysis
        await wait_until(pilot, lambda: len(screen.step_status) == 15, what="checklist")
        assert screen.query_one("#steps").border_title == "through focus (section 2.2.4)"
        assert "Depth of field (section 2.2.4)" in str(screen.query_one("#run-status").render())
        assert "params depth.toml" in str(screen.query_one("#run-status").render())
        with app.device_lock:  # the chart in front of the camera, as the live view leaves it
            app.bench.mount("usaf")
        await pilot.press("s")

        def setup_figure() -> bool:  # the set-up prompt reads the chart's edges while it is up
            dialog = app.screen
            return isinstance(dialog, PromptDialog) and "mean MTF50 now" in dialog.live_figure

        await wait_until(pilot, setup_figure, what="the set-up prompt's MTF50")
        figure = app.screen.live_figure  # type: ignore[attr-defined]
        now, best = (float(w) for w in re.findall(r"\d+\.\d", figure)[:2])
        assert 20.0 < now <= best < 120.0, figure
        table = screen.query_one("#results-table", DataTable)
        prompts: list[str] = []
        shown: set[tuple[str, ...]] = set()

        def done() -> bool:
            dialog = app.screen
            if isinstance(dialog, PromptDialog) and dialog._title not in prompts:
                prompts.append(dialog._title)
            if screen.state == "running":
                shown.update(_rows(table))
            return screen.state != "running"

        answered = await wait_until(pilot, done, answer_prompts=True, what="run end")
        assert screen.state == "done", screen.message
        assert answered == 3
        assert [t.split(":")[0] for t in prompts] == ["Step section 2.2.4"] * 3
        assert "Mount the chart for 60-68 mm" in prompts[-1]  # the re-mount between segments
        # each position's edges' MTF50 per orientation, as it was taken
        positions = {r[0]: r[1] for r in shown if r[0].endswith(" mm")}
        assert {"52 mm", "60 mm", "68 mm"} <= set(positions)
        s_lp, t_lp = (float(x) for x in positions["60 mm"].split()[1::2])
        assert 40 < s_lp < 120 and 40 < t_lp < 120  # near best focus (60 mm on the sim bench)

        session = Session.open(screen.session_path)
        assert session.status == "completed"
        latest = session.latest_results()
        assert latest is not None
        data = read_results(latest)[0]["depth_of_field"]
        stored = data["rows"] if isinstance(data, dict) else data
        # The digest first: per criterion and orientation, from the stored rows.
        assert "depth of field shared" in str(screen.query_one("#results").border_title)
        digest = _rows(table)
        criteria = {r["criterion"] for r in stored}
        assert len(digest) == 2 * len(criteria)
        header = [str(c.label) for c in table.ordered_columns]
        assert header[:5] == ["criterion", "orient.", "best mm", "near mm", "far mm"]
        first = dict(zip(header, digest[0], strict=True))
        mine = [r for r in stored if r["criterion"] == first["criterion"]
                and r["orientation"][0].upper() == first["orient."]]
        nears = [r["near_mm"] for r in mine if r["near_mm"] is not None]
        fars = [r["far_mm"] for r in mine if r["far_mm"] is not None]
        # (this short sweep leaves some DOF ends beyond its reach: "N/A", never a number)
        assert first["near mm"] == (f"{max(nears):.2f}" if nears else "N/A")
        assert first["far mm"] == (f"{min(fars):.2f}" if fars else "N/A")
        assert any(d[4] != "N/A" for d in digest)  # some criterion's ends are within reach
        assert first["points"] == str(len(mine))
        # v: the full table as stored (a row per field point and criterion, its intervals)
        await pilot.press("v")
        assert str(screen.query_one("#results").border_title).startswith("Depth of field")
        assert table.row_count == len(stored)
        header = [str(c.label) for c in table.ordered_columns]
        assert {"best mm", "near mm", "far mm", "95 % CI", "verdict"} <= set(header)
        row = dict(zip(header, _rows(table)[0], strict=False))
        assert row["field pt"] == stored[0]["field_point"]
        assert row["verdict"] == stored[0]["verdict"]
