"""Frames and radial views are deflated by Python's zlib in strips tifffile writes as they are
(:func:`benchlab.storage.zlib_strips`) and inflated by whatever codec tifffile picks
(libdeflate with ``imagecodecs`` installed): the files are the bytes tifffile's own zlib codec
writes, the pixels read back are the ones zlib gives (issue 39)."""

from __future__ import annotations

import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
import tifffile

from benchlab.radial_views import VIEW_FORMAT, VIEW_FORMAT_VERSION, encode_view_tiff
from benchlab.storage import (
    METADATA_FORMAT,
    METADATA_VERSION,
    SOFTWARE,
    ZLIB_LEVEL,
    encode_frame_tiff,
    json_default,
    load_frame_tiff,
    read_tiff_frame,
)

_python_zlib = pytest.importorskip("tifffile._imagecodecs")


@pytest.fixture
def plain_zlib(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """tifffile as it is without imagecodecs: Python's zlib both ways."""
    compressors: Any = tifffile.TIFF.COMPRESSORS
    decompressors: Any = tifffile.TIFF.DECOMPRESSORS
    if not hasattr(compressors, "_codecs") or not hasattr(decompressors, "_codecs"):
        pytest.skip("this tifffile keeps no codec table to pin")
    monkeypatch.setitem(compressors._codecs, 8, _python_zlib.zlib_encode)
    monkeypatch.setitem(decompressors._codecs, 8, _python_zlib.zlib_decode)
    yield


def _frames() -> Iterator[npt.NDArray[Any]]:
    rng = np.random.default_rng(39)
    for shape in [(1024, 1280), (96, 128), (1, 1), (7, 3), (205, 1280), (3, 131073), (300, 2)]:
        for dtype, top in ((np.uint8, 255), (np.uint16, 4095)):
            noisy = rng.normal(top / 2, top / 8, shape).clip(0, top).astype(dtype)
            noisy[: shape[0] // 3] = top  # a flat band: long runs for the deflate streams
            yield noisy


def _plain_frame_bytes(pixels: npt.NDArray[Any], meta: dict[str, Any]) -> bytes:
    """:func:`encode_frame_tiff` as it was: the array handed to tifffile's zlib codec."""
    full = {"format": METADATA_FORMAT, "version": METADATA_VERSION, **meta}
    imagej = {"axes": "YX", "Info": json.dumps(full, allow_nan=False, default=json_default),
              "min": 0.0, "max": 4095.0}
    buf = io.BytesIO()
    tifffile.imwrite(buf, pixels, imagej=True, resolution=None, metadata=imagej,
                     software=SOFTWARE, compression="zlib",
                     compressionargs={"level": ZLIB_LEVEL})
    return buf.getvalue()


def test_frames_are_the_bytes_tifffiles_zlib_codec_writes(plain_zlib: None) -> None:
    for pixels in _frames():
        meta = {"bits": 12, "exposure_ms": 12.5}
        assert encode_frame_tiff(pixels, meta) == _plain_frame_bytes(pixels, meta), pixels.shape


def test_frames_read_back_the_pixels_zlib_gives(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    files = []
    for i, pixels in enumerate(_frames()):
        path = tmp_path / f"f{i}.tiff"
        path.write_bytes(encode_frame_tiff(pixels, {"bits": 12}))
        files.append((path, pixels))
    fast = [(load_frame_tiff(p)[0], read_tiff_frame(p)[0]) for p, _ in files]
    monkeypatch.setitem(tifffile.TIFF.DECOMPRESSORS._codecs,  # type: ignore[attr-defined]
                        8, _python_zlib.zlib_decode)
    for (path, pixels), (loaded, read) in zip(files, fast, strict=True):
        plain = load_frame_tiff(path)[0]
        for got in (loaded, read):
            assert got.dtype == plain.dtype == pixels.dtype
            assert np.array_equal(got, plain) and np.array_equal(got, pixels)


def test_radial_views_are_the_bytes_tifffiles_zlib_codec_writes(plain_zlib: None) -> None:
    rng = np.random.default_rng(7)
    for shape, dtype in [((300, 700), np.float32), ((64, 64), np.uint16), ((5, 3), np.float64),
                         ((1, 1), np.uint8), ((4, 70000), np.float32)]:
        view = (rng.random(shape) * 1000).astype(dtype)
        view[: shape[0] // 2] = 7
        valid = rng.random(shape) > 0.3
        got = encode_view_tiff(view, valid, {"a": 1})
        doc = {"format": VIEW_FORMAT, "version": VIEW_FORMAT_VERSION, "a": 1}
        buf = io.BytesIO()
        with tifffile.TiffWriter(buf) as tif:
            tif.write(view, description=json.dumps(doc, allow_nan=False), metadata=None,
                      compression="zlib")
            tif.write(valid.astype(np.uint8) * 255, description="valid mask (255 = raw pixel)",
                      metadata=None, compression="zlib")
        assert got == buf.getvalue(), (shape, dtype)
