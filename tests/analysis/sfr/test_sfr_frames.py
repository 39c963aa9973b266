"""Frames of one edge averaged for the SFR (sfr_frames, ``benchlab sfr A B C``) and the
benchmark's edge-length and frames tables."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import tifffile

from benchlab.analysis.sfr.frames import MAX_SHIFT_PX, FramesDiffer, average_frames
from benchlab.analysis.sfr.measure import measure_sfr
from benchlab.benchmarks.sfr.edges import (
    format_by_length,
    format_frames,
    frames_needed_by_floor,
    noise_floor,
    roi_shape,
    run_accuracy,
    run_frames,
)
from benchlab.cli.main import main
from benchlab.synthetic.edges import synthetic_edge

THETA = math.radians(6.0)


def _frames(n: int, snr: float, seed: int, moved: dict[int, float] | None = None,
            tilt: dict[int, float] | None = None) -> np.ndarray:
    """``n`` 12-bit frames of a 6 deg edge; ``moved`` shifts frame k along the normal (px),
    ``tilt`` turns it by that many degrees."""
    rng = np.random.default_rng(seed)
    moved, tilt = moved or {}, tilt or {}
    return np.stack([synthetic_edge((100, 100), 6.0 + tilt.get(k, 0.0), 1.0,
                                    offset_px=moved.get(k, 0.0), noise_sigma=0.6 / snr,
                                    bits=12, rng=rng) for k in range(n)])


def test_still_frames_are_averaged_and_the_noise_falls_as_root_n() -> None:
    stack = _frames(4, 20.0, 1)
    check = average_frames(stack, THETA)
    assert check.frames == 4 and check.max_shift_px < MAX_SHIFT_PX
    single = measure_sfr(stack[0]).noise_sigma
    assert measure_sfr(check.mean).noise_sigma == pytest.approx(single / 2, rel=0.15)
    assert np.array_equal(check.mean, stack.mean(axis=0))


def test_one_frame_is_its_own_mean() -> None:
    stack = _frames(1, 50.0, 2)
    check = average_frames(stack, THETA)
    assert check.frames == 1 and check.max_shift_px == 0.0


@pytest.mark.parametrize("snr", [20.0, 100.0])
def test_a_moved_frame_is_refused_and_named(snr: float) -> None:
    with pytest.raises(FramesDiffer) as exc:
        average_frames(_frames(4, snr, 3, moved={2: 0.3}), THETA)
    assert exc.value.frame == 2 and "frame 3 of 4" in str(exc.value)


def test_a_turned_frame_is_refused() -> None:
    # 0.3 deg about the ROI centre: the ends move +-0.26 px, the middle not at all.
    with pytest.raises(FramesDiffer) as exc:
        average_frames(_frames(3, 100.0, 4, tilt={0: 0.3}), THETA)
    assert exc.value.frame == 0


def test_a_brightness_change_is_not_a_different_scene() -> None:
    stack = _frames(3, 50.0, 5)
    stack[1] = stack[1] * 1.1 + 20.0  # LED drift: gain and offset
    check = average_frames(stack, THETA)
    assert check.gain_spread > 0.05 and check.max_shift_px < MAX_SHIFT_PX


def test_noise_within_the_frames_does_not_read_as_movement() -> None:
    # SNR 5 per frame: a 0.05 px shift is far inside the noise; no refusal.
    check = average_frames(_frames(6, 5.0, 6, moved={1: 0.05}), THETA)
    assert check.frames == 6


def test_bad_stack_shape_is_an_error() -> None:
    with pytest.raises(ValueError, match="stack"):
        average_frames(np.zeros((10, 10)), THETA)


def test_cli_averages_frames_from_several_files_and_names_a_moved_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    stack = _frames(3, 20.0, 7, moved={2: 0.6}).astype(np.uint16)
    paths = []
    for k in range(3):
        paths.append(tmp_path / f"f{k}.tiff")
        tifffile.imwrite(paths[-1], stack[k], photometric="minisblack")
    args = ["sfr", str(paths[0]), str(paths[1]), "--roi", "0,0,100,100", "--json"]
    assert main(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["frames"] == 2 and doc["frames_max_shift_px"] < MAX_SHIFT_PX
    assert doc["images"] == [str(paths[0]), str(paths[1])]
    assert doc["lsf_windows"][0]["flat_half_px"] > doc["lsf_windows"][-1]["flat_half_px"]
    assert main(["sfr", *map(str, paths), "--roi", "0,0,100,100"]) == 1
    err = capsys.readouterr().err
    assert "f2.tiff" in err and "moved" in err
    small = tmp_path / "small.tiff"
    tifffile.imwrite(small, stack[0][:50], photometric="minisblack")
    assert main(["sfr", str(paths[0]), str(small), "--roi", "0,0,40,40"]) == 1
    assert "small.tiff" in capsys.readouterr().err


def test_roi_widens_only_for_long_steep_edges() -> None:
    assert roi_shape(100, 40.0) == (100, 100)
    rows, cols = roi_shape(300, 40.0)
    assert rows == 300 and cols == 100 + math.ceil(200 * math.tan(math.radians(40.0)))
    assert roi_shape(300, 2.0)[1] < 110


def test_floor_falls_as_root_of_the_edge_length_and_bounds_the_frames() -> None:
    short, long = noise_floor(3.0, 20.0), noise_floor(3.0, 20.0, rows=300)
    assert long.mtf_nyquist_sd == pytest.approx(short.mtf_nyquist_sd / math.sqrt(3.0))
    n = frames_needed_by_floor(3.0, 20.0, 100)
    # n frames bring the floor to what 95 % within 0.02 needs; n - 1 do not.
    assert noise_floor(3.0, 20.0 * math.sqrt(n)).mtf_reachable
    assert not noise_floor(3.0, 20.0 * math.sqrt(n - 1)).mtf_reachable
    assert frames_needed_by_floor(0.3, 500.0, 100) == 1


def test_length_table_sets_every_failure_against_its_floor() -> None:
    snrs = (20.0, 500.0)
    results = {rows: run_accuracy(1, 3, rows, (1.0,), snrs) for rows in (100, 300)}
    assert all(b.rows == rows for rows, bs in results.items() for b in bs)
    text = format_by_length(results)
    lines = text.splitlines()
    assert "100 rows" in lines[0] and "300 rows" in lines[0] and len(lines) == 5
    cells = [c.strip() for c in lines[1][14:].split("  ") if c.strip()]
    assert cells[0] in ("pass", "FAIL (floor 2.60x)")
    assert cells[1] in ("pass", "FAIL (floor 1.50x)")
    assert "1.0   500" in lines[2] and lines[2].count("pass") == 2


def test_frames_table_finds_what_snr_20_needs() -> None:
    needs = run_frames(cases_per_cell=2, seed=5, sigmas_px=(2.0,), max_tries=1)
    nd = needs[0]
    assert nd.floor_frames == frames_needed_by_floor(2.0, 20.0, 100) > 1
    assert nd.tried_frames == nd.floor_frames and nd.bucket is not None
    assert nd.bucket.cases == 4
    text = format_frames(needs)
    assert "SNR 20" in text and f"{nd.floor_frames:>11d}" in text.splitlines()[2]


def test_a_different_scene_is_refused_even_where_the_edge_fits() -> None:
    stack = _frames(3, 50.0, 8)
    other = synthetic_edge((100, 100), 25.0, 2.0, noise_sigma=0.6 / 50, bits=12,
                           rng=np.random.default_rng(9))
    stack[1] = other
    with pytest.raises(FramesDiffer) as exc:
        average_frames(stack, THETA)
    assert exc.value.frame == 1


def test_noise_free_frames_of_one_edge_pass() -> None:
    stack = np.stack([synthetic_edge((100, 100), 6.0, 1.0, bits=12) for _ in range(3)])
    check = average_frames(stack, THETA)
    assert check.max_shift_px < 1e-9 and check.gain_spread < 1e-9


def test_cli_refuses_frames_clipped_in_some_frames_only(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The mean of a clipped and an unclipped frame is below full scale: checked per frame.
    bright = synthetic_edge((80, 80), 6.0, 1.0, dark=0.3, bright=1.2, bits=12)
    dim = synthetic_edge((80, 80), 6.0, 1.0, dark=0.3 * 0.7, bright=1.2 * 0.7, bits=12)
    paths = [tmp_path / "bright.tiff", tmp_path / "dim.tiff"]
    for path, img in zip(paths, (bright, dim), strict=True):
        tifffile.imwrite(path, img.astype(np.uint16), photometric="minisblack")
    assert float(np.max((bright + dim) / 2)) < 4095
    assert main(["sfr", *map(str, paths), "--roi", "0,0,80,80"]) == 1
    assert "clipped" in capsys.readouterr().err


# ---- a frame without the edge, frames of different edges, named by file and page ------------
def _edge(angle: float, seed: int) -> np.ndarray:
    return synthetic_edge((100, 100), angle, 1.0, noise_sigma=0.01, bits=12,
                          rng=np.random.default_rng(seed))


def _blank(kind: str, seed: int) -> np.ndarray:
    """Pure noise at the edge's mean level, or a dark frame (the lens cap on)."""
    rng = np.random.default_rng(seed)
    level, sd = (2048.0, 41.0) if kind == "noise" else (20.0, 2.0)
    return np.round(rng.normal(level, sd, (100, 100))).clip(0, 4095)


