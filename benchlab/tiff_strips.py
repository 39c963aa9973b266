"""Decode the frames benchlab writes without tifffile (start-up of a re-analysis, issue 11).

A saved frame is one classic TIFF image: 8- or 16-bit unsigned grey, one sample per pixel,
zlib strips (or none), no predictor, and the ImageJ ``Info`` property (benchlab's JSON) in the
IJMetadata tags (:func:`benchlab.storage.encode_frame_tiff`). For that layout this module reads
the first image directory with :mod:`struct` and inflates the strips with ISA-L's zlib
(``isal``: the same bytes as :mod:`zlib` in about half its CPU, the GIL released likewise;
inflating was a tenth of a batch re-analysis): importing tifffile costs 15-20 ms and its
general reader ~2 ms of interpreter time per frame, more than a re-analysis of a frame's ROIs.

Anything else (BigTIFF, tiles, a predictor, RGB, other compressions, frames written before
they were ImageJ TIFFs) and anything inconsistent (a damaged directory or strip) is
:data:`NOT_HANDLED`: the caller reads it with tifffile, so this is only ever a faster path to
the same pixels and text, and a damaged file fails as it always did.
"""

from __future__ import annotations

import struct
from typing import Any, cast

import numpy as np
import numpy.typing as npt
from isal import isal_zlib
from isal.isal_zlib import decompress as inflate

#: What a damaged zlib strip raises (a class: isal's stubs type it as an instance).
_INFLATE_ERROR = cast("type[Exception]", isal_zlib.error)
#: Returned for a file outside the layout decoded here (read it with tifffile instead).
NOT_HANDLED = None

_TYPE_SIZES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8}
_TYPE_CODES = {1: "B", 3: "H", 4: "I", 6: "b", 8: "h", 9: "i"}  # integer types
_WIDTH, _LENGTH, _BITS, _COMPRESSION, _PHOTOMETRIC = 256, 257, 258, 259, 262
_DESCRIPTION, _STRIP_OFFSETS, _SAMPLES, _ROWS_PER_STRIP, _STRIP_BYTES = 270, 273, 277, 278, 279
_PLANAR, _PREDICTOR, _TILE_WIDTH, _SAMPLE_FORMAT = 284, 317, 322, 339
_IJ_BYTE_COUNTS, _IJ_METADATA = 50838, 50839
_ZLIB = (8, 32946)  # Adobe deflate, old-style deflate
_IJ_MAGIC = 0x494A494A  # "IJIJ"
_IJ_INFO = 0x696E666F  # "info"
#: Most bytes a deflate stream can expand to per byte (1032:1), with margin.
_MAX_INFLATION = 1100


def _tags(data: bytes, order: str) -> dict[int, tuple[int, int, int]] | None:
    """First image directory: tag -> (type, count, offset of the value), or None."""
    (ifd,) = struct.unpack_from(order + "I", data, 4)
    (n,) = struct.unpack_from(order + "H", data, ifd)
    tags: dict[int, tuple[int, int, int]] = {}
    for k in range(n):
        at = ifd + 2 + 12 * k
        tag, kind, count = struct.unpack_from(order + "HHI", data, at)
        size = _TYPE_SIZES.get(kind)
        if size is None:
            return None
        value_at = at + 8
        if size * count > 4:
            (value_at,) = struct.unpack_from(order + "I", data, at + 8)
        if value_at + size * count > len(data):
            raise ValueError(f"tag {tag} points past the end of the file")
        tags[tag] = (kind, count, value_at)
    return tags


def _ints(data: bytes, order: str, tags: dict[int, tuple[int, int, int]], tag: int,
          default: int | None = None) -> tuple[int, ...]:
    if tag not in tags:
        if default is None:
            raise ValueError(f"required tag {tag} missing")
        return (default,)
    kind, count, at = tags[tag]
    code = _TYPE_CODES.get(kind)
    if code is None:
        raise ValueError(f"tag {tag} is not an integer")
    return struct.unpack_from(f"{order}{count}{code}", data, at)


