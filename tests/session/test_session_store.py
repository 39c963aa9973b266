"""The session store: journal, frames, results and crash safety."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from benchlab import storage
from benchlab.session import FrameExistsError, Session, SessionError
from benchlab.session import results as session_mod
from benchlab.storage import load_frame_tiff, sha256_file


def _new(root: Path, **kw: object) -> Session:
    args: dict[str, object] = dict(
        procedure="mtf",
        params={"exposure_ms": 300.0, "frequencies": [0.5, 1.0]},
        operator="ada",
        devices={"camera": {"model": "MCE-B013-U", "serial": "13-0001", "firmware": "1.0.6"}},
        software_version="0.1.0",
    )
    args.update(kw)
    return Session.create(root, **args)  # type: ignore[arg-type]


def _frame(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (16, 20), dtype=np.uint8)


def test_create_open_round_trip(tmp_path: Path) -> None:
    s = _new(tmp_path)
    assert s.path.parent == tmp_path and s.path.name.endswith("_mtf")
    assert {p.name for p in s.path.iterdir()} == {
        "session.json",
        "events.jsonl",
        "frames",
        "results",
        "owner.lock",
    }
    meta = json.loads((s.path / "session.json").read_text())
    assert meta["status"] == "running" and meta["finished_at"] is None
    assert meta["operator"] == "ada" and meta["devices"]["camera"]["serial"] == "13-0001"
    assert meta["software_version"] == "0.1.0" and meta["started_at"]
    again = Session.open(s.path)
    assert again.params == {"exposure_ms": 300.0, "frequencies": [0.5, 1.0]}
    assert again.meta == s.meta and again.procedure == "mtf"
    again.finish()
    reopened = Session.open(s.path)
    assert reopened.status == "completed" and reopened.meta["finished_at"]
    assert [e["kind"] for e in reopened.events()] == ["session_created", "session_finished"]
    # a second session in the same second never reuses the folder
    assert _new(tmp_path, name=s.path.name).path != s.path


def test_open_names_the_bad_file(tmp_path: Path) -> None:
    with pytest.raises(SessionError, match=r"session\.json"):
        Session.open(tmp_path)
    s = _new(tmp_path)
    (s.path / "session.json").write_text('{"format": "benchlab.session", "procedure": ')
    with pytest.raises(SessionError, match=r"session\.json.*corrupt"):
        Session.open(s.path)
    (s.path / "session.json").write_text("[1, 2]")
    with pytest.raises(SessionError, match="not a benchlab session"):
        Session.open(s.path)


def test_journal_is_append_only_and_tolerates_a_torn_last_line(tmp_path: Path) -> None:
    s = _new(tmp_path)
    s.log_event("step_started", step="forward")
    before = (s.path / "events.jsonl").read_bytes()
    s.log_event("note", text="x" * 10, value=float("nan"))
    after = (s.path / "events.jsonl").read_bytes()
    assert after.startswith(before) and after.count(b"\n") == before.count(b"\n") + 1
    assert s.events()[-1]["value"] is None  # NaN is not JSON: recorded as null
    with open(s.path / "events.jsonl", "ab") as fh:  # kill -9 in the middle of a line
        fh.write(b'{"time": "2026-01-01", "kind": "step_comp')
    assert [e["kind"] for e in Session.open(s.path).events()][-1] == "note"
    s.mark_step_completed("forward", frames=1)
    kinds = [e["kind"] for e in s.events()]
    assert kinds[-2:] == ["journal_repaired", "step_completed"]
    assert s.completed_steps() == {"forward"}
    # a broken line that nothing repaired is reported, naming the file and line
    with open(s.path / "events.jsonl", "ab") as fh:
        fh.write(b"garbage\n" + json.dumps({"kind": "note"}).encode() + b"\n")
    with pytest.raises(SessionError, match=r"events\.jsonl: line \d+"):
        s.events()


def test_frames_are_flushed_hashed_and_never_overwritten(tmp_path: Path) -> None:
    s = _new(tmp_path)
    pixels = _frame()
    path = s.save_frame("forward", "frame", pixels, {"exposure_ms": 300.0, "gain": 1.0})
    assert path == s.path / "frames" / "forward__frame.tiff"
    loaded, meta = load_frame_tiff(path)
    assert np.array_equal(loaded, pixels) and meta["exposure_ms"] == 300.0
    assert meta["step_id"] == "forward"
    ev = [e for e in s.events() if e["kind"] == "frame_saved"][-1]
    assert ev["sha256"] == sha256_file(path) and ev["file"] == "frames/forward__frame.tiff"
    digest = sha256_file(path)
    with pytest.raises(FrameExistsError, match="forward__frame"):
        s.save_frame("forward", "frame", _frame(1), {})
    assert sha256_file(path) == digest
    assert s.step_frames("forward") == {"frame": path}
    assert s.step_frames("radial") == {}
    px, _ = s.load_frame("forward", "frame")
    assert np.array_equal(px, pixels)
    with pytest.raises(ValueError):
        s.save_frame("../x", "frame", pixels, {})
    with pytest.raises(ValueError):
        s.save_frame("a__b", "frame", pixels, {})


def test_verify_frames_catches_a_modified_frame(tmp_path: Path) -> None:
    s = _new(tmp_path)
    a = s.save_frame("s1", "mask", _frame(1), {})
    s.save_frame("s1", "measurement", _frame(2), {})
    assert s.verify_frames() == []
    data = bytearray(a.read_bytes())
    data[-1] ^= 0xFF
    a.write_bytes(bytes(data))
    assert s.verify_frames() == ["frames/s1__mask.tiff"]
    with pytest.raises(SessionError, match="modified"):
        s.load_frame("s1", "mask")
    (s.path / "frames" / "s1__measurement.tiff").unlink()
    assert s.verify_frames() == ["frames/s1__mask.tiff", "frames/s1__measurement.tiff"]
    with pytest.raises(SessionError, match="recorded frame is missing"):
        s.load_frame("s1", "measurement")


def test_results_are_versioned_and_never_overwritten(tmp_path: Path) -> None:
    s = _new(tmp_path)
    s.save_frame("forward", "frame", _frame(), {})
    assert s.latest_results() is None
    rows = [{"label": "G2E4S", "modulation": 0.62, "mtf": float("nan")}, {"label": "G2E4T", "x": 1}]
    v1 = s.write_results({"forward": rows}, summary={"mean": 0.5}, estimator="histogram")
    assert v1 == s.path / "results" / "v1"
    assert sorted(p.name for p in v1.iterdir()) == ["forward.csv", "forward.json", "summary.json"]
    assert (v1 / "forward.csv").read_text().splitlines() == [
        "label,modulation,mtf,x",
        "G2E4S,0.62,NA,NA",
        "G2E4T,NA,NA,1",
    ]
    assert json.loads((v1 / "forward.json").read_text())[0]["mtf"] is None
    summary = json.loads((v1 / "summary.json").read_text())
    assert summary["version"] == 1 and summary["estimator"] == "histogram"
    assert summary["frames_sha256"] == s.frames() and summary["summary"] == {"mean": 0.5}
    snapshot = {p.name: p.read_bytes() for p in v1.iterdir()}
    v2 = s.write_results({"forward": rows[:1]}, summary={}, estimator="fit")
    assert v2.name == "v2" and s.latest_results() == v2
    assert {p.name: p.read_bytes() for p in v1.iterdir()} == snapshot
    assert Session.open(s.path).result_versions() == [1, 2]
    assert not [p for p in (s.path / "results").iterdir() if p.name.startswith(".")]


def test_a_crash_mid_write_leaves_the_old_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = _new(tmp_path)
    meta_before = (s.path / "session.json").read_bytes()

    def crash(*_a: object, **_k: object) -> None:
        raise OSError("power cut")

    monkeypatch.setattr(storage.os, "replace", crash)
    with pytest.raises(OSError, match="power cut"):
        s.update_meta(status="failed")
    assert (s.path / "session.json").read_bytes() == meta_before
    assert not [p for p in s.path.iterdir() if p.name.startswith(".")]  # no temp file left
    monkeypatch.undo()

    s.write_results({"t": [{"a": 1}]}, summary={}, estimator="histogram")
    calls = {"n": 0}
    real = session_mod.write_new_file  # the table files of a version (its folder is private)

    def crash_on_second_table(path: Path, data: bytes) -> Path:
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError("disk full")
        return real(path, data)

    monkeypatch.setattr(session_mod, "write_new_file", crash_on_second_table)
    with pytest.raises(OSError, match="disk full"):
        s.write_results({"t": [{"a": 2}], "u": [{"b": 3}]}, summary={}, estimator="fit")
    monkeypatch.undo()
    assert s.result_versions() == [1]
    assert sorted(p.name for p in (s.path / "results").iterdir()) == ["v1"]
    assert json.loads((s.path / "results/v1/t.json").read_text()) == [{"a": 1}]


def test_frame_flushed_before_a_crash_is_recovered_by_the_next_writer(tmp_path: Path) -> None:
    s = _new(tmp_path)
    # the frame reached the disk but the process died before its journal line
    storage.save_frame_tiff(s.path / "frames" / "radial-1__frame.tiff", _frame(3), {"gain": 1})
    s.release()  # the writer is gone (its lock with it)
    journal = (s.path / "events.jsonl").read_bytes()
    reader = Session.open(s.path)  # a reader (report, list) writes nothing
    assert reader.step_frames("radial-1") == {}
    assert (s.path / "events.jsonl").read_bytes() == journal
    reopened = Session.open(s.path)
    reopened.hold()  # the next writer (resume, re-analysis) records it
    assert set(reopened.step_frames("radial-1")) == {"frame"}
    ev = [e for e in reopened.events() if e["kind"] == "frame_saved"][-1]
    assert ev["recovered"] is True
    assert reopened.verify_frames() == []
    reopened.release()
    again = Session.open(s.path)
    again.hold()
    assert len([e for e in again.events() if e["kind"] == "frame_saved"]) == 1


def test_kill_9_while_journalling_leaves_a_readable_session(tmp_path: Path) -> None:
    s = _new(tmp_path)
    script = textwrap.dedent(
        f"""
        from benchlab.session import Session
        s = Session.open({str(s.path)!r})
        i = 0
        while True:
            s.log_event("tick", i=i, pad="x" * 500)
            i += 1
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script])
    try:
        journal = s.path / "events.jsonl"
        for _ in range(2000):  # wait for some lines, not for a time
            if journal.stat().st_size > 50_000:
                break
            time.sleep(0.01)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    reopened = Session.open(s.path)
    ticks = [e["i"] for e in reopened.events() if e["kind"] == "tick"]
    assert len(ticks) > 10 and ticks == list(range(len(ticks)))
    reopened.mark_step_completed("after")
    assert "after" in Session.open(s.path).completed_steps()


