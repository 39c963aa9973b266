"""Terminal image protocols for the live frame: Sixel and Kitty's graphics protocol.

Two line-API widgets that show one RGB image centred in their area, built for a stream:

- :class:`SixelCanvas` encodes the image at the pixel size it is shown at, never above the
  image's own size (a Sixel image is drawn 1:1 by the terminal, so every extra pixel is encode
  and transfer time: the cost per frame stays bounded at any terminal size). The image becomes
  32 gray levels plus the overlay colours it holds (no colour quantisation), encoded by
  :mod:`benchlab.tui.sixel`.
- :class:`KittyCanvas` transmits the image at its own resolution and lets the terminal scale
  it to the placement's cells (Unicode placeholders), so a larger terminal costs nothing more.

Both encode only when a new image arrived or their size changed, and never re-layout the
screen. ``textual-image`` supplies the Kitty transmission and the terminal's cell size
(queried before Textual starts).
"""

from __future__ import annotations

import io
import math
from base64 import standard_b64encode
from functools import lru_cache
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from rich.control import Control
from rich.segment import ControlType, Segment
from rich.style import Style
from textual.geometry import Region, Size
from textual.strip import Strip
from textual.widget import Widget

from benchlab.tui.sixel import encode_sixel

#: Gray levels of a Sixel frame (the half-block view shows 32 too): fewer palette colours per
#: six-row band is less to encode and send.
SIXEL_GRAY_LEVELS = 32
_NULL = Style()


def cell_size_px() -> tuple[int, int]:
    """The terminal's cell size in pixels (width, height); 10 x 20 when it can't be asked."""
    from textual_image._terminal import get_cell_size

    size = get_cell_size()
    return int(size.width), int(size.height)


def fit_image(image_px: tuple[int, int], area_cells: tuple[int, int], cell_px: tuple[int, int],
              *, upscale: bool) -> tuple[tuple[int, int], tuple[int, int]]:
    """Where an image goes in an area of cells, aspect ratio kept.

    Parameters
    ----------
    image_px : (int, int)
        Image width and height, pixels.
    area_cells : (int, int)
        Available columns and rows.
    cell_px : (int, int)
        Width and height of one cell, pixels.
    upscale : bool
        Whether the image may be shown larger than its own size (Kitty: the terminal scales;
        Sixel: no, every shown pixel is encoded).

    Returns
    -------
    ((int, int), (int, int))
        The shown size in pixels (width, height) and the cells it covers (columns, rows);
        zeros when nothing fits.
    """
    (w, h), (cols, rows), (cw, ch) = image_px, area_cells, cell_px
    if min(w, h, cols, rows, cw, ch) <= 0:
        return (0, 0), (0, 0)
    scale = min(cols * cw / w, rows * ch / h)
    if not upscale:
        scale = min(scale, 1.0)
    px_w, px_h = max(1, int(w * scale)), max(1, int(h * scale))
    return (px_w, px_h), (min(cols, math.ceil(px_w / cw)), min(rows, math.ceil(px_h / ch)))


