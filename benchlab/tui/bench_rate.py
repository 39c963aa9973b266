"""``benchlab benchmark tui``: how many frames a second the live view shows, per terminal size
and drawing method, on the simulated bench (headless Textual, the same code as on screen).

Besides the rate, it reports CPU time per shown frame: of the UI thread (compositing, drawing,
image encoding: what limits the display rate) and of the whole process (with acquisition and
the simulated camera). CPU time hardly depends on other load, so ``1000 / all ms`` (capped at
the display's 20 Hz) is the rate the view reaches on a quiet machine even if acquisition and
drawing could never overlap (they share the interpreter lock; numpy and OpenCV release it, so
the real rate is at least this). ``cam/shown`` counts the frames read from the (simulated)
camera per frame shown: the live view takes the newest frame, one read per grab.

A second table times grabs on the camera simulator running on wall time, as a real camera
does: the newest frame (the live view) against a fresh frame exposed wholly after the request
(measurements), which waits out the exposure already under way and then a whole new one.

Run as a module, it measures the live view's focus aid instead (:func:`focus_aid_rate`)::

    python -m benchlab.tui.bench_rate [--seconds 10] [--size 120x36]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from benchlab.tui.live import DISPLAY_INTERVAL_S, MAX_GRAB_RATE_HZ

SIZES = ((80, 24), (120, 36), (200, 60))


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Kitty's protocol writes images straight to the terminal: send them nowhere here."""
    saved = os.dup(1)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


@dataclass(frozen=True)
class Rate:
    """One case's figures."""

    protocol: str
    size: tuple[int, int]
    hz: float  #: frames shown per second (wall clock: depends on the machine's load)
    ui_ms: float  #: UI-thread CPU per shown frame
    process_ms: float  #: whole-process CPU per shown frame
    reads_per_frame: float  #: frames read from the camera per shown frame

    @property
    def implied_hz(self) -> float:
        """The rate the whole process's CPU per frame allows, capped at the display rate."""
        if self.process_ms <= 0:
            return 0.0
        return min(1.0 / DISPLAY_INTERVAL_S, 1000.0 / self.process_ms)


async def _measure(size: tuple[int, int], protocol: str, seconds: float) -> tuple[float, ...]:
    from benchlab.tui.app import BenchlabApp
    from benchlab.tui.live import LiveScreen

    with tempfile.TemporaryDirectory() as tmp:
        app = BenchlabApp(simulate=True, sessions_dir=Path(tmp), image_protocol=protocol)
        async with app.run_test(size=size) as pilot:
            while app.bench is None:
                await pilot.pause(0.05)
            await pilot.press("2")
            screen = app.screen
            assert isinstance(screen, LiveScreen)
            await pilot.pause(1.5)  # warm up: first frames, caches
            camera = app.bench.sim_camera
            assert camera is not None  # the simulated bench
            n0, t0 = screen.frames_displayed, time.monotonic()
            ui0, cpu0 = time.thread_time(), time.process_time()  # the app runs on this thread
            reads0 = camera.frames_sent
            await pilot.pause(seconds)
            n1, t1 = screen.frames_displayed, time.monotonic()
            ui1, cpu1 = time.thread_time(), time.process_time()
            reads1 = camera.frames_sent
            n = max(1, n1 - n0)
            return ((n1 - n0) / (t1 - t0), 1000 * (ui1 - ui0) / n, 1000 * (cpu1 - cpu0) / n,
                    (reads1 - reads0) / n)


def live_view_rates(seconds: float = 4.0, protocols: tuple[str, ...] = (
        "halfblock", "sixel", "kitty")) -> Iterator[Rate]:
    """Frames shown per second and CPU per frame for each drawing method and terminal size."""
    for protocol in protocols:
        for size in SIZES:
            with _quiet_stdout() if protocol == "kitty" else contextlib.nullcontext():
                hz, ui_ms, process_ms, reads = asyncio.run(_measure(size, protocol, seconds))
            yield Rate(protocol, size, hz, ui_ms, process_ms, reads)


def grab_rates(exposures_ms: tuple[float, ...], seconds: float) -> Iterator[tuple[float, ...]]:
    """``(exposure ms, newest-frame grabs/s, fresh-frame grabs/s)`` through ``Bench.grab`` on
    the camera simulator running on wall time (a real camera's frame period)."""
    from benchlab.bench import Bench, BenchConfig
    from benchlab.drivers.mightex.camera import MightexCamera
    from benchlab.drivers.mightex.sim import RealTimeClock, SimCameraBackend, SimulatedCamera

    bench = Bench(BenchConfig.load(None, simulate=True), simulated=True)
    sim = SimulatedCamera(clock=RealTimeClock(), noise=False)
    with MightexCamera.open(backend=SimCameraBackend([sim])) as camera:
        bench.camera = camera
        bench.configure_camera()
        for exposure_ms in exposures_ms:
            rates = []
            for fresh in (False, True):
                bench.grab(exposure_ms=exposure_ms, gain=1.0, fresh=True)  # settled
                n, t0 = 0, time.monotonic()
                while time.monotonic() - t0 < seconds:
                    bench.grab(exposure_ms=exposure_ms, gain=1.0, fresh=fresh)
                    n += 1
                rates.append(n / (time.monotonic() - t0))
            yield (exposure_ms, *rates)


