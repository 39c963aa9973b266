"""Real pixels in the live view: protocol choice, the RGB frame, Sixel and Kitty output."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from test_tui_helpers import connected, wait_until
from textual.geometry import Region

from benchlab.tui.app import BenchlabApp
from benchlab.tui.drawing.pixels import GraphicsFrameView, choose_image_protocol, frame_rgb
from benchlab.tui.widgets import ROI_RGB, FrameView, Roi


def test_forced_and_environment_choices(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("BENCHLAB_IMAGE", raising=False)
    assert choose_image_protocol("kitty") == "kitty"
    assert choose_image_protocol("SIXEL") == "sixel"
    monkeypatch.setenv("BENCHLAB_IMAGE", "sixel")
    assert choose_image_protocol(None) == "sixel"
    assert choose_image_protocol("halfblock") == "halfblock"  # the option beats the variable
    with pytest.raises(ValueError, match="kitty, sixel, halfblock"):
        choose_image_protocol("png")


def test_auto_without_a_terminal_is_halfblock(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("BENCHLAB_IMAGE", raising=False)
    monkeypatch.setattr("sys.__stdout__", io.StringIO())  # not a tty: never query anything
    assert choose_image_protocol("auto") == "halfblock"


def test_frame_rgb_scales_codes_and_outlines_the_roi() -> None:
    px = np.full((20, 30), 2048, np.uint16)
    rgb = frame_rgb(px, Roi(5, 6, 4, 8), 4095.0)
    assert rgb.shape == (20, 30, 3) and rgb.dtype == np.uint8
    assert tuple(rgb[0, 0]) == (127, 127, 127)
    assert tuple(rgb[5, 6]) == tuple(ROI_RGB) and tuple(rgb[8, 13]) == tuple(ROI_RGB)
    assert tuple(rgb[6, 7]) == (127, 127, 127)  # inside the outline: the frame
    edge = frame_rgb(np.zeros((4, 4), np.uint8), Roi(2, 2, 10, 10), 255.0)  # past the edge
    assert tuple(edge[3, 3]) == tuple(ROI_RGB) and tuple(edge[0, 0]) == (0, 0, 0)
    assert frame_rgb(np.full((2, 2), 300.0), None, 255.0).max() == 255  # clipped, no wrap


@pytest.mark.slow
@pytest.mark.asyncio
@pytest.mark.parametrize("protocol, introducer", [("sixel", "\x1bP"), ("kitty", "\x1b_G")])
async def test_live_view_sends_real_pixels(tmp_path: Path, protocol: str, introducer: str,
                                           capfd: pytest.CaptureFixture[str]) -> None:
    app = BenchlabApp(simulate=True, sessions_dir=tmp_path / "s", image_protocol=protocol)
    async with app.run_test(size=(100, 32)) as pilot:
        await connected(pilot)
        await pilot.press("2")
        view = app.screen.query_one("#frame", FrameView)
        assert isinstance(view, GraphicsFrameView) and view.protocol == protocol
        await wait_until(pilot, lambda: view.frames_shown >= 2, what="frames")
        assert view.last_rgb is not None and view.last_rgb.shape == (512, 640, 3)
        assert (view.last_rgb == np.asarray(ROI_RGB, np.uint8)).all(axis=2).any()  # ROI drawn
        canvas = view.image_widget
        assert canvas is not None and canvas.image is view.last_rgb
        # the image fits the frame (10 x 20 px cells when the terminal can't say): it fills
        # the limiting side, or (Sixel) is shown 1:1 - once the canvas is laid out
        def laid_out() -> bool:
            cols, rows = canvas.content_size
            width, height = view.content_size
            return (0 < cols <= width and 0 < rows <= height
                    and (cols == width or rows == height or canvas.shown_px() == (640, 512)))

        await wait_until(pilot, laid_out, what="canvas laid out")
        cols, rows = canvas.content_size
        text = "".join(seg.text for strip in canvas.render_lines(Region(0, 0, cols, rows))
                       for seg in strip)
        # Kitty's protocol transmits the image straight to the terminal; Sixel travels in
        # the rendered lines.
        text += capfd.readouterr().out
        assert introducer in text
        if protocol == "sixel":  # drawn 1:1 at most: the raster is the shown size, <= 640x512
            w, h = canvas.shown_px()
            assert f'"1;1;{w};{h}' in text and w <= 640 and h <= 512 and w <= cols * 10
        else:  # a virtual placement of exactly the canvas' cells; the terminal scales
            assert f"a=p,i={canvas.image_id},c={cols},r={rows}" in text


@pytest.mark.asyncio
async def test_halfblock_stays_the_default(tmp_path: Path) -> None:
    app = BenchlabApp(simulate=True, sessions_dir=tmp_path / "s")
    async with app.run_test(size=(80, 24)) as pilot:
        await connected(pilot)
        await pilot.press("2")
        view = app.screen.query_one("#frame", FrameView)
        assert not isinstance(view, GraphicsFrameView)  # half-blocks (with the chart overlay)
        await wait_until(pilot, lambda: view.frames_shown >= 1, what="frames")
