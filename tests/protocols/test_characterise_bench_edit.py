"""``run characterise`` pointing the user's bench file at the new calibration: the [camera]
table found however it is written, a file it cannot edit safely refused (before the run, and
at its end without an orphan response file), and a radiometry run refused at start when the
calibration has no curve for its gain and bit depth."""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path

import pytest
from sim_runs import (
    RAD_SMALL,
    TINY,  # one small characterise plan for both files
    yes,
)

from benchlab.bench import Bench, BenchConfig
from benchlab.calibration import (
    FORMAT,
    CalibrationError,
    set_camera_reference,
)
from benchlab.protocols import start_run


def _packaged_text() -> str:
    return Path(BenchConfig.load(None, simulate=True).source).read_text(encoding="utf-8")


def test_a_commented_header_gets_the_key_after_it() -> None:
    text = '[camera]   # Mightex on the left bench\nserial = "X"\n[led]\nchannel = 2\n'
    out = set_camera_reference(text, "c.json", "b.toml")
    assert out == text.replace("bench\n", 'bench\nresponse_calibration = "c.json"\n')
    again = set_camera_reference(out, "d.json", "b.toml")  # replaced, not added twice
    assert again == out.replace("c.json", "d.json")
    spaced = '[ camera ]\nserial = "X"\n'
    assert tomllib.loads(set_camera_reference(spaced, "c.json"))["camera"] == {
        "serial": "X", "response_calibration": "c.json"}


def test_a_bench_file_without_a_camera_table_gets_one_at_its_end() -> None:
    # Prepending "[camera]" would have moved the top-level dotted key into the camera table.
    text = 'paths.sessions = "/data/s"\n[led]\nchannel = 1\n'
    out = set_camera_reference(text, "c.json")
    assert out.startswith(text)
    assert tomllib.loads(out) == {"paths": {"sessions": "/data/s"}, "led": {"channel": 1},
                                  "camera": {"response_calibration": "c.json"}}


def test_crlf_line_endings_are_kept() -> None:
    out = set_camera_reference('[camera]\r\nserial = "X"\r\n', "c.json")
    assert out == '[camera]\r\nresponse_calibration = "c.json"\r\nserial = "X"\r\n'


@pytest.mark.parametrize("text", [
    'camera.serial = ""\n[led]\nchannel = 1\n',  # dotted keys
    'camera = { serial = "" }\n[led]\nchannel = 1\n',  # an inline table
])
def test_camera_tables_it_cannot_edit_are_refused_naming_the_file(text: str) -> None:
    with pytest.raises(CalibrationError, match=r"^b\.toml: camera: given as dotted keys"):
        set_camera_reference(text, "c.json", "b.toml")


def test_edits_that_would_change_other_keys_or_fail_validation_are_refused() -> None:
    multi = '[camera]\nresponse_calibration = """\nold.json"""\nserial = "X"\n'
    with pytest.raises(CalibrationError, match=r"b\.toml: camera\.response_calibration: "
                                               "could not be set"):
        set_camera_reference(multi, "c.json", "b.toml")
    with pytest.raises(CalibrationError, match=r"^b\.toml: camera\.bogus: unknown parameter; "
                                               "file not edited$"):
        set_camera_reference('[camera]\nbogus = 1\n', "c.json", "b.toml")
    with pytest.raises(CalibrationError, match=r"b\.toml: not valid TOML"):
        set_camera_reference('[camera\n', "c.json", "b.toml")


def _dotted(folder: Path) -> Path:
    folder.mkdir(exist_ok=True)
    bench = folder / "bench.toml"
    bench.write_text(_packaged_text().replace('[camera]\n', '').replace(
        'serial = ""', 'camera.serial = ""'))
    assert BenchConfig.load(bench, simulate=True).camera.serial is None  # a valid bench file
    return bench


def test_characterise_refuses_an_uneditable_bench_file_before_any_session(
        tmp_path: Path) -> None:
    bench, params = _dotted(tmp_path), tmp_path / "tiny.toml"
    params.write_text(TINY)
    before = bench.read_bytes()
    with Bench.open(BenchConfig.load(bench, simulate=True), simulate=True) as b, \
            pytest.raises(CalibrationError, match=f"{bench}: camera: given as dotted keys"):
        start_run("characterise", bench=b, params=params, root=tmp_path / "s", prompt=yes)
    assert bench.read_bytes() == before
    assert not (tmp_path / "s").exists() and not (tmp_path / "calibration").exists()


def test_a_bench_file_made_uneditable_during_the_run_leaves_no_response_file(
        tmp_path: Path) -> None:
    bench, params = tmp_path / "bench.toml", tmp_path / "tiny.toml"
    bench.write_text(_packaged_text())
    params.write_text(TINY)
    with Bench.open(BenchConfig.load(bench, simulate=True), simulate=True) as b:
        runner = start_run("characterise", bench=b, params=params, root=tmp_path / "s",
                           prompt=yes)
        shutil.copy(_dotted(tmp_path / "edit"), bench)  # the operator edits it meanwhile
        before = bench.read_bytes()
        with pytest.raises(Exception, match="camera: given as dotted keys"):
            runner.run()
    assert bench.read_bytes() == before
    assert list((tmp_path / "calibration").glob("response-v*.json")) == []


def test_radiometry_refuses_a_calibration_without_its_gain_at_start(tmp_path: Path) -> None:
    calib = tmp_path / "calibration" / "response-v1.json"
    calib.parent.mkdir()
    curve = {"gain": 4.0, "bits": 12, "black_level_dn": 64.0, "measured_dn": [0.0, 100.0],
             "linear_dn": [0.0, 100.0]}
    calib.write_text(json.dumps({"format": FORMAT, "version": 1, "curves": [curve]}))
    bench = tmp_path / "bench.toml"
    bench.write_text(set_camera_reference(_packaged_text(), "calibration/response-v1.json"))
    with Bench.open(BenchConfig.load(bench, simulate=True), simulate=True) as b, \
            pytest.raises(CalibrationError, match=rf"{calib}: no curve for gain 1, 8-bit "
                                                  r"\(has gain 4.0 12-bit\)"):
        start_run("radiometry", bench=b, params=RAD_SMALL, root=tmp_path / "s", prompt=yes)
    assert not (tmp_path / "s").exists()
    # With the curve (any bit depth of that gain) the run starts.
    calib.write_text(json.dumps({"format": FORMAT, "version": 1,
                                 "curves": [curve, {**curve, "gain": 1.0}]}))
    with Bench.open(BenchConfig.load(bench, simulate=True), simulate=True) as b:
        runner = start_run("radiometry", bench=b, params=RAD_SMALL, root=tmp_path / "s",
                           prompt=yes)
    assert Path(runner.session.path).is_dir()