def sixel_palette(rgb: npt.NDArray[np.uint8]) -> tuple[npt.NDArray[np.uint8],
                                                      npt.NDArray[np.uint8]]:
    """``rgb`` as palette indices and a palette: 32 gray levels plus its overlay colours.

    Gray pixels (r = g = b within a few codes) keep their level; coloured ones (ROI and chart
    outlines) take the nearest of the few distinct colours present.
    """
    px = rgb.astype(np.int16)
    spread = np.abs(px[..., 0] - px[..., 1]) + np.abs(px[..., 1] - px[..., 2])
    coloured = spread > 24
    index = (rgb[..., 1] // (256 // SIXEL_GRAY_LEVELS)).astype(np.uint8)
    grays = np.round(np.arange(SIXEL_GRAY_LEVELS) * 255 / (SIXEL_GRAY_LEVELS - 1))
    palette = np.repeat(grays.astype(np.uint8)[:, None], 3, axis=1)
    if coloured.any():
        colours = np.unique(rgb[coloured], axis=0)[: 256 - SIXEL_GRAY_LEVELS]
        d2 = ((px[coloured][:, None, :] - colours[None, :, :].astype(np.int16)) ** 2).sum(axis=2)
        index[coloured] = SIXEL_GRAY_LEVELS + d2.argmin(axis=1).astype(np.uint8)
        palette = np.concatenate((palette, colours.astype(np.uint8)))
    return index, palette


class _Canvas(Widget):
    """An RGB image; the widget is sized (``width``/``height: auto``) to the cells it covers,
    so the parent centres it and paints the margins."""

    DEFAULT_CSS = """
    _Canvas { width: auto; height: auto; }
    """
    #: Whether the shown image may be larger than the image itself.
    UPSCALE = False

    def __init__(self, *, classes: str | None = None) -> None:
        super().__init__(classes=classes)
        self.image: npt.NDArray[np.uint8] | None = None
        self.serial = 0  # bumped per new image: what the encode caches are keyed on
        self.encodes = 0  # how many times an image was encoded (each costs real time)

    def set_image(self, rgb: npt.NDArray[np.uint8] | None) -> None:
        """Show ``rgb`` (H x W x 3, uint8) from the next refresh; ``None`` clears."""
        old = None if self.image is None else self.image.shape
        self.image = rgb
        self.serial += 1
        # A new image of the same shape covers the same cells: no layout pass.
        self.refresh(layout=(None if rgb is None else rgb.shape) != old)

    def _fit(self, cols: int, rows: int) -> tuple[tuple[int, int], tuple[int, int]]:
        if self.image is None:
            return (0, 0), (0, 0)
        return fit_image((self.image.shape[1], self.image.shape[0]), (cols, rows),
                         cell_size_px(), upscale=self.UPSCALE)

    def get_content_width(self, container: Size, viewport: Size) -> int:
        return self._fit(container.width, container.height or 2**16)[1][0]

    def get_content_height(self, container: Size, viewport: Size, width: int) -> int:
        return self._fit(width, container.height or 2**16)[1][1]

    def shown_px(self) -> tuple[int, int]:
        """The image's shown size in pixels (width, height) in the cells the widget has."""
        return self._fit(*self.content_size)[0]


class SixelCanvas(_Canvas):
    """The image as Sixel data, injected into the rendered lines."""

    def __init__(self, *, classes: str | None = None) -> None:
        super().__init__(classes=classes)
        self._sixel_key: tuple[Any, ...] = ()
        self._sixel = ""

    def sixel_data(self) -> str:
        """The Sixel string of the current image at its shown size (cached per image/size)."""
        shown = self.shown_px()
        key = (self.serial, shown)
        if key != self._sixel_key:
            self._sixel = ""
            if self.image is not None and shown[0] > 0:
                rgb = self.image
                if shown != (rgb.shape[1], rgb.shape[0]):
                    rgb = np.asarray(cv2.resize(rgb, shown, interpolation=cv2.INTER_AREA),
                                     np.uint8)
                self._sixel = encode_sixel(*sixel_palette(rgb))
                self.encodes += 1
            self._sixel_key = key
        return self._sixel

    def render_lines(self, crop: Region) -> list[Strip]:
        lines = [Strip([])] * crop.height  # cells under the image: nothing written
        try:
            if self.image is None or not self.screen.is_active or not crop.height:
                return lines
            visible = self.screen.find_widget(self).visible_region
        except Exception:  # noqa: BLE001 - not on a screen (yet): nothing to draw
            return lines
        if crop != Region(0, 0, *self.size) or visible.size != self.size:
            return lines  # partly covered (a toast, a dialog): the terminal keeps the last one
        data = self.sixel_data()
        if not data:
            return lines
        # The image goes out with the last line, after the cells it is drawn over (text
        # written later would erase its pixels); the cursor is put back afterwards.
        image = [
            Segment(Control.move_to(visible.x, visible.y).segment.text, _NULL),
            Segment(data, _NULL, [(ControlType.CURSOR_FORWARD, 0)]),
            Segment(Control.move_to(visible.right, visible.bottom).segment.text, _NULL),
        ]
        return [*lines[:-1], Strip(image, crop.width)]


@lru_cache(maxsize=1)
def _tgp_image_class() -> type:
    """textual-image's Kitty renderable, sending the image at its own size (PNG, fast level).

    The placement is sized in cells and the terminal scales the image into it, so scaling it
    here to the cells' pixel size (textual-image's default) would only cost time.
    """
    from textual_image.renderable.tgp import Image as TGPImage
    from textual_image.renderable.tgp import _send_tgp_message

    class NativeSizeTGP(TGPImage):  # type: ignore[misc]
        png: bytes = b""

        def _send_image_to_terminal(self, width: int, height: int) -> None:
            self.terminal_image_id = next(TGPImage._image_id_counter)
            data = standard_b64encode(self.png).decode("ascii")
            while data:
                chunk, data = data[:4096], data[4096:]
                _send_tgp_message(i=self.terminal_image_id, m=1 if data else 0, f=100,
                                  payload=chunk, q=2)

    return NativeSizeTGP


class KittyCanvas(_Canvas):
    """The image through Kitty's graphics protocol: one transmission and placement per image,
    shown by placeholder cells that the terminal replaces with the scaled image."""

    UPSCALE = True

    def __init__(self, *, classes: str | None = None) -> None:
        super().__init__(classes=classes)
        self._tgp: Any = None
        self._tgp_key: tuple[Any, ...] = ()
        self._lines: list[Strip] = []

    def _ensure_placed(self) -> None:
        from PIL import Image

        cells = (self.content_size.width, self.content_size.height)
        key = (self.serial, cells)
        if key == self._tgp_key:
            return
        old, self._tgp, self._lines = self._tgp, None, []
        if self.image is not None and min(cells) > 0:
            rows, cols = self.image.shape[:2]
            buffer = io.BytesIO()
            Image.fromarray(self.image, mode="RGB").save(buffer, format="png", compress_level=1)
            tgp = _tgp_image_class()(Image.new("L", (cols, rows)), *cells)
            tgp.png = buffer.getvalue()
            console = self.app.console
            options = console.options.update(width=cells[0], height=cells[1])
            self._lines = [Strip([Segment(s.text.rstrip("\n"), s.style)], cells[0])
                           for s in tgp.__rich_console__(console, options)]
            self._tgp = tgp
            self.encodes += 1
        if old is not None:
            _free_tgp(old)  # after the new one is placed: no blank flash
        self._tgp_key = key

    def render_line(self, y: int) -> Strip:
        self._ensure_placed()
        if 0 <= y < len(self._lines):
            return self._lines[y]
        return Strip.blank(self.size.width)

    def on_unmount(self) -> None:
        if self._tgp is not None:
            _free_tgp(self._tgp)
            self._tgp = None


def _free_tgp(tgp: Any) -> None:
    """Delete a transmitted image and its virtual placement (``d=I``: by id, data freed; the
    default ``d=a`` would not touch virtual placements and leave the image stored)."""
    from textual_image.renderable.tgp import _send_tgp_message

    if tgp.terminal_image_id:
        _send_tgp_message(a="d", d="I", i=tgp.terminal_image_id, q=2)
        tgp.terminal_image_id = None
