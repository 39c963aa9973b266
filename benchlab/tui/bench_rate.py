"""``benchlab benchmark tui``: how many frames a second the live view shows, per terminal size
and drawing method, on the simulated bench (headless Textual, the same code as on screen)."""

from __future__ import annotations

import asyncio
import contextlib
import os
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

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


async def _measure(size: tuple[int, int], protocol: str, seconds: float) -> tuple[float, float]:
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
            n0, t0 = screen.frames_displayed, time.monotonic()
            await pilot.pause(seconds)
            n1, t1 = screen.frames_displayed, time.monotonic()
            return (n1 - n0) / (t1 - t0), screen.display_rate_hz


def live_view_rates(seconds: float = 4.0, protocols: tuple[str, ...] = (
        "halfblock", "sixel", "kitty")) -> list[tuple[str, tuple[int, int], float]]:
    """Frames shown per second for each drawing method and terminal size."""
    rows = []
    for protocol in protocols:
        for size in SIZES:
            with _quiet_stdout() if protocol == "kitty" else contextlib.nullcontext():
                hz, _ = asyncio.run(_measure(size, protocol, seconds))
            rows.append((protocol, size, hz))
    return rows


def main(seconds: float, protocols: tuple[str, ...]) -> int:
    print(f"live view on the simulated bench, {seconds:g} s per case "
          f"(display capped at 20 Hz, acquisition at 25 Hz)")
    print(f"{'method':<10} {'terminal':>9} {'frames/s':>9}")
    for protocol, (w, h), hz in live_view_rates(seconds, protocols):
        print(f"{protocol:<10} {f'{w}x{h}':>9} {hz:9.1f}", flush=True)
    return 0
