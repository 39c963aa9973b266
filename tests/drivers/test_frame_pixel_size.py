"""Issue 42: a frame's pixel size comes from the camera driver (its profile's pitch times the
binning) and storage copies it into the TIFF's calibration; storage computes none."""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import tifffile

from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.camera import MightexCamera
from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera
from benchlab.storage import load_frame_tiff, save_frame_tiff

MCE = p.SPECS["MCE-B013-U"]


def _um_per_px(tag: tifffile.TiffTag) -> float:
    num, den = tag.value
    return float(1 / Fraction(num, den))


def test_the_profile_gives_pitch_times_the_binned_rows() -> None:
    assert MCE.pixel_size_um(0) == (5.2, 5.2)
    assert MCE.pixel_size_um(0x81) == (5.2, 10.4)  # 1:2 row binning (vertical only)
    assert MCE.pixel_size_um(0x83) == (5.2, 20.8)


def test_the_driver_records_its_profiles_pitch_and_storage_copies_it(tmp_path: Path) -> None:
    """A camera of another pitch (6 um): the frame says 6 um and so does the TIFF - storage
    used to write the bench camera's 5.2 um whatever the camera was."""
    wide = replace(MCE, pixel_pitch_um=6.0)
    sim = SimulatedCamera(noise=False, profile=wide)
    with MightexCamera.open(backend=SimCameraBackend([sim]),  # type: ignore[arg-type]
                            profile=wide) as cam:
        cam.configure(width=64, height=16)
        frame = cam.grab()
    assert frame.meta.pixel_size_um == (6.0, 6.0)
    meta = frame.meta.to_dict()
    path = save_frame_tiff(tmp_path / "f.tiff", frame.pixels, meta)
    with tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        assert _um_per_px(page.tags["XResolution"]) == pytest.approx(6.0)
        assert _um_per_px(page.tags["YResolution"]) == pytest.approx(6.0)
        assert tif.imagej_metadata is not None and tif.imagej_metadata["unit"] == "um"
    assert load_frame_tiff(path)[1]["pixel_size_um"] == [6.0, 6.0]


def test_a_frame_whose_metadata_gives_no_pixel_size_is_written_uncalibrated(
        tmp_path: Path) -> None:
    pixels = np.zeros((8, 8), np.uint8)
    path = save_frame_tiff(tmp_path / "f.tiff", pixels, {"bits": 8, "bin_code": 0x81})
    with tifffile.TiffFile(path) as tif:
        ij = tif.imagej_metadata
        assert ij is not None and "unit" not in ij  # no pitch guessed from the bin code
        assert _um_per_px(tif.pages.first.tags["XResolution"]) == pytest.approx(1.0)


@pytest.mark.parametrize("bad", [[5.2], [0.0, 5.2], ["a", 1], 5.2, [float("nan"), 5.2]])
def test_a_bad_pixel_size_is_refused_naming_the_field(tmp_path: Path, bad: object) -> None:
    with pytest.raises(ValueError, match="pixel_size_um"):
        save_frame_tiff(tmp_path / "f.tiff", np.zeros((8, 8), np.uint8),
                        {"bits": 8, "pixel_size_um": bad})
    assert not (tmp_path / "f.tiff").exists()
