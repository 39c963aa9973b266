"""Image files that are not benchlab's own TIFF frames: JPEG, PNG and BMP, through Pillow.

Cameras and the standard ISO 12233 charts write JPEG; other tools write PNG or BMP. Pillow
decodes all of them (8-bit grey, 16-bit grey PNG, palette, RGB, RGBA). What comes back is the
monochrome frame the analyses read:

- grey (``L``, ``I;16``, ``I`` within 0..65535, bilevel ``1``): as stored, 8 or 16 bit;
- colour whose channels agree (a grey image saved as RGB, a palette of greys): one channel;
- colour JPEG: its luminance, ``0.2126 R + 0.7152 G + 0.0722 B`` (ISO 12233's weights),
  rounded to 8 bit - a JPEG of a grey chart is never exactly grey after chroma subsampling;
- other colour (PNG, BMP): refused - benchlab analyses monochrome frames.

JPEG codes are read as they are: a camera's JPEG is usually gamma-encoded, and no gamma is
undone here (linearise first where the camera's response is known).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

#: Suffixes read through Pillow (TIFF goes through :func:`benchlab.storage.read_tiff_frame`).
PILLOW_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")
JPEG_SUFFIXES = (".jpg", ".jpeg")
#: Luminance weights of ISO 12233 (Rec. 709 primaries) for a colour JPEG.
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)


class ColourImageError(ValueError):
    """A true colour image (not JPEG) where a monochrome frame is needed."""


def decode_image(path: Path) -> npt.NDArray[Any]:
    """The monochrome pixels of a JPEG, PNG or BMP file (uint8 or uint16, 2-D).

    Raises
    ------
    ColourImageError
        A colour PNG or BMP whose channels differ.
    ValueError
        A file Pillow cannot decode, or an image mode with no monochrome reading (CMYK,
        float, 32-bit integers beyond 16 bit).
    """
    from PIL import Image

    with Image.open(path) as opened:
        opened.load()
        mode = opened.mode
        if mode == "1":
            return np.asarray(opened.convert("L"), dtype=np.uint8)
        im: Image.Image = opened
        if mode == "P":
            im = opened.convert("RGBA" if "transparency" in opened.info else "RGB")
            mode = im.mode
        arr = np.asarray(im)
    if mode in ("L", "LA"):
        return np.ascontiguousarray(arr if arr.ndim == 2 else arr[..., 0], dtype=np.uint8)
    if mode.startswith("I;16"):
        return np.ascontiguousarray(arr, dtype=np.uint16)
    if mode == "I":
        if arr.size and (int(arr.min()) < 0 or int(arr.max()) > 65535):
            raise ValueError(f"32-bit integer pixels outside 0..65535 (mode {mode})")
        return np.ascontiguousarray(arr, dtype=np.uint16)
    if mode in ("RGB", "RGBA"):
        colour = arr[..., :3]
        if np.all(colour == colour[..., :1]):
            return np.ascontiguousarray(colour[..., 0], dtype=np.uint8)
        if path.suffix.lower() in JPEG_SUFFIXES:
            w = np.asarray(LUMINANCE_WEIGHTS, dtype=np.float64)
            luma = colour.astype(np.float64) @ w
            return np.clip(np.rint(luma), 0, 255).astype(np.uint8)
        raise ColourImageError("colour image; benchlab analyses monochrome frames")
    raise ValueError(f"image mode {mode} has no monochrome reading")
