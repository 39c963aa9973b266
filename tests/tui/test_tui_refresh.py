"""The live view's refresh rules: the side panel redraws at a few Hz and only when changed;
Sixel / Kitty frames are encoded once per new frame, at the size they are shown."""

from __future__ import annotations

import base64
import io
import re
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_tui_helpers import open_live, wait_until
from textual.app import App, ComposeResult
from textual.geometry import Region

from benchlab.tui.app import BenchlabApp
from benchlab.tui.drawing.graphics import (
    SIXEL_GRAY_LEVELS,
    KittyCanvas,
    SixelCanvas,
    fit_image,
    overlay_colours,
    to_palette,
)
from benchlab.tui.drawing.sixel import encode_sixel
from benchlab.tui.widgets import ROI_RGB, Readout, RoiHistogram


class _Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class _Side(App[None]):
    def __init__(self, clock: _Clock) -> None:
        super().__init__()
        self.clock = clock

    def compose(self) -> ComposeResult:
        yield RoiHistogram(id="hist", min_interval_s=0.25, clock=self.clock)
        yield Readout("start", id="readout", min_interval_s=0.25, clock=self.clock)


def _roi(peak: float, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(peak, 3.0, 800)


@pytest.mark.asyncio
async def test_histogram_redraws_at_most_every_interval() -> None:
    clock = _Clock()
    app = _Side(clock)
    async with app.run_test(size=(60, 20)):
        hist = app.query_one(RoiHistogram)
        drawn = [hist.show(_roi(40 + 5 * (i % 20), i), 255.0, 40.0, 200.0) for i in range(1)]
        # 40 frames at 16 Hz (2.5 s), every one different: 10 redraws at 0.25 s, not 40
        for i in range(1, 40):
            clock.now += 0.0625
            drawn.append(hist.show(_roi(40 + 5 * (i % 20), i), 255.0, 40.0, 200.0))
        assert sum(drawn) == hist.redraws == 10
        assert drawn[:6] == [True, False, False, False, True, False]
        # a changed setting (force) redraws at once
        clock.now += 0.01
        assert hist.show(_roi(150, 99), 255.0, 150.0, None, force=True)
        assert "D" in hist.text_lines()[-1] and "B" not in hist.text_lines()[-1]


@pytest.mark.asyncio
async def test_histogram_is_not_redrawn_when_the_drawing_is_unchanged() -> None:
    clock = _Clock()
    app = _Side(clock)
    async with app.run_test(size=(60, 20)):
        hist = app.query_one(RoiHistogram)
        roi = _roi(80, 1)
        assert hist.show(roi, 255.0, 80.0, 200.0)
        clock.now += 1.0
        assert not hist.show(roi.copy(), 255.0, 80.0, 200.0)  # same counts: no refresh
        clock.now += 1.0
        assert hist.show(roi, 255.0, 80.0, 120.0)  # a moved mark is a change
        assert hist.redraws == 2


@pytest.mark.asyncio
async def test_readout_skips_unchanged_text_and_throttles_the_rest() -> None:
    clock = _Clock()
    app = _Side(clock)
    async with app.run_test(size=(60, 20)):
        readout = app.query_one(Readout)
        assert not readout.show("start")  # unchanged: not re-rendered
        assert readout.show("frame 1")
        clock.now += 0.1
        assert not readout.show("frame 2")  # too soon
        assert readout.show("exposure 5 ms", urgent=True)  # a key press shows at once
        clock.now += 0.3
        assert not readout.show("exposure 5 ms")  # unchanged, even when due
        assert readout.show("frame 3")
        assert readout.redraws == 3
        assert "frame 3" in str(readout.render())


def test_fit_image_keeps_the_aspect_and_never_upscales_sixel() -> None:
    cell = (10, 20)
    # 640 x 512 into 50 x 20 cells (500 x 400 px): width-limited at 500 x 400
    assert fit_image((640, 512), (50, 20), cell, upscale=False) == ((500, 400), (50, 20))
    # a big terminal: Sixel stays 1:1 (64 x 26 cells), Kitty fills the height (the terminal
    # scales the 640 x 512 image into 140 x 56 cells)
    assert fit_image((640, 512), (160, 56), cell, upscale=False) == ((640, 512), (64, 26))
    assert fit_image((640, 512), (160, 56), cell, upscale=True) == ((1400, 1120), (140, 56))
    assert fit_image((640, 512), (0, 10), cell, upscale=True) == ((0, 0), (0, 0))
    assert fit_image((0, 512), (10, 10), cell, upscale=True) == ((0, 0), (0, 0))


def test_sixel_palette_keeps_gray_levels_and_overlay_colours() -> None:
    rgb = np.repeat(np.tile(np.arange(256, dtype=np.uint8), (8, 1))[:, :, None], 3, axis=2)
    rgb[2, 10:20] = ROI_RGB
    rgb[5, 30:40] = (0, 220, 60)
    index, palette = to_palette(rgb)
    assert index.shape == (8, 256) and palette.shape == (SIXEL_GRAY_LEVELS + 2, 3)
    shown = palette[index]
    assert tuple(shown[2, 15]) == ROI_RGB and tuple(shown[5, 35]) == (0, 220, 60)
    gray_error = np.abs(shown[0, :, 0].astype(int) - np.arange(256))
    assert gray_error.max() <= 256 // SIXEL_GRAY_LEVELS  # 32 levels
    assert len(np.unique(index)) == SIXEL_GRAY_LEVELS + 2
    # a downscaled copy's blended edges map to the full image's two colours, no new entries
    blended = rgb.copy()
    blended[2, 20] = (180, 150, 40)  # half ROI yellow, half gray
    index, palette = to_palette(blended, colours=overlay_colours(rgb))
    assert len(palette) == SIXEL_GRAY_LEVELS + 2 and tuple(palette[index[2, 20]]) == ROI_RGB


def _decode_sixel(data: str) -> tuple[np.ndarray, dict[int, tuple[int, ...]]]:
    """A plain Sixel decoder (one character at a time) to check the vectorised encoder."""
    head = re.match(r'\x1bP0;0;0q"1;1;(\d+);(\d+)', data)
    assert head is not None and data.endswith("\x1b\\")
    width, height = int(head.group(1)), int(head.group(2))
    body, image = data[head.end():-2], np.full((height, width), -1)
    registers: dict[int, tuple[int, ...]] = {}
    i = x = band = colour = 0
    while i < len(body):
        if body[i] == "#":
            m = re.match(r"#(\d+)(?:;2;(\d+);(\d+);(\d+))?", body[i:])
            assert m is not None
            colour = int(m.group(1))
            if m.group(2):
                registers[colour] = tuple(int(v) for v in m.groups()[1:])
            i += m.end()
            continue
        if body[i] in "$-":
            x, band, i = 0, band + (body[i] == "-"), i + 1
            continue
        n = 1
        if body[i] == "!":
            m = re.match(r"!(\d+)", body[i:])
            assert m is not None
            n, i = int(m.group(1)), i + m.end()
        bits = ord(body[i]) - 63
        assert 0 <= bits < 64
        for r in range(6):
            if bits >> r & 1 and band * 6 + r < height:
                image[band * 6 + r, x:x + n] = colour
        x, i = x + n, i + 1
    return image, registers


@pytest.mark.parametrize("height, width, colours", [
    (1, 1, 1), (7, 13, 3), (64, 80, 34), (13, 5, 256), (6, 700, 2)])
def test_sixel_encoder_round_trips(height: int, width: int, colours: int) -> None:
    rng = np.random.default_rng(height * width)
    index = rng.integers(0, colours, (height, width)).astype(np.uint8)
    index[:, : width // 2] = 0  # long runs (sent as !<n><char>)
    palette = rng.integers(0, 256, (colours, 3)).astype(np.uint8)
    data = encode_sixel(index, palette)
    image, registers = _decode_sixel(data)
    assert (image == index).all()
    for c in np.unique(index).tolist():  # every used colour defined, in percent
        assert registers[c] == tuple(round(v * 100 / 255) for v in palette[c].tolist())
    if width >= 8:
        assert "!" in data  # runs are compressed
    with pytest.raises(ValueError, match="palette index"):
        encode_sixel(np.full((2, 2), colours, np.uint8), palette) if colours < 256 else \
            encode_sixel(np.full((2, 2), 1, np.uint8), palette[:1])


class _Canvases(App[None]):
    def compose(self) -> ComposeResult:
        yield SixelCanvas()
        yield KittyCanvas()


def _frame(value: int) -> np.ndarray:
    rgb = np.full((512, 640, 3), value, np.uint8)
    rgb[100:110, 100:300] = ROI_RGB
    return rgb


@pytest.mark.asyncio
async def test_image_canvases_encode_once_per_new_frame(
        capfd: pytest.CaptureFixture[str]) -> None:
    app = _Canvases()
    async with app.run_test(size=(200, 120)) as pilot:
        sixel, kitty = app.query_one(SixelCanvas), app.query_one(KittyCanvas)
        sixel.set_image(_frame(50))
        kitty.set_image(_frame(50))
        await pilot.pause()
        for _ in range(3):  # redraws of the same frame: no new encode
            sixel.render_lines(Region(0, 0, *sixel.size))
            for y in range(kitty.size.height):
                kitty.render_line(y)
        assert (sixel.encodes, kitty.encodes) == (1, 1)
        data = sixel.sixel_data()
        # Sixel at most 1:1: the 640 x 512 raster even though the terminal has room for more
        assert re.search(r'"1;1;640;512', data) and sixel.size == (64, 26)
        # Kitty: the image is sent at its own size and placed over the cells it fills
        # 640 x 512 scaled into 200 x 80 cells of 10 x 20 px: fills both sides (same aspect)
        assert kitty.size == (200, 80)
        out = capfd.readouterr().out
        payload = "".join(re.findall(r"\x1b_G[^;]*f=100[^;]*;([^\x1b]*)\x1b\\", out))
        png = base64.b64decode(payload)
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        assert struct.unpack(">II", png[16:24]) == (640, 512)
        sent = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
        assert np.abs(sent - _frame(50)).max() <= 2  # 128 gray levels, the outline exact
        assert tuple(sent[105, 200]) == ROI_RGB
        assert f"c={kitty.size.width},r={kitty.size.height}" in out
        sixel.set_image(_frame(60))
        kitty.set_image(_frame(60))
        await pilot.pause()
        sixel.render_lines(Region(0, 0, *sixel.size))
        kitty.render_line(0)
        assert (sixel.encodes, kitty.encodes) == (2, 2)
        old_id = int(re.findall(r"a=p,i=(\d+)", out)[0])
        # the previous Kitty image was freed by its id, after the new one was placed
        out = capfd.readouterr().out
        assert out.index(f"a=d,d=I,i={old_id}") > out.index("a=p,")


@pytest.mark.slow
@pytest.mark.asyncio
async def test_live_side_panel_lags_the_frame_rate(tmp_path: Path) -> None:
    app = BenchlabApp(simulate=True, sessions_dir=tmp_path / "s")
    async with app.run_test(size=(120, 36)) as pilot:
        live = await open_live(pilot, 3)
        hist, readout = live.query_one(RoiHistogram), live.query_one(Readout)
        n0, h0, r0 = live.frames_displayed, hist.redraws, readout.redraws
        t0 = time.monotonic()
        await wait_until(pilot, lambda: live.frames_displayed >= n0 + 10
                         and time.monotonic() - t0 >= 1.0, what="frames")
        elapsed = time.monotonic() - t0
        # never more than one redraw per interval, whatever the frame rate (every frame's
        # readout differs: its frame number)
        assert hist.redraws - h0 <= elapsed / hist.min_interval_s + 1
        assert 0 < readout.redraws - r0 <= elapsed / readout.min_interval_s + 1


def test_display_pacing_keeps_15_hz_when_a_frame_takes_longer_than_the_interval() -> None:
    from benchlab.tui.live import DISPLAY_INTERVAL_S, POLL_INTERVAL_S, display_due

    assert display_due(DISPLAY_INTERVAL_S, 0.0) and not display_due(0.8 * DISPLAY_INTERVAL_S, 0.0)
    # polls on a POLL_INTERVAL_S grid; every shown frame takes 55 ms (> the 50 ms interval)
    shown, last, poll = 0, -1.0, 0
    while poll * POLL_INTERVAL_S < 2.0:
        now = poll * POLL_INTERVAL_S
        if display_due(now, last):
            shown, last = shown + 1, now
            poll = int(np.ceil((now + 0.055) / POLL_INTERVAL_S - 1e-9))  # busy until then
        else:
            poll += 1
    assert shown / 2.0 >= 15  # on a 50 ms grid it would be every other tick: 10 Hz
    assert shown / 2.0 <= 1 / DISPLAY_INTERVAL_S
