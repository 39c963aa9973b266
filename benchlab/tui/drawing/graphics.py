"""Terminal image protocols for the live frame: Sixel and Kitty's graphics protocol.

Two line-API widgets that show one RGB image centred in their area, built for a stream:

- :class:`SixelCanvas` encodes the image at the pixel size it is shown at, never above the
  image's own size (a Sixel image is drawn 1:1 by the terminal, so every extra pixel is encode
  and transfer time: the cost per frame stays bounded at any terminal size). The image becomes
  32 gray levels plus the overlay colours it holds (no colour quantisation), encoded by
  :mod:`benchlab.tui.drawing.sixel`.
- :class:`KittyCanvas` transmits the image at its own resolution (a palette PNG, 128 grays)
  and lets the terminal scale it to the placement's cells (Unicode placeholders), so a larger
  terminal costs nothing more.

Both encode only when a new image arrived or their size changed, and never re-layout the
screen. ``textual-image`` supplies the terminal's cell size (queried before Textual starts)
and Kitty's placeholder numbering table.
"""

from __future__ import annotations

import io
import itertools
import math
import random
import sys
from base64 import standard_b64encode
from functools import lru_cache
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from rich.color import Color
from rich.control import Control
from rich.segment import ControlType, Segment
from rich.style import Style
from textual.geometry import Region, Size
from textual.strip import Strip
from textual.widget import Widget

from benchlab.tui.drawing.sixel import encode_sixel

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


def _coloured(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.bool_]:
    """Pixels that are not gray (r, g, b more than a few codes apart): the outlines."""
    px = rgb.astype(np.int16)
    return (np.abs(px[..., 0] - px[..., 1]) + np.abs(px[..., 1] - px[..., 2])) > 24