def _write(tmp_path: Path, **frames: np.ndarray) -> dict[str, str]:
    out = {}
    for name, img in frames.items():
        out[name] = str(tmp_path / f"{name}.tiff")
        tifffile.imwrite(out[name], img.astype(np.uint16), photometric="minisblack")
    return out


@pytest.mark.parametrize("kind", ["noise", "dark"])
def test_a_frame_without_the_edge_is_refused_not_averaged(kind: str) -> None:
    """Two frames of an edge and a blank one: the offset and a gain near 0 fitted the blank
    frame perfectly, and its mean read contrast 0.40 instead of 0.60."""
    stack = np.stack([_edge(5.0, 1), _edge(5.0, 2), _blank(kind, 3)])
    with pytest.raises(FramesDiffer) as exc:
        average_frames(stack, math.radians(5.0))
    assert exc.value.frame == 2 and exc.value.frames == (2,)
    assert str(exc.value).startswith("frame 3 of 3: its edge step is 0.00x the other frames' "
                                     "(allowed 0.5-2x, an exposure change): the edge is not "
                                     "there")


def test_an_exposure_change_within_the_range_passes_and_beyond_it_is_refused() -> None:
    base = [_edge(5.0, k) for k in range(3)]
    half = 0.6 * base[2] + 100.0
    assert average_frames(np.stack([base[0], base[1], half])).frames == 3
    dim = 0.4 * base[2] + 100.0
    with pytest.raises(FramesDiffer) as exc:
        average_frames(np.stack([base[0], base[1], dim]))
    assert exc.value.frame == 2 and "edge step is 0.40x" in str(exc.value)
    inverted = 4095.0 - base[2]
    with pytest.raises(FramesDiffer) as exc:
        average_frames(np.stack([base[0], base[1], inverted]))
    assert exc.value.frame == 2 and "inverted" in str(exc.value)


