"""JPEG (and PNG/BMP) frames through Pillow for ``benchlab sfr``, ``analyze`` and
``find-chart``: a compressed slanted edge reads as its lossless original does."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tifffile
from PIL import Image

from benchlab.cli.frames.analysis import AnalysisInputError, read_image
from benchlab.cli.main import main
from benchlab.synthetic.edges import synthetic_edge

ROI = "0,0,120,120"


def _edge_u8(angle_deg: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = synthetic_edge((120, 120), angle_deg, 1.0, dark=0.2, bright=0.75, offset_px=0.3,
                         noise_sigma=0.005, bits=8, rng=rng)
    return img.astype(np.uint8)


def _mtf50(path: Path, capsys: pytest.CaptureFixture[str]) -> dict:  # type: ignore[type-arg]
    assert main(["sfr", str(path), "--roi", ROI, "--json"]) == 0, capsys.readouterr().err
    doc: dict = json.loads(capsys.readouterr().out)  # type: ignore[type-arg]
    return doc


@pytest.mark.parametrize(("angle_deg", "seed"), [(5.0, 1), (8.0, 2), (12.0, 3)])
def test_a_jpeg_slanted_edge_reads_within_2_percent_of_its_tiff(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], angle_deg: float, seed: int
) -> None:
    """Was "unsupported image type .jpg"; and decoded, quality 75 put 1-1.5 % of the pixels
    more than 5 noise sigmas off the edge profile, which refused the edge."""
    img = _edge_u8(angle_deg, seed)
    tif, jpg = tmp_path / "edge.tiff", tmp_path / "edge.jpg"
    tifffile.imwrite(tif, img)
    Image.fromarray(img).save(jpg, format="JPEG", quality=75)
    lossless, compressed = _mtf50(tif, capsys), _mtf50(jpg, capsys)
    assert compressed["mtf50_cycles_per_px"] == pytest.approx(
        lossless["mtf50_cycles_per_px"], rel=0.02)


def test_jpeg_png_bmp_and_colour_jpeg_decode_to_the_same_monochrome_frame(
    tmp_path: Path
) -> None:
    img = _edge_u8(5.0, 4)
    for name in ("f.png", "f.bmp"):
        Image.fromarray(img).save(tmp_path / name)
        got = read_image(tmp_path / name)
        assert got.dtype == np.uint8 and np.array_equal(got, img)
    wide = (img.astype(np.uint16) * 257)
    Image.fromarray(wide).save(tmp_path / "f16.png")
    got16 = read_image(tmp_path / "f16.png")
    assert got16.dtype == np.uint16 and np.array_equal(got16, wide)
    Image.fromarray(np.dstack([img] * 3)).save(tmp_path / "c.jpg", quality=95)
    Image.fromarray(img).save(tmp_path / "g.jpg", quality=95)
    colour, grey = read_image(tmp_path / "c.jpg"), read_image(tmp_path / "g.jpg")
    assert colour.shape == img.shape and colour.dtype == np.uint8
    assert np.max(np.abs(colour.astype(int) - grey.astype(int))) <= 3
    true_colour = np.dstack([img, np.zeros_like(img), img])
    Image.fromarray(true_colour).save(tmp_path / "c.png")
    with pytest.raises(AnalysisInputError, match=r"c\.png: colour image"):
        read_image(tmp_path / "c.png")
    (tmp_path / "bad.jpg").write_bytes(b"\xff\xd8 not really a jpeg")
    with pytest.raises(AnalysisInputError, match=r"bad\.jpg: not a readable image"):
        read_image(tmp_path / "bad.jpg")


def test_analyze_reads_a_jpeg_of_bars(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                      ) -> None:
    row = np.tile(np.repeat(np.array([60, 190], dtype=np.uint8), 6), 8)
    img = np.tile(row, (48, 1))
    Image.fromarray(img).save(tmp_path / "bars.jpg", quality=90)
    assert main(["analyze", str(tmp_path / "bars.jpg"), "--roi", "4,4,44,88", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["modulation"] == pytest.approx((190 - 60) / (190 + 60), abs=0.03)
