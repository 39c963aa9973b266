"""Live-view chart overlay: the found USAF elements drawn on the frame, picked as the ROI.

:class:`ChartFrameView` (half-blocks) and :class:`ChartGraphicsFrameView` (Kitty / Sixel
images) are the live frame views plus a list of boxes (frame pixels) drawn in green;
:func:`set_overlay` gives them the boxes, :func:`pick_element` chooses the found element under
a point (mouse click, half-block view) and :func:`roi_of` turns it into the live view's
:class:`Roi`.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from benchlab.analysis.chart.finder import ChartFit, FoundElement
from benchlab.analysis.chart.layout import Box
from benchlab.tui.drawing.pixels import GraphicsFrameView, frame_rgb
from benchlab.tui.widgets import FrameView, Roi

FOUND_RGB = (0, 220, 60)


def roi_of(element: FoundElement) -> Roi:
    """The live-view ROI of a found element (its measurement ROI)."""
    r0, c0, r1, c1 = element.roi
    return Roi(r0, c0, r1 - r0, c1 - c0)


def _draw_boxes(rgb: npt.NDArray[np.uint8], boxes: list[Box],
                frame_shape: tuple[int, int]) -> None:
    """Outline ``boxes`` (frame pixels) on ``rgb``, an image of the whole frame at any size."""
    if not boxes or rgb.size == 0:
        return
    sy, sx = rgb.shape[0] / frame_shape[0], rgb.shape[1] / frame_shape[1]
    for r0, c0, r1, c1 in boxes:
        a, b = int(r0 * sy), int((r1 - 1) * sy)
        c, d = int(c0 * sx), int((c1 - 1) * sx)
        if 0 <= a and b < rgb.shape[0] and 0 <= c and d < rgb.shape[1]:
            rgb[a, c:d + 1] = FOUND_RGB
            rgb[b, c:d + 1] = FOUND_RGB
            rgb[a:b + 1, c] = FOUND_RGB
            rgb[a:b + 1, d] = FOUND_RGB


def set_overlay(view: FrameView, boxes: list[Box], frame_shape: tuple[int, int]) -> None:
    """Give a live frame view the boxes to draw (views without an overlay ignore them)."""
    if isinstance(view, ChartFrameView | ChartGraphicsFrameView):
        view.set_overlay(boxes, frame_shape)


def pick_element(fit: ChartFit, point_rc: tuple[float, float]) -> FoundElement | None:
    """The found element whose set holds the point, else the nearest within two set sizes."""
    best: tuple[float, FoundElement] | None = None
    for el in fit.found:
        d = math.dist(point_rc, el.posed.centre_rc)
        reach = 2.0 * 5.0 * el.posed.bar_width_px
        if d <= reach and (best is None or d < best[0]):
            best = (d, el)
    return None if best is None else best[1]


class ChartFrameView(FrameView):
    """A :class:`FrameView` that also draws the found chart's ROIs (frame coordinates)."""

    def __init__(self, *, id: str | None = None, classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        self._boxes: list[Box] = []
        self._frame_shape: tuple[int, int] = (1, 1)
        self._rgb_shape: tuple[int, int] = (0, 0)

    def set_overlay(self, boxes: list[Box], frame_shape: tuple[int, int]) -> None:
        """Boxes to draw (empty: none) over a frame of ``frame_shape``."""
        if boxes != self._boxes or frame_shape != self._frame_shape:
            self._boxes, self._frame_shape = list(boxes), frame_shape
            self._strips = None
            self.refresh()

    def _decorate(self, rgb: npt.NDArray[np.uint8]) -> None:
        self._draw(rgb)
        self._rgb_shape = (rgb.shape[0], rgb.shape[1])

    def _draw(self, rgb: npt.NDArray[np.uint8]) -> None:
        _draw_boxes(rgb, self._boxes, self._frame_shape)

    def cell_to_frame(self, x: int, y: int) -> tuple[float, float] | None:
        """Frame pixel (row, col) under a widget cell, or None outside the image."""
        rows, cols = self._rgb_shape
        if rows == 0 or cols == 0:
            return None
        pad = max(0, self.size.width - cols) // 2
        col_img, row_img = x - pad + 0.5, 2 * y + 1.0
        if not (0 <= col_img < cols and 0 <= row_img < rows):
            return None
        return (row_img * self._frame_shape[0] / rows, col_img * self._frame_shape[1] / cols)


class ChartGraphicsFrameView(GraphicsFrameView):
    """A :class:`GraphicsFrameView` that also draws the found chart's ROIs."""

    def __init__(self, protocol: str, *, id: str | None = None,  # noqa: A002 - Textual's
                 classes: str | None = None) -> None:
        super().__init__(protocol, id=id, classes=classes)
        self._boxes: list[Box] = []
        self._frame_shape: tuple[int, int] = (1, 1)

    def set_overlay(self, boxes: list[Box], frame_shape: tuple[int, int]) -> None:
        """Boxes to draw (empty: none) over a frame of ``frame_shape``; shown with the next
        frame."""
        self._boxes, self._frame_shape = list(boxes), frame_shape

    def show(self, pixels: npt.NDArray[np.generic], roi: Roi | None, max_code: float) -> None:
        rgb = frame_rgb(pixels, roi, max_code)
        _draw_boxes(rgb, self._boxes, self._frame_shape)
        self.show_rgb(rgb)
