"""benchlab.tiff_strips reads benchlab's frames exactly as tifffile does (pixels, dtype, Info
text), hands every other layout and every damaged file to tifffile, and never raises."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tifffile
from hypothesis import given, settings
from hypothesis import strategies as st

from benchlab.storage import FrameFileError, encode_frame_tiff, load_frame_tiff
from benchlab.tiff_strips import decode_frame


def _tifffile(data: bytes) -> tuple[np.ndarray, str]:
    with tifffile.TiffFile(io.BytesIO(data)) as tif:
        ij = tif.imagej_metadata or {}
        return tif.pages.first.asarray(), str(ij.get("Info") or "")


def _imagej(pixels: np.ndarray, info: str = '{"a": 1}', **kwargs: Any) -> bytes:
    buf = io.BytesIO()
    tifffile.imwrite(buf, pixels, imagej=True, metadata={"Info": info}, **kwargs)
    return buf.getvalue()


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(1, 70), cols=st.integers(1, 70), wide=st.booleans(),
       big_endian=st.booleans(), compression=st.sampled_from([None, "zlib"]),
       rows_per_strip=st.integers(1, 80), seed=st.integers(0, 2**16),
       text=st.text(max_size=40))
def test_decodes_what_tifffile_decodes(rows: int, cols: int, wide: bool, big_endian: bool,
                                       compression: str | None, rows_per_strip: int,
                                       seed: int, text: str) -> None:
    dtype = np.uint16 if wide else np.uint8
    pixels = np.random.default_rng(seed).integers(0, np.iinfo(dtype).max, (rows, cols),
                                                  dtype=dtype, endpoint=True)
    info = json.dumps({"note": text}, ensure_ascii=False)
    data = _imagej(pixels, info, byteorder=">" if big_endian else "<",
                   compression=compression, rowsperstrip=rows_per_strip)
    fast = decode_frame(data)
    assert fast is not None
    ref_pixels, ref_info = _tifffile(data)
    assert fast[0].dtype == ref_pixels.dtype and fast[0].dtype.isnative
    assert np.array_equal(fast[0], ref_pixels) and np.array_equal(fast[0], pixels)
    assert fast[1] == ref_info == info
    assert fast[0].flags.writeable


@pytest.mark.parametrize("shape", [(1, 1), (1, 1280), (1024, 1), (1024, 1280)])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_saved_frames_take_the_fast_path(shape: tuple[int, int], dtype: type) -> None:
    pixels = np.random.default_rng(3).integers(0, 255, shape, dtype=dtype)
    data = encode_frame_tiff(pixels, {"bits": 8, "gain": 2.0, "note": "caf\u00e9"})
    fast = decode_frame(data)
    assert fast is not None
    assert np.array_equal(fast[0], pixels) and fast[0].dtype == dtype
    assert json.loads(fast[1])["note"] == "caf\u00e9" and fast[1] == _tifffile(data)[1]
    # extremes of the codes survive
    edge: np.ndarray = np.zeros(shape, dtype=dtype)
    edge.flat[-1] = np.iinfo(dtype).max
    out = decode_frame(encode_frame_tiff(edge, {}))
    assert out is not None and np.array_equal(out[0], edge)


def test_other_layouts_are_left_to_tifffile(tmp_path: Path) -> None:
    grey = np.arange(12 * 16, dtype=np.uint16).reshape(12, 16)
    others = {
        "predictor": _imagej(grey, compression="zlib", predictor=True),
        "tiles": _imagej(grey.astype(np.uint8), tile=(16, 16)),
        "rgb": _imagej(np.zeros((8, 8, 3), np.uint8)),
        "float": _imagej(grey.astype(np.float32)),
        "bigtiff": (lambda b: (tifffile.imwrite(b, grey, bigtiff=True), b.getvalue())[1])(
            io.BytesIO()),
        "no imagej": (lambda b: (tifffile.imwrite(b, grey, description="{}"), b.getvalue())[1])(
            io.BytesIO()),
        "not a tiff": b"P5\n2 2\n255\n\0\0\0\0",
        "empty": b"",
    }
    for name, data in others.items():
        assert decode_frame(data) is None, name
    # a frame of the older layout (JSON in the ImageDescription) still loads, through tifffile
    old = tmp_path / "old.tiff"
    meta = {"format": "benchlab.frame", "version": 1, "gain": 1.0}
    tifffile.imwrite(old, grey, description=json.dumps(meta), compression="zlib")
    pixels, loaded = load_frame_tiff(old)
    assert np.array_equal(pixels, grey) and loaded == meta


@pytest.mark.parametrize("damage", ["truncate", "flip strip", "strip offset", "zero tail"])
def test_damaged_frames_are_refused_as_before(tmp_path: Path, damage: str) -> None:
    pixels = np.random.default_rng(0).integers(0, 255, (64, 80), dtype=np.uint8)
    data = bytearray(encode_frame_tiff(pixels, {"bits": 8}))
    with tifffile.TiffFile(io.BytesIO(bytes(data))) as tif:
        page = tif.pages.first
        offset, size = page.dataoffsets[0], page.databytecounts[0]
        offsets_tag = page.tags["StripOffsets"]
    if damage == "truncate":
        data = data[: len(data) // 2]
    elif damage == "flip strip":
        data[offset + size // 2] ^= 0xFF  # the zlib checksum no longer matches
    elif damage == "strip offset":  # the directory sends the first strip past the end
        at = offsets_tag.valueoffset
        data[at:at + 4] = (len(data) + 100).to_bytes(4, "little")
    else:
        data[-40:] = bytes(40)
    assert decode_frame(bytes(data)) is None
    path = tmp_path / "frame.tiff"
    path.write_bytes(bytes(data))
    with pytest.raises(FrameFileError, match="not a readable TIFF"):
        load_frame_tiff(path)


def test_a_blank_frame_compressed_to_almost_nothing_still_takes_the_fast_path() -> None:
    blank = np.zeros((1024, 1280), np.uint8)
    data = encode_frame_tiff(blank, {"bits": 8})
    fast = decode_frame(data)
    assert len(data) < 20_000 and fast is not None and np.array_equal(fast[0], blank)
