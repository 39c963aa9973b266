"""A radiometry session keeps the response calibration it was run with: the bench file's
relative reference is made absolute, the file is copied into the session (sha256 recorded)
before any frame, and every re-analysis uses that copy - from any folder - or refuses, naming
the file and both sha256, when it is not the one recorded."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
from sim_runs import RAD_SMALL

from benchlab.bench import BenchConfig
from benchlab.calibration import FORMAT, set_camera_reference
from benchlab.cli.main import main


def _calibration(linear_dn: list[float]) -> str:
    return json.dumps({"format": FORMAT, "version": 1, "curves": [
        {"gain": 1.0, "bits": 8, "black_level_dn": 0.0, "measured_dn": [10.0, 100.0, 255.0],
         "linear_dn": linear_dn}]})


@pytest.fixture
def bench_dirs(tmp_path: Path) -> tuple[Path, Path]:
    """Folder A: bench.toml -> calibration/response-v1.json; folder B: a different file of the
    same relative name."""
    a, b = tmp_path / "A", tmp_path / "B"
    for folder, curve in ((a, [10.0, 100.0, 255.0]), (b, [10.0, 150.0, 400.0])):
        (folder / "calibration").mkdir(parents=True)
        (folder / "calibration" / "response-v1.json").write_text(_calibration(curve))
    text = Path(str(BenchConfig.load(None, simulate=True).source)).read_text()
    (a / "bench.toml").write_text(set_camera_reference(text, "calibration/response-v1.json"))
    return a, b


def _rows(results: Path) -> list[dict[str, object]]:
    return json.loads((results / "relative_radiometry.json").read_text())


def test_relative_reference_is_absolute_at_load(bench_dirs: tuple[Path, Path],
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    a, _ = bench_dirs
    monkeypatch.chdir(a)
    ref = BenchConfig.load("bench.toml").camera.response_calibration
    assert ref == str(a / "calibration" / "response-v1.json")


@pytest.mark.slow
def test_reanalysis_elsewhere_uses_the_sessions_copy_or_refuses(
        bench_dirs: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    a, b = bench_dirs
    monkeypatch.chdir(a)
    assert main(["run", "radiometry", "--simulate", "--config", "bench.toml", "--yes",
                 "--params", str(RAD_SMALL), "--out", "s"]) == 0
    (session,) = (a / "s").glob("*_radiometry")
    original = a / "calibration" / "response-v1.json"
    sha = hashlib.sha256(original.read_bytes()).hexdigest()
    meta = json.loads((session / "session.json").read_text())
    assert meta["response_calibration"] == {"file": str(original), "sha256": sha,
                                            "copy": "calibration/response-v1.json"}
    assert (session / "calibration" / "response-v1.json").read_bytes() == original.read_bytes()
    events = [json.loads(x) for x in (session / "events.jsonl").read_text().splitlines()]
    kinds = [e["kind"] for e in events]
    assert kinds.index("response_calibration_recorded") < kinds.index("frame_saved")
    v1 = _rows(session / "results" / "v1")
    summary = json.loads((session / "results" / "v1" / "summary.json").read_text())["summary"]
    assert summary["linearised"]["sha256"] == sha
    capsys.readouterr()

    # From B, whose calibration/response-v1.json is another curve: the session's copy is used.
    monkeypatch.chdir(b)
    # The run's results byte for byte: the re-analysis matches v1 and adds no version.
    assert main(["analyze", str(session)]) == 0
    out = capsys.readouterr().out
    assert f"sha256 {sha}" in out and "identical to v1" in out
    # The original file edited afterwards changes nothing either.
    original.write_text(_calibration([10.0, 150.0, 400.0]))
    assert main(["analyze", str(session)]) == 0
    assert "identical to v1" in capsys.readouterr().out
    assert sorted(p.name for p in (session / "results").iterdir()) == ["v1"]
    assert _rows(session / "results" / "v1") == v1

    # The session's copy changed: refused, naming the file and both sha256; nothing written.
    copy = session / "calibration" / "response-v1.json"
    copy.write_text(_calibration([10.0, 150.0, 400.0]))
    now = hashlib.sha256(copy.read_bytes()).hexdigest()
    assert main(["analyze", str(session)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("benchlab: error:") and str(copy) in err
    assert sha in err and now in err
    assert sorted(p.name for p in (session / "results").iterdir()) == ["v1"]


@pytest.mark.slow
def test_session_without_a_copy_is_refused_when_the_file_differs(
        bench_dirs: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A session recorded before the copy existed (relative reference, no record): the sha256
    its first results used is the reference; another file of the same name is refused."""
    a, b = bench_dirs
    monkeypatch.chdir(a)
    assert main(["run", "radiometry", "--simulate", "--config", "bench.toml", "--yes",
                 "--params", str(RAD_SMALL), "--out", "s"]) == 0
    (session,) = (a / "s").glob("*_radiometry")
    meta = json.loads((session / "session.json").read_text())
    del meta["response_calibration"]
    meta["params"]["bench"]["camera"]["response_calibration"] = "calibration/response-v1.json"
    (session / "session.json").write_text(json.dumps(meta))
    capsys.readouterr()
    monkeypatch.chdir(b)
    assert main(["analyze", str(session)]) == 1
    err = capsys.readouterr().err
    other = hashlib.sha256((b / "calibration" / "response-v1.json").read_bytes()).hexdigest()
    first = hashlib.sha256((a / "calibration" / "response-v1.json").read_bytes()).hexdigest()
    assert str(b / "calibration" / "response-v1.json") in err and other in err and first in err
    monkeypatch.chdir(a)
    assert main(["analyze", str(session)]) == 0
    assert _rows(session / "results" / "v2") == _rows(session / "results" / "v1")


def test_missing_calibration_refuses_the_run_before_any_session(
        bench_dirs: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    a, _ = bench_dirs
    (a / "calibration" / "response-v1.json").unlink()
    monkeypatch.chdir(a)
    assert main(["run", "radiometry", "--simulate", "--config", "bench.toml", "--yes",
                 "--params", str(RAD_SMALL), "--out", "s"]) == 1
    assert "response-v1.json: no such response calibration file" in capsys.readouterr().err
    assert not list((a / "s").glob("*_radiometry"))
