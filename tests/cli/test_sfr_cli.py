"""``benchlab sfr`` and ``benchlab benchmark sfr``: output, errors that name the culprit, files
never overwritten."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import tifffile

from benchlab.analysis.sfr.measure import measure_sfr
from benchlab.analysis.sfr.target import edge_specs
from benchlab.benchmarks.sfr.edges import (
    MTF_TOL,
    SIGMAS_PX,
    format_accuracy,
    noise_floor,
    run_accuracy,
    run_extremes,
)
from benchlab.cli.main import main
from benchlab.synthetic.edges import edge_truth_mtf, synthetic_edge


@pytest.fixture(scope="module")
def edge_frame(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sfr") / "edge.tiff"
    assert main(["snap", "--simulate", "--scene", "edge", "--exposure-ms", "300", "--gain", "1",
                 "--bits", "12", str(out)]) == 0
    return out


def _roi(label: str) -> str:
    spec = next(e for e in edge_specs() if e.label == label)
    return ",".join(map(str, spec.roi))


def test_sfr_text_and_json_on_the_simulated_edge_target(
    edge_frame: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["sfr", str(edge_frame), "--roi", _roi("E0R"), "--bootstrap", "20"]) == 0
    text = capsys.readouterr().out
    assert "MTF50" in text and "lp/mm" in text and "96.15" in text and "warning" not in text
    assert main(["sfr", str(edge_frame), "--roi", _roi("E0B"), "--json",
                 "--freq", "48.08,96.15"]) == 0
    doc = json.loads(capsys.readouterr().out)
    at = doc["mtf_at"]
    assert [r["freq_cycles_per_px"] for r in at] == pytest.approx([0.25, 0.5], abs=1e-4)
    assert at[1]["mtf"] == pytest.approx(doc["mtf_nyquist"], abs=2e-3)
    assert doc["direction"] == "vertical" and doc["warnings"] == []
    assert 0.4 < doc["mtf50_cycles_per_px"] < 0.7
    assert doc["mtf50_lp_per_mm"] == pytest.approx(doc["mtf50_cycles_per_px"] * 1000 / 5.2)
    assert doc["freqs_lp_per_mm"][50] == pytest.approx(96.15, abs=0.01)
    assert doc["mtf_sigma"] is not None and doc["roi"] == [int(v) for v in _roi("E0B").split(",")]


def test_sfr_plot_is_written_once_and_never_overwritten(
    edge_frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plot = tmp_path / "sfr.png"
    assert main(["sfr", str(edge_frame), "--roi", _roi("E1L"), "--plot", str(plot)]) == 0
    data = plot.read_bytes()
    assert data.startswith(b"\x89PNG")
    capsys.readouterr()
    assert main(["sfr", str(edge_frame), "--roi", _roi("E1L"), "--plot", str(plot)]) == 2
    assert f"--plot {plot}: already exists" in capsys.readouterr().err  # usage (issue 38)
    assert plot.read_bytes() == data
    assert main(["sfr", str(edge_frame), "--roi", _roi("E1L"), "--plot",
                 str(tmp_path / "x.jpg")]) == 2  # a usage error
    assert ".png, .svg or .pdf" in capsys.readouterr().err
    missing = tmp_path / "missing" / "x.png"  # was created (folder and all) before
    assert main(["sfr", str(edge_frame), "--roi", _roi("E1L"), "--plot", str(missing)]) == 1
    assert f"folder {missing.parent} does not exist" in capsys.readouterr().err
    assert not missing.parent.exists()


def test_sfr_refusals_and_bad_input_are_errors_naming_the_cause(
    edge_frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["sfr", str(edge_frame), "--roi", "100,100,200,200"]) == 1  # dark surround
    err = capsys.readouterr().err
    assert err.startswith("benchlab: error: ") and "no edge" in err and "100,100,200,200" in err
    square = tmp_path / "square.tiff"
    tifffile.imwrite(square, (synthetic_edge((80, 80), 0.0, 1.0, bits=8)).astype(np.uint8))
    assert main(["sfr", str(square), "--roi", "0,0,80,80"]) == 1
    assert "pixel axis" in capsys.readouterr().err
    assert main(["sfr", str(edge_frame), "--roi", "10,10,5,20"]) == 2  # reversed: usage
    assert "R1" in capsys.readouterr().err
    assert main(["sfr", str(edge_frame), "--roi", _roi("E0B"), "--freq", "300"]) == 2
    assert "--freq 300 is outside" in capsys.readouterr().err
    assert main(["sfr", str(edge_frame), "--roi", "0,0,10,99999"]) == 1  # outside the image
    assert "C1=99999" in capsys.readouterr().err
    assert main(["sfr", str(tmp_path / "missing.tiff"), "--roi", "0,0,5,5"]) == 1
    assert "no such file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["sfr", str(edge_frame)])  # --roi is required: a usage error
    assert exc.value.code == 2


def _corner_roi(label: str, sx: int, sy: int, half: int = 20) -> str:
    """A box of 2 x ``half`` px centred on one corner of the edge target's square ``label``."""
    sq = next(e.square for e in edge_specs() if e.square.label == label)
    x, y, t = sx * sq.side_px / 2, sy * sq.side_px / 2, math.radians(sq.rotation_deg)
    row = round(sq.centre_rc[0] + x * math.sin(t) + y * math.cos(t))
    col = round(sq.centre_rc[1] + x * math.cos(t) - y * math.sin(t))
    return f"{row - half},{col - half},{row + half},{col + half}"


