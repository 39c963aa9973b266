"""Start-up of ``benchlab analyze SESSION`` (issue 11): it imports no OpenCV nor SciPy, its
results are byte for byte those of the OpenCV morphology it replaced, each frame is hashed
once, and the garbage-collector settings of a command run in-process are left as they were."""

from __future__ import annotations

import gc
import json
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from sim_runs import MTF_SMALL, reseal_results, run_sim

import benchlab.analysis.chart.finder as chart_finder
import benchlab.analysis.chart.morphology as morphology
import benchlab.session.frames as session_module
import benchlab.storage as storage
from benchlab.cli.main import main
from benchlab.protocols.runs import reanalyze
from benchlab.session import Session

#: Imported by ``analyze SESSION`` before issue 11's start-up work, or never needed by it.
NOT_IMPORTED = ("cv2", "scipy", "skimage", "matplotlib", "textual")


@pytest.fixture(scope="module")
def small_mtf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return run_sim("mtf", tmp_path_factory.mktemp("mtf"), MTF_SMALL).session_path


def _copy(src: Path, dst: Path) -> Path:
    return Path(shutil.copytree(src, dst / src.name))


@pytest.mark.slow
def test_analyze_session_imports_no_opencv_nor_scipy(small_mtf: Path, tmp_path: Path) -> None:
    path = _copy(small_mtf, tmp_path)
    # As a real bench writes it: the simulated bench's truth (simulator_truth, rendered from the
    # scenes, which need SciPy) is not part of a real session's analysis.
    meta = json.loads((path / "session.json").read_text(encoding="utf-8"))
    meta["devices"]["simulated"] = False
    (path / "session.json").write_text(json.dumps(meta), encoding="utf-8")
    code = ("import sys, json; from benchlab.cli.main import main; "
            f"status = main(['analyze', {str(path)!r}]); "
            "print(json.dumps([status, sorted(sys.modules)]))")
    # the forward frame's analysis (chart finder) imports nothing heavy either
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=120)
    status, loaded = json.loads(done.stdout.strip().splitlines()[-1])
    # the run's own results again, byte for byte, less the simulator's truth
    assert status == 0 and sorted(p.name for p in (path / "results").iterdir()) == ["v1", "v2"]
    v1, v2 = _files(path / "results" / "v1"), _files(path / "results" / "v2")
    assert sorted(set(v1) - set(v2)) == ["simulator_truth.csv", "simulator_truth.json"]
    assert all(v1[name] == v2[name] for name in v2 if name != "summary.json")
    heavy = sorted({m.split(".")[0] for m in loaded} & set(NOT_IMPORTED))
    assert heavy == []
    # ... while the code that used them ran: the chart finder, the hole fill, the bar model
    for used in ("benchlab.analysis.chart.finder", "benchlab.analysis.chart.morphology",
                 "benchlab.analysis.geometry", "benchlab.analysis.bars.model"):
        assert used in loaded, used


def _files(version: Path) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for p in sorted(version.iterdir()):
        if p.name == "summary.json":
            doc = json.loads(p.read_text(encoding="utf-8"))
            for varying in ("version", "created_at"):
                doc.pop(varying)
            out[p.name] = doc
        else:
            out[p.name] = p.read_bytes()
    return out


def _opencv_close(img: np.ndarray, size: int) -> np.ndarray:
    box = cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))
    return np.asarray(cv2.morphologyEx(img, cv2.MORPH_CLOSE, box))


def _opencv_labels(mask: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8),
                                                           connectivity=4)
    return n, labels, stats[:, cv2.CC_STAT_AREA]


def _opencv_fill(mask: np.ndarray) -> np.ndarray:
    background = np.pad(~np.asarray(mask, bool), 1, constant_values=True).astype(np.uint8)
    cv2.floodFill(background, None, (0, 0), 2, flags=4)
    filled: np.ndarray = background[1:-1, 1:-1] != 2
    return filled


