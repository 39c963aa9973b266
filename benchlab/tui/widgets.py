"""Display widgets: a camera frame in half-block characters and an ROI histogram."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt
from rich.color import Color
from rich.segment import Segment
from rich.style import Style
from rich.text import Text
from textual.strip import Strip
from textual.widget import Widget
from textual.widgets import Static

UPPER_HALF = "\u2580"
ROI_RGB = (255, 200, 0)
BARS = " \u2581\u2582\u2583\u2584\u2585\u2586\u2587\u2588"


@dataclass(frozen=True)
class Roi:
    """A rectangle in frame pixels, numpy convention: top-left ``(row, col)`` and size."""

    row: int
    col: int
    height: int
    width: int

    def moved(self, d_row: int, d_col: int, frame_shape: tuple[int, int]) -> Roi:
        """Shifted by ``(d_row, d_col)``, kept inside a frame of ``frame_shape``."""
        rows, cols = frame_shape
        row = min(max(0, self.row + d_row), max(0, rows - self.height))
        col = min(max(0, self.col + d_col), max(0, cols - self.width))
        return Roi(row, col, self.height, self.width)

    def resized(self, d_height: int, d_width: int, frame_shape: tuple[int, int]) -> Roi:
        """Grown (or shrunk) about its centre by ``(d_height, d_width)``; at least 8 px."""
        rows, cols = frame_shape
        height = min(max(8, self.height + d_height), rows)
        width = min(max(8, self.width + d_width), cols)
        row = self.row - (height - self.height) // 2
        col = self.col - (width - self.width) // 2
        return Roi(row, col, height, width).moved(0, 0, frame_shape)

    def slice(self, pixels: npt.NDArray[np.generic]) -> npt.NDArray[np.generic]:
        """The ROI's pixels of ``pixels``."""
        return pixels[self.row : self.row + self.height, self.col : self.col + self.width]

    def label(self) -> str:
        return f"ROI (r{self.row}, c{self.col}) {self.width}x{self.height}"


@lru_cache(maxsize=16384)
def _cell_style(top: int, bottom: int) -> Style:
    """Style of a half-block cell from packed ``0xRRGGBB`` colours (fg = top, bg = bottom)."""
    return Style(
        color=Color.from_rgb((top >> 16) & 255, (top >> 8) & 255, top & 255),
        bgcolor=Color.from_rgb((bottom >> 16) & 255, (bottom >> 8) & 255, bottom & 255),
    )