def _imagej_info(data: bytes, order: str, tags: dict[int, tuple[int, int, int]]) -> str | None:
    """The ImageJ ``Info`` property, or None when the IJMetadata tags do not hold one."""
    if _IJ_BYTE_COUNTS not in tags or _IJ_METADATA not in tags:
        return None
    counts = _ints(data, order, tags, _IJ_BYTE_COUNTS)
    _, size, start = tags[_IJ_METADATA]
    blob = data[start:start + size]
    if len(counts) < 1 or counts[0] < 4 or (counts[0] - 4) % 8 or sum(counts) > len(blob):
        return None
    if struct.unpack_from(order + "I", blob, 0)[0] != _IJ_MAGIC:
        return None
    pos, entry = counts[0], 1
    encoding = "utf-16-le" if order == "<" else "utf-16-be"
    for k in range(4, counts[0], 8):
        kind, n = struct.unpack_from(order + "II", blob, k)
        if entry + n > len(counts):
            return None
        if kind == _IJ_INFO and n == 1:
            return blob[pos:pos + counts[entry]].decode(encoding)
        pos += sum(counts[entry:entry + n])
        entry += n
    return None


def decode_frame(data: bytes) -> tuple[npt.NDArray[Any], str] | None:
    """``(pixels, ImageJ Info text)`` of a frame in the layout above, else :data:`NOT_HANDLED`
    (never raises for what a file holds).

    The pixels are the first image's, writable, in native byte order (as tifffile's
    ``pages.first.asarray()`` returns them).
    """
    if len(data) < 8 or data[:4] not in (b"II*\0", b"MM\0*"):
        return NOT_HANDLED
    try:
        return _decode(data, "<" if data[:2] == b"II" else ">")
    except (ValueError, struct.error, _INFLATE_ERROR, UnicodeDecodeError):
        return NOT_HANDLED  # damaged: tifffile reads it, or names what is wrong


def _decode(data: bytes, order: str) -> tuple[npt.NDArray[Any], str] | None:
    tags = _tags(data, order)
    if tags is None or _TILE_WIDTH in tags:
        return NOT_HANDLED

    def ints(tag: int, default: int | None = None) -> tuple[int, ...]:
        return _ints(data, order, tags, tag, default)

    width, height, rows_per_strip = ints(_WIDTH)[0], ints(_LENGTH)[0], ints(_ROWS_PER_STRIP,
                                                                          2**32 - 1)[0]
    layout = (ints(_SAMPLES, 1), ints(_PLANAR, 1), ints(_PREDICTOR, 1), ints(_SAMPLE_FORMAT, 1),
              ints(_PHOTOMETRIC))
    bits, compression = ints(_BITS, 1), ints(_COMPRESSION, 1)[0]
    offsets, byte_counts = ints(_STRIP_OFFSETS), ints(_STRIP_BYTES)
    description, info = tags.get(_DESCRIPTION), _imagej_info(data, order, tags)
    if (layout != ((1,), (1,), (1,), (1,), (1,)) or bits not in ((8,), (16,))
            or compression not in (1, *_ZLIB) or description is None or info is None
            or not data[description[2]:description[2] + description[1]].startswith(b"ImageJ=")
            or width < 1 or height < 1 or rows_per_strip < 1):
        return NOT_HANDLED  # (an Info that ImageJ would not read as ImageJ's is not one)
    row_bytes = width * bits[0] // 8
    n_strips = -(-height // rows_per_strip)
    if (len(offsets) != n_strips or len(byte_counts) != n_strips
            or height * row_bytes > _MAX_INFLATION * len(data)):
        return NOT_HANDLED  # (no zlib stream inflates more: a damaged size, not a frame)
    out = np.empty(height * row_bytes, dtype=np.uint8)
    pos = 0
    for k, (offset, size) in enumerate(zip(offsets, byte_counts, strict=True)):
        want = min(rows_per_strip, height - k * rows_per_strip) * row_bytes
        if offset + size > len(data):
            return NOT_HANDLED
        raw = data[offset:offset + size]
        strip = inflate(raw) if compression in _ZLIB else raw  # frees the GIL, as zlib
        if len(strip) != want:
            return NOT_HANDLED
        out[pos:pos + want] = np.frombuffer(strip, dtype=np.uint8)
        pos += want
    dtype = np.dtype(np.uint8) if bits == (8,) else np.dtype(order + "u2")
    pixels = out.view(dtype).reshape(height, width)
    if not pixels.dtype.isnative:
        pixels = pixels.byteswap().view(pixels.dtype.newbyteorder("="))
    return pixels, info
