"""Frames are saved at zlib level 1 (a third of the default level's CPU per frame), losslessly."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import tifffile

from benchlab.storage import encode_frame_tiff, load_frame_tiff


def test_frames_are_saved_at_the_fast_level_and_lossless(tmp_path: Path) -> None:
    pixels = (np.random.default_rng(0).normal(2000, 40, (96, 128))
              .clip(0, 4095).astype(np.uint16))
    data = encode_frame_tiff(pixels, {"bits": 12})
    with tifffile.TiffFile(io.BytesIO(data)) as tif:
        page = tif.pages.first
        assert page.compression == tifffile.COMPRESSION.ADOBE_DEFLATE
        start = page.dataoffsets[0]
    # the zlib stream's header names its level: 0x78 0x01 for level 1 (0x78 0x9C: default 6)
    assert data[start:start + 2] == b"\x78\x01"
    path = tmp_path / "f.tif"
    path.write_bytes(data)
    assert np.array_equal(load_frame_tiff(path)[0], pixels)