@pytest.mark.parametrize(("label", "sx", "sy"), [("E0", 1, 1), ("E1", 1, -1), ("E1", -1, 1),
                                                 ("E2", 1, 1), ("E2", -1, -1)])
def test_sfr_says_an_roi_holds_a_corner_of_the_edge_target(
    edge_frame: Path, capsys: pytest.CaptureFixture[str], label: str, sx: int, sy: int
) -> None:
    """Was "edge 0.31 deg from the pixel axis (< 1.5 deg): too few sample phases; tilt the edge
    2-10 deg" (E2 +1,+1; E1's 0.13 and 1.43 deg), or "30.0 % of the pixels are more than 5 noise
    sigmas off the edge profile ... (try fit_order 2)?" (E0)."""
    roi = _corner_roi(label, sx, sy)
    assert main(["sfr", str(edge_frame), "--roi", roi]) == 1
    err = capsys.readouterr().err
    assert re.fullmatch(
        rf"benchlab: error: {re.escape(str(edge_frame))} roi {roi}: edge refused: the ROI holds "
        r"a corner \(two edges at (8[5-9]|9[0-5]) deg to each other, \d+ and \d+ px long\), not "
        r"one edge: put the ROI along one side only, clear of the corner\n", err), err
    assert "tilt the edge" not in err


