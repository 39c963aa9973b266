"""Sessions screen on the catalogue: filter, sort, and the trend of a figure."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from many_sessions_helpers import copy_session, real_session
from sim_runs import reseal_results
from test_tui_helpers import make_app, wait_until
from textual.widgets import DataTable, Input, Static

from benchlab.catalog.index import CATALOG_FILE
from benchlab.tui.sessions import SessionsScreen


def _set_modulation(session: Path, element: str, value: float) -> None:
    path = session / "results" / "v1" / "forward_view_modulation.json"
    rows = json.loads(path.read_text())
    for row in rows:
        if row["element"] == element:
            row["sagittal_modulation"] = value
    path.write_text(json.dumps(rows))
    reseal_results(path.parent)


@pytest.mark.slow
@pytest.mark.asyncio
async def test_catalogue_listing_filter_sort_and_trend(tmp_path: Path) -> None:
    source = real_session(tmp_path / "source")
    root = tmp_path / "sessions"
    values = {"p0": 0.61, "p1": 0.55, "p2": 0.70}
    samples = {"p0": "lens-b", "p1": "lens-c", "p2": "lens-a"}
    for i, name in enumerate(values):
        s = copy_session(source, root / name, sample=samples[name],
                         started_at=f"2026-0{i + 1}-01T00:00:00+00:00")
        _set_modulation(s, "G2E1", values[name])
    assert not (root / CATALOG_FILE).exists()  # the screen builds it from the folders
    app = make_app(tmp_path)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("4")
        screen = app.screen
        assert isinstance(screen, SessionsScreen)
        listing = screen.query_one("#session-list", DataTable)

        def names() -> list[str]:
            return [str(listing.get_row_at(i)[0]) for i in range(listing.row_count)]

        await wait_until(pilot, lambda: names() == ["p2", "p1", "p0"], what="newest first")
        assert [str(c) for c in listing.get_row_at(0)][3] == "lens-a"

        await pilot.press("slash")
        for key in "lens-c":
            await pilot.press(key)
        await pilot.press("enter")
        await wait_until(pilot, lambda: names() == ["p1"], what="filtered")
        screen.query_one("#sessions-filter", Input).value = ""
        await pilot.press("slash", "enter")
        await wait_until(pilot, lambda: len(names()) == 3, what="unfiltered")

        await pilot.press("o")  # sort by sample
        await wait_until(pilot, lambda: names() == ["p2", "p0", "p1"], what="by sample")

        wanted = ("forward", "G2E1", "sagittal", "modulation")
        for _ in range(40):
            await pilot.press("t")
            await wait_until(pilot, lambda: screen._current_figure() is not None, what="fig")
            if screen._current_figure() == wanted:
                break
        assert screen._current_figure() == wanted
        await wait_until(pilot, lambda: screen.trend_values == list(values.values()),
                         what="trend oldest first")
        text = str(screen.query_one("#session-trend", Static).render())
        assert "G2E1" in text and "3 sessions" in text and "lens-a 0.700" in text
