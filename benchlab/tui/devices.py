"""Devices panel: what is connected, its identity and state, connect / disconnect."""

from __future__ import annotations

from typing import Any

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid
from textual.widgets import Footer, Static
from textual.worker import get_current_worker

from benchlab.tui import services
from benchlab.tui.screen import BenchScreen
from benchlab.tui.ui_calls import call_ui
from benchlab.tui.widgets import ModeBar

REFRESH_S = 1.0


def format_rows(rows: list[tuple[str, str]]) -> str:
    """``label  value`` lines, labels aligned."""
    if not rows:
        return "[dim]not connected[/dim]"
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


class DevicesScreen(BenchScreen):
    """Camera, LED controller and stage: identity, state, errors in plain words."""

    DEFAULT_CSS = """
    DevicesScreen #bench-status { height: auto; padding: 0 1; background: $boost; }
    DevicesScreen Grid { grid-size: 2 2; grid-columns: 1fr 1fr; height: 1fr; }
    DevicesScreen .device { border: round $primary; padding: 0 1; height: 100%; }
    DevicesScreen Grid { grid-rows: auto 1fr; }
    DevicesScreen #camera { height: auto; }
    DevicesScreen #leds { row-span: 2; }
    """
    BINDINGS = [
        Binding("c", "connect", "Connect"),
        Binding("x", "disconnect", "Disconnect"),
        Binding("h", "home", "Home stage"),
        Binding("o", "safe", "LEDs off"),
    ]

    def compose(self) -> ComposeResult:
        yield ModeBar("devices")
        yield Static("", id="bench-status")
        with Grid():
            yield Static("", id="camera", classes="device")
            yield Static("", id="leds", classes="device")
            yield Static("", id="stage", classes="device")
        yield Footer(compact=True)

    def on_mount(self) -> None:
        for wid, title in (("camera", "camera"), ("leds", "LED controller"), ("stage", "stage")):
            self.query_one(f"#{wid}").border_title = title
        self.watch(self.app, "bench_status", self._on_bench_status)
        self.set_interval(REFRESH_S, self._poll)
        self._poll()

    def _on_bench_status(self, status: str) -> None:
        self.query_one("#bench-status", Static).update(f"bench: [b]{status}[/b]")
        self._poll()

    def _poll(self) -> None:
        if self.app.screen is self:
            self._read_devices()

    @work(thread=True, exclusive=True, group="devices", exit_on_error=False)
    def _read_devices(self) -> None:
        app: Any = self.app
        bench = app.bench
        if bench is None:
            info: dict[str, list[tuple[str, str]]] = {"camera": [], "leds": [], "stage": []}
        else:
            with app.device_activity():
                # procedure_running is read under the lock: a run sets it before its thread
                # passes the lock, so a read that got the lock first ends before the run starts
                with app.device_lock:
                    live = not app.procedure_running
                    if live:
                        info = services.describe_devices(bench, live=True)
                if not live:  # the runner owns the devices: show the cached identity
                    info = services.describe_devices(bench, live=False)
        if not get_current_worker().is_cancelled:
            call_ui(app, self._show, info)

    def _show(self, info: dict[str, list[tuple[str, str]]]) -> None:
        for key in ("camera", "leds", "stage"):
            self.query_one(f"#{key}", Static).update(format_rows(info.get(key, [])))

    def action_connect(self) -> None:
        self.app.connect_bench()

    def action_disconnect(self) -> None:
        self.app.disconnect_bench()

    def action_safe(self) -> None:
        self._device_action("safe")

    def action_home(self) -> None:
        self._device_action("home")

    @work(thread=True, group="device-action", exit_on_error=False)
    def _device_action(self, what: str) -> None:
        app: Any = self.app
        if app.bench is None:
            call_ui(app, self.notify, "The bench is not connected.", severity="warning")
            return
        if app.procedure_running:
            call_ui(app, self.notify, "A procedure is running.", severity="warning")
            return
        try:
            with app.device_activity(), app.device_lock:
                if app.procedure_running:  # started while this thread waited for the lock
                    call_ui(app, self.notify, "A procedure is running.",
                                         severity="warning")
                    return
                message = services.device_action(app.bench, what, stop=app.device_stop)
        except Exception as exc:  # noqa: BLE001 - shown in plain words
            call_ui(app, app.show_error, "Device command failed", exc)
            return
        call_ui(app, self.notify, message)
        call_ui(app, self._poll)