@pytest.fixture(scope="module")
def bar_frames(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("sfr_bars")
    frames = {"bars": out / "bars.tiff", "usaf": out / "usaf.tiff"}
    assert main(["snap", "--simulate", "--scene", "bars", "--exposure-ms", "300", "--gain", "1",
                 "--bits", "8", str(frames["bars"])]) == 0
    assert main(["snap", "--simulate", "--scene", "usaf", "--exposure-ms", "300", "--gain", "1",
                 "--bits", "12", str(frames["usaf"])]) == 0
    return frames


@pytest.mark.parametrize(("scene", "roi", "says"), [
    # One dark bar of the 32 px bar target (dark columns 528-543), bright beside it: was "no
    # edge: ESF step 0.096 is lost in the noise 1.05".
    ("bars", "450,520,550,560", "the ROI holds a bar or a line (two parallel edges of opposite "
                                "sign, 98 and 98 px long)"),
    # Three bars of a USAF element: was "no edge: ESF step 2.84 is lost in the noise 26.2".
    ("usaf", "665,512,690,538", "the ROI holds bars (6 parallel edges alternating in sign)"),
])
def test_sfr_says_an_roi_holds_a_bar_or_bars(
    bar_frames: dict[str, Path], capsys: pytest.CaptureFixture[str], scene: str, roi: str,
    says: str
) -> None:
    assert main(["sfr", str(bar_frames[scene]), "--roi", roi]) == 1
    err = capsys.readouterr().err
    assert err == (f"benchlab: error: {bar_frames[scene]} roi {roi}: edge refused: {says}, not "
                   "one edge: put the ROI over one edge only, with a plain plateau on each side "
                   "of it\n")


def test_stack_of_frames_is_averaged(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(0)
    frames = np.stack([synthetic_edge((60, 60), 6.0, 1.0, noise_sigma=0.01, bits=12, rng=rng)
                       for _ in range(4)]).astype(np.uint16)
    path = tmp_path / "stack.tiff"
    tifffile.imwrite(path, frames, photometric="minisblack")
    assert main(["sfr", str(path), "--roi", "0,0,60,60", "--json", "--bootstrap", "0"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["clipped_fraction"] == 0 and doc["uncertainty_method"] == "analytic"
    assert doc["mtf_sigma"][0] == 0 and all(s > 0 for s in doc["mtf_sigma"][1:])
    assert doc["noise_sigma"] < 0.01 * 4095 * 0.75  # four frames averaged: half the noise


ROUNDING = 1.0 / math.sqrt(12.0)  # a 1-code step's rounding sigma, 0.2887


def _sfr_noise(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[str, dict[str, object]]:
    """``benchlab sfr`` on the whole 100 x 100 image: its noise line and the JSON."""
    assert main(["sfr", str(path), "--roi", "0,0,100,100"]) == 0
    (line,) = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("noise")]
    assert main(["sfr", str(path), "--roi", "0,0,100,100", "--json"]) == 0
    return line, json.loads(capsys.readouterr().out)


@pytest.mark.parametrize(("bits", "dtype", "step"), [(12, np.uint16, 1), (8, np.uint8, 1),
                                                     (12, np.uint16, 16)])
def test_clean_quantised_edge_prints_the_rounding_noise_it_used(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], bits: int, dtype: type,
        step: int) -> None:
    """Noise-free codes: nothing measured on the plateaus, and the uncertainty uses the
    rounding of one code step (step 16: 12-bit codes MSB-aligned in 16 bits)."""
    codes = synthetic_edge((100, 100), 5.0, 1.0, noise_sigma=0.0, bits=bits).astype(dtype)
    path = tmp_path / "clean.tiff"
    tifffile.imwrite(path, codes * dtype(step))
    line, doc = _sfr_noise(path, capsys)
    sd = step * ROUNDING
    assert line == (f"noise (1 sigma)    {sd:.2f} dark / {sd:.2f} bright "
                    "(code rounding: measured 0.00)")
    assert doc["noise_dark_sigma"] == pytest.approx(sd, rel=1e-12)
    assert doc["noise_bright_sigma"] == pytest.approx(sd, rel=1e-12)
    assert doc["noise_rounding_sigma"] == pytest.approx(sd, rel=1e-12)
    assert doc["noise_dark_measured"] == doc["noise_bright_measured"] == 0.0
    assert doc["noise_rounding_floor"] == ["dark", "bright"]
    assert doc["noise_sigma"] == 0.0


def test_noisy_edge_prints_the_measured_noise_and_no_rounding_note(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(4)
    codes = synthetic_edge((100, 100), 5.0, 1.0, noise_sigma=2e-3, bits=12, rng=rng)
    path = tmp_path / "noisy.tiff"
    tifffile.imwrite(path, codes.astype(np.uint16))
    line, doc = _sfr_noise(path, capsys)
    truth = math.sqrt((2e-3 * 4095) ** 2 + ROUNDING**2)  # 8.19 codes of noise, rounded
    for side in ("dark", "bright"):
        assert doc[f"noise_{side}_sigma"] == doc[f"noise_{side}_measured"]
        assert doc[f"noise_{side}_sigma"] == pytest.approx(truth, rel=0.06)
    assert doc["noise_rounding_floor"] == []
    assert doc["noise_rounding_sigma"] == pytest.approx(ROUNDING, rel=1e-12)
    assert line == (f"noise (1 sigma)    {doc['noise_dark_sigma']:.2f} dark / "
                    f"{doc['noise_bright_sigma']:.2f} bright")


def test_rounding_note_names_the_side_it_stood_in_for(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Noise on the bright side only (shot noise of a dark side below one code)."""
    rng = np.random.default_rng(5)
    clean = synthetic_edge((100, 100), 5.0, 1.0, noise_sigma=0.0, bits=12)
    noisy = np.round(clean + np.where(clean > 2048, rng.normal(0.0, 3.0, clean.shape), 0.0))
    path = tmp_path / "bright-noise.tiff"
    tifffile.imwrite(path, noisy.astype(np.uint16))
    line, doc = _sfr_noise(path, capsys)
    assert doc["noise_rounding_floor"] == ["dark"] and doc["noise_dark_measured"] == 0.0
    assert doc["noise_dark_sigma"] == pytest.approx(ROUNDING, rel=1e-12)
    assert doc["noise_bright_sigma"] == doc["noise_bright_measured"]
    assert doc["noise_bright_sigma"] == pytest.approx(math.sqrt(9.0 + 1.0 / 12.0), rel=0.06)
    assert line == (f"noise (1 sigma)    0.29 dark (code rounding: measured 0.00) / "
                    f"{doc['noise_bright_sigma']:.2f} bright")


def test_accuracy_table_has_every_bucket_and_a_verdict() -> None:
    buckets = run_accuracy(cases_per_cell=1, seed=3)
    assert len(buckets) == 30 and all(b.cases == 2 for b in buckets)
    text = format_accuracy(buckets)
    assert text.count("\n") == 33 and "buckets with SNR 20-500" in text and "cover" in text
    assert text.splitlines()[-1].startswith("floor:")
    best = next(b for b in buckets if b.sigma_px == 1.0 and b.snr == 500.0)
    assert best.mtf50_within == 1.0 and best.mtf_within == 1.0
    assert all(0.0 <= b.mtf_coverage <= 1.0 for b in buckets)


@pytest.mark.parametrize("sigma", SIGMAS_PX)
def test_noise_floor_says_what_snr_20_cannot_reach(sigma: float) -> None:
    low, mid, high = (noise_floor(sigma, snr) for snr in (20.0, 50.0, 500.0))
    assert not low.mtf_reachable and high.mtf_reachable and high.mtf50_reachable
    assert low.mtf_nyquist_sd == pytest.approx(2.5 * mid.mtf_nyquist_sd)  # 1 / SNR
    assert low.mtf_nyquist_sd > MTF_TOL / 1.96


def test_noise_floor_is_a_floor_of_the_measured_scatter() -> None:
    # sigma 0.6 px, SNR 50, 21 deg: the model-free readings at Nyquist scatter more than the
    # ideal model-free estimator's floor, but not by much (the window is close to the LSF's
    # support). The LSF model (the default reads these edges with it) is not bound by that
    # floor: it scatters less, without a bias.
    rng = np.random.default_rng(8)
    theta = math.radians(21.0)
    truth = edge_truth_mtf([0.5], 0.6, theta)[0]
    free, auto, used = [], [], []
    for _ in range(30):
        img = synthetic_edge((100, 100), 21.0, 0.6, noise_sigma=0.6 / 50, bits=12, rng=rng)
        free.append(measure_sfr(img.astype(np.uint16), method="free").mtf_at([0.5])[0] - truth)
        res = measure_sfr(img.astype(np.uint16))
        auto.append(res.mtf_at([0.5])[0] - truth)
        used.append(res.estimator == "LSF model")
    floor = noise_floor(0.6, 50.0).mtf_nyquist_sd
    assert floor < float(np.std(free, ddof=1)) < 2.5 * floor
    assert sum(used) >= 27
    assert float(np.std(auto, ddof=1)) < 0.6 * floor
    assert abs(float(np.mean(auto))) < 0.003


def test_benchmark_sfr_is_registered(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["benchmark", "sfr", "--help"])
    assert exc.value.code == 0
    assert "Coltman" in capsys.readouterr().out


def test_benchmark_extremes_refuse_or_measure_as_the_issue_asks() -> None:
    got = dict(run_extremes())
    assert got["0 deg edge"].startswith("refused:") and "pixel axis" in got["0 deg edge"]
    assert got["45 deg edge"].startswith("measured") and "coarse lattice" in got["45 deg edge"]
    assert "clipped" in got["clipped edge (bright side 1.3x full scale)"]
    assert got["clipped edge (bright side 1.3x full scale)"].startswith("refused:")
    assert "short edge" in got["20-row edge, 8 deg"]
    assert got["noise only"].startswith("refused: no edge")


# ---- usage errors (exit 2, before any file is read) vs runtime errors (exit 1) ---------------
@pytest.fixture
def edge5(tmp_path: Path) -> Path:
    path = tmp_path / "e5.tiff"
    img = synthetic_edge((100, 100), 5.0, 1.0, noise_sigma=0.01, bits=12,
                         rng=np.random.default_rng(11))
    tifffile.imwrite(path, img.astype(np.uint16))
    return path


@pytest.mark.parametrize(("option", "says"), [
    (["--freq=-5"], "--freq -5 is outside 0..192.31 lp/mm"),
    (["--freq", "abc"], "--freq must be numbers in lp/mm, comma-separated, got 'abc'"),
    (["--freq", "50,,60"], "--freq must be numbers in lp/mm, comma-separated, got '' in "
                           "'50,,60'"),
    (["--freq", "nan"], "--freq must be finite numbers in lp/mm, got 'nan'"),
    (["--freq", "inf"], "--freq must be finite numbers in lp/mm, got 'inf'"),
    (["--freq", "192.32"], "--freq 192.32 is outside 0..192.31 lp/mm"),
    (["--plot", "out.jpg"], "--plot out.jpg: use a .png, .svg or .pdf file name"),
])
def test_sfr_values_that_cannot_be_meant_exit_2(
    edge5: Path, capsys: pytest.CaptureFixture[str], option: list[str], says: str
) -> None:
    assert main(["sfr", str(edge5), "--roi", "0,0,100,100", *option]) == 2
    err = capsys.readouterr().err
    assert err == f"benchlab: error: {says}\n" or (err.startswith("benchlab: error: ")
                                                    and says in err)


def test_sfr_usage_errors_come_before_any_file_is_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = str(tmp_path / "missing.tiff")
    for argv, says in (
        (["--roi", "539,714,489,750"], "--roi R1=489 must be > R0=539"),
        (["--roi", "0,0,10,10", "--freq", "abc"], "--freq must be numbers"),
        (["--roi", "0,0,10,10", "--plot", str(tmp_path / "x.jpg")], ".png, .svg or .pdf"),
    ):
        assert main(["sfr", missing, *argv]) == 2, argv
        err = capsys.readouterr().err
        assert says in err and "no such file" not in err


def test_sfr_freq_at_the_printed_bound_is_one_cycle_per_px(
    edge5: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """1 cycle/px is 192.3077 lp/mm, printed 192.31 (the table's figure): 192.31 is accepted
    and read as 1 cycle/px; a value above the printed bound is refused."""
    assert main(["sfr", str(edge5), "--roi", "0,0,100,100", "--json",
                 "--freq", "192.31,0"]) == 0
    at = json.loads(capsys.readouterr().out)["mtf_at"]
    assert at[0]["freq_cycles_per_px"] == 1.0 and at[1]["freq_cycles_per_px"] == 0.0
    assert main(["sfr", str(edge5), "--roi", "0,0,100,100", "--freq", "192.311"]) == 2
    assert "outside 0..192.31 lp/mm" in capsys.readouterr().err


@pytest.mark.parametrize(("rows", "says"), [("abc", "--rows must be whole numbers"),
                                            ("0", "--rows 0 is outside 20..2000"),
                                            ("100,2001", "--rows 2001 is outside 20..2000")])
def test_benchmark_sfr_bad_rows_exit_2(capsys: pytest.CaptureFixture[str], rows: str,
                                       says: str) -> None:
    assert main(["benchmark", "sfr", "--rows", rows]) == 2
    assert says in capsys.readouterr().err


def test_bootstrap_of_one_resample_is_a_usage_error(
    edge5: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["sfr", str(edge5), "--roi", "0,0,100,100", "--bootstrap", "1"])
    assert exc.value.code == 2
    assert "argument --bootstrap: 1 resample gives no spread" in capsys.readouterr().err


def test_text_says_whether_the_sigmas_are_bootstrapped(
    edge5: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["sfr", str(edge5), "--roi", "0,0,100,100", "--bootstrap", "20"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert ("uncertainty        bootstrap over rows, 20 resamples (1 sigma = their spread; "
            "overstates a sharp edge's noise)") in lines
    assert any(ln.startswith("cycles/px") and ln.endswith("1 sigma  (bootstrap)")
               for ln in lines)
    assert main(["sfr", str(edge5), "--roi", "0,0,100,100", "--bootstrap", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["uncertainty_method"] == "bootstrap" and doc["bootstrap_resamples"] == 2
    assert main(["sfr", str(edge5), "--roi", "0,0,100,100"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "uncertainty        analytic (the pixel noise per level propagated)" in lines
    assert any(ln.startswith("cycles/px") and ln.endswith("1 sigma") for ln in lines)


def test_a_session_folder_is_not_an_image(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    session = tmp_path / "2024_mtf"
    (session / "frames").mkdir(parents=True)
    (session / "session.json").write_text("{}")
    assert main(["sfr", str(session), "--roi", "0,0,10,10"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"benchlab: error: {session}: a session folder; `benchlab sfr` takes "
                          "image files, not session folders")
    assert str(session / "frames") in err and "needs session.json" not in err
    assert main(["sfr", str(tmp_path), "--roi", "0,0,10,10"]) == 1
    assert f"{tmp_path}: a folder; `benchlab sfr` takes image files" in capsys.readouterr().err


def test_help_states_the_ranges_the_benchmark_uses(capsys: pytest.CaptureFixture[str]) -> None:
    from benchlab.benchmarks.sfr.edges import MIN_ROWS_LENGTHS
    from benchlab.cli.frames.sfr import MIN_ROWS_TRIED

    assert MIN_ROWS_TRIED == (MIN_ROWS_LENGTHS[0], MIN_ROWS_LENGTHS[-1])
    with pytest.raises(SystemExit):
        main(["benchmark", "sfr", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert (f"shortest edge ({MIN_ROWS_LENGTHS[0]}-{MIN_ROWS_LENGTHS[-1]} rows)" in text
            and "100-400" not in text)
    assert "each 20..2000" in text
    assert "method free and method auto" in text and "(model-free)," not in text


def _ten_bit_edge_frame(path: Path, bits: int | None) -> Path:
    """A benchlab TIFF of one slanted edge from a camera set to 10 bits (uint16 codes; 30
    bright pixels at 1023, where the sensor saturates), with ``bits`` in its metadata (None:
    a benchlab frame without it)."""
    from benchlab.storage import METADATA_FORMAT, save_frame_tiff

    img = synthetic_edge((100, 100), 6.0, 1.0, dark=0.2, bright=0.7, noise_sigma=0.01,
                         rng=np.random.default_rng(3))
    codes = np.clip(np.round(img * 1023), 0, 1023).astype(np.uint16)
    # 0.3 % of the bright side saturated at the camera's top code (scattered, as pixels whose
    # full well fills first): warned, not refused.
    bright_side = np.flatnonzero(img.ravel() > 0.65)
    codes.ravel()[np.random.default_rng(4).choice(bright_side, 30, replace=False)] = 1023
    meta: dict[str, object] = {"format": METADATA_FORMAT}
    if bits is not None:
        meta["bits"] = bits
    return save_frame_tiff(path, codes, meta)


def test_sfr_takes_the_ceiling_from_a_benchlab_frames_bit_depth(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A 10-bit camera's frame in uint16: the codes alone say 4095 and see nothing clipped.
    ten = _ten_bit_edge_frame(tmp_path / "ten.tiff", 10)
    assert main(["sfr", str(ten), "--roi", "0,0,100,100", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert any("pixels clipped (0 or 1023)" in w for w in doc["warnings"])
    plain = _ten_bit_edge_frame(tmp_path / "plain.tiff", None)
    assert main(["sfr", str(plain), "--roi", "0,0,100,100", "--json"]) == 0
    plain_warnings = json.loads(capsys.readouterr().out)["warnings"]
    # Without the metadata the strip is not known as saturation: only odd pixels to the ESF.
    assert not any("pixels clipped (0 or" in w for w in plain_warnings)
    assert any(w.startswith("30 pixel(s) more than 5 noise sigmas") for w in plain_warnings)


def test_sfr_refuses_frames_of_different_bit_depths(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a = _ten_bit_edge_frame(tmp_path / "a.tiff", 10)
    b = _ten_bit_edge_frame(tmp_path / "b.tiff", 12)
    assert main(["sfr", str(a), str(b), "--roi", "0,0,100,100"]) == 1
    err = capsys.readouterr().err
    assert "different bit depths (a.tiff: 1023, b.tiff: 4095)" in err
