"""``benchlab analyze IMAGE`` and ``benchlab benchmark analysis``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile

from benchlab.benchmarks.bars.estimators import format_table, run_benchmark
from benchlab.cli.main import main
from benchlab.synthetic.bars import bar_roi

ROI = "50,60,90,110"  # 40 x 50 = 2,000 pixels


@pytest.fixture(scope="module")
def bars() -> tuple[np.ndarray, float]:
    roi, case = bar_roi(0, shape=(40, 50), px_per_period=16.0, noise_sigma=1.5)
    img = np.full((200, 240), 100, np.uint8)
    img[50:90, 60:110] = roi
    return img, case.truth


def run_json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    assert main(["analyze", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("suffix", [".png", ".bmp", ".tif"])
def test_analyze_8bit_images(tmp_path: Path, bars, capsys, suffix: str) -> None:
    img, truth = bars
    path = tmp_path / f"bars{suffix}"
    if suffix == ".tif":
        tifffile.imwrite(path, img)
    else:
        cv2.imwrite(str(path), img)
    out = run_json(capsys, str(path), "--roi", ROI, "--freq", f"{1000 / 16 / 5.2}")
    assert out["resolved"] is True and out["estimator"] == "profilefit"  # auto
    assert out["modulation"] == pytest.approx(truth, abs=0.01)
    assert out["diagnostics"]["n_pixels"] == 2000
    assert out["roi"] == [50, 60, 90, 110]


def test_analyze_16bit_and_estimators(tmp_path: Path, bars, capsys) -> None:
    img, truth = bars
    path = tmp_path / "bars16.png"
    cv2.imwrite(str(path), img.astype(np.uint16) * 16 * 16)  # 12-bit MSB-aligned
    out = run_json(capsys, str(path), "--roi", ROI, "--estimator", "histogram")
    assert out["estimator"] == "histogram" and out["diagnostics"]["code_step"] == 256.0
    assert out["modulation"] == pytest.approx(truth, abs=0.03)
    both = run_json(capsys, str(path), "--roi", ROI, "--all-estimators")
    assert set(both["estimators"]) == {"profilefit", "profilefit-fast", "histogram", "sinefit",
                                       "variance"}


def test_analyze_manual_peaks_and_unresolved(tmp_path: Path, capsys) -> None:
    path = tmp_path / "flat.tif"
    tifffile.imwrite(path, np.full((20, 20), 77, np.uint8))
    out = run_json(capsys, str(path), "--roi", "0,0,20,20", "--estimator", "histogram")
    assert out["resolved"] is False and out["dark"] is None and out["bright"] is None
    assert out["modulation"] == 0.0
    manual = run_json(capsys, str(path), "--roi", "0,0,20,20", "--peaks", "41,174")
    assert manual["estimator"] == "manual" and manual["modulation"] == pytest.approx(0.6186, 1e-3)


def test_analyze_prints_a_table(tmp_path: Path, bars, capsys) -> None:
    path = tmp_path / "bars.tif"
    tifffile.imwrite(path, bars[0])
    assert main(["analyze", str(path), "--roi", ROI, "--orientation", "sagittal"]) == 0
    text = capsys.readouterr().out
    assert "modulation (Eq. 2.9)" in text and "resolved" in text


@pytest.mark.parametrize(
    ("roi", "message", "status"),
    [  # missing or malformed: a usage error (2); outside this image: an input error (1)
        (None, "--roi R0,C0,R1,C1 is required", 2),
        ("1,2,3", "4 integers", 2),
        ("a,2,3,4", "R0 must be an integer", 2),
        ("10,10,5,20", "R1=5 must be > R0=10", 2),  # reversed: cannot be meant
        ("5,10,5,20", "R1=5 must be > R0=5", 2),  # empty
        ("0,0,10,999", "C1=999", 1),
        ("-1,0,10,10", "R0=-1 must be >= 0", 2),
        ("30,0,40,10", "R0=30 is outside 0..29", 1),
    ],
)
def test_bad_roi_names_the_field(tmp_path: Path, capsys, roi: str | None, message: str,
                                 status: int) -> None:
    path = tmp_path / "x.tif"
    tifffile.imwrite(path, np.zeros((30, 40), np.uint8))
    argv = ["analyze", str(path)] + ([] if roi is None else [f"--roi={roi}"])
    assert main(argv) == status
    err = capsys.readouterr().err
    assert message in err and err.startswith("benchlab: error:")


def test_bad_files_are_named(tmp_path: Path, capsys) -> None:
    assert main(["analyze", str(tmp_path / "missing.tif"), "--roi", "0,0,1,1"]) == 1
    assert "missing.tif: no such file" in capsys.readouterr().err
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image")
    assert main(["analyze", str(junk), "--roi", "0,0,1,1"]) == 1
    assert "junk.png: not a readable image" in capsys.readouterr().err
    txt = tmp_path / "a.txt"
    txt.write_text("x")
    assert main(["analyze", str(txt), "--roi", "0,0,1,1"]) == 1
    assert "unsupported image type" in capsys.readouterr().err
    colour = tmp_path / "colour.png"
    cv2.imwrite(str(colour), np.dstack([np.zeros((4, 4)), np.ones((4, 4)), np.zeros((4, 4))]))
    assert main(["analyze", str(colour), "--roi", "0,0,2,2"]) == 1
    assert "colour image" in capsys.readouterr().err
    assert main(["analyze", str(tmp_path), "--roi", "0,0,1,1"]) == 1
    assert "without session.json" in capsys.readouterr().err


def test_session_folder_is_handed_to_procedures(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "session.json").write_text("{}")
    seen: list[argparse.Namespace] = []

    def fake(args: argparse.Namespace) -> int:
        seen.append(args)
        return 0

    import benchlab.cli.runs.procedures as procedures

    monkeypatch.setattr(procedures, "analyze_session_command", fake)
    assert main(["analyze", str(tmp_path), "--estimator", "histogram"]) == 0
    assert seen and seen[0].target == str(tmp_path) and seen[0].estimator == "histogram"


@pytest.mark.slow
def test_benchmark_table_on_a_small_grid() -> None:
    cases, scores = run_benchmark(n_cases=40, seed=1, workers=1,
                                  estimators=("profilefit", "histogram"))
    assert len(cases) == 40
    assert {c.kind for c in cases} == {"bars", "flat", "below-noise", "aliased"}
    assert {s.estimator for s in scores} == {"profilefit", "histogram"}
    overall = {s.estimator: s for s in scores if s.bucket == "all"}
    assert overall["profilefit"].n == overall["histogram"].n > 10
    assert overall["profilefit"].wrong_resolved == 0  # no flat/below-noise/aliased as a number
    assert overall["profilefit"].n_negative == 8
    assert overall["profilefit"].rmse < 0.1
    table = format_table(scores)
    for word in ("bias", "RMSE", "<=.03", "wrong res", "cover95", "oblique", "period 8-20"):
        assert word in table


def test_reversed_roi_is_refused_before_the_image_is_read(tmp_path: Path, capsys) -> None:
    assert main(["analyze", str(tmp_path / "missing.tif"), "--roi", "539,714,489,750"]) == 2
    err = capsys.readouterr().err
    assert "--roi R1=489 must be > R0=539" in err and "no such file" not in err
