"""Live view: the camera image with the ROI, its histogram and the focusing figures."""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

from rich.markup import escape
from textual import events, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.reactive import reactive
from textual.timer import Timer
from textual.widgets import Footer
from textual.worker import get_current_worker

from benchlab.analysis.bars.result import format_modulation
from benchlab.bench import plain_target
from benchlab.tui import services
from benchlab.tui.drawing.chart_overlay import (
    ChartFrameView,
    ChartGraphicsFrameView,
    pick_element,
    roi_of,
    set_overlay,
)
from benchlab.tui.drawing.pixels import GRAPHICS_PREVIEW_SIDE
from benchlab.tui.drawing.unwrap_view import UnwrapPreview
from benchlab.tui.focus_aid import FocusAidPanel, FrameSlot
from benchlab.tui.screen import BenchScreen
from benchlab.tui.ui_calls import call_ui
from benchlab.tui.widgets import FrameView, ModeBar, Readout, Roi, RoiHistogram

#: Exposure steps offered by the e / E keys, ms.
EXPOSURES_MS = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 300.0, 375.0, 500.0, 1000.0)
#: Gain steps offered by the g / G keys.
GAINS = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
#: Shortest time between two shown frames (the display is capped at 1 / this).
DISPLAY_INTERVAL_S = 1 / 20
#: How often the screen looks for a newer frame. Finer than the display interval so that a
#: frame taking a little longer than it to draw delays the next by a poll, not by a whole
#: interval (on a 50 ms grid, 55 ms of work would halve the rate to 10 Hz).
POLL_INTERVAL_S = 1 / 100
#: Cap on the acquisition loop so it never hogs the interpreter.
MAX_GRAB_RATE_HZ = 25.0
#: Orientations the o key cycles through ("auto": the analysis detects it).
ORIENTATIONS = ("auto", "sagittal", "tangential")
#: Targets the t key mounts on the simulated bench (a real bench's target is set by hand).
SIM_TARGETS: tuple[object, ...] = (
    "usaf", ("radial", 2.0, "sagittal"), ("radial", 2.0, "tangential"), "led", "dark",
)
#: With the chart overlay on, the chart is looked for again at most this often (the finder
#: takes ~0.1-0.3 s of the acquisition thread per full frame).
CHART_REFRESH_S = 1.0


def display_due(now_s: float, last_shown_s: float) -> bool:
    """Whether a new frame may be shown ``now_s``: the display interval has passed since the
    last one, give or take half a poll (so polls on a grid don't stretch it by one poll)."""
    return now_s - last_shown_s >= DISPLAY_INTERVAL_S - POLL_INTERVAL_S / 2


def _step(values: tuple[float, ...], current: float, direction: int) -> float:
    """The next value of ``values`` above (``direction`` 1) or below (-1) ``current``."""
    if direction > 0:
        return next((v for v in values if v > current + 1e-9), values[-1])
    return next((v for v in reversed(values) if v < current - 1e-9), values[0])


