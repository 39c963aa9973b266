"""Devices panel: identities and state, LEDs off, homing, disconnect and reconnect."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest
from test_tui_helpers import connected, make_app, wait_until
from textual.widgets import Static

from benchlab.tui import services
from benchlab.tui.devices import DevicesScreen


def _panel(screen: DevicesScreen, wid: str) -> str:
    return str(screen.query_one(f"#{wid}", Static).render())


@pytest.mark.slow
@pytest.mark.asyncio
async def test_devices_panel_shows_state_and_controls_the_bench(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await connected(pilot)
        screen = app.screen
        assert isinstance(screen, DevicesScreen)
        await wait_until(pilot, lambda: "position" in _panel(screen, "stage"), what="stage")
        assert "SIM-130001" in _panel(screen, "camera") and "1.0.6" in _panel(screen, "camera")
        assert "homed     no" in _panel(screen, "stage")
        leds = _panel(screen, "leds")
        assert "ch 1      off" in leds and "limit 50" in leds

        bench = app.bench
        bench.led_on(1, 20.0)  # e.g. left on by a script
        await wait_until(pilot, lambda: "ch 1      ON" in _panel(screen, "leds"), what="LED on")
        await pilot.press("o")
        await wait_until(pilot, lambda: bench.sim_led.channel_output_ma(1) == 0, what="off")
        await wait_until(pilot, lambda: "ch 1      off" in _panel(screen, "leds"), what="shown")

        await pilot.press("h")
        await wait_until(pilot, lambda: "homed     yes" in _panel(screen, "stage"), what="home")

        await pilot.press("x")
        await wait_until(pilot, lambda: app.bench is None, what="disconnect")
        await wait_until(pilot, lambda: "not connected" in _panel(screen, "camera"),
                         what="panels cleared")
        assert "disconnected" in str(screen.query_one("#bench-status", Static).render())
        await pilot.press("c")
        await connected(pilot)
        await wait_until(pilot, lambda: "SIM-130001" in _panel(screen, "camera"), what="again")


class _GatedLock:
    """The app's device lock, saying when a thread starts waiting for it."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.waiting = threading.Event()

    def __enter__(self) -> _GatedLock:
        self.waiting.set()
        self.lock.acquire()
        return self

    def __exit__(self, *_: object) -> None:
        self.lock.release()


@pytest.mark.asyncio
async def test_a_device_read_waiting_for_the_lock_leaves_a_starting_run_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await connected(pilot)
        screen = app.screen
        assert isinstance(screen, DevicesScreen)
        await pilot.press("4")  # no polling from here: the read below is the only one
        await wait_until(pilot, lambda: not any(
            w.group == "devices" and not w.is_finished for w in app.workers), what="idle")
        reads: list[bool] = []
        real = services.describe_devices

        def describe(bench: Any, live: bool) -> Any:
            reads.append(live)
            return real(bench, live=live)

        monkeypatch.setattr(services, "describe_devices", describe)
        gate = _GatedLock()
        app.device_lock = gate  # type: ignore[assignment]
        gate.lock.acquire()  # e.g. the last live-view grab
        try:
            screen._read_devices()
            await wait_until(pilot, gate.waiting.is_set, what="the read waiting for the lock")
            app.procedure_running = True  # a run starts: its thread takes the lock next
        finally:
            gate.lock.release()
        await wait_until(pilot, lambda: bool(reads) and not any(
            w.group == "devices" and not w.is_finished for w in app.workers), what="read")
        assert reads == [False]  # the cached identity, not a live exchange with the devices
        app.procedure_running = False