def overlay_colours(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """The distinct non-gray colours of ``rgb`` (ROI and chart outlines), shape (n, 3)."""
    return np.unique(rgb[_coloured(rgb)], axis=0).astype(np.uint8).reshape(-1, 3)


def to_palette(rgb: npt.NDArray[np.uint8], gray_levels: int = SIXEL_GRAY_LEVELS,
                  colours: npt.NDArray[np.uint8] | None = None,
                  ) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint8]]:
    """``rgb`` as palette indices and a palette: ``gray_levels`` (a power of two <= 128) gray
    levels plus the overlay colours.

    Gray pixels keep their level; coloured ones (ROI and chart outlines) take the nearest of
    ``colours`` (default: the distinct ones in ``rgb``; pass the full-size image's when ``rgb``
    is a downscaled copy, whose blended edge colours are not worth palette entries).
    """
    coloured = _coloured(rgb)
    index = (rgb[..., 1] // (256 // gray_levels)).astype(np.uint8)
    grays = np.round(np.arange(gray_levels) * 255 / (gray_levels - 1))
    palette = np.repeat(grays.astype(np.uint8)[:, None], 3, axis=1)
    if colours is None:
        colours = overlay_colours(rgb)
    colours = colours[: 256 - gray_levels]
    if coloured.any() and len(colours):
        px = rgb[coloured].astype(np.int32)
        d2 = ((px[:, None, :] - colours[None, :, :].astype(np.int32)) ** 2).sum(axis=2)
        index[coloured] = gray_levels + d2.argmin(axis=1).astype(np.uint8)
        palette = np.concatenate((palette, colours))
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
                colours = overlay_colours(rgb)
                if shown != (rgb.shape[1], rgb.shape[0]):
                    rgb = np.asarray(cv2.resize(rgb, shown, interpolation=cv2.INTER_AREA),
                                     np.uint8)
                self._sixel = encode_sixel(*to_palette(rgb, colours=colours))
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


#: Gray levels of a Kitty frame: sent as a palette PNG (a fifth of the RGB PNG's time).
KITTY_GRAY_LEVELS = 128
_KITTY_PLACEHOLDER = "\U0010EEEE"
_kitty_ids = itertools.count(random.randint(1, 2**23))


def _kitty_id() -> int:
    """A new 24-bit image id: the placeholder cells' colour alone names it."""
    return next(_kitty_ids) % (2**24 - 1) + 1


def _kitty_diacritics() -> list[int]:
    """Kitty's row / column numbering diacritics (textual-image carries the table)."""
    from textual_image.renderable.tgp import _NUMBER_TO_DIACRITIC

    return list(_NUMBER_TO_DIACRITIC)


@lru_cache(maxsize=8)
def _placeholder_rows(cols: int, rows: int) -> tuple[str, ...]:
    """The placeholder text of a ``cols`` x ``rows`` placement (the same for every image)."""
    marks = [chr(c) for c in _kitty_diacritics()]
    return tuple("".join(_KITTY_PLACEHOLDER + marks[r] + marks[c] for c in range(cols))
                 for r in range(rows))


def _kitty_command(payload: str = "", **keys: int | str) -> str:
    """One graphics command (APC ``G`` keys ``;`` payload ST)."""
    head = ",".join(f"{k}={v}" for k, v in keys.items())
    return f"\x1b_G{head}{';' + payload if payload else ''}\x1b\\"


def _to_terminal(data: str) -> None:
    """Write straight to the terminal (Kitty graphics commands don't go through Textual)."""
    out = sys.__stdout__
    if out is not None:
        out.write(data)
        out.flush()


class KittyCanvas(_Canvas):
    """The image through Kitty's graphics protocol: one transmission and virtual placement per
    image, shown by placeholder cells (their colour names the image) that the terminal
    replaces with the image scaled to them."""

    UPSCALE = True

    def __init__(self, *, classes: str | None = None) -> None:
        super().__init__(classes=classes)
        self.image_id = 0  # the placed image (0: none)
        self._placed_key: tuple[Any, ...] = ()
        self._style = Style()

    def _fit(self, cols: int, rows: int) -> tuple[tuple[int, int], tuple[int, int]]:
        most = len(_kitty_diacritics())  # placeholders can number this many rows / columns
        return super()._fit(min(cols, most), min(rows, most))

    def png(self) -> bytes:
        """The current image as a palette PNG (128 grays and its outline colours)."""
        from PIL import Image

        assert self.image is not None
        index, palette = to_palette(self.image, KITTY_GRAY_LEVELS)
        image = Image.frombytes("P", (index.shape[1], index.shape[0]), index.tobytes())
        image.putpalette(palette.ravel().tolist())
        buffer = io.BytesIO()
        image.save(buffer, format="png", compress_level=1)
        return buffer.getvalue()

    def _ensure_placed(self) -> None:
        cells = (self.content_size.width, self.content_size.height)
        key = (self.serial, cells)
        if key == self._placed_key:
            return
        old, self.image_id = self.image_id, 0
        if self.image is not None and min(cells) > 0:
            self.image_id = _kitty_id()
            data = standard_b64encode(self.png()).decode("ascii")
            chunks = [data[i:i + 4096] for i in range(0, len(data), 4096)]
            commands = [_kitty_command(chunk, i=self.image_id, f=100, q=2,
                                       m=int(n < len(chunks) - 1))
                        for n, chunk in enumerate(chunks)]
            commands.append(_kitty_command(a="p", i=self.image_id, c=cells[0], r=cells[1],
                                           U=1, q=2))
            if old:  # after the new one is placed: no blank flash
                commands.append(_free_command(old))
            _to_terminal("".join(commands))
            self._style = Style(color=Color.from_rgb((self.image_id >> 16) & 255,
                                                     (self.image_id >> 8) & 255,
                                                     self.image_id & 255))
            self.encodes += 1
        elif old:
            _to_terminal(_free_command(old))
        self._placed_key = key

    def render_line(self, y: int) -> Strip:
        self._ensure_placed()
        cols, rows = self.content_size
        if self.image_id and 0 <= y < rows:
            return Strip([Segment(_placeholder_rows(cols, rows)[y], self._style)], cols)
        return Strip.blank(self.size.width)

    def on_unmount(self) -> None:
        if self.image_id:
            _to_terminal(_free_command(self.image_id))
            self.image_id = 0


def _free_command(image_id: int) -> str:
    """Delete an image and its virtual placement by id (``d=I``: data freed too; the default
    ``d=a`` would not touch virtual placements and leave the image stored)."""
    return _kitty_command(a="d", d="I", i=image_id, q=2)