class LiveScreen(BenchScreen):
    """Continuous acquisition while this screen is shown; the newest frame wins."""

    DEFAULT_CSS = """
    LiveScreen #live-body { height: 1fr; }
    LiveScreen #frame { width: 2fr; border: round $primary; }
    LiveScreen #side { width: 1fr; min-width: 30; }
    LiveScreen #readout { height: auto; border: round $primary; padding: 0 1; }
    LiveScreen #histogram { height: 1fr; min-height: 5; max-height: 14; border: round $primary; }
    """
    BINDINGS = [
        Binding("up", "move(-1, 0)", "ROI", key_display="\u2190\u2191\u2193\u2192"),
        Binding("down", "move(1, 0)", "ROI down", show=False),
        Binding("left", "move(0, -1)", "ROI left", show=False),
        Binding("right", "move(0, 1)", "ROI right", show=False),
        Binding("plus,equals_sign", "resize(1)", "Size", key_display="+-"),
        Binding("minus", "resize(-1)", "Shrink", show=False),
        Binding("E", "exposure(1)", "Exposure", key_display="eE"),
        Binding("e", "exposure(-1)", "Exposure-", show=False),
        Binding("G", "gain(1)", "Gain", key_display="gG"),
        Binding("g", "gain(-1)", "Gain-", show=False),
        Binding("m", "estimator", "Method"),
        Binding("o", "orientation", "Orient"),
        Binding("z", "zoom", "Zoom"),
        Binding("t", "target", "Target"),
        Binding("c", "chart", "Chart"),
        Binding("f", "focus_aid", "Focus"),
        Binding("right_square_bracket", "pick(1)", "Pick", key_display="[]"),
        Binding("left_square_bracket", "pick(-1)", "Pick prev", show=False),
        Binding("u", "unwrap", "Unwrap"),
        # The peaks' reset is named in the focus-aid panel's title (the footer is full).
        Binding("r", "reset_peaks", "Reset peaks", show=False),
    ]

    exposure_ms: reactive[float] = reactive(300.0)
    gain: reactive[float] = reactive(1.0)
    #: Default ROI: one bar set of the forward-view USAF chart (move it with the arrows).
    roi: reactive[Roi] = reactive(Roi(598, 521, 10, 12))
    estimator: reactive[str] = reactive("")
    orientation: reactive[str] = reactive("auto")
    #: Show the ROI's surroundings instead of the whole frame.
    zoom: reactive[bool] = reactive(False)
    #: Find the USAF chart and draw its found elements (c); [ ] or a click picks one as ROI.
    chart: reactive[bool] = reactive(False)
    #: Show the radial annulus unwrapped (estimated orthographic view, thesis 5.2).
    unwrapped: reactive[bool] = reactive(False)
    #: The focus aid (f): the whole chart read on every frame the reader can take, as bars.
    focus_aid: reactive[bool] = reactive(False)

    def __init__(self) -> None:
        super().__init__()
        self._latest: services.LiveReading | None = None
        self._latest_lock = threading.Lock()
        self._shown_index = -1
        self._timer: Timer | None = None
        self._display_times: deque[float] = deque(maxlen=30)
        self._frame_shape: tuple[int, int] = (1024, 1280)
        self.frames_displayed = 0
        self._last_error = ""
        self._last_error_at = 0.0
        self._idle_reason = ""
        self._shown_settings: tuple[object, ...] = ()
        graphics = getattr(self.app, "image_protocol", "halfblock") in ("kitty", "sixel")
        self._preview_side = GRAPHICS_PREVIEW_SIDE if graphics else 320
        self.chart_fit: Any = None  # the latest ChartFit (None: off or not found)
        self._chart_at = 0.0
        self._chart_note = ""
        self._picked = -1
        self._chart_lock = threading.Lock()
        self._chart_gen = 0  # bumped by the c key: a fit started before it is dropped
        self._unwrap = UnwrapPreview()
        self._focus_slot = FrameSlot()
        self._focus_gen = 0  # bumped by the f key: a reading started before it is dropped
        self._focus_refind = threading.Event()  # set when the target changed: find it again

    def compose(self) -> ComposeResult:
        yield ModeBar("live")
        with Horizontal(id="live-body"):
            protocol = getattr(self.app, "image_protocol", "halfblock")
            if protocol in ("kitty", "sixel"):
                yield ChartGraphicsFrameView(protocol, id="frame")
            else:
                yield ChartFrameView(id="frame")
            with Vertical(id="side"):
                yield Readout("waiting for the camera...", id="readout")
                yield RoiHistogram(id="histogram")
                yield FocusAidPanel(id="focus-aid")
        yield Footer(compact=True)

    def on_mount(self) -> None:
        self.query_one("#frame").border_title = "camera"
        self.query_one("#histogram").border_title = "histogram peaks: D dark, B bright"
        self.query_one("#readout").border_title = "ROI"
        panel = self.query_one(FocusAidPanel)
        panel.border_title = "focus aid (r: reset peaks)"
        panel.display = False
        if not self.estimator:
            self.estimator = services.default_estimator()

    # -- acquisition runs only while the screen is visible ----------------------------------

    def on_screen_resume(self) -> None:
        self._timer = self.set_interval(POLL_INTERVAL_S, self._show_latest)
        self._acquire()
        if self.focus_aid:  # bars from before the screen was left are not current
            self.query_one(FocusAidPanel).show_problem("looking for the chart...")
            self._read_focus(self._focus_gen)

    def on_screen_suspend(self) -> None:
        if self._timer is not None:
            self._timer.stop()
            self._timer = None
        self.workers.cancel_group(self, "live")
        self.workers.cancel_group(self, "focus-aid")
        self._focus_slot.clear()

    @work(thread=True, exclusive=True, group="live", exit_on_error=False)
    def _acquire(self) -> None:
        worker = get_current_worker()
        app = self.app
        index = self._shown_index + 1  # frame numbers never repeat across restarts
        with app.device_activity():
            while not worker.is_cancelled:
                bench = app.bench
                if bench is None or app.procedure_running:
                    time.sleep(0.1)
                    continue
                started = time.monotonic()
                settings = (self.exposure_ms, self.gain)
                try:
                    with app.device_lock:
                        # Checked again under the lock: a run that started while this thread
                        # waited owns the camera now (it sets the flag, then takes the lock).
                        if app.procedure_running:
                            continue
                        if bench.simulated and bench.mounted is None:
                            services.mount_target(bench, SIM_TARGETS[0])
                        # The newest frame, without waiting for a new exposure (frames
                        # exposed at older settings are dropped by the driver: trailer).
                        frame = services.grab(bench, *settings, fresh=False)
                    orientation = None if self.orientation == "auto" else self.orientation
                    reading = services.live_reading(
                        frame, self.roi, self.estimator, orientation, index, *settings,
                        zoom=self.zoom, preview_max_side=self._preview_side,
                    )
                    if self.unwrapped:
                        reading = self._unwrap.apply(reading, frame[0], self._preview_side)
                except Exception as exc:  # noqa: BLE001 - shown in plain words, then retried
                    if not worker.is_cancelled:
                        call_ui(app, self._live_error, exc)
                    for _ in range(10):  # 1 s before retrying, cancellable every 0.1 s
                        if worker.is_cancelled:
                            break
                        time.sleep(0.1)
                    continue
                if self.focus_aid:  # the reader takes the newest; an untaken frame is dropped
                    self._focus_slot.offer(frame[0])
                if self.chart and time.monotonic() - self._chart_at >= CHART_REFRESH_S:
                    self._find_chart(frame[0])
                with self._latest_lock:
                    self._latest = reading
                index += 1
                spare = 1.0 / MAX_GRAB_RATE_HZ - (time.monotonic() - started)
                if spare > 0:
                    time.sleep(spare)

    @work(thread=True, exclusive=True, group="focus-aid", exit_on_error=False)
    def _read_focus(self, gen: int) -> None:
        """The focus aid's reader: the newest frame's whole-chart reading, to the panel."""
        worker = get_current_worker()
        tracker = services.focus_tracker()
        while not worker.is_cancelled:
            pixels = self._focus_slot.take(timeout_s=0.1)
            if pixels is None:
                continue
            if self._focus_refind.is_set():
                self._focus_refind.clear()
                tracker.reset()
            try:
                reading, summary, why = services.read_focus(tracker, pixels)
            except Exception as exc:  # noqa: BLE001 - said in the panel; the next frame is read
                tracker.reset()
                reading, summary, why = None, None, f"no reading: {services.plain_error(exc)}"
            if worker.is_cancelled:
                break
            call_ui(self.app, self._focus_read, gen, reading, summary, why)

    def _focus_read(self, gen: int, reading: Any, summary: float | None, why: str) -> None:
        app: Any = self.app
        if gen != self._focus_gen or not self.focus_aid or app.procedure_running:
            return  # read for a focus aid since switched off, or before a run took the camera
        panel = self.query_one(FocusAidPanel)
        if reading is None:
            panel.show_problem(why)
        else:
            panel.show_reading(reading, summary)

    def _find_chart(self, pixels: Any) -> None:
        """Look for the chart in one frame (acquisition thread); keep the fit or say why not."""
        from benchlab.analysis.chart.finder import ChartNotFoundError, find_chart

        self._chart_at = time.monotonic()
        gen = self._chart_gen
        try:
            fit = find_chart(pixels)
            p = fit.pose
            note = f"{len(fit.found)} found, scale {p.scale:.3f}, rot {p.rotation_deg:+.1f} deg"
        except (ChartNotFoundError, ValueError) as exc:
            fit, note = None, str(exc).split(":")[0]
        with self._chart_lock:
            if gen == self._chart_gen and self.chart:
                self.chart_fit, self._chart_note = fit, note

    def _live_error(self, exc: BaseException) -> None:
        """Notify once per distinct problem (at most every 5 s), not once per failed frame."""
        text = services.plain_error(exc)
        now = time.monotonic()
        if text != self._last_error or now - self._last_error_at > 5.0:
            self._last_error, self._last_error_at = text, now
            self.notify(text, title="Live view", severity="error", timeout=4)
        self.query_one(Readout).show(f"[red]{escape(text)}[/red]", urgent=True)

    def _show_idle(self) -> None:
        app: Any = self.app
        if app.bench is None:
            why = "bench not connected (Devices: c)"
        elif app.procedure_running:
            why = "a procedure is using the camera; live view paused"
        else:
            return
        if self._idle_reason != why:
            self._idle_reason = why
            self.query_one(FrameView).clear()
            if self.focus_aid:  # no frames: the last bars are not current any more
                self.query_one(FocusAidPanel).show_problem(why)
            self.query_one(Readout).show(f"[dim]{why}[/dim]", urgent=True)

    def _show_latest(self) -> None:
        app: Any = self.app
        if app.bench is None or app.procedure_running:
            self._show_idle()
            return
        self._idle_reason = ""
        now = time.monotonic()
        if self._display_times and not display_due(now, self._display_times[-1]):
            return
        with self._latest_lock:
            reading = self._latest
        if reading is None or reading.index == self._shown_index:
            return
        self._shown_index = reading.index
        self._frame_shape = reading.frame_shape
        self.frames_displayed += 1
        self._display_times.append(now)
        view = self.query_one("#frame", FrameView)
        fit = self.chart_fit if self.chart and not self.zoom and not self.unwrapped else None
        set_overlay(view, [el.roi for el in fit.found] if fit is not None else [],
                    reading.frame_shape)
        roi = None if self.unwrapped else reading.preview_roi  # no ROI box on the unwrapped
        view.show(reading.preview, roi, reading.max_code)
        # The side panel follows at a few Hz (a changed setting at once): redrawing it with
        # every frame cost more than the frame itself at large terminal sizes.
        settings = (reading.roi, reading.exposure_ms, reading.gain, self.estimator,
                    self.orientation, self.zoom, self.chart, self.unwrapped)
        changed, self._shown_settings = settings != self._shown_settings, settings
        self.query_one(RoiHistogram).show(reading.roi_pixels, reading.max_code, *reading.peaks,
                                          force=changed)
        self.query_one(Readout).show(self._readout_text(reading), urgent=changed)

    @property
    def display_rate_hz(self) -> float:
        """Frames shown per second over the last (up to) 30 updates."""
        if len(self._display_times) < 2:
            return 0.0
        span = self._display_times[-1] - self._display_times[0]
        return (len(self._display_times) - 1) / span if span > 0 else 0.0

    def _readout_text(self, r: services.LiveReading) -> str:
        def num(value: float | None, fmt: str) -> str:
            return "n/a" if value is None else format(value, fmt)

        mod = format_modulation(r.modulation, r.resolved, r.lower_bound)
        clipped = num(None if r.clipped_fraction is None else 100 * r.clipped_fraction, ".2f")
        lines = [
            f"{r.roi.label()}",
            f"exposure {r.exposure_ms:g} ms  gain {r.gain:g}",
            f"method {self.estimator}  {self.orientation}{'  zoom' if self.zoom else ''}",
            f"modulation [b]{mod}[/b]",
            f"dark {num(r.dark, '.1f')}  bright {num(r.bright, '.1f')}",
            f"clipped {clipped} %",
            f"sharpness [b]{num(r.sharpness, '.4g')}[/b]",
            f"frame {r.index}  view {self.display_rate_hz:.1f} Hz",
        ]
        if self.chart:
            lines.append(f"chart: {escape(self._chart_note or 'looking...')}")
        if r.note:
            lines.append(f"[yellow]{escape(r.note)}[/yellow]")
        return "\n".join(lines)

    # -- keys -------------------------------------------------------------------------------

    def action_move(self, d_row: int, d_col: int) -> None:
        step = max(2, min(self.roi.height, self.roi.width) // 4)
        self.roi = self.roi.moved(d_row * step, d_col * step, self._frame_shape)

    def action_resize(self, direction: int) -> None:
        d_h = direction * max(2, self.roi.height // 4)
        d_w = direction * max(2, self.roi.width // 4)
        self.roi = self.roi.resized(d_h, d_w, self._frame_shape)

    def action_zoom(self) -> None:
        self.zoom = not self.zoom

    def action_chart(self) -> None:
        with self._chart_lock:
            self._chart_gen += 1
            self.chart = not self.chart
            self._chart_at, self._chart_note, self._picked = 0.0, "", -1
            self.chart_fit = None
        if not self.chart:
            set_overlay(self.query_one("#frame", FrameView), [], self._frame_shape)
        self.notify("chart overlay " + ("on: [ ] or a click picks an element" if self.chart
                                        else "off"), timeout=1.5)

    def action_pick(self, direction: int) -> None:
        fit = self.chart_fit
        if not self.chart or fit is None or not fit.found:
            self.notify("no found chart elements (c turns the chart overlay on)",
                        severity="warning", timeout=2)
            return
        self._picked = (self._picked + direction) % len(fit.found)
        self._use_element(fit.found[self._picked])

    def _use_element(self, el: Any) -> None:
        self.roi = roi_of(el)
        self.orientation = el.posed.orientation
        self.notify(f"ROI: {el.label} ({el.posed.image_lp_per_mm:.1f} lp/mm)", timeout=1.5)

    def on_click(self, event: events.Click) -> None:
        """A click on the frame picks the found element under it (chart overlay on)."""
        fit = self.chart_fit
        view = self.query_one("#frame", FrameView)
        if (not self.chart or fit is None or self.zoom or self.unwrapped
                or event.widget is not view
                or not isinstance(view, ChartFrameView)):  # image views: keys only
            return
        point = view.cell_to_frame(event.x, event.y)
        el = pick_element(fit, point) if point is not None else None
        if el is not None:
            self._picked = fit.found.index(el)
            self._use_element(el)

    def action_focus_aid(self) -> None:
        """Show or hide the focus aid; its reader runs only while it is shown."""
        self._focus_gen += 1
        self.focus_aid = not self.focus_aid
        panel = self.query_one(FocusAidPanel)
        self.workers.cancel_group(self, "focus-aid")
        self._focus_slot.clear()
        panel.clear()
        panel.display = self.focus_aid
        self.query_one(Readout).display = not self.focus_aid
        self.query_one(RoiHistogram).display = not self.focus_aid
        if self.focus_aid:
            self._read_focus(self._focus_gen)
        self.notify("focus aid " + ("on: turn the focus for the longest bars (r: reset peaks)"
                                    if self.focus_aid else "off"), timeout=1.5)

    def action_reset_peaks(self) -> None:
        if not self.focus_aid:
            self.notify("the focus aid is off (f)", severity="warning", timeout=1.5)
            return
        self.query_one(FocusAidPanel).reset_peaks()
        self.notify("peaks reset", timeout=1.5)

    def action_unwrap(self) -> None:
        self.unwrapped = not self.unwrapped
        self._unwrap.reset()
        self.query_one("#frame").border_title = "camera, unwrapped" if self.unwrapped else "camera"

    def action_target(self) -> None:
        self._mount_next_target()

    @work(thread=True, group="live-target", exit_on_error=False)
    def _mount_next_target(self) -> None:
        app: Any = self.app
        bench = app.bench
        if bench is None or not bench.simulated or app.procedure_running:
            call_ui(app, self.notify, "Targets are mounted by hand on a real bench.",
                    severity="warning")
            return
        current = plain_target(bench.mounted)
        names = [plain_target(t) for t in SIM_TARGETS]
        nxt = SIM_TARGETS[(names.index(current) + 1) % len(SIM_TARGETS)] if current in names \
            else SIM_TARGETS[0]
        try:
            with app.device_lock:
                services.mount_target(bench, nxt)
                self._focus_refind.set()
        except Exception as exc:  # noqa: BLE001
            call_ui(app, app.show_error, "Could not mount the target", exc)
            return
        call_ui(app, self.notify, f"simulated target: {services.target_words(nxt)}")

    def action_exposure(self, direction: int) -> None:
        self.exposure_ms = _step(EXPOSURES_MS, self.exposure_ms, direction)

    def action_gain(self, direction: int) -> None:
        self.gain = _step(GAINS, self.gain, direction)

    def action_estimator(self) -> None:
        names = services.estimator_names()
        if names:
            i = names.index(self.estimator) if self.estimator in names else -1
            self.estimator = names[(i + 1) % len(names)]
            self.notify(f"estimator: {self.estimator}", timeout=1.5)

    def action_orientation(self) -> None:
        i = ORIENTATIONS.index(self.orientation) if self.orientation in ORIENTATIONS else -1
        self.orientation = ORIENTATIONS[(i + 1) % len(ORIENTATIONS)]
