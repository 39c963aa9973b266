"""Whole-chart readings the live view's focus aid shows per second, on the simulated bench
(1280 x 1024, 8 bit; headless Textual, the same code as on screen)::

    python -m benchlab.tui.focus_aid_rate [--seconds 10] [--size 120x36]

The figure counts readings drawn in the panel over the window, after a warm-up; it includes
everything the live view does meanwhile (acquisition at up to 25 frames/s, the frame preview,
the ROI readout) on the same interpreter. ``benchlab benchmark focus-aid`` times the reading
alone.
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
import time
from pathlib import Path


async def measure(seconds: float, size: tuple[int, int] = (120, 36)) -> dict[str, float]:
    """Readings shown per second, and frames offered to / dropped by the reader."""
    from benchlab.tui.app import BenchlabApp
    from benchlab.tui.focus_aid import FocusAidPanel
    from benchlab.tui.live import LiveScreen

    with tempfile.TemporaryDirectory() as tmp:
        app = BenchlabApp(simulate=True, sessions_dir=Path(tmp))
        async with app.run_test(size=size) as pilot:
            while app.bench is None:
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
            await pilot.pause(seconds)
            n1, off1, drop1, t1 = (panel.readings_shown, slot.offered, slot.dropped,
                                   time.monotonic())
            return {"readings_per_s": (n1 - n0) / (t1 - t0),
                    "frames_per_s": (off1 - off0) / (t1 - t0),
                    "dropped_fraction": (drop1 - drop0) / max(1, off1 - off0),
                    "sets": float(sum(v is not None for v in panel.reading.modulation.values()))
                    if panel.reading is not None else 0.0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else "")
    parser.add_argument("--seconds", type=float, default=10.0, help="measuring window (10 s)")
    parser.add_argument("--size", default="120x36", help="terminal columns x rows (120x36)")
    args = parser.parse_args(argv)
    cols, rows = (int(x) for x in args.size.lower().split("x"))
    r = asyncio.run(measure(args.seconds, (cols, rows)))
    print(f"focus aid, simulated bench 1280x1024 8 bit, terminal {cols}x{rows}, "
          f"{args.seconds:g} s: {r['readings_per_s']:.1f} readings shown/s, "
          f"{r['frames_per_s']:.1f} frames/s offered, {100 * r['dropped_fraction']:.0f} % "
          f"dropped, {r['sets']:.0f} sets read")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
