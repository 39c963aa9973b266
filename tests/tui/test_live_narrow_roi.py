"""The live view says when its ROI is too narrow for an honest reading of the bars in it
(issue 37: its default 12 x 10 px ROI on 2.1-2.3 px bars read "1.000 resolved")."""

from __future__ import annotations

import numpy as np

from benchlab.analysis.bars.profilefit import narrow_roi_note
from benchlab.synthetic.bars import bar_roi
from benchlab.tui import services
from benchlab.tui.widgets import Roi


def _frame(period_px: float) -> tuple[np.ndarray, dict[str, object]]:
    pixels, _ = bar_roi(3, shape=(120, 160), px_per_period=period_px, modulation=0.6,
                        psf_sigma_px=0.4, noise_sigma=1.0, orientation="horizontal")
    return pixels, {"bits": 8}


def test_the_default_sized_roi_on_near_nyquist_bars_is_called_too_narrow() -> None:
    frame = _frame(2.2)
    reading = services.live_reading(frame, Roi(50, 60, 10, 12), "auto", None, 0, 10.0, 1.0)
    assert reading.note.startswith("ROI too narrow for"), reading.note
    assert ">= " in reading.note and "px across the bars" in reading.note
    if reading.resolved:  # a value there would be a guess: only a bound
        assert reading.lower_bound or (reading.modulation or 0.0) < 0.999


def test_a_wide_roi_on_the_same_bars_reads_without_the_warning() -> None:
    frame = _frame(2.2)
    reading = services.live_reading(frame, Roi(40, 40, 20, 40), "auto", None, 0, 10.0, 1.0)
    assert "too narrow" not in reading.note
    assert reading.resolved and not reading.lower_bound


def test_coarse_bars_in_the_default_roi_need_no_warning() -> None:
    frame = _frame(6.0)
    reading = services.live_reading(frame, Roi(50, 60, 10, 12), "auto", None, 0, 10.0, 1.0)
    assert "too narrow" not in reading.note


def test_the_note_names_the_width_that_reads_and_is_silent_with_a_frequency() -> None:
    note = narrow_roi_note((10, 12), 2.2, 0.0, freq_given=False)
    assert note is not None and ">= 28 px across" in note
    assert narrow_roi_note((10, 12), 2.2, 0.0, freq_given=True) is None
    assert narrow_roi_note((10, 40), 2.2, 0.0, freq_given=False) is None
    assert narrow_roi_note((10, 12), 1.8, 0.0, freq_given=False) is None  # aliased: said so
