"""Cassettes: a session recorded with --trace-io replays with --replay, without devices or
simulators, byte for byte; a driver that does something else is told where it diverged."""

from __future__ import annotations

import hashlib
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tifffile

from benchlab.cli.main import main
from benchlab.drivers.mightex.camera import MightexCamera
from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera
from benchlab.drivers.trace import io_trace, replay
from benchlab.drivers.trace.cassette import CassetteError, ReplayDivergedError, load

CASSETTES = Path(__file__).parents[2] / "fixtures" / "cassettes"
ENTRIES: list[dict[str, Any]] = tomllib.loads(
    (CASSETTES / "cassettes.toml").read_text(encoding="utf-8"))["cassette"]


def _args(args: list[str], out: Path) -> list[str]:
    return [str(out) if a == "OUT.tiff" else a for a in args]


@pytest.fixture(autouse=True)
def _no_replay_left() -> Any:
    yield
    replay.stop()
    io_trace.stop()


@pytest.mark.slow
def test_a_snap_replays_pixel_identical_without_a_simulator(tmp_path: Path) -> None:
    cassette, a, b = tmp_path / "snap.jsonl.gz", tmp_path / "a.tiff", tmp_path / "b.tiff"
    assert main(["--trace-io", str(cassette), "snap", "--simulate", "--seed", "5",
                 "--exposure-ms", "5", "--gain", "1", str(a)]) == 0
    assert main(["--replay", str(cassette), "snap", "--exposure-ms", "5", "--gain", "1",
                 str(b)]) == 0
    pa, pb = tifffile.imread(a), tifffile.imread(b)
    assert pa.std() > 0.5  # noisy: identical only because these are the recorded bytes
    assert np.array_equal(pa, pb)


def test_a_replay_with_other_settings_names_the_exchange(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cassette = tmp_path / "snap.jsonl"
    assert main(["--trace-io", str(cassette), "snap", "--simulate", "--exposure-ms", "5",
                 "--gain", "1", str(tmp_path / "a.tiff")]) == 0
    capsys.readouterr()
    assert main(["--replay", str(cassette), "snap", "--exposure-ms", "6", "--gain", "1",
                 str(tmp_path / "b.tiff")]) == 1
    n = next(e.n for e in load(cassette) if e.data == bytes.fromhex("63 02 00 64"))
    assert (f"replay diverged at exchange {n}: sent 63 02 00 78, recorded 63 02 00 64 "
            "on EP 0x01") in capsys.readouterr().err


@pytest.mark.parametrize("entry", ENTRIES, ids=[e["file"] for e in ENTRIES])
def test_shipped_cassettes_replay_and_diverge(
    entry: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = CASSETTES / entry["file"]
    out = tmp_path / "frame.tiff"
    assert main(["--replay", str(path), *_args(entry["replay"], out)]) == 0
    if "pixels_sha256" in entry:
        assert hashlib.sha256(tifffile.imread(out).tobytes()).hexdigest() == \
            entry["pixels_sha256"]
    capsys.readouterr()
    assert main(["--replay", str(path), *_args(entry["diverging"], tmp_path / "x.tiff")]) == 1
    assert "replay diverged at exchange " in capsys.readouterr().err


def test_the_backend_refuses_a_write_past_the_end(tmp_path: Path) -> None:
    cassette = tmp_path / "c.jsonl"
    io_trace.start(cassette)
    sim = SimulatedCamera(noise=False)
    with MightexCamera.open(backend=SimCameraBackend([sim])):
        pass
    io_trace.stop()
    replay.start(cassette)
    cam = MightexCamera.open()
    with pytest.raises(ReplayDivergedError, match="after the last recorded camera exchange"):
        cam.set_gain(2.0)


def test_a_bad_cassette_names_the_file_and_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"cassette": 1}\n{"n": 1, "dev": "camera", "dir": "?"}\n', "ascii")
    with pytest.raises(CassetteError, match=r"bad.jsonl: line 2: bad exchange"):
        load(bad)
    (tmp_path / "old.txt").write_text("# benchlab I/O trace\n", "ascii")
    with pytest.raises(CassetteError, match="line 1 is not JSON"):
        load(tmp_path / "old.txt")
