"""The benchlab Textual application: one mode per job, the bench shared between them."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from textual import work
from textual.app import App
from textual.binding import Binding
from textual.reactive import reactive
from textual.worker import get_current_worker

from benchlab.tui import services
from benchlab.tui.devices import DevicesScreen
from benchlab.tui.dialogs import ConfirmDialog, ErrorDialog
from benchlab.tui.live import LiveScreen
from benchlab.tui.runner import RunScreen
from benchlab.tui.sessions import SessionsScreen
from benchlab.tui.signal_exit import SignalExit
from benchlab.tui.ui_calls import call_ui

if TYPE_CHECKING:
    from benchlab.bench import Bench


class BenchlabApp(App[None]):
    """Devices, live view, procedure runner and sessions, keyboard first."""

    TITLE = "benchlab"
    ENABLE_COMMAND_PALETTE = False
    CSS = """
    Screen { layout: vertical; }
    .panel { border: round $primary; padding: 0 1; height: auto; }
    .panel-title { text-style: bold; }
    .status { height: 1; background: $boost; padding: 0 1; }
    """
    MODES = {
        "devices": DevicesScreen,
        "live": LiveScreen,
        "run": RunScreen,
        "sessions": SessionsScreen,
    }
    DEFAULT_MODE = "devices"
    BINDINGS = [
        # shown in each screen's mode bar rather than the footer (which keeps the screen's keys)
        Binding("1", "switch_mode('devices')", "Devices", show=False),
        Binding("2", "switch_mode('live')", "Live", show=False),
        Binding("3", "switch_mode('run')", "Run", show=False),
        Binding("4", "switch_mode('sessions')", "Sessions", show=False),
        Binding("q", "quit", "Quit", priority=True, show=False),
    ]

    #: One line describing the bench connection ("connected (simulated)", "disconnected", ...).
    bench_status: reactive[str] = reactive("disconnected")
    #: True while a procedure runs (the live view then leaves the camera alone).
    procedure_running: reactive[bool] = reactive(False)

    def __init__(
        self,
        *,
        simulate: bool = True,
        config: Path | None = None,
        sessions_dir: Path | None = None,
        autoconnect: bool = True,
        seed: int | None = 0,
        params_files: dict[str, Path] | None = None,
        operator: str = "",
        image_protocol: str = "halfblock",
    ) -> None:
        super().__init__()
        #: How the live view draws frames: "kitty" / "sixel" (real pixels) or "halfblock";
        #: chosen before the app starts (:func:`benchlab.tui.drawing.pixels.choose_image_protocol`).
        self.image_protocol = image_protocol
        self.simulate = simulate
        self.config_path = config
        self.sessions_dir = Path(sessions_dir) if sessions_dir else Path("sessions")
        self.autoconnect = autoconnect
        self.seed = seed
        #: Parameter file per procedure (``None``: the packaged defaults).
        self.params_files: dict[str, Path | None] = dict(params_files or {})
        #: Recorded in ``session.json`` of every run started here.
        self.operator = operator
        self.bench: Bench | None = None
        self._opened: services.OpenedBench | None = None
        #: Serialises device access between the live view, the devices panel and the runner.
        self.device_lock = threading.RLock()
        #: Set to stop a running procedure (abort key, quit).
        self.abort_event = threading.Event()
        #: Set once the app quits: stops a stage homing from the Devices screen at once.
        self.device_stop = threading.Event()
        self._activity = threading.Condition()
        self._active_threads = 0
        #: Set when closing the bench failed (e.g. LEDs not confirmed off); the CLI reports it.
        self.close_error: BaseException | None = None
        #: The stop signal (SIGTERM, SIGHUP, SIGINT) that ended the app, if one did.
        self.stop_signal: int | None = None
        self._signal_loop: asyncio.AbstractEventLoop | None = None
        #: Ends the process if the orderly quit after a stop signal hangs (a closed terminal).
        self.signal_exit = SignalExit(self)

    def on_mount(self) -> None:
        self._signal_loop = asyncio.get_running_loop()
        self.sub_title = "simulated bench" if self.simulate else "bench"
        if self.autoconnect:
            self.connect_bench()

    # -- the bench -------------------------------------------------------------------------

    @work(thread=True, exclusive=True, group="bench", exit_on_error=False)
    def connect_bench(self) -> None:
        """Open the bench (devices) in a thread; errors become a dialog."""
        if self.bench is not None:
            return
        call_ui(self, setattr, self, "bench_status", "connecting...")
        with self.device_activity():
            try:
                opened = services.open_bench(self.config_path, self.simulate, seed=self.seed)
            except Exception as exc:  # noqa: BLE001 - shown to the operator in plain words
                call_ui(self, setattr, self, "bench_status", "disconnected")
                call_ui(self, self.show_error, "Could not connect the bench", exc)
                return
            if get_current_worker().is_cancelled:
                opened.close()
                return
            self._opened, self.bench = opened, opened.bench
        kind = "simulated" if self.simulate else "hardware"
        call_ui(self, setattr, self, "bench_status", f"connected ({kind})")

    @work(thread=True, exclusive=True, group="bench", exit_on_error=False)
    def disconnect_bench(self) -> None:
        """LEDs off, stage stopped, devices closed."""
        if self.procedure_running:
            call_ui(self, self.notify, "Abort the running procedure first.", severity="warning")
            return
        error = self._close_bench()
        call_ui(self, setattr, self, "bench_status", "disconnected")
        if error is not None:
            call_ui(self, self.show_error, "The bench may not be safe", error)

    def _close_bench(self) -> BaseException | None:
        """Safe state and close; an error is kept in :attr:`close_error` and returned."""
        with self.device_lock:
            opened, self._opened, self.bench = self._opened, None, None
            if opened is None:
                return None
            try:
                opened.close()
            except Exception as exc:  # noqa: BLE001 - closing must not crash the UI
                self.log.error(f"closing the bench: {exc!r}")
                self.close_error = exc
                return exc
            return None

    def force_close_bench(self, lock_timeout_s: float) -> BaseException | None:
        """Safe state and close from the signal watchdog: waits ``lock_timeout_s`` for the
        device lock, then closes without it (a thread stuck mid-exchange must not keep the
        LEDs lit); returns the error of the close, if any."""
        locked = self.device_lock.acquire(timeout=lock_timeout_s)
        try:
            opened, self._opened, self.bench = self._opened, None, None
            if opened is None:
                return None
            try:
                opened.close()
            except Exception as exc:  # noqa: BLE001 - reported by the watchdog
                self.close_error = exc
                return exc
            return None
        finally:
            if locked:
                self.device_lock.release()

    @contextmanager
    def device_activity(self) -> Iterator[None]:
        """Wrap a thread worker's device work so quitting waits for it to wind down."""
        with self._activity:
            self._active_threads += 1
        try:
            yield
        finally:
            with self._activity:
                self._active_threads -= 1
                self._activity.notify_all()

    def wait_for_device_threads(self, timeout_s: float = 15.0) -> bool:
        """Block until no thread worker is inside :meth:`device_activity`."""
        with self._activity:
            return self._activity.wait_for(lambda: self._active_threads == 0, timeout_s)

    async def resume_session(self, path: Path) -> None:
        """Switch to the runner and continue ``path`` from its first incomplete step."""
        await self.switch_mode("run")
        screen = self.screen
        if isinstance(screen, RunScreen):
            screen.resume(path)

    def show_error(self, title: str, exc: BaseException | str) -> None:
        """A dialog with the error in plain words."""
        text = exc if isinstance(exc, str) else services.plain_error(exc)
        self.push_screen(ErrorDialog(title, text))

    def on_unmount(self) -> None:
        """Whatever way the app ends: stop the runner, leave the bench safe and closed."""
        self.abort_event.set()
        self.device_stop.set()
        self.workers.cancel_all()
        if self.bench is not None:
            self.wait_for_device_threads(timeout_s=10.0)
            self._close_bench()

    def stop_from_signal(self, signum: int) -> None:
        """SIGTERM / SIGHUP / SIGINT (see :mod:`benchlab.drivers.shutdown`): quit at once, as a
        confirmed ``q`` does (nobody is there to confirm) - runner aborted, LEDs off, stage
        stopped. Runs inside the signal handler, so it only schedules the quit, and starts
        the watchdog that ends the process within seconds if the quit hangs
        (:mod:`benchlab.tui.signal_exit`)."""
        self.stop_signal = self.stop_signal or signum
        self.signal_exit.on_signal(signum)
        loop = self._signal_loop
        if loop is None or loop.is_closed():
            return  # not mounted yet or already closed: on_unmount / the bench context clean up
        loop.call_soon_threadsafe(self.call_later, self.quit_now)

    async def action_quit(self) -> None:
        """Quit; while a run is active, ask first (``q`` again or ``y`` confirms)."""
        if self.procedure_running:
            if isinstance(self.screen, ConfirmDialog):  # q pressed again: that is a yes
                self.screen.dismiss(True)
                return
            self.push_screen(ConfirmDialog(
                "Quit while a run is active?",
                "Quitting aborts the run: LEDs off, stage stopped. The session keeps every "
                "frame saved so far and can be resumed (Sessions, u).",
                yes=("y/q", "Quit"), no=("n", "Keep running")), self._quit_confirmed)
            return
        await self.quit_now()

    async def _quit_confirmed(self, yes: bool | None) -> None:
        if yes:
            await self.quit_now()

    async def quit_now(self) -> None:
        """Stop every worker, leave the bench safe (LEDs off, stage stopped), exit."""
        self.abort_event.set()
        self.device_stop.set()
        self.workers.cancel_all()
        await asyncio.to_thread(self.wait_for_device_threads)
        await asyncio.to_thread(self._close_bench)
        self.exit()
