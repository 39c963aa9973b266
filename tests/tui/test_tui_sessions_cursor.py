"""Sessions screen: n, w and u act on the highlighted session, never on one opened before;
a trend leaves readings with no value out of the sparkline and min / max."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from many_sessions_helpers import copy_session, real_session
from test_tui_helpers import make_app, wait_until
from textual.widgets import DataTable, Static

from benchlab.catalog.index import TrendPoint
from benchlab.tui import services
from benchlab.tui.sessions import SessionsScreen


@pytest.mark.slow
@pytest.mark.asyncio
async def test_actions_follow_the_cursor_not_the_opened_session(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    source = real_session(tmp_path / "source")
    root = tmp_path / "sessions"
    first = copy_session(source, root / "a-newer", started_at="2026-02-01T00:00:00+00:00")
    second = copy_session(source, root / "b-older", started_at="2026-01-01T00:00:00+00:00")
    acted: list[tuple[str, Path]] = []

    def reanalyse(path: Path, estimator: str | None) -> Path:
        acted.append(("n", path))
        return path / "results" / "v1"

    def write_report(path: Path) -> Path:
        acted.append(("w", path))
        return path / "report.html"

    async def resume_session(path: Path) -> None:
        acted.append(("u", path))

    monkeypatch.setattr(services, "reanalyse", reanalyse)
    monkeypatch.setattr(services, "write_report", write_report)
    app = make_app(tmp_path)
    monkeypatch.setattr(app, "resume_session", resume_session)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("4")
        screen = app.screen
        assert isinstance(screen, SessionsScreen)
        await wait_until(pilot, lambda: [s.path.name for s in screen.sessions]
                         == ["a-newer", "b-older"], what="listing, newest first")
        await pilot.press("enter")
        await wait_until(pilot, lambda: screen.opened == first.resolve()
                         or screen.opened == first, what="first opened")
        await pilot.press("down")
        listing = screen.query_one("#session-list", DataTable)
        assert listing.cursor_row == 1
        await pilot.press("n")
        await wait_until(pilot, lambda: len(acted) == 1, what="re-analysis")
        await pilot.press("w")
        await wait_until(pilot, lambda: len(acted) == 2, what="report")
        app.bench = object()  # resume needs a connected bench; the resume itself is recorded
        await pilot.press("u")
        await wait_until(pilot, lambda: len(acted) == 3, what="resume")
        assert [(k, p.name) for k, p in acted] == [("n", second.name), ("w", second.name),
                                                  ("u", second.name)]
        app.bench = None

        # A reload in another order keeps the highlight on its session.
        await pilot.press("o")  # sort by sample (both empty: then by id) ...
        await wait_until(pilot, lambda: screen._sort_index == 1, what="sorted")
        await pilot.pause()
        name = screen.sessions[listing.cursor_row].path.name
        assert name == second.name


@pytest.mark.asyncio
async def test_trend_leaves_out_readings_with_no_value(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("4")
        screen = app.screen
        assert isinstance(screen, SessionsScreen)
        await pilot.pause()
        screen.sessions = [services.SessionSummary(tmp_path / sid, "mtf", "completed", "",
                                                   "", 10, 1) for sid in ("s0", "s1", "s2", "s3")]

        def point(sid: str, value: float | None, text: str) -> TrendPoint:
            return TrendPoint(sid, "", sid, 1, "histogram", "4lp", "tangential", 70.0, value,
                              text)

        pts: list[Any] = [point("s0", 0.42, "resolved"), point("s1", None, "unresolved"),
                          point("s2", 0.38, "resolved"), point("s3", None, "aliased")]
        screen._show_trend(("radial", "4lp", "tangential", "modulation"), pts)
        assert screen.trend_values == [0.42, 0.38]  # no 0 for the two without a value
        text = str(screen.query_one("#session-trend", Static).render())
        assert "2 sessions" in text and "min 0.380 max 0.420" in text
        assert "1 not resolved" in text and "1 aliased" in text