def test_load_frame_checks_the_bit_depth_as_the_analysis_paths_do(tmp_path: Path) -> None:
    """A recorded frame whose codes its own ``bits`` rule out (8-bit metadata, codes to 4095)
    is refused on load, naming the file, the field and the code - as ``benchlab analyze IMAGE``
    refuses the same file (issue 29); the frame on disk is untouched."""
    s = _new(tmp_path)
    ok = s.save_frame("s1", "fine", _frame(), {"bits": 8, "exposure_ms": 1.0})
    bad_pixels = np.random.default_rng(1).integers(0, 4096, (16, 20), dtype=np.uint16)
    bad = s.save_frame("s1", "bad", bad_pixels, {"bits": 8, "exposure_ms": 1.0})
    before = sha256_file(bad)
    pixels, meta = s.load_frame("s1", "fine")
    assert pixels.dtype == np.uint8 and meta["bits"] == 8
    with pytest.raises(storage.FrameFileError, match=r"metadata says 8-bit but the frame holds "
                                                     r"codes up to \d+ \(> 255\)") as info:
        s.load_frame("s1", "bad")
    assert str(bad) in str(info.value)
    with pytest.raises(storage.FrameFileError, match="metadata says 8-bit"):
        storage.read_tiff_frame(bad)  # the analysis paths' reader says the same
    assert sha256_file(bad) == before and ok.is_file()
