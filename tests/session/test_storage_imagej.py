"""Frames open calibrated in Fiji/ImageJ: ImageJ metadata, the driver's pixel size, Software
benchlab, and the full acquisition metadata still read back by benchlab (old frames too)."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import tifffile

from benchlab.storage import FrameFileError, load_frame_tiff, save_frame_tiff

META = {"exposure_ms": 300.0, "gain": 1.0, "bits": 12, "bin_code": 0, "camera_serial": "SIM-1",
        "pixel_size_um": [5.2, 5.2], "bench": {"target": ["radial", 4.0, "sagittal"]}}


def _frame() -> np.ndarray:
    return (np.arange(64 * 80, dtype=np.uint32) * 7 % 4096).astype(np.uint16).reshape(64, 80)


def _um_per_px(tag: tifffile.TiffTag) -> float:
    num, den = tag.value
    return float(1 / Fraction(num, den))


def test_frame_carries_imagej_calibration(tmp_path: Path) -> None:
    path = save_frame_tiff(tmp_path / "f.tiff", _frame(), META)
    with tifffile.TiffFile(path) as tif:
        assert tif.is_imagej
        ij = tif.imagej_metadata
        assert ij is not None and ij["unit"] == "um"
        assert (ij["min"], ij["max"]) == (0.0, 4095.0)  # Fiji's display range: 12 bits
        page = tif.pages.first
        assert page.tags["Software"].value == "benchlab"
        assert _um_per_px(page.tags["XResolution"]) == pytest.approx(5.2)
        assert _um_per_px(page.tags["YResolution"]) == pytest.approx(5.2)
        assert page.compression == tifffile.COMPRESSION.ADOBE_DEFLATE  # lossless zlib
        info = json.loads(ij["Info"])
    assert info["exposure_ms"] == 300.0 and info["bench"]["target"] == ["radial", 4.0, "sagittal"]
    pixels, meta = load_frame_tiff(path)
    assert pixels.dtype == np.uint16 and np.array_equal(pixels, _frame())
    assert {k: meta[k] for k in META} == META
    assert meta["format"] == "benchlab.frame"


def test_binning_scales_the_pixel_size(tmp_path: Path) -> None:
    """The driver's pixel size of a 1:2 row-binned frame (storage copies it)."""
    path = save_frame_tiff(tmp_path / "b.tiff", _frame()[:32],
                           {**META, "bin_code": 0x81, "pixel_size_um": [5.2, 10.4]})
    with tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        assert _um_per_px(page.tags["XResolution"]) == pytest.approx(5.2)
        assert _um_per_px(page.tags["YResolution"]) == pytest.approx(10.4)  # 1:2 row binning


def test_8_bit_frame_display_range(tmp_path: Path) -> None:
    px = (_frame() % 256).astype(np.uint8)
    path = save_frame_tiff(tmp_path / "e.tiff", px, {**META, "bits": 8})
    with tifffile.TiffFile(path) as tif:
        ij = tif.imagej_metadata
        assert ij is not None and ij["max"] == 255.0
    assert np.array_equal(load_frame_tiff(path)[0], px)


def test_frames_written_the_old_way_still_load(tmp_path: Path) -> None:
    """Before ImageJ metadata: JSON in the ImageDescription, plain TIFF, no calibration."""
    old = {"format": "benchlab.frame", "version": 1, **META}
    path = tmp_path / "old.tiff"
    tifffile.imwrite(path, _frame(), description=json.dumps(old), metadata=None,
                     compression="zlib")
    with tifffile.TiffFile(path) as tif:
        assert not tif.is_imagej
    pixels, meta = load_frame_tiff(path)
    assert np.array_equal(pixels, _frame()) and meta == old


def test_imagej_tiff_without_benchlab_metadata_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "fiji.tif"
    tifffile.imwrite(path, _frame(), imagej=True, metadata={"unit": "um"})
    with pytest.raises(FrameFileError, match="fiji.tif: ImageDescription is not benchlab JSON"):
        load_frame_tiff(path)
