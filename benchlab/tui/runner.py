"""Procedure runner: the Table 4.10 checklist or the radiometry positions, run step by step."""

from __future__ import annotations

import concurrent.futures
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.markup import escape
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.coordinate import Coordinate
from textual.message import Message
from textual.reactive import reactive
from textual.widgets import DataTable, Footer, ProgressBar, Static
from textual.worker import get_current_worker

from benchlab.procedures import PROCEDURES, REGISTRY
from benchlab.report.text_table import footnoted
from benchlab.tui import services
from benchlab.tui.checklist import checklist_layout, numbered, short_step_label
from benchlab.tui.depth_summary import depth_summary_rows
from benchlab.tui.dialogs import InputDialog, PromptDialog
from benchlab.tui.drawing.plot import CtfPlot, PlotPoint
from benchlab.tui.screen import BenchScreen
from benchlab.tui.ui_calls import call_ui
from benchlab.tui.widgets import ModeBar

if TYPE_CHECKING:
    from benchlab.protocols.engine import Runner

#: Title of the checklist panel per procedure.
CHECKLIST_TITLES = {name: e.checklist_title for name, e in REGISTRY.items()}
#: The status line's name of each procedure.
PROCEDURE_LABELS = {name: e.label for name, e in REGISTRY.items()}
ORIENTATION_SHORT = {"sagittal": "S", "tangential": "T"}
#: Room kept for the checklist's vertical scrollbar (a long procedure scrolls).
STEPS_SCROLLBAR_CHARS = 2
STATUS_MARK = {
    "pending": "  ",
    "running": "\u25b6 ",
    "done": "\u2714 ",
    "failed": "\u2718 ",
    "aborted": "\u25a0 ",
}