def test_the_normal_defaults_to_the_mean_gradient_direction() -> None:
    from benchlab.analysis.sfr.frames import edge_normal_of

    assert math.degrees(edge_normal_of(_edge(5.0, 4))) == pytest.approx(5.0, abs=0.5)
    stack = _frames(4, 20.0, 3, moved={2: 0.3})
    with pytest.raises(FramesDiffer) as exc:
        average_frames(stack)
    assert exc.value.frame == 2 and "frame 3 of 4: the edge moved" in str(exc.value)


@pytest.mark.parametrize("kind", ["noise", "dark"])
def test_cli_refuses_the_blank_frame_by_file_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str
) -> None:
    files = _write(tmp_path, f0=_edge(5.0, 1), f1=_edge(5.0, 2), blank=_blank(kind, 3))
    plot = tmp_path / "p.png"
    assert main(["sfr", files["f0"], files["f1"], files["blank"], "--roi", "0,0,100,100",
                 "--plot", str(plot)]) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and not plot.exists()
    assert captured.err.startswith(f"benchlab: error: {files['blank']} roi 0,0,100,100: frame 3 "
                                   "of 3: its edge step is 0.00x")


@pytest.mark.parametrize("order", [("e5", "noise"), ("noise", "e5")])
def test_cli_names_the_blank_frame_in_either_order(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], order: tuple[str, str]
) -> None:
    files = _write(tmp_path, e5=_edge(5.0, 1), noise=_blank("noise", 3))
    assert main(["sfr", *(files[n] for n in order), "--roi", "0,0,100,100"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"benchlab: error: {files['noise']} roi ") and "e5.tiff" not in err


def test_cli_frames_of_different_edges_are_reported_as_differing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Edges at 5 and 0 deg: was "e5.tiff: 1.9 % of the pixels ... other structure" (the mean
    of two different edges measured before the frames were compared)."""
    files = _write(tmp_path, e5=_edge(5.0, 1), e0=_edge(0.0, 2), f1=_edge(5.0, 3))
    assert main(["sfr", files["e5"], files["e0"], "--roi", "0,0,100,100"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"benchlab: error: {files['e5']} and {files['e0']} roi 0,0,100,100: "
                          "frames 1 and 2 of 2 differ from each other by ")
    assert "not the same scene" in err and "other structure" not in err
    assert main(["sfr", files["e5"], files["e0"], files["f1"], "--roi", "0,0,100,100"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"benchlab: error: {files['e0']} roi 0,0,100,100: frame 2 of 3 "
                          "differs from the others by ")


def test_cli_names_the_page_of_a_multi_page_tiff(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    stack = np.stack([_edge(5.0, 1), _edge(5.0, 2), _blank("dark", 3), _edge(5.0, 4)])
    path = tmp_path / "stack.tiff"
    tifffile.imwrite(path, stack.astype(np.uint16), photometric="minisblack")
    assert main(["sfr", str(path), "--roi", "0,0,100,100"]) == 1
    assert capsys.readouterr().err.startswith(f"benchlab: error: {path} page 3 of 4 roi "
                                              "0,0,100,100: frame 3 of 4: its edge step")


def test_cli_refuses_the_same_file_twice(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    files = _write(tmp_path, e5=_edge(5.0, 1))
    again = str(tmp_path / "." / "e5.tiff")
    assert main(["sfr", files["e5"], again, "--roi", "0,0,100,100"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("benchlab: error: ") and "given twice" in err
    assert main(["sfr", files["e5"], files["e5"], "--roi", "0,0,100,100"]) == 2
    assert "given twice" in capsys.readouterr().err


def test_cli_text_and_plot_title_name_every_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import benchlab.cli.frames.sfr as cli_sfr

    titles: list[str] = []
    monkeypatch.setattr(cli_sfr, "_plot", lambda result, out, title, force: titles.append(title))
    files = _write(tmp_path, a=_edge(5.0, 1), b=_edge(5.0, 2), c=_edge(5.0, 3))
    assert main(["sfr", files["a"], files["b"], files["c"], "--roi", "0,0,100,100",
                 "--plot", str(tmp_path / "p.png")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"image              {files['a']}, {files['b']}, {files['c']}"
    assert titles == ["a.tiff + 2 more roi 0,0,100,100"]


def test_cli_refuses_two_files_with_identical_pixels(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two file names (or a copied page) for one frame: refused, both named, nothing written -
    averaging them would claim the noise of two frames (issue 29)."""
    stack = _frames(2, 20.0, 11).astype(np.uint16)
    a, b, c = tmp_path / "a.tiff", tmp_path / "copy.tiff", tmp_path / "other.tiff"
    tifffile.imwrite(a, stack[0], photometric="minisblack")
    tifffile.imwrite(b, stack[0].copy(), photometric="minisblack")
    tifffile.imwrite(c, stack[1], photometric="minisblack")
    assert main(["sfr", str(a), str(c), "--roi", "0,0,100,100", "--json"]) == 0
    capsys.readouterr()
    assert main(["sfr", str(a), str(c), str(b), "--roi", "0,0,100,100"]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert f"{b}: identical pixel for pixel to {a}" in captured.err
    pages = tmp_path / "pages.tiff"
    tifffile.imwrite(pages, np.stack([stack[0], stack[0]]), photometric="minisblack")
    assert main(["sfr", str(pages), "--roi", "0,0,100,100"]) == 1
    assert "page 2 of 2: identical pixel for pixel to" in capsys.readouterr().err
