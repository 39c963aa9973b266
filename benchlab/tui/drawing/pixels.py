"""Real pixels in the live view where the terminal can show them.

Terminals with an image protocol (Kitty's graphics protocol: kitty; Sixel: WezTerm, foot,
recent xterm, mlterm) get the camera frame as an image (:mod:`benchlab.tui.drawing.graphics`; the
terminal is asked through ``textual-image``); every other terminal keeps the half-block
rendering of :class:`benchlab.tui.widgets.FrameView`.

The terminal must be asked what it supports *before* Textual takes it over, so
:func:`choose_image_protocol` runs in ``benchlab tui`` before the app starts. ``--image`` (or
``BENCHLAB_IMAGE``) forces a choice: ``kitty``, ``sixel`` or ``halfblock``.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np
import numpy.typing as npt
from textual.app import ComposeResult

from benchlab.tui.drawing.graphics import KittyCanvas, SixelCanvas
from benchlab.tui.widgets import ROI_RGB, FrameView, Roi

IMAGE_PROTOCOLS = ("auto", "kitty", "sixel", "halfblock")
#: Longest side of the preview sent as an image (pixels): sharp enough to focus by, small
#: enough to encode 15+ times a second.
GRAPHICS_PREVIEW_SIDE = 640


def choose_image_protocol(requested: str | None = None) -> str:
    """``"kitty"``, ``"sixel"`` or ``"halfblock"`` for this terminal.

    Parameters
    ----------
    requested : str, optional
        One of :data:`IMAGE_PROTOCOLS`; default ``BENCHLAB_IMAGE`` or ``"auto"``. ``auto``
        queries the terminal (only when standard output is a terminal).
    """
    choice = (requested or os.environ.get("BENCHLAB_IMAGE") or "auto").strip().lower()
    if choice not in IMAGE_PROTOCOLS:
        raise ValueError(f"image protocol must be one of {', '.join(IMAGE_PROTOCOLS)}, "
                         f"got {choice!r}")
    if choice != "auto":
        return choice
    stdout = sys.__stdout__
    if stdout is None or not stdout.isatty():
        return "halfblock"
    try:
        # Importing the renderables queries the terminal (Sixel first, then Kitty's protocol).
        from textual_image import renderable
    except Exception:  # noqa: BLE001 - a terminal that cannot be asked gets half-blocks
        return "halfblock"
    if renderable.Image is renderable.SixelImage:
        return "sixel"
    if renderable.Image is renderable.TGPImage:
        return "kitty"
    return "halfblock"


def frame_rgb(pixels: npt.NDArray[np.generic], roi: Roi | None,
              max_code: float) -> npt.NDArray[np.uint8]:
    """A preview frame as 8-bit RGB with the ROI outlined (1 px) in the live view's yellow."""
    gray = np.clip(np.asarray(pixels, dtype=np.float32) * (255.0 / max(max_code, 1.0)), 0, 255)
    rgb = np.repeat(gray.astype(np.uint8)[:, :, None], 3, axis=2)
    if roi is not None and rgb.size:
        rows, cols = rgb.shape[:2]
        r0, c0 = min(max(roi.row, 0), rows - 1), min(max(roi.col, 0), cols - 1)
        r1 = min(max(r0, roi.row + roi.height - 1), rows - 1)
        c1 = min(max(c0, roi.col + roi.width - 1), cols - 1)
        rgb[r0, c0:c1 + 1] = ROI_RGB
        rgb[r1, c0:c1 + 1] = ROI_RGB
        rgb[r0:r1 + 1, c0] = ROI_RGB
        rgb[r0:r1 + 1, c1] = ROI_RGB
    return rgb


class GraphicsFrameView(FrameView):
    """The live frame as a real image (Kitty graphics or Sixel): :mod:`.graphics`."""

    DEFAULT_CSS = """
    GraphicsFrameView { width: 1fr; height: 1fr; min-height: 4; align: center middle; }
    """

    def __init__(self, protocol: str, *, id: str | None = None,  # noqa: A002 - Textual's
                 classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        if protocol not in ("kitty", "sixel"):
            raise ValueError(f"GraphicsFrameView needs kitty or sixel, got {protocol!r}")
        self.protocol = protocol
        self.image_widget: KittyCanvas | SixelCanvas | None = None
        self.last_rgb: npt.NDArray[np.uint8] | None = None

    def compose(self) -> ComposeResult:
        cls = SixelCanvas if self.protocol == "sixel" else KittyCanvas
        self.image_widget = cls(classes="frame-image")
        yield self.image_widget

    def show(self, pixels: npt.NDArray[np.generic], roi: Roi | None, max_code: float) -> None:
        self.show_rgb(frame_rgb(pixels, roi, max_code))

    def show_rgb(self, rgb: npt.NDArray[np.uint8]) -> None:
        """Show an already drawn RGB frame (encoded when the terminal next draws it)."""
        self.frames_shown += 1
        self.last_rgb = rgb
        if self.image_widget is not None:
            self.image_widget.set_image(rgb)

    def clear(self) -> None:
        self.last_rgb = None
        if self.image_widget is not None:
            self.image_widget.set_image(None)

    def render_line(self, y: int) -> Any:  # the child image widget draws; margins blank
        from textual.strip import Strip

        return Strip.blank(self.size.width)