def _format_value(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


#: What a partial result is mainly about, in order of preference: (key, label).
PRIMARY_RESULTS = (("modulation", "M"), ("measured_mean_gray", "gray"), ("sharpness", "sharpness"))


def result_row(data: Mapping[str, Any]) -> tuple[str, str]:
    """A partial result as (what, value), short enough for 80 columns: ("G2E4 S", "M 0.612")."""
    what: list[str] = []
    if "element" in data:
        what.append(str(data["element"]))
    if "freq_lp_per_mm" in data:
        what.append(f"{_format_value(data['freq_lp_per_mm'])} lp/mm")
    if "orientation" in data:
        what.append(ORIENTATION_SHORT.get(str(data["orientation"]), str(data["orientation"])))
    if "position_mm" in data:
        what.append(f"{_format_value(data['position_mm'])} mm")
    if "distance_mm" in data:  # a depth-of-field position: the edges' MTF50 per orientation
        what.append(f"{_format_value(data['distance_mm'])} mm")
        if "mtf50_sagittal_lp_per_mm" in data or "mtf50_tangential_lp_per_mm" in data:
            def lp(key: str) -> str:
                value = data.get(key)
                return "-" if value is None else f"{float(value):.0f}"

            return " ".join(what), (f"S {lp('mtf50_sagittal_lp_per_mm')} "
                                    f"T {lp('mtf50_tangential_lp_per_mm')}")
    for key, label in PRIMARY_RESULTS:
        if key in data:
            if key == "modulation" and data.get("resolved") is False:
                return " ".join(what), "not resolved"
            value = data[key]
            text = f"{label} {value:.3f}" if isinstance(value, float) else f"{label} {value}"
            if key == "sharpness" and "best" in data:
                text += f" (best {_format_value(data['best'])})"
            return " ".join(what), text
    numbers = [
        f"{k} {_format_value(v)}"
        for k, v in data.items()
        if isinstance(v, int | float) and not isinstance(v, bool)
    ]
    return " ".join(what), "  ".join(numbers)


class ChecklistTable(DataTable[Any]):
    """The checklist; says when its size changes, so that its rows are laid out again."""

    class Resized(Message):
        """The checklist's size changed."""

    def on_resize(self) -> None:
        self.post_message(self.Resized())


class RunScreen(BenchScreen):
    """Choose a procedure, start it, answer its prompts, watch results fill in."""

    DEFAULT_CSS = """
    RunScreen #run-status { height: auto; padding: 0 1; background: $boost; }
    RunScreen #run-body { height: 1fr; }
    RunScreen #steps { width: 1fr; height: 1fr; border: round $primary; }
    RunScreen #results { width: 1fr; height: 1fr; border: round $primary; }
    RunScreen #run-body.-tables #results { width: 2fr; }
    RunScreen #results-table { height: 1fr; }
    RunScreen #ctf-plot { height: 9; border-top: solid $primary; }
    RunScreen #progress { height: 1; padding: 0 1; }
    RunScreen #progress Bar { width: 1fr; }
    RunScreen DataTable > .datatable--cursor { background: $accent 40%; }
    """
    BINDINGS = [
        Binding("p", "procedure", "Procedure"),
        Binding("f", "params_file", "Params"),
        Binding("s", "start", "Start"),
        Binding("a", "abort", "Abort"),
        Binding("t", "retry", "Retry"),
        Binding("v", "next_table", "Table"),
        # Acceptance (docs/guide/acceptance.md): not in the footer, which 80 columns fill.
        Binding("n", "unit", "Unit", show=False),
        Binding("k", "spec", "Spec", show=False),
    ]

    procedure: reactive[str] = reactive("mtf")
    #: idle | running | done | failed | aborted
    state: reactive[str] = reactive("idle")
    message: reactive[str] = reactive("")

    def __init__(self) -> None:
        super().__init__()
        self.runner: Runner | None = None
        self.outcome: Any = None
        self.session_path: Path | None = None
        self.step_status: dict[str, str] = {}
        self._step_ids: list[str] = []
        self._steps: list[Any] = []
        self._step_numbers: list[str] = []
        self._tables: list[tuple[str, Mapping[str, Any]]] = []
        self._table_index = 0
        self._prompt: PromptDialog | None = None
        #: The unit under test (serial number, lot) and the spec its runs are verified against.
        self.unit_serial = ""
        self.unit_lot = ""
        self.spec_file: Path | None = None
        #: The stored verdict of the last run (with a spec), else None.
        self.verdict: dict[str, Any] | None = None
        self.verify_error = ""

    def compose(self) -> ComposeResult:
        yield ModeBar("run")
        yield Static("", id="run-status")
        with Horizontal(id="run-body"):
            yield ChecklistTable(id="steps", cursor_type="row", zebra_stripes=False)
            with Vertical(id="results"):
                yield DataTable(id="results-table", cursor_type="row")
                yield CtfPlot(id="ctf-plot")
        yield ProgressBar(id="progress", show_eta=False)
        yield Footer(compact=True)

    def on_mount(self) -> None:
        self.query_one("#results").border_title = "results"
        self._reset_results()
        self._show_procedure()
        self._load_plot_curves()
        self.call_after_refresh(self._refresh_status)
        self._load_checklist()

    # -- status -----------------------------------------------------------------------------

    def watch_state(self) -> None:
        self._refresh_status()

    def watch_message(self) -> None:
        self._refresh_status()

    def watch_procedure(self) -> None:
        self._refresh_status()
        if self.is_mounted:
            self._show_procedure()

    def _show_procedure(self) -> None:
        """Panel titles and the plot follow the chosen procedure."""
        self.query_one("#steps").border_title = CHECKLIST_TITLES.get(self.procedure, "checklist")
        self.query_one("#ctf-plot").display = self.procedure == "mtf"

    @work(thread=True, exclusive=True, group="plot-curves", exit_on_error=False)
    def _load_plot_curves(self) -> None:
        try:
            bands, nyq = services.simulated_ctf_bands()
        except Exception as exc:  # noqa: BLE001 - the plot then shows the points alone
            self.log.warning(f"simulated curves unavailable: {exc!r}")
            return
        call_ui(self.app, lambda: self.query_one("#ctf-plot", CtfPlot).set_curves(bands, nyq))

    def _refresh_status(self) -> None:
        if not self.is_mounted:
            return
        label = PROCEDURE_LABELS
        params = self.app.params_files.get(self.procedure)
        where = f"  session {self.session_path.name}" if self.session_path else ""
        text = (
            f"[b]{label.get(self.procedure, self.procedure)}[/b]  "
            f"params {Path(params).name if params else 'defaults'}  "
            f"[b]{self.state}[/b]{where}"
        )
        if self.unit_serial or self.unit_lot or self.spec_file:
            text += (f"\nunit {escape(self.unit_serial or '-')}  lot "
                     f"{escape(self.unit_lot or '-')}  spec "
                     f"{escape(self.spec_file.name) if self.spec_file else '-'}")
        if self.message:
            text += f"\n{self.message}"
        self.query_one("#run-status", Static).update(text)

    # -- checklist --------------------------------------------------------------------------

    @work(thread=True, exclusive=True, group="checklist", exit_on_error=False)
    def _load_checklist(self) -> None:
        """Show the chosen procedure's steps (from its parameters) before a run starts."""
        procedure = self.procedure
        try:
            steps = services.procedure_checklist(
                procedure, self.app.params_files.get(procedure)
            )
        except Exception as exc:  # noqa: BLE001 - parameter problems shown in plain words
            call_ui(self.app, self._checklist_error, exc)
            return
        call_ui(self.app, self._checklist_loaded, steps)

    def _checklist_loaded(self, steps: list[Any]) -> None:
        self.message = ""
        self._show_steps(steps, set())

    def _checklist_error(self, exc: BaseException) -> None:
        self.query_one("#steps", DataTable).clear()
        self.step_status = {}
        self._steps, self._step_ids = [], []
        self.message = f"[red]{escape(services.plain_error(exc))}[/red]"

    def _show_steps(self, steps: list[Any], done: set[str]) -> None:
        self._steps = list(steps)
        self._step_ids = [s.id for s in steps]
        self.step_status = {s.id: ("done" if s.id in done else "pending") for s in steps}
        self._fill_steps()
        progress = self.query_one(ProgressBar)
        progress.update(total=max(1, len(steps)), progress=len(done))

    def _fill_steps(self) -> None:
        """The checklist at the panel's width: each description whole, wrapped in its column
        (columns re-made, so a previous procedure's widths do not squeeze this one's)."""
        table = self.query_one("#steps", DataTable)
        width = table.scrollable_content_region.width or table.size.width
        layout = checklist_layout(self._steps, max(0, width - STEPS_SCROLLBAR_CHARS))
        table.clear(columns=True)
        for header, w in zip(layout.headers, layout.widths, strict=True):
            table.add_column(header, key=header, width=w)
        self._step_numbers = [row[0] for row in layout.rows]
        for step, (number, *rest) in zip(self._steps, layout.rows, strict=True):
            table.add_row(numbered(STATUS_MARK[self.step_status[step.id]], number), *rest,
                          key=step.id, height=None)
        running = [i for i, sid in enumerate(self._step_ids)
                   if self.step_status.get(sid) == "running"]
        if running:
            table.move_cursor(row=running[0])

    def _widen_results(self, wide: bool) -> None:
        """The results take two thirds of the width while a finished run's tables are shown
        (the checklist is laid out again when its width changes)."""
        body = self.query_one("#run-body")
        if body.has_class("-tables") != wide:
            body.set_class(wide, "-tables")

    def on_checklist_table_resized(self) -> None:
        if self._steps:
            self._fill_steps()

    def _set_step(self, step_id: str, status: str) -> None:
        if step_id not in self.step_status:
            return
        self.step_status[step_id] = status
        table = self.query_one("#steps", DataTable)
        row = self._step_ids.index(step_id)
        table.update_cell_at(Coordinate(row, 0),
                             numbered(STATUS_MARK[status], self._step_numbers[row]))
        if status == "running":
            table.move_cursor(row=row)

    # -- results ----------------------------------------------------------------------------

    def _reset_results(self) -> None:
        table = self.query_one("#results-table", DataTable)
        table.clear(columns=True)
        table.fixed_columns = 0
        self._widen_results(False)
        self.query_one("#results").border_subtitle = ""
        table.add_columns("what", "result")
        self.query_one("#ctf-plot", CtfPlot).clear_points()
        self._tables = []
        self._table_index = 0
        self.query_one("#results").border_title = "results"

    def _add_result(self, step_label: str, data: Mapping[str, Any]) -> None:
        what, numbers = result_row(data)
        table = self.query_one("#results-table", DataTable)
        table.add_row(what or step_label, numbers)
        table.move_cursor(row=table.row_count - 1)
        if "modulation" in data and "image_lp_per_mm" in data:
            plot = self.query_one("#ctf-plot", CtfPlot)
            f = float(data["image_lp_per_mm"])
            resolved = data.get("resolved") is not False
            tc = data.get("target_contrast")  # the reading's target: {value, source, ...}
            target = tc.get("value") if isinstance(tc, Mapping) else None
            plot.add_point(str(data.get("view", "forward")), PlotPoint(
                f, float(data["modulation"]) if resolved else None,
                str(data.get("orientation", "")), bool(data.get("aliased", f > plot.nyquist)),
                float(target) if target is not None else None))

    def _show_table(self) -> None:
        if not self._tables:
            return
        name, data = self._tables[self._table_index % len(self._tables)]
        table = self.query_one("#results-table", DataTable)
        table.clear(columns=True)
        title, headers, cells = services.display_table(name, data)
        cells, notes = footnoted(cells)  # a reason repeated in cells: once, under the table
        table.add_columns(*headers)
        table.fixed_columns = 1  # a wide table scrolls sideways under its first column
        for row in cells:
            table.add_row(*row)
        self.query_one("#results").border_subtitle = "  ".join(notes)
        self._widen_results(True)
        self.query_one("#results").border_title = (
            f"{title} ({self._table_index % len(self._tables) + 1}/{len(self._tables)}, v: next)"
        )

    # -- keys -------------------------------------------------------------------------------

    def action_procedure(self) -> None:
        if self.state == "running":
            self.notify("A procedure is running.", severity="warning")
            return
        i = PROCEDURES.index(self.procedure)
        self.procedure = PROCEDURES[(i + 1) % len(PROCEDURES)]
        self._forget_run()
        self._load_checklist()

    def action_params_file(self) -> None:
        if self.state == "running":
            self.notify("A procedure is running.", severity="warning")
            return
        app: Any = self.app
        current = app.params_files.get(self.procedure)
        self.app.push_screen(
            InputDialog(
                f"Parameter file for {self.procedure}",
                "A TOML file (empty: the packaged defaults). Enter to load, Escape to cancel.",
                str(current or ""),
            ),
            self._set_params_file,
        )

    def _set_params_file(self, value: str | None) -> None:
        if value is None:
            return
        app: Any = self.app
        app.params_files[self.procedure] = Path(value).expanduser() if value else None
        self._forget_run()
        self._load_checklist()

    def action_unit(self) -> None:
        """Ask the unit's serial number, then its lot (stored in session.json at the start)."""
        if self.state == "running":
            self.notify("A procedure is running.", severity="warning")
            return
        self.app.push_screen(InputDialog(
            "Unit under test: serial number", "Stored in session.json when the run starts "
            "(empty: none). Enter to go on to the lot, Escape to cancel.", self.unit_serial),
            self._set_serial)

    def _set_serial(self, value: str | None) -> None:
        if value is None:
            return
        self.unit_serial = value.strip()
        self.app.push_screen(InputDialog(
            "Unit under test: lot", "The production lot (empty: none).", self.unit_lot),
            self._set_lot)

    def _set_lot(self, value: str | None) -> None:
        if value is not None:
            self.unit_lot = value.strip()
        self._refresh_status()

    def action_spec(self) -> None:
        """Choose the spec file a finished run is verified against (empty: none)."""
        if self.state == "running":
            self.notify("A procedure is running.", severity="warning")
            return
        self.app.push_screen(InputDialog(
            "Spec file", "A benchlab.spec TOML file: each run is verified against it when it "
            "ends (empty: no verification).", str(self.spec_file or "")), self._set_spec)

    def _set_spec(self, value: str | None) -> None:
        if value is None:
            return
        path = Path(value).expanduser() if value.strip() else None
        if path is not None:
            try:
                services.check_spec(path)
            except Exception as exc:  # noqa: BLE001 - every problem shown, nothing changed
                self.app.show_error("The spec file cannot be used", exc)
                return
        self.spec_file = path
        self._refresh_status()

    def _forget_run(self) -> None:
        self.verdict = None
        self.runner = None
        self.outcome = None
        self.session_path = None
        self.state = "idle"
        self.message = ""
        self._reset_results()

    def action_start(self) -> None:
        if self.state == "running":
            return
        if self.app.bench is None:
            self.notify("Connect the bench first (Devices, c).", severity="error")
            return
        if self.state in ("done", "aborted", "failed"):
            self._forget_run()
        self._launch(resume=None)

    def action_retry(self) -> None:
        if self.state not in ("failed", "aborted") or self.runner is None:
            self.notify("Nothing to retry.", severity="warning")
            return
        self._launch(resume=None)

    def action_abort(self) -> None:
        if self.state != "running":
            return
        self.app.abort_event.set()
        self.message = "aborting: LEDs off, stage stopped..."

    def action_next_table(self) -> None:
        if self._tables:
            self._table_index += 1
            self._show_table()

    def resume(self, session_path: Path) -> None:
        """Continue an interrupted session from its first incomplete step."""
        if self.state == "running":
            self.notify("A procedure is running.", severity="warning")
            return
        self._forget_run()
        self._launch(resume=Path(session_path))

    # -- the run, in a thread ---------------------------------------------------------------

    def _launch(self, resume: Path | None) -> None:
        app: Any = self.app
        app.abort_event.clear()
        app.procedure_running = True
        self.state = "running"
        self.message = ""
        self._run(resume)

    @work(thread=True, exclusive=True, group="run", exit_on_error=False)
    def _run(self, resume: Path | None) -> None:
        # Every call into the UI from here goes through call_ui: a display problem is logged
        # and dropped, so the run's outcome depends on the bench and the data only.
        app: Any = self.app
        ending: BaseException | None = None
        with app.device_activity():
            try:
                with app.device_lock:  # the live view is out of the camera from here on
                    pass
                if self.runner is None:
                    self.runner = services.make_runner(
                        procedure=self.procedure,
                        resume=resume,
                        bench=app.bench,
                        params=app.params_files.get(self.procedure),
                        root=app.sessions_dir,
                        prompt=self._prompt_operator,
                        progress=self._progress,
                        abort=app.abort_event,
                        on_result=self._on_result,
                        operator=app.operator,
                        sample=self.unit_serial,
                        lot=self.unit_lot,
                    )
                    call_ui(app, self._started, self.runner)
                self.outcome = self.runner.run()
                self._verify(Path(self.runner.session.path))
            except BaseException as exc:  # noqa: BLE001 - every ending is shown to the operator
                ending = exc
                if not isinstance(exc, Exception):
                    raise
            finally:
                # One call ends the run in the UI: state and procedure_running change together
                # (a retry started right after sees no late "not running" from this thread).
                if not call_ui(app, self._ended, ending):
                    call_ui(app, setattr, app, "procedure_running", False)

    def _verify(self, session_path: Path) -> None:
        """Verify the finished run against the chosen spec (in the run's thread); a failure
        is said beside the run's success, never turned into a failed run."""
        self.verdict = None
        self.verify_error = ""
        if self.spec_file is None:
            return
        try:
            self.verdict = services.verify_run(session_path, self.spec_file)
        except Exception as exc:  # noqa: BLE001 - shown to the operator in plain words
            self.verify_error = services.plain_error(exc)

    def _started(self, runner: Runner) -> None:
        self.session_path = Path(runner.session.path)
        if resume_proc := getattr(runner.session, "procedure", None):
            self.set_reactive(RunScreen.procedure, resume_proc)
            self._show_procedure()
        self._show_steps(runner.steps, set(runner.completed()))
        self._refresh_status()

    def _ended(self, exc: BaseException | None) -> None:
        self.app.procedure_running = False
        running = [s for s, st in self.step_status.items() if st == "running"]
        if exc is None:
            for sid in running:
                self._set_step(sid, "done")
            self.state = "done"
            self.message = "[green]Run complete; results saved in the session.[/green]"
            outcome = self.outcome
            self._tables = list((outcome.tables or {}).items()) if outcome else []
            dof = dict(self._tables).get("depth_of_field")
            if dof is not None:  # the digest first, then the full table, then the others
                digest = depth_summary_rows(services.table_rows(dof)[1])
                self._tables = [("depth of field shared by the field points", {"rows": digest}),
                                ("depth_of_field", dof),
                                *[t for t in self._tables if t[0] != "depth_of_field"]]
            if self.verdict is not None:  # the verdicts first: what the unit is judged by
                rows = services.verdict_rows(self.verdict)
                self._tables.insert(0, ("acceptance", {"rows": rows}))
                colour = {"pass": "green", "fail": "red"}.get(self.verdict["verdict"], "yellow")
                self.message += (f"\n[{colour}]Unit verdict: {self.verdict['verdict'].upper()}"
                                 f"[/{colour}] against {escape(self.verdict['spec']['name'])} "
                                 f"(verdicts/v{self.verdict['version']}.json)")
            elif self.verify_error:
                self.message += f"\n[red]Not verified: {escape(self.verify_error)}[/red]"
            self._table_index = 0
            self._show_table()
            return
        kind = services.run_ending(exc)
        if kind == "aborted":
            for sid in running:
                self._set_step(sid, "aborted")
            self.state = "aborted"
            self.message = (
                "[yellow]Aborted: LEDs off, stage stopped. The session can be resumed "
                "(t: retry from the first incomplete step).[/yellow]"
            )
        elif kind == "failed":
            for sid in running:
                self._set_step(sid, "failed")
            self.state = "failed"
            cause = getattr(exc, "cause", exc)
            self.message = f"[red]{escape(services.plain_error(cause))}[/red]\n t: retry the step"
            self.app.show_error("A step failed", cause)
        else:
            self.state = "failed" if self.runner is not None else "idle"
            self.message = f"[red]{escape(services.plain_error(exc))}[/red]"
            self.app.show_error("The run could not continue", exc)

    # callbacks from the runner thread ------------------------------------------------------

    def _progress(self, done: int, total: int, step: Any) -> None:
        call_ui(self.app, self._on_progress, done, total, step.id if step else None)

    def _on_progress(self, done: int, total: int, step_id: str | None) -> None:
        for sid, status in self.step_status.items():
            if status == "running":
                self._set_step(sid, "done")
        if step_id is not None:
            self._set_step(step_id, "running")
        self.query_one(ProgressBar).update(total=max(1, total), progress=done)

    def _on_result(self, step: Any, data: Mapping[str, Any]) -> None:
        label = short_step_label(step.table_step or step.id)
        call_ui(self.app, self._add_result, label, dict(data))

    def _prompt_operator(self, step: Any, message: str) -> bool:
        """Show a manual step and wait for the operator; polls abort and the live figure.

        A dialog that cannot be shown is a declined prompt (the run stops, resumable), never a
        failed step."""
        app: Any = self.app
        answer: concurrent.futures.Future[bool] = concurrent.futures.Future()
        dialog = PromptDialog(f"Step {step.table_step or step.id}: {step.title}", message)

        def answered(ok: bool | None) -> None:
            if not answer.done():  # a second dismissal (a double key press) changes nothing
                answer.set_result(bool(ok))

        def show() -> None:
            self._prompt = dialog
            app.push_screen(dialog, callback=answered)

        if not call_ui(app, show):
            return False
        worker = get_current_worker()
        # The depth sweep's set-up asks for the back focus set and locked: the whole chart's
        # edges read while the dialog is up, as the live view's focus aid does.
        procedure = getattr(self.runner, "procedure", None)
        chart_figure = (getattr(procedure, "name", "") == "depth" and step.id == "setup"
                        and getattr(getattr(procedure, "params", None), "view", "") == "forward")
        tracker = services.focus_tracker() if chart_figure else None
        best: list[float] = []
        try:
            while True:
                try:
                    return answer.result(timeout=0.25)
                except concurrent.futures.TimeoutError:
                    pass
                if app.abort_event.is_set() or worker.is_cancelled:
                    call_ui(app, self._close_prompt, dialog)
                    return False
                if step.kind == "focus":
                    self._update_focus_figure(dialog)
                elif tracker is not None:
                    self._update_chart_figure(dialog, tracker, best)
        finally:
            self._prompt = None

    def _close_prompt(self, dialog: PromptDialog) -> None:
        if dialog.is_attached and self.app.screen is dialog:
            dialog.dismiss(False)

    def _update_focus_figure(self, dialog: PromptDialog) -> None:
        app: Any = self.app
        try:
            if self.runner is None:
                raise RuntimeError("no run in progress")
            value = services.focus_sharpness(app.bench, self.runner)
        except Exception as exc:  # noqa: BLE001 - a figure, not a reason to stop the run
            text = f"sharpness: unavailable ({services.plain_error(exc)})"
        else:
            text = f"sharpness now: {value:.4g}  (turn the back focus to maximise it)"
        call_ui(app, dialog.set_live_figure, text)

    def _update_chart_figure(self, dialog: PromptDialog, tracker: Any, best: list[float]) -> None:
        """The edges' mean MTF50 of a fresh frame and the best so far (``best``, kept by the
        caller) in the prompt; the chart not found is said, never a stale number."""
        app: Any = self.app
        try:
            if self.runner is None:
                raise RuntimeError("no run in progress")
            pixels = services.procedure_frame(app.bench, self.runner)
            reading, mean, why = services.read_focus(tracker, pixels)
        except Exception as exc:  # noqa: BLE001 - a figure, not a reason to stop the run
            text = f"edges' MTF50: unavailable ({services.plain_error(exc)})"
        else:
            if reading is None or mean is None:
                text = why or "edges' MTF50: no edge read"
            else:
                best[:] = [max([mean, *best])]
                text = (f"edges' mean MTF50 now {mean:.1f} lp/mm, best {best[0]:.1f} "
                        "(turn the back focus to the best, then lock it)")
        call_ui(app, dialog.set_live_figure, text)