def test_results_are_those_of_opencv(small_mtf: Path, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    path = _copy(small_mtf, tmp_path)
    now = reanalyze(path, new_version=True)  # written, to compare the files of both
    with monkeypatch.context() as m:
        m.setattr(chart_finder, "box_close", _opencv_close)
        m.setattr(chart_finder, "label_components", _opencv_labels)
        m.setattr(morphology, "fill_holes", _opencv_fill)
        before = reanalyze(path, new_version=True)
    assert (now.name, before.name) == ("v2", "v3")
    ours, theirs = _files(now), _files(before)
    assert sorted(ours) == sorted(theirs) and len(ours) >= 9
    for name in ours:
        assert ours[name] == theirs[name], name
    # and they are the run's own results (v1), the same functions on the same frames
    assert _files(path / "results" / "v1") == ours


def test_each_frame_is_hashed_once_and_any_write_is_still_caught(
        small_mtf: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = _copy(small_mtf, tmp_path)
    hashed: list[str] = []
    real = session_module.sha256_file

    def counting(p: str | os.PathLike[str]) -> str:
        hashed.append(Path(p).name)
        return real(p)

    monkeypatch.setattr(session_module, "sha256_file", counting)
    session = Session.open(path)
    session.prefetch_frames(2)
    assert session.verify_frames() == []  # waits for the loads, which hashed every frame
    frames = sorted(session.frames())
    for rel in frames:
        step, name = Path(rel).stem.split("__")
        session.load_frame(step, name)
    assert session.verify_frames() == [] and hashed == []
    first = path / frames[0]
    stat = first.stat()
    first.write_bytes(first.read_bytes())  # same bytes, same size, mtime put back: hashed
    os.utime(first, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert session.verify_frames() == [] and hashed == [first.name]
    data = bytearray(first.read_bytes())
    data[-10] ^= 0xFF
    first.write_bytes(bytes(data))
    os.utime(first, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert session.verify_frames() == [frames[0]]
    # a fresh Session hashes everything itself
    hashed.clear()
    assert Session.open(path).verify_frames() == [frames[0]] and len(hashed) == len(frames)


def test_in_process_commands_leave_the_garbage_collector_as_it_was(
        small_mtf: Path, tmp_path: Path) -> None:
    frozen = gc.get_freeze_count()
    assert gc.isenabled()
    assert main(["analyze", str(_copy(small_mtf, tmp_path))]) == 0
    assert gc.isenabled() and gc.get_freeze_count() == frozen
    broken = _copy(small_mtf, tmp_path / "broken")
    (broken / "session.json").write_text("not json", encoding="utf-8")
    assert main(["analyze", str(broken)]) == 1
    assert gc.isenabled() and gc.get_freeze_count() == frozen
    # the catalogue thread started beside the analysis has ended, recording nothing
    assert not [t for t in threading.enumerate() if t.name == "benchlab-catalogue"]
    assert not (broken.parent / "catalog.sqlite").exists()


def test_results_files_are_written_in_place_with_the_usual_mode(tmp_path: Path) -> None:
    target = storage.write_new_file(tmp_path / "a.json", b"[]\n")
    assert target.read_bytes() == b"[]\n"
    assert target.stat().st_mode & 0o777 == storage._FILE_MODE
    with pytest.raises(FileExistsError):
        storage.write_new_file(target, b"other")
    assert target.read_bytes() == b"[]\n"  # never replaced
    session = Session.create(tmp_path, procedure="mtf", params={}, operator="ada", devices={},
                             software_version="0")
    version = session.write_results({"t": [{"a": 1.5, "b": np.float64("nan")}]}, summary={},
                                    estimator="fit")
    files = sorted(p.name for p in version.iterdir())
    assert files == ["summary.json", "t.csv", "t.json"]  # no temporary file left
    assert {(version / f).stat().st_mode & 0o777 for f in files} == {storage._FILE_MODE}
    assert json.loads((version / "t.json").read_text()) == [{"a": 1.5, "b": None}]
    assert (version / "t.csv").read_text() == "a,b\n1.5,NA\n"


@pytest.mark.parametrize("frame", ["forward__forward.tiff", "radial-0.5-sagittal__radial.tiff"])
def test_a_changed_frame_still_stops_the_reanalysis_before_any_result(
        small_mtf: Path, tmp_path: Path, frame: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The analysis starts while frames load; a load finding its frame changed stops it with
    the same error, and no results version is written."""
    path = _copy(small_mtf, tmp_path)
    target = path / "frames" / frame
    data = bytearray(target.read_bytes())
    data[-10] ^= 0xFF
    target.write_bytes(bytes(data))
    assert main(["analyze", str(path)]) == 1
    err = capsys.readouterr().err
    assert "frames changed since acquisition" in err and frame in err
    assert sorted(p.name for p in (path / "results").iterdir()) == ["v1"]


def test_the_catalogue_reads_only_the_tables_it_takes_figures_from(
    small_mtf: Path, tmp_path: Path
) -> None:
    import shutil

    from benchlab.catalog.extract import NOT_FIGURES, figures_of, read_session_record
    from benchlab.session import read_results

    version = small_mtf / "results" / "v1"
    every, summary = read_results(version)
    some, same_summary = read_results(version, skip=NOT_FIGURES)
    assert "table_sfr_curves" in every and "table_sfr_curves" not in some
    assert set(some) == set(every) - NOT_FIGURES and same_summary == summary
    assert list(figures_of(1, some)) == list(figures_of(1, every))
    assert len(list(figures_of(1, some))) > 20
    # A table of another kind (characterisation, simulator truth, ...) keeps its figures.
    copy = Path(shutil.copytree(small_mtf, tmp_path / small_mtf.name))
    (copy / "results" / "v1" / "extra_table.json").write_text(
        '[{"name": "gain", "value": 0.42}]', encoding="utf-8")
    reseal_results(copy / "results" / "v1")  # as if written with the version
    record = read_session_record(copy)
    assert any(f.view == "extra_table" and f.quantity == "value" and f.value == 0.42
               for f in record.figures), record.figures


def test_a_reanalysis_writes_no_results_from_a_frame_no_load_has_checked(
    small_mtf: Path, tmp_path: Path
) -> None:
    """The analysis may start before the last frames are hashed (their loads check them);
    write_results checks every recorded frame first, so a changed frame that no load read
    still leaves the session's results as they were."""
    from benchlab.session import Session, SessionError

    path = _copy(small_mtf, tmp_path)
    session = Session.open(path)
    session.verify_frames_before_results = True
    frame = sorted((path / "frames").iterdir())[0]
    data = bytearray(frame.read_bytes())
    data[-10] ^= 0xFF
    frame.write_bytes(bytes(data))
    with pytest.raises(SessionError, match="frames changed since acquisition"):
        session.write_results({"table_x": [{"a": 1}]}, summary={}, estimator="auto")
    assert sorted(p.name for p in (path / "results").iterdir()) == ["v1"]
    session.verify_frames_before_results = False  # an acquisition writes without the check
    assert session.write_results({"table_x": [{"a": 1}]}, summary={}, estimator="auto").name \
        == "v2"
