"""Sessions browser: list, open, re-analyse with another estimator, write report, resume.

The list comes from the session catalogue (``sessions/catalog.sqlite``, rebuilt from the
folders when missing): filter it by typing in the filter box (``/``), change the sort (``o``),
and follow one figure across the listed sessions (``t``: next figure, a sparkline and the
values oldest first).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.markup import escape
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.reactive import reactive
from textual.widgets import DataTable, Footer, Input, Sparkline, Static

from benchlab.tui import services
from benchlab.tui.screen import BenchScreen
from benchlab.tui.ui_calls import call_ui
from benchlab.tui.widgets import ModeBar


class SessionsScreen(BenchScreen):
    """Saved sessions under the sessions folder."""

    DEFAULT_CSS = """
    SessionsScreen #sessions-status { height: auto; padding: 0 1; background: $boost; }
    SessionsScreen #sessions-body { height: 1fr; }
    SessionsScreen #session-left { width: 1fr; height: 1fr; }
    SessionsScreen #sessions-filter { height: 3; }
    SessionsScreen #session-list { height: 1fr; border: round $primary; }
    SessionsScreen #session-trend-box { height: auto; border: round $primary; }
    SessionsScreen #session-sparkline { height: 3; }
    SessionsScreen #session-trend { height: auto; }
    SessionsScreen #session-detail { width: 1fr; border: round $primary; }
    SessionsScreen #session-info { height: auto; }
    SessionsScreen #session-table { height: 1fr; }
    """
    BINDINGS = [
        Binding("enter", "open", "Open", show=True),
        Binding("m", "estimator", "Method"),
        Binding("n", "reanalyse", "Re-analyse"),
        Binding("w", "report", "Report"),
        Binding("u", "resume", "Resume"),
        Binding("v", "next_table", "Table"),
        Binding("R", "reload", "Reload"),
        Binding("slash", "filter", "Filter"),
        Binding("o", "sort", "Sort"),
        Binding("t", "trend", "Trend"),
        Binding("i", "reindex", "Reindex"),
    ]

    #: Keys are commands: the list has the focus, the filter box only after ``/``.
    AUTO_FOCUS = "#session-list"
    estimator: reactive[str] = reactive("")

    def __init__(self) -> None:
        super().__init__()
        self.sessions: list[services.SessionSummary] = []
        self.opened: Path | None = None
        self._tables: list[tuple[str, dict[str, Any]]] = []
        self._table_index = 0
        self._sort_index = 0
        self._figures: list[tuple[str, str, str, str]] = []
        self._figure_index = -1
        self.trend_values: list[float] = []

    def compose(self) -> ComposeResult:
        yield ModeBar("sessions")
        yield Static("", id="sessions-status")
        with Horizontal(id="sessions-body"):
            with Vertical(id="session-left"):
                yield Input(placeholder="filter: id, sample, procedure, status, operator "
                            "(Enter)", id="sessions-filter")
                yield DataTable(id="session-list", cursor_type="row")
                with Vertical(id="session-trend-box"):
                    yield Sparkline([], id="session-sparkline")
                    yield Static("[dim]t: trend of a figure across the listed sessions[/dim]",
                                 id="session-trend")
            with Vertical(id="session-detail"):
                yield Static("[dim]Enter: open the selected session[/dim]", id="session-info")
                yield DataTable(id="session-table", cursor_type="row")
        yield Footer(compact=True)

    def on_mount(self) -> None:
        table = self.query_one("#session-list", DataTable)
        table.add_columns("session", "procedure", "status", "sample", "results")
        table.border_title = "sessions"
        self.query_one("#session-detail").border_title = "session"
        self.query_one("#session-trend-box").border_title = "trend"
        if not self.estimator:
            self.estimator = "auto"
        self.call_after_refresh(self._status)

    def on_screen_resume(self) -> None:
        self.action_reload()

    def watch_estimator(self) -> None:
        self._status()

    def _status(self, extra: str = "") -> None:
        if not self.is_mounted:
            return
        root = self.app.sessions_dir
        sort, _ = services.CATALOG_SORTS[self._sort_index]
        text = (f"folder [b]{root}[/b]  re-analysis method [b]{self.estimator or 'default'}[/b]"
                f"  sorted by [b]{sort}[/b]")
        if extra:
            text += f"\n{extra}"
        self.query_one("#sessions-status", Static).update(text)

    # -- listing ----------------------------------------------------------------------------

    def action_reload(self) -> None:
        self._load()

    @work(thread=True, exclusive=True, group="sessions-list", exit_on_error=False)
    def _load(self) -> None:
        app: Any = self.app
        sort, descending = services.CATALOG_SORTS[self._sort_index]
        text = app.call_from_thread(lambda: self.query_one("#sessions-filter", Input).value)
        try:
            found = services.catalog_sessions(Path(app.sessions_dir), text, sort, descending)
        except Exception as exc:  # noqa: BLE001
            call_ui(app, app.show_error, "Could not list sessions", exc)
            return
        call_ui(app, self._show_list, found)

    def _show_list(self, found: list[services.SessionSummary]) -> None:
        table = self.query_one("#session-list", DataTable)
        # The highlight stays on its session across a reload (a new sort, a re-analysis):
        # n, w and u act on the highlighted row, so it must not slide onto another session.
        was = (self.sessions[table.cursor_row].path
               if 0 <= table.cursor_row < len(self.sessions) else None)
        self.sessions = found
        table.clear()
        for s in found:
            table.add_row(
                s.path.name, s.procedure, s.status, s.sample,
                (f"v{s.result_versions}" if s.result_versions else "-")
                + (f" (v{s.unreadable_version} unreadable)" if s.unreadable_version else ""),
                key=str(s.path),
            )
        at = next((i for i, s in enumerate(found) if s.path == was), None)
        if at is not None:
            table.move_cursor(row=at)
        self._status(f"{len(found)} session(s)")
        if self._figure_index >= 0:
            self._trend(self._current_figure())

    def _selected(self) -> Path | None:
        table = self.query_one("#session-list", DataTable)
        if not self.sessions or table.cursor_row < 0 or table.cursor_row >= len(self.sessions):
            self.notify("No session selected.", severity="warning")
            return None
        return self.sessions[table.cursor_row].path

    # -- open -------------------------------------------------------------------------------

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        if event.data_table.id == "session-list":
            self.action_open()

    def action_open(self) -> None:
        path = self._selected()
        if path is not None:
            self._open(path)

    @work(thread=True, exclusive=True, group="sessions-open", exit_on_error=False)
    def _open(self, path: Path) -> None:
        app: Any = self.app
        try:
            tables, summary = services.session_tables(path)
            # One folder, not the whole root: the listing itself comes from the catalogue.
            info = next(iter(services.list_sessions_of([path])), None)
        except Exception as exc:  # noqa: BLE001
            call_ui(app, app.show_error, f"Could not open {path.name}", exc)
            return
        call_ui(app, self._show_session, path, info, tables, summary)

    def _show_session(
        self,
        path: Path,
        info: services.SessionSummary | None,
        tables: dict[str, Any],
        summary: dict[str, Any],
    ) -> None:
        self.opened = path
        lines = [f"[b]{path.name}[/b]"]
        if info is not None:
            lines.append(
                f"{info.procedure}  {info.status}  started {info.started_at}  "
                f"operator {info.operator}  steps done {info.steps_done}  "
                f"results v{info.result_versions}"
            )
            if info.error:
                lines.append(f"[red]{escape(info.error)}[/red]")
        if summary.get("estimator"):
            lines.append(f"estimator {summary['estimator']}")
        if summary.get("partial"):
            lines.append(f"[yellow]PARTIAL results: the session was {summary.get('session_status')}"
                         f" ({summary.get('steps_done')} of {summary.get('steps_total')} steps "
                         "done); u resumes it[/yellow]")
        if not tables:
            lines.append("[dim]no results yet (u: resume the run)[/dim]")
        self.query_one("#session-info", Static).update("\n".join(lines))
        self._tables = list(tables.items())
        self._table_index = 0
        self._show_table()

    def _show_table(self) -> None:
        table = self.query_one("#session-table", DataTable)
        table.clear(columns=True)
        if not self._tables:
            return
        name, data = self._tables[self._table_index % len(self._tables)]
        title, headers, cells = services.display_table(name, data)
        table.add_columns(*headers)
        for row in cells:
            table.add_row(*row)
        self.query_one("#session-detail").border_title = (
            f"{title} ({self._table_index % len(self._tables) + 1}/{len(self._tables)})"
        )

    def action_next_table(self) -> None:
        if self._tables:
            self._table_index += 1
            self._show_table()

    # -- catalogue: filter, sort, trend ----------------------------------------------------

    def action_filter(self) -> None:
        self.query_one("#sessions-filter", Input).focus()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        if event.input.id == "sessions-filter":
            self.query_one("#session-list", DataTable).focus()
            self._load()

    def action_sort(self) -> None:
        self._sort_index = (self._sort_index + 1) % len(services.CATALOG_SORTS)
        self._load()

    @work(thread=True, exclusive=True, group="sessions-list", exit_on_error=False)
    def action_reindex(self) -> None:
        app: Any = self.app
        try:
            n = services.catalog_reindex(Path(app.sessions_dir))
        except Exception as exc:  # noqa: BLE001
            call_ui(app, app.show_error, "Could not rebuild the catalogue", exc)
            return
        call_ui(app, self.notify, f"Catalogue rebuilt: {n} session(s)")
        call_ui(app, self._load)

    def _current_figure(self) -> tuple[str, str, str, str] | None:
        if not self._figures or self._figure_index < 0:
            return None
        return self._figures[self._figure_index % len(self._figures)]

    @work(thread=True, exclusive=True, group="sessions-trend", exit_on_error=False)
    def action_trend(self) -> None:
        app: Any = self.app
        try:
            self._figures = services.catalog_figures(Path(app.sessions_dir))
        except Exception as exc:  # noqa: BLE001
            call_ui(app, app.show_error, "Could not read the catalogue", exc)
            return
        if not self._figures:
            call_ui(app, self.notify, "No figures yet: analyse a session first.",
                                 severity="warning")
            return
        self._figure_index += 1
        call_ui(app, self._trend, self._current_figure())

    @work(thread=True, exclusive=True, group="sessions-trend-load", exit_on_error=False)
    def _trend(self, figure: tuple[str, str, str, str] | None) -> None:
        app: Any = self.app
        if figure is None:
            return
        try:
            points = services.catalog_trend(Path(app.sessions_dir), figure)
        except Exception as exc:  # noqa: BLE001
            call_ui(app, app.show_error, "Could not read the trend", exc)
            return
        call_ui(app, self._show_trend, figure, points)

    def _show_trend(self, figure: tuple[str, str, str, str], points: list[Any]) -> None:
        listed = {s.path.name for s in self.sessions}
        every = [p for p in points if p.session_id in listed]
        # Not resolved / aliased readings have no value: left out of the sparkline and of
        # min / max (never drawn as a measured 0), but counted and named.
        points = [p for p in every if p.value is not None]
        missing = [p for p in every if p.value is None]
        self.trend_values = [float(p.value) for p in points]
        view, element, orientation, quantity = figure
        title = " ".join(x for x in (view, element, orientation, quantity) if x)
        self.query_one("#session-sparkline", Sparkline).data = self.trend_values or [0.0]
        counts: dict[str, int] = {}
        for p in missing:
            word = {"unresolved": "not resolved"}.get(p.text, p.text or "no value")
            counts[word] = counts.get(word, 0) + 1
        gaps = "; ".join(f"{n} {word}" for word, n in counts.items())
        if not points:
            text = f"[b]{escape(title)}[/b]: no listed session has a value" + (
                f" ({escape(gaps)})" if gaps else "")
        else:
            lo, hi = min(self.trend_values), max(self.trend_values)
            tail = "  ".join(f"{escape(p.sample or p.session_id)} {p.value:.3f}"
                             for p in points[-4:])
            text = (f"[b]{escape(title)}[/b]  {len(points)} sessions, oldest first; "
                    f"min {lo:.3f} max {hi:.3f}" + (f"; {escape(gaps)} (no value)" if gaps
                                                    else "") + f"\nlatest: {tail}")
        self.query_one("#session-trend", Static).update(text)

    # -- actions ----------------------------------------------------------------------------

    def action_estimator(self) -> None:
        names = services.reanalysis_estimators()
        i = names.index(self.estimator) if self.estimator in names else -1
        self.estimator = names[(i + 1) % len(names)]

    def action_reanalyse(self) -> None:
        path = self._selected()  # the highlighted row, never the last opened
        if path is not None:
            self._status(f"re-analysing {path.name} with {self.estimator}...")
            self._reanalyse(path, self.estimator)

    @work(thread=True, exclusive=True, group="sessions-analyse", exit_on_error=False)
    def _reanalyse(self, path: Path, estimator: str) -> None:
        app: Any = self.app
        try:
            out = services.reanalyse(path, estimator or None)
        except Exception as exc:  # noqa: BLE001 - frames untouched; shown in plain words
            call_ui(app, app.show_error, "Re-analysis failed", exc)
            return
        call_ui(app, self.notify, f"New results: {out.name} ({estimator})")
        call_ui(app, self._after_change, path)

    def _after_change(self, path: Path) -> None:
        self._load()
        self._open(path)

    def action_report(self) -> None:
        path = self._selected()  # the highlighted row, never the last opened
        if path is not None:
            self._status(f"writing the report of {path.name}...")
            self._report(path)

    @work(thread=True, exclusive=True, group="sessions-report", exit_on_error=False)
    def _report(self, path: Path) -> None:
        app: Any = self.app
        try:
            out = services.write_report(path)
        except Exception as exc:  # noqa: BLE001
            call_ui(app, app.show_error, "Report failed", exc)
            return
        call_ui(app, self._status, f"report written: {out}")
        call_ui(app, self.notify, f"Report written: {out}")

    async def action_resume(self) -> None:
        path = self._selected()  # the highlighted row, never the last opened
        if path is None:
            return
        app: Any = self.app
        if app.bench is None:
            self.notify("Connect the bench first (Devices, c).", severity="error")
            return
        await app.resume_session(path)
