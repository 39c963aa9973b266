"""The live view's focus aid on the simulated bench: the whole chart read in a worker, bars
with a peak hold that follows focus, "chart not found" said, the reader stopped with the panel."""

from __future__ import annotations

import re
import threading
from pathlib import Path
from typing import Any

import pytest
from test_tui_helpers import make_app, open_live, wait_until

from benchlab.protocols.depth.params import DepthParams
from benchlab.tui import services
from benchlab.tui.focus_aid import SUMMARY_KEY, FocusAidPanel
from benchlab.tui.live import LiveScreen


class Recorder:
    """Wraps :func:`services.read_focus`: every reading the worker made, in order."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.readings: list[tuple[Any, float | None]] = []
        self.problems = 0
        self.started = 0
        self.threads: set[str] = set()
        self._real = services.read_focus

    def __call__(self, tracker: Any, pixels: Any) -> tuple[Any, float | None, str]:
        with self.lock:
            self.started += 1
            self.threads.add(threading.current_thread().name)
        out = self._real(tracker, pixels)
        with self.lock:
            if out[0] is None:
                self.problems += 1
            else:
                self.readings.append((out[0], out[1]))
        return out

    def settled(self, live: LiveScreen, panel: FocusAidPanel) -> bool:
        """No frame waiting, no reading under way, every reading made shown in the panel."""
        with self.lock:
            finished = len(self.readings) + self.problems
            return (live._focus_slot.offered == live._focus_slot.dropped + self.started
                    and self.started == finished
                    and panel.readings_shown == len(self.readings))


def _carry(app: Any, distance_mm: float) -> None:
    """The chart on the stage carriage at ``distance_mm`` from the simulated prototype."""
    bench = app.bench
    with app.device_lock:
        bench.world.through_focus = DepthParams().lens()
        bench.carry_target(distance_mm - bench.sim_stage.position_mm)


@pytest.mark.slow
@pytest.mark.asyncio
async def test_bars_follow_focus_and_the_peak_hold_is_the_best_reading(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    recorder = Recorder()
    monkeypatch.setattr(services, "read_focus", recorder)
    app = make_app(tmp_path)
    async with app.run_test(size=(100, 34)) as pilot:
        live = await open_live(pilot, 2)
        _carry(app, 46.0)  # 14 mm in front of best focus: soft
        await pilot.press("f")
        panel = live.query_one(FocusAidPanel)
        assert panel.display and not live.query_one("#histogram").display

        await wait_until(pilot, lambda: panel.readings_shown >= 3, what="first readings")
        await pilot.press("r")  # peaks from here on: frames surely taken after the move
        after = panel.readings_at_reset
        assert after >= 3
        await wait_until(pilot, lambda: panel.readings_shown >= after + 4,
                         what="defocused readings")
        soft = panel.peaks.peaks[SUMMARY_KEY]
        assert soft < 60.0  # mean edge MTF50, lp/mm (~90 in focus)
        _carry(app, 60.0)  # best focus
        await wait_until(pilot, lambda: panel.peaks.peaks[SUMMARY_KEY] > soft + 20.0,
                         what="the peak moved with focus")
        # every set of the chart is a bar pair, S and T
        text = panel.render()
        lines = str(text).splitlines()
        elements = {line[:4] for line in lines if line.startswith("G") and " T" in line}
        assert {"G0E1", "G1E1", "G2E1"} <= elements
        assert any(line.startswith("E0 L") for line in lines)
        # stop feeding frames, let the reader finish, then compare with what it delivered
        monkeypatch.setattr(live._focus_slot, "offer", lambda pixels: None)
        await wait_until(pilot, lambda: recorder.settled(live, panel), what="reader settled")
        assert recorder.threads and threading.current_thread().name not in recorder.threads
        values: dict[str, list[float]] = {}
        for reading, summary in recorder.readings[after:]:  # delivered since the reset
            for key, v in {**reading.modulation, **reading.edge_mtf50_lp_per_mm,
                           SUMMARY_KEY: summary}.items():
                if v is not None:
                    values.setdefault(key, []).append(v)
        assert set(panel.peaks.peaks) == set(values)
        assert all(panel.peaks.peaks[k] == max(v) for k, v in values.items())
        assert max(values[SUMMARY_KEY]) > 1.3 * values[SUMMARY_KEY][0]


@pytest.mark.slow
@pytest.mark.asyncio
async def test_chart_not_found_is_said_without_bars_and_off_stops_the_reader(
        tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=(100, 34)) as pilot:
        live = await open_live(pilot, 2)
        text = re.sub(r"<[^>]+>", "", app.export_screenshot()).replace("&#160;", " ")
        assert "c Chartf Focus" in text  # in the footer (tags stripped: no space between keys)
        await pilot.press("f")
        panel = live.query_one(FocusAidPanel)
        assert panel.border_title == "focus aid (r: reset peaks)"
        await wait_until(pilot, lambda: panel.readings_shown >= 2, what="chart read")
        assert panel.reading is not None
        # leaving the live view and coming back: the old bars are not shown as current
        problems = panel.problems_shown
        await pilot.press("1", "2")
        await wait_until(pilot, lambda: panel.problems_shown > problems, what="bars dropped")
        shown = panel.readings_shown
        await wait_until(pilot, lambda: panel.readings_shown > shown, what="reading again")
        await pilot.press("t")  # the next simulated target: a radial pattern, no USAF chart
        await wait_until(pilot, lambda: panel.problems_shown > 0 and panel.reading is None,
                         what="chart not found")
        lines = str(panel.render()).splitlines()
        assert lines[0].startswith("chart not found")
        assert not any(line.startswith("G") for line in lines)  # no stale bars
        # f again: the panel goes, the reader thread ends, no frame is handed to it any more
        await pilot.press("f")
        assert not panel.display and live.query_one("#histogram").display

        def stopped() -> bool:
            return not any(w.group == "focus-aid" and not w.is_finished for w in app.workers)

        await wait_until(pilot, stopped, what="reader stopped")
        offered = live._focus_slot.offered
        shown = live.frames_displayed
        await wait_until(pilot, lambda: live.frames_displayed > shown + 2, what="live goes on")
        assert live._focus_slot.offered == offered