def main(seconds: float, protocols: tuple[str, ...]) -> int:
    print(f"live view on the simulated bench, {seconds:g} s per case (display capped at "
          f"{1 / DISPLAY_INTERVAL_S:g} Hz, acquisition at {MAX_GRAB_RATE_HZ:g} Hz); CPU ms per "
          f"shown frame; 'implied' = min({1 / DISPLAY_INTERVAL_S:g}, 1000 / all ms)")
    print(f"{'method':<10} {'terminal':>9} {'frames/s':>9} {'UI ms':>7} {'all ms':>7} "
          f"{'implied/s':>9} {'cam/shown':>9}")
    for r in live_view_rates(seconds, protocols):
        w, h = r.size
        print(f"{r.protocol:<10} {f'{w}x{h}':>9} {r.hz:9.1f} {r.ui_ms:7.1f} "
              f"{r.process_ms:7.1f} {r.implied_hz:9.1f} {r.reads_per_frame:9.2f}", flush=True)
    print(f"\ngrabs per second, camera simulator on wall time, {seconds:g} s per case: "
          "newest frame (live view) vs fresh frame (measurements)")
    print(f"{'exposure ms':>11} {'newest/s':>9} {'fresh/s':>8}")
    for exposure_ms, newest_hz, fresh_hz in grab_rates((20.0, 100.0), seconds):
        print(f"{exposure_ms:11g} {newest_hz:9.1f} {fresh_hz:8.1f}", flush=True)
    return 0


async def focus_aid_rate(seconds: float, size: tuple[int, int] = (120, 36)) -> dict[str, float]:
    """Whole-chart readings the focus aid's panel shows per second on the simulated bench
    (1280 x 1024, 8 bit), counted over ``seconds`` after a warm-up, with everything the live
    view does meanwhile (acquisition at up to 25 frames/s, preview, ROI readout) on the same
    interpreter; and the frames offered to / dropped by its reader. ``benchlab benchmark
    focus-aid`` times the reading alone."""
    from textual.widgets import Static

    from benchlab.tui.app import BenchlabApp
    from benchlab.tui.dialogs import ErrorDialog
    from benchlab.tui.focus_aid import FocusAidPanel
    from benchlab.tui.live import LiveScreen

    with tempfile.TemporaryDirectory() as tmp:
        app = BenchlabApp(simulate=True, sessions_dir=Path(tmp))
        async with app.run_test(size=size) as pilot:
            deadline = time.monotonic() + 60.0
            while app.bench is None:  # an error dialog (a starved simulator) ends the wait
                if isinstance(app.screen, ErrorDialog) or time.monotonic() > deadline:
                    raise RuntimeError("the simulated bench did not connect: "
                                       f"{app.screen.query_one('#error-text', Static).render()}"
                                       if isinstance(app.screen, ErrorDialog) else
                                       "the simulated bench did not connect within 60 s")
                await pilot.pause(0.05)
            await pilot.press("2")
            screen = app.screen
            assert isinstance(screen, LiveScreen)
            await pilot.press("f")
            panel = screen.query_one(FocusAidPanel)
            deadline = time.monotonic() + 30.0
            while panel.readings_shown < 5 and time.monotonic() < deadline:
                await pilot.pause(0.05)  # warm-up: the chart found, caches filled
            slot = screen._focus_slot
            n0, off0, drop0, t0 = (panel.readings_shown, slot.offered, slot.dropped,
                                   time.monotonic())
            cpu0 = time.process_time()
            await pilot.pause(seconds)
            n1, off1, drop1, t1 = (panel.readings_shown, slot.offered, slot.dropped,
                                   time.monotonic())
            cpu1 = time.process_time()
            return {"readings_per_s": (n1 - n0) / (t1 - t0),
                    "cpu_per_s": (cpu1 - cpu0) / (t1 - t0),
                    "frames_per_s": (off1 - off0) / (t1 - t0),
                    "dropped_fraction": (drop1 - drop0) / max(1, off1 - off0),
                    "sets": float(sum(v is not None for v in panel.reading.modulation.values()))
                    if panel.reading is not None else 0.0}


def focus_aid_main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="Readings per second of the live view's focus aid (simulated bench).")
    parser.add_argument("--seconds", type=float, default=10.0, help="measuring window (10 s)")
    parser.add_argument("--size", default="120x36", help="terminal columns x rows (120x36)")
    args = parser.parse_args(argv)
    cols, rows = (int(x) for x in args.size.lower().split("x"))
    r = asyncio.run(focus_aid_rate(args.seconds, (cols, rows)))
    print(f"focus aid, simulated bench 1280x1024 8 bit, terminal {cols}x{rows}, "
          f"{args.seconds:g} s: {r['readings_per_s']:.1f} readings shown/s, "
          f"{r['frames_per_s']:.1f} frames/s offered, {100 * r['dropped_fraction']:.0f} % "
          f"dropped, {r['sets']:.0f} sets read; the process got {r['cpu_per_s']:.2f} CPU s/s: "
          f"{r['readings_per_s'] / max(r['cpu_per_s'], 1e-9):.1f} readings per CPU second")
    return 0


if __name__ == "__main__":
    raise SystemExit(focus_aid_main())
