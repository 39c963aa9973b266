"""`benchlab devices`, `benchlab snap` and `benchlab benchmark camera` on the simulated camera."""

from __future__ import annotations

import json

import numpy as np
import pytest

import benchlab
import benchlab.cli.devices.serial
from benchlab.cli.main import main
from benchlab.storage import load_frame_tiff, sha256_file


@pytest.fixture
def no_serial(monkeypatch: pytest.MonkeyPatch) -> None:
    """Only the camera part is under test here: serial listing returns nothing."""
    monkeypatch.setattr(benchlab.cli.devices.serial, "list_serial_devices", lambda simulate: [],
                        raising=False)


def test_devices_simulated_json(no_serial: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices", "--simulate", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows == [{"kind": "camera", "model": "MCE-B013-U", "serial": "SIM-130001",
                     "firmware": "1.0.6", "pid": 0x0428, "bus": 1, "address": 2, "error": None,
                     "port": "usb 1:2 pid 0x0428"}]


def test_devices_simulated_table(no_serial: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices", "--simulate", "--pid", "0x0529"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["KIND", "MODEL", "SERIAL", "FIRMWARE", "WHERE"]
    assert lines[1].split() == ["camera", "MCE-B013-U", "SIM-130001", "1.0.6", "usb", "1:2",
                                "pid", "0x0529"]


def test_snap_writes_lossless_tiff_with_metadata(tmp_path, capsys) -> None:
    out = tmp_path / "frame.tiff"
    assert main(["snap", "--simulate", "--exposure-ms", "300", "--gain", "1", "--bits", "12",
                 str(out)]) == 0
    assert "saved" in capsys.readouterr().out
    pixels, meta = load_frame_tiff(out)
    assert pixels.dtype == np.uint16 and pixels.shape == (1024, 1280)
    assert (meta["exposure_ms"], meta["gain"], meta["bits"]) == (300.0, 1.0, 12)
    assert meta["camera"] == {"model": "MCE-B013-U", "serial": "SIM-130001",
                              "firmware": "1.0.6", "pid": 0x0428}
    assert meta["software"] == {"name": "benchlab", "version": benchlab.__version__}
    assert meta["simulated"] is True and "timestamp_ms" in meta
    columns = pixels.mean(axis=0)  # default bar target: 32 px period, ~3070 vs ~490 DN12
    assert columns[:16].min() > 2800 and columns[16:32].max() < 700


def test_snap_never_overwrites(tmp_path, capsys) -> None:
    out = tmp_path / "frame.tiff"
    args = ["snap", "--simulate", "--exposure-ms", "10", "--gain", "2", str(out)]
    assert main(args) == 0
    digest = sha256_file(out)
    assert main(args) == 1
    assert "already exists" in capsys.readouterr().err
    assert sha256_file(out) == digest


def test_snap_out_of_range_names_the_range(tmp_path, capsys) -> None:
    out = tmp_path / "frame.tiff"
    assert main(["snap", "--simulate", "--exposure-ms", "0.01", "--gain", "1", str(out)]) == 1
    assert "0.05 .. 750 ms" in capsys.readouterr().err  # the MCE-B013-U profile ([SH])
    assert main(["snap", "--simulate", "--exposure-ms", "1", "--gain", "9", str(out)]) == 1
    assert "0.125 .. 8x" in capsys.readouterr().err
    assert not out.exists()


def test_benchmark_camera_prints_a_table(capsys) -> None:
    assert main(["benchmark", "camera", "--frames", "3"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split() == ["bits", "fps", "end-to-end", "decode", "ms", "copy", "ms",
                                "decode/copy"]
    assert [line.split()[0] for line in lines[2:4]] == ["8", "12"]
