"""The live view's focus aid (issue 27, Table 4.10 step 3): the whole chart read on every frame
the reader can take, shown as bars with a peak hold and a history, to find best focus by hand.

Three parts, so that the reading never runs in the UI thread and never falls behind:

* :class:`FrameSlot` - the acquisition thread *offers* each frame; the reader *takes* the
  newest. A frame not taken before the next arrives is dropped (counted), never queued.
* the reader - a thread worker of :class:`~benchlab.tui.live.LiveScreen` that reads the slot's
  frame with :func:`benchlab.tui.services.read_focus` and hands the result to the panel
  through :func:`~benchlab.tui.ui_calls.call_ui`.
* :class:`FocusAidPanel` - keeps the peak hold (:class:`~benchlab.analysis.focus.live.PeakHold`)
  in the UI thread and draws :func:`~benchlab.tui.drawing.focus_bars.render_focus_aid`.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

import numpy.typing as npt
from textual.widgets import Static

from benchlab.analysis.focus.live import PeakHold
from benchlab.tui.drawing.focus_bars import FocusAidView, render_focus_aid

#: PeakHold key of the history's summary value (no chart label looks like it).
SUMMARY_KEY = "mean MTF50"


class FrameSlot:
    """One frame waiting for the reader; a newer frame replaces it (the older is dropped)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._frame: npt.NDArray[Any] | None = None
        #: Frames offered, and frames replaced before the reader took them.
        self.offered = 0
        self.dropped = 0

    def offer(self, pixels: npt.NDArray[Any]) -> None:
        with self._cond:
            if self._frame is not None:
                self.dropped += 1
            self._frame = pixels
            self.offered += 1
            self._cond.notify_all()

    def take(self, timeout_s: float) -> npt.NDArray[Any] | None:
        """The newest frame (the slot is then empty), or None after ``timeout_s``."""
        with self._cond:
            self._cond.wait_for(lambda: self._frame is not None, timeout_s)
            frame, self._frame = self._frame, None
            return frame

    def clear(self) -> None:
        with self._cond:
            self._frame = None


class FocusAidPanel(Static):
    """The focus-aid panel: every element's S and T bars with a peak hold, the edges' MTF50,
    the mean MTF50's history (see :func:`render_focus_aid`)."""

    DEFAULT_CSS = """
    FocusAidPanel { height: 1fr; border: round $primary; padding: 0 1; overflow-y: auto; }
    """

    def __init__(self, *, id: str | None = None, history: int = 200) -> None:  # noqa: A002
        super().__init__("", id=id)
        self.peaks = PeakHold(history=history)
        #: The reading now shown (None: none yet, or the chart was not found on the last frame).
        self.reading: Any = None
        self.summary_now: float | None = None
        self.note = "looking for the chart..."
        #: Readings drawn since the panel was created (the displayed-readings figure).
        self.readings_shown = 0
        #: Frames with no reading shown (:meth:`show_problem`).
        self.problems_shown = 0
        #: :attr:`readings_shown` when the peaks were last reset (they hold the readings since).
        self.readings_at_reset = 0
        self._times: deque[float] = deque(maxlen=30)

    @property
    def rate_hz(self) -> float:
        """Readings shown per second over the last (up to) 30."""
        if len(self._times) < 2:
            return 0.0
        span = self._times[-1] - self._times[0]
        return (len(self._times) - 1) / span if span > 0 else 0.0

    def show_reading(self, reading: Any, summary: float | None) -> None:
        """A new whole-chart reading (UI thread): peaks updated, then drawn."""
        self.peaks.update({**reading.modulation, **reading.edge_mtf50_lp_per_mm,
                           SUMMARY_KEY: summary})
        self.reading, self.summary_now, self.note = reading, summary, ""
        self.readings_shown += 1
        self._times.append(time.monotonic())
        self._draw()

    def show_problem(self, text: str) -> None:
        """No reading for the last frame (chart not found, a reading error): the bars go, the
        peaks and the history stay for when the chart is back."""
        self.reading, self.summary_now, self.note = None, None, text
        self.problems_shown += 1
        self._times.clear()
        self._draw()

    def reset_peaks(self) -> None:
        """Forget every peak and the history (a new focusing session)."""
        self.peaks = PeakHold(history=self.peaks.history)
        self.readings_at_reset = self.readings_shown
        self._draw()

    def clear(self) -> None:
        """Back to the state of a new panel (the focus aid switched off)."""
        self.reset_peaks()
        self.reading, self.summary_now, self.note = None, None, "looking for the chart..."
        self._times.clear()
        self._draw()

    def view(self) -> FocusAidView:
        """What the panel shows now."""
        r = self.reading
        if r is None:
            status = self.note
        else:
            found = sum(v is not None for v in r.modulation.values())
            status = f"{found} sets, {self.rate_hz:.1f} readings/s"
        return FocusAidView(
            modulation=r.modulation if r is not None else {},
            mtf50_lp_per_mm=r.edge_mtf50_lp_per_mm if r is not None else {},
            peaks=dict(self.peaks.peaks),
            history=list(self.peaks.series.get(SUMMARY_KEY, ())),
            status=status, summary_label=SUMMARY_KEY, summary_now=self.summary_now,
            summary_peak=self.peaks.peaks.get(SUMMARY_KEY))

    def _draw(self) -> None:
        text = render_focus_aid(self.view(), max(20, self.content_size.width or 30))
        if self.reading is None:
            text.stylize("yellow", 0, len(text.plain.split("\n", 1)[0]))
        self.update(text)
