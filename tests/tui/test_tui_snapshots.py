"""A few pinned snapshots of the TUI on the seeded simulated bench (no clocks on screen)."""

from __future__ import annotations

from importlib.metadata import version
from pathlib import Path

import pytest
from test_tui_helpers import MTF_PARAMS, make_app, wait_until
from textual.pilot import Pilot
from textual.widgets import Static

from benchlab.tui.drawing.plot import CtfPlot
from benchlab.tui.runner import RunScreen

#: The SVGs were recorded with these versions; rendering details change between releases, so
#: after an upgrade review the new pictures and re-record them with ``--snapshot-update``.
RECORDED_WITH = {"textual": "8.2.8", "pytest-textual-snapshot": "1.1.0"}
pytestmark = pytest.mark.skipif(
    any(version(pkg) != want for pkg, want in RECORDED_WITH.items()),
    reason=f"snapshots recorded with {RECORDED_WITH}",
)


def test_devices_panel_80x24(snap_compare, tmp_path: Path) -> None:  # noqa: ANN001
    app = make_app(tmp_path)

    async def ready(pilot: Pilot[None]) -> None:
        await wait_until(pilot, lambda: app.bench is not None, what="bench")
        stage = app.screen.query_one("#stage", Static)
        await wait_until(pilot, lambda: "position" in str(stage.render()), what="stage row")
        await pilot.pause()

    assert snap_compare(app, terminal_size=(80, 24), run_before=ready)


def test_mtf_checklist_120x36(snap_compare, tmp_path: Path) -> None:  # noqa: ANN001
    app = make_app(tmp_path, mtf=MTF_PARAMS)

    async def ready(pilot: Pilot[None]) -> None:
        await wait_until(pilot, lambda: app.bench is not None, what="bench")
        await pilot.press("3")
        screen = app.screen
        assert isinstance(screen, RunScreen)
        await wait_until(pilot, lambda: len(screen.step_status) == 14, what="checklist")
        plot = screen.query_one("#ctf-plot", CtfPlot)
        await wait_until(pilot, lambda: bool(plot.curves), what="simulated CTF band")
        await pilot.pause()

    assert snap_compare(app, terminal_size=(120, 36), run_before=ready)
