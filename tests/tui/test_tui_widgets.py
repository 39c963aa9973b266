"""The TUI's display widgets: half-block frame rendering with the ROI, ROI histogram."""

from __future__ import annotations

import errno

import numpy as np
import pytest
from textual.app import App, ComposeResult

from benchlab.drivers.errors import DeviceLostError, SafetyLimitError
from benchlab.protocols import ParamsError
from benchlab.tui.services import plain_error
from benchlab.tui.widgets import (
    ROI_RGB,
    UPPER_HALF,
    FrameView,
    Roi,
    RoiHistogram,
    rgb_to_strips,
    to_display_rgb,
)


def test_roi_moves_and_resizes_inside_the_frame() -> None:
    roi = Roi(10, 20, 32, 64)
    assert roi.moved(-100, 5, (1024, 1280)) == Roi(0, 25, 32, 64)
    assert roi.moved(5000, 5000, (1024, 1280)) == Roi(1024 - 32, 1280 - 64, 32, 64)
    grown = Roi(500, 600, 32, 32).resized(32, 32, (1024, 1280))
    assert grown == Roi(484, 584, 64, 64)  # about its centre
    assert Roi(0, 0, 16, 16).resized(-100, -100, (1024, 1280)).height == 8  # floor of 8 px
    pixels = np.arange(100).reshape(10, 10)
    assert Roi(2, 3, 4, 5).slice(pixels).shape == (4, 5)
    assert Roi(2, 3, 4, 5).slice(pixels)[0, 0] == 23


def test_display_keeps_aspect_and_draws_the_roi() -> None:
    frame = np.tile(np.linspace(0, 255, 1280), (1024, 1)).astype(np.uint8)
    rgb = to_display_rgb(frame, (80, 20), Roi(256, 320, 512, 640), 255.0)
    # 1280 x 1024 into 80 columns x 40 half-rows: height-limited, 40 rows x 50 columns
    assert rgb.shape == (40, 50, 3)
    assert tuple(rgb[10, 12]) == ROI_RGB  # top-left corner of the ROI (rows /25.6, cols /25.6)
    assert tuple(rgb[20, 12]) == ROI_RGB  # left edge
    assert tuple(rgb[20, 25]) != ROI_RGB  # inside is the image
    assert rgb[20, 45, 0] > rgb[20, 5, 0]  # the gradient survives the downscale
    strips = rgb_to_strips(rgb)
    assert len(strips) == 20
    assert all(s.cell_length == 50 for s in strips)
    assert UPPER_HALF in strips[0].text


class _Harness(App[None]):
    def compose(self) -> ComposeResult:
        yield FrameView(id="frame")
        yield RoiHistogram(id="hist")


@pytest.mark.asyncio
async def test_widgets_render_a_frame_and_a_marked_histogram() -> None:
    app = _Harness()
    async with app.run_test(size=(60, 30)) as pilot:
        view = app.query_one(FrameView)
        assert "no camera image" in "".join(
            view.render_line(y).text for y in range(view.size.height)
        )
        frame = np.full((1024, 1280), 40, np.uint8)
        frame[:, 640:] = 200
        view.show(frame, Roi(400, 500, 200, 280), 255.0)
        hist = app.query_one(RoiHistogram)
        rng = np.random.default_rng(1)
        roi = np.concatenate([rng.normal(40, 3, 500), rng.normal(200, 3, 500)])
        hist.show(roi, 255.0, 40.0, 200.0)
        await pilot.pause()
        lines = [view.render_line(y).text for y in range(view.size.height)]
        assert sum(line.count(UPPER_HALF) for line in lines) > 100
        assert view.frames_shown == 1
        text = hist.text_lines()
        assert [hist.render_line(y).text for y in range(len(text))] == text
        axis = text[-1]
        width = hist.size.width
        assert axis.index("D") == int(40 / 256 * width)
        assert axis.index("B") == int(200 / 256 * width)
        # the tallest bars are at the two peaks
        top = text[0]
        assert top[axis.index("D")] != " " and top[axis.index("B")] != " "


def test_errors_are_explained_in_plain_words() -> None:
    full = plain_error(OSError(errno.ENOSPC, "No space left on device"))
    assert full.startswith("The disk is full") and "resume" in full
    lost = plain_error(DeviceLostError("LED controller: port closed"))
    assert lost.startswith("The connection to a device was lost")
    assert "LED controller: port closed" in lost
    assert plain_error(SafetyLimitError("60 mA > 50 mA")).startswith("Refused")
    problems = plain_error(ParamsError("mtf.toml", ["camera.gain: must be > 0", "radial: bad"]))
    assert "camera.gain" in problems and "radial: bad" in problems and "2 problems" in problems