def to_display_rgb(
    pixels: npt.NDArray[np.generic], cells: tuple[int, int], roi: Roi | None, max_code: float
) -> npt.NDArray[np.uint8]:
    """Downscale ``pixels`` to fit ``cells`` (columns, rows) of half-blocks; RGB with the ROI.

    Returns an ``(2 * rows', cols', 3)`` uint8 array (aspect ratio kept, so it may be smaller
    than the cell grid).
    """
    cols, rows = cells
    frame_rows, frame_cols = pixels.shape[:2]
    if cols < 1 or rows < 1 or frame_rows < 1 or frame_cols < 1:
        return np.zeros((0, 0, 3), np.uint8)
    scale = min(cols / frame_cols, 2 * rows / frame_rows)
    out_cols = max(1, int(frame_cols * scale))
    out_rows = max(2, int(frame_rows * scale) // 2 * 2)
    gray = np.asarray(pixels, dtype=np.float32) * (255.0 / max(max_code, 1.0))
    small = cv2.resize(gray, (out_cols, out_rows), interpolation=cv2.INTER_AREA)
    small8 = np.clip(small, 0, 255).astype(np.uint8) & 0xF8  # 32 levels: fewer styles, longer runs
    rgb = np.repeat(small8[:, :, None], 3, axis=2)
    if roi is not None:
        sy, sx = out_rows / frame_rows, out_cols / frame_cols
        r0 = min(out_rows - 1, int(roi.row * sy))
        r1 = min(out_rows - 1, max(r0, int((roi.row + roi.height) * sy) - 1))
        c0 = min(out_cols - 1, int(roi.col * sx))
        c1 = min(out_cols - 1, max(c0, int((roi.col + roi.width) * sx) - 1))
        rgb[r0, c0 : c1 + 1] = ROI_RGB
        rgb[r1, c0 : c1 + 1] = ROI_RGB
        rgb[r0 : r1 + 1, c0] = ROI_RGB
        rgb[r0 : r1 + 1, c1] = ROI_RGB
    return rgb


def rgb_to_strips(rgb: npt.NDArray[np.uint8]) -> list[Strip]:
    """One :class:`Strip` per pair of image rows (upper half-block: fg = top, bg = bottom).

    Runs of identical cells become one segment; the work per cell is vectorised, so the
    Python loop only visits runs.
    """
    packed = (
        (rgb[..., 0].astype(np.int64) << 16) | (rgb[..., 1].astype(np.int64) << 8) | rgb[..., 2]
    )
    width = rgb.shape[1]
    strips: list[Strip] = []
    for y in range(0, rgb.shape[0] - 1, 2):
        top, bottom = packed[y], packed[y + 1]
        change = (top[1:] != top[:-1]) | (bottom[1:] != bottom[:-1])
        starts = np.concatenate(([0], np.flatnonzero(change) + 1))
        lengths = np.diff(np.concatenate((starts, [width]))).tolist()
        tops, bottoms = top[starts].tolist(), bottom[starts].tolist()
        segments = [
            Segment(UPPER_HALF * n, _cell_style(t, b))
            for n, t, b in zip(lengths, tops, bottoms, strict=True)
        ]
        strips.append(Strip(segments, width))
    return strips


class FrameView(Widget):
    """The latest camera frame, downscaled into half-block characters, with the ROI drawn."""

    DEFAULT_CSS = """
    FrameView { width: 1fr; height: 1fr; min-height: 4; }
    """

    def __init__(self, *, id: str | None = None, classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        self._pixels: npt.NDArray[np.generic] | None = None
        self._roi: Roi | None = None
        self._max_code = 255.0
        self._strips: list[Strip] | None = None
        self._strips_size: tuple[int, int] = (0, 0)
        self.frames_shown = 0

    def show(self, pixels: npt.NDArray[np.generic], roi: Roi | None, max_code: float) -> None:
        """Display ``pixels`` (any size) with ``roi`` marked; codes scale to ``max_code``."""
        self._pixels = pixels
        self._roi = roi
        self._max_code = max_code
        self._strips = None
        self.frames_shown += 1
        self.refresh()

    def clear(self) -> None:
        self._pixels = None
        self._strips = None
        self.refresh()

    def _ensure_strips(self) -> list[Strip]:
        size = (self.size.width, self.size.height)
        if self._strips is None or self._strips_size != size:
            if self._pixels is None:
                self._strips = []
            else:
                rgb = to_display_rgb(self._pixels, size, self._roi, self._max_code)
                self._decorate(rgb)
                width = size[0]  # centred once per frame, not once per line drawn
                self._strips = [
                    Strip([Segment(" " * (max(0, width - s.cell_length) // 2)), *s._segments])
                    .crop(0, width) for s in rgb_to_strips(rgb)
                ]
            self._strips_size = size
        return self._strips

    def _decorate(self, rgb: npt.NDArray[np.uint8]) -> None:
        """Draw over the downscaled frame before it becomes cells (subclasses: overlays)."""

    def render_line(self, y: int) -> Strip:
        strips = self._ensure_strips()
        width = self.size.width
        if y < len(strips):
            return strips[y]
        if not strips and y == self.size.height // 2:
            return Strip([Segment("no camera image".center(width), Style(dim=True))])
        return Strip.blank(width)


#: The ROI histogram is redrawn at most this often, s (the eye can't follow more; every redraw
#: costs a compositor pass that would otherwise slow the live frame).
HISTOGRAM_INTERVAL_S = 0.2
_HIST_STYLE = Style(color="cyan")
_DARK_STYLE = Style(color="blue", bold=True)
_BRIGHT_STYLE = Style(color="yellow", bold=True)
_AXIS_STYLE = Style(bold=True)


class RoiHistogram(Widget):
    """Histogram of the ROI's gray codes with the dark and bright levels marked.

    :meth:`show` takes every frame but redraws at most once per ``min_interval_s`` and only
    when the drawing changed; the drawing is a few cached strips (one segment per colour run).
    """

    DEFAULT_CSS = """
    RoiHistogram { height: 7; width: 1fr; }
    """

    def __init__(self, *, id: str | None = None, classes: str | None = None,  # noqa: A002
                 min_interval_s: float = HISTOGRAM_INTERVAL_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(id=id, classes=classes)
        self.min_interval_s = min_interval_s
        self._clock = clock
        self._counts: npt.NDArray[np.float64] | None = None
        self._max_code = 255.0
        self._dark: float | None = None
        self._bright: float | None = None
        self._shown_at = -math.inf
        self._strips: list[Strip] | None = None
        self._strips_size = (0, 0)
        self.redraws = 0  # refreshes asked for (a changed drawing)

    def show(
        self,
        roi_pixels: npt.NDArray[np.generic],
        max_code: float,
        dark: float | None,
        bright: float | None,
        *,
        force: bool = False,
    ) -> bool:
        """Histogram ``roi_pixels`` over ``[0, max_code]``; mark ``dark`` / ``bright``.

        Skipped (returns False) within ``min_interval_s`` of the last update unless ``force``,
        or when the drawing would not change.
        """
        now = self._clock()
        if not force and now - self._shown_at < self.min_interval_s:
            return False
        self._shown_at = now
        bins = max(8, self.size.width or 64)
        counts, _ = np.histogram(
            np.asarray(roi_pixels, dtype=np.float64), bins=bins, range=(0.0, max_code + 1.0)
        )
        before = self.text_lines()
        self._counts = counts.astype(np.float64)
        self._max_code = max_code
        self._dark, self._bright = dark, bright
        self._strips = None
        if self.text_lines() == before:
            return False
        self.redraws += 1
        self.refresh()
        return True

    def _column(self, level: float | None, width: int) -> int | None:
        if level is None or not np.isfinite(level):
            return None
        return int(min(width - 1, max(0, level / (self._max_code + 1.0) * width)))

    def _ensure_strips(self) -> list[Strip]:
        size = (max(1, self.size.width), max(2, self.size.height))
        if self._strips is None or self._strips_size != size:
            self._strips = self._draw(*size)
            self._strips_size = size
        return self._strips

    def _draw(self, width: int, height: int) -> list[Strip]:
        if self._counts is None or self._counts.sum() == 0:
            return [Strip([Segment("no histogram"[:width], Style(dim=True))], width)]
        counts = self._counts
        if len(counts) != width:  # re-bin to the widget width
            edges = np.linspace(0, len(counts), width + 1).astype(int)
            sums = np.concatenate(([0.0], np.cumsum(counts)))
            counts = sums[edges[1:]] - sums[edges[:-1]]
        peak = counts.max() or 1.0
        plot_rows = height - 1
        levels = np.sqrt(counts / peak) * plot_rows * 8  # sqrt: show small populations
        marks = {c: st for c, st in ((self._column(self._dark, width), _DARK_STYLE),
                                     (self._column(self._bright, width), _BRIGHT_STYLE))
                 if c is not None}
        bars = np.array(list(BARS))
        strips = []
        for row in range(plot_rows):
            base = (plot_rows - 1 - row) * 8
            fill = np.clip(levels - base, 0, 8).astype(int)
            strips.append(_marked(("".join(bars[fill])), _HIST_STYLE, marks, width))
        axis = [" "] * width
        for col, st in marks.items():
            axis[col] = "D" if st is _DARK_STYLE else "B"
        strips.append(_marked("".join(axis), _AXIS_STYLE, {}, width))
        return strips

    def text_lines(self) -> list[str]:
        """The drawing as plain text, one string per row (what the widget shows)."""
        if self._counts is None:
            return []
        return [strip.text for strip in self._ensure_strips()]

    def render_line(self, y: int) -> Strip:
        strips = self._ensure_strips()
        return strips[y] if y < len(strips) else Strip.blank(self.size.width)


def _marked(text: str, style: Style, marks: dict[int, Style], width: int) -> Strip:
    """``text`` in ``style`` with the characters at ``marks`` (column: style) restyled."""
    segments, start = [], 0
    for col in sorted(marks):
        if start < col:
            segments.append(Segment(text[start:col], style))
        segments.append(Segment(text[col], marks[col]))
        start = col + 1
    if start < len(text):
        segments.append(Segment(text[start:], style))
    return Strip(segments, width)


#: The live readout's figures change at most this often, s (settings changes show at once).
READOUT_INTERVAL_S = 0.2


class Readout(Static):
    """Text that changes every frame, redrawn at most every ``min_interval_s`` (unless
    ``urgent``: a key press, an error) and never when the text is unchanged."""

    def __init__(self, text: str = "", *, id: str | None = None,  # noqa: A002 - Textual's
                 min_interval_s: float = READOUT_INTERVAL_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(text, id=id)
        self.min_interval_s = min_interval_s
        self._clock = clock
        self._text = text
        self._shown_at = -math.inf
        self.redraws = 0

    def show(self, text: str, *, urgent: bool = False) -> bool:
        """Show ``text`` (Rich markup); False when skipped (unchanged, or too soon)."""
        now = self._clock()
        if text == self._text or (not urgent and now - self._shown_at < self.min_interval_s):
            return False
        self._text, self._shown_at = text, now
        self.redraws += 1
        self.update(text)
        return True


class ModeBar(Widget):
    """One line at the top: the four screens with their keys (current one highlighted)."""

    DEFAULT_CSS = """
    ModeBar { height: 1; width: 1fr; background: $panel; }
    """
    MODES = (("1", "devices", "Devices"), ("2", "live", "Live"), ("3", "run", "Run"),
             ("4", "sessions", "Sessions"))

    def __init__(self, current: str, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.current = current

    def render(self) -> Text:
        text = Text(" benchlab ", style="bold")
        for key, mode, label in self.MODES:
            style = "reverse bold" if mode == self.current else ""
            text.append(" ")
            text.append(f" {key} {label} ", style=style)
        simulated = getattr(self.app, "simulate", False)
        text.append("   q Quit", style="dim")
        if simulated:
            text.append("   simulated", style="italic")
        return text
