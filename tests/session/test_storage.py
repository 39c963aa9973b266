"""Atomic writes and lossless self-describing frames (benchlab.storage)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from benchlab.storage import (
    FrameFileError,
    atomic_write_bytes,
    atomic_write_json,
    encode_frame_tiff,
    load_frame_tiff,
    save_frame_tiff,
    sha256_file,
)


def test_atomic_write_replaces_and_leaves_no_temp_files(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "a.bin"
    atomic_write_bytes(target, b"first")
    atomic_write_bytes(target, b"second")
    assert target.read_bytes() == b"second"
    assert sorted(p.name for p in target.parent.iterdir()) == ["a.bin"]


def test_written_files_follow_the_umask(tmp_path: Path) -> None:
    mask = os.umask(0)
    os.umask(mask)
    path = atomic_write_bytes(tmp_path / "f.bin", b"x")
    assert path.stat().st_mode & 0o777 == 0o666 & ~mask
    assert path.stat().st_mode & 0o444 == 0o444 & ~mask  # readable by the group, not only 0600


def test_no_overwrite_refuses_and_keeps_existing(tmp_path: Path) -> None:
    target = tmp_path / "frame.bin"
    atomic_write_bytes(target, b"raw data")
    with pytest.raises(FileExistsError):
        atomic_write_bytes(target, b"other", overwrite=False)
    assert target.read_bytes() == b"raw data"
    assert [p.name for p in tmp_path.iterdir()] == ["frame.bin"]


def test_crash_during_write_keeps_old_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "r.json"
    atomic_write_json(target, {"v": 1})

    def boom(src: object, dst: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        atomic_write_json(target, {"v": 2})
    assert json.loads(target.read_text()) == {"v": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_json_refuses_nan(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        atomic_write_json(tmp_path / "x.json", {"m": float("nan")})
    assert not (tmp_path / "x.json").exists()


@settings(max_examples=25, deadline=None)
@given(
    arrays(
        dtype=st.sampled_from([np.uint8, np.uint16]),
        shape=st.tuples(st.integers(1, 40), st.integers(1, 40)),
    )
)
def test_frame_round_trip_is_lossless(
    tmp_path_factory: pytest.TempPathFactory, pixels: np.ndarray
) -> None:
    path = tmp_path_factory.mktemp("f") / "f.tiff"
    # bits that hold the codes: a load refuses codes its bits rule out (check_bit_depth)
    bits = 8 if pixels.dtype == np.uint8 else 16
    save_frame_tiff(path, pixels, {"exposure_ms": 300.0, "gain": 1.0, "bits": bits})
    back, meta = load_frame_tiff(path)
    assert back.dtype == pixels.dtype
    np.testing.assert_array_equal(back, pixels)
    assert meta["exposure_ms"] == 300.0 and meta["format"] == "benchlab.frame"


def test_12bit_full_frame_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    pixels = rng.integers(0, 4096, size=(1024, 1280), dtype=np.uint16)
    path = save_frame_tiff(tmp_path / "f.tiff", pixels, {"bits": 12})
    back, meta = load_frame_tiff(path)
    np.testing.assert_array_equal(back, pixels)
    assert meta["bits"] == 12
    assert len(sha256_file(path)) == 64


def test_frame_save_never_overwrites(tmp_path: Path) -> None:
    path = tmp_path / "f.tiff"
    save_frame_tiff(path, np.zeros((4, 4), np.uint8), {"n": 1})
    digest = sha256_file(path)
    with pytest.raises(FileExistsError):
        save_frame_tiff(path, np.ones((4, 4), np.uint8), {"n": 2})
    assert sha256_file(path) == digest


@pytest.mark.parametrize(
    ("pixels", "message"),
    [
        (np.zeros((2, 2, 3), np.uint8), "2-D"),
        (np.zeros((2, 2), np.float32), "uint8 or uint16"),
    ],
)
def test_bad_frames_refused(pixels: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        encode_frame_tiff(pixels, {})


def test_load_errors_name_the_file(tmp_path: Path) -> None:
    missing = tmp_path / "missing.tiff"
    with pytest.raises(FrameFileError, match="missing.tiff"):
        load_frame_tiff(missing)
    garbage = tmp_path / "garbage.tiff"
    garbage.write_bytes(b"II*\x00not a tiff at all")
    with pytest.raises(FrameFileError, match="garbage.tiff"):
        load_frame_tiff(garbage)
    import tifffile

    foreign = tmp_path / "foreign.tiff"
    tifffile.imwrite(foreign, np.zeros((3, 3), np.uint8), description="hello")
    with pytest.raises(FrameFileError, match="foreign.tiff: ImageDescription"):
        load_frame_tiff(foreign)


def test_results_table_json_is_one_row_a_line_and_the_same_json(tmp_path: Path) -> None:
    from benchlab.storage import json_rows_text

    rows = [{"element": "G2E2", "mod": np.float64(0.738), "n": np.int64(3), "curve": [0.5, 1.0],
             "none": None, "path": Path("frames/x.tiff")},
            {"element": "G2E3", "mod": 0.709}]
    text = json_rows_text(rows)
    atomic_write_json(tmp_path / "indented.json", rows)
    assert json.loads(text) == json.loads((tmp_path / "indented.json").read_text())
    lines = text.splitlines()
    assert lines[0] == "[" and lines[-1] == "]" and len(lines) == 2 + len(rows)
    assert json_rows_text([]) == "[]\n" and json.loads(json_rows_text([])) == []
    with pytest.raises(ValueError):
        json_rows_text([{"mod": float("nan")}])  # NaN is not JSON: refused as before


def test_tiff_written_page_by_page_reads_every_page(tmp_path: Path) -> None:
    # tifffile append=True (as many tools write stacks) makes one series per page: read as
    # the first page only before, now as the stack.
    import tifffile

    from benchlab.storage import read_tiff_pixels

    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 4096, (6, 5), dtype=np.uint16) for _ in range(3)]
    path = tmp_path / "pages.tiff"
    for i, f in enumerate(frames):
        tifffile.imwrite(path, f, photometric="minisblack", append=i > 0)
    np.testing.assert_array_equal(read_tiff_pixels(path), np.stack(frames))
    once = tmp_path / "stack.tiff"
    tifffile.imwrite(once, np.stack(frames), photometric="minisblack")
    np.testing.assert_array_equal(read_tiff_pixels(once), np.stack(frames))
    mixed = tmp_path / "mixed.tiff"
    tifffile.imwrite(mixed, frames[0], photometric="minisblack")
    tifffile.imwrite(mixed, frames[1][:4], photometric="minisblack", append=True)
    with pytest.raises(FrameFileError, match=r"mixed.tiff: page 2 is \(4, 5\) uint16, page 1 "
                                             r"\(6, 5\) uint16"):
        read_tiff_pixels(mixed)
    # A saved session frame (one page + metadata) still reads as that one frame.
    saved = save_frame_tiff(tmp_path / "f.tiff", frames[0], {"bits": 12})
    got = read_tiff_pixels(saved)
    assert got.shape == (6, 5) and np.array_equal(got, frames[0])
    assert np.array_equal(load_frame_tiff(saved)[0], got)
