"""The journal is parsed as it grows: each byte once, torn and repaired lines as before, a
replaced or truncated file from the start (issue 39)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

import benchlab.session.journal_reader as journal_mod
from benchlab.benchmarks.journal import format_journal_benchmark, run_journal_benchmark
from benchlab.session import Session, SessionError
from benchlab.session.journal_reader import JournalError, JournalReader


def _line(kind: str, **data: object) -> bytes:
    return (json.dumps({"kind": kind, **data}) + "\n").encode()


def _append(path: Path, data: bytes) -> None:
    with path.open("ab") as fh:
        fh.write(data)


def test_reads_only_what_was_appended(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "events.jsonl"
    path.write_bytes(_line("a", n=1) + _line("b", n=2))
    parsed: list[str] = []
    real = journal_mod.json.loads
    monkeypatch.setattr(journal_mod.json, "loads", lambda s: parsed.append(s) or real(s))
    reader = JournalReader(path)
    assert reader.read() == (True, [{"kind": "a", "n": 1}, {"kind": "b", "n": 2}])
    assert len(parsed) == 2
    _append(path, _line("c", n=3))
    complete, events = reader.read()
    assert complete and [e["kind"] for e in events] == ["a", "b", "c"]
    assert len(parsed) == 3  # the old lines were not parsed again
    assert reader.read()[1] is events and len(parsed) == 3  # unchanged file: nothing read
    assert reader.generation == 1


def test_torn_tail_waits_and_repair_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "events.jsonl"
    path.write_bytes(_line("a") + b'{"kind": "fram')  # a crash mid-append
    reader = JournalReader(path)
    assert reader.read() == (False, [{"kind": "a"}])
    # What Session.log_event does next: end the fragment, journal the repair, append.
    _append(path, b"\n" + _line("journal_repaired", torn_bytes=14) + _line("b"))
    complete, events = reader.read()
    assert complete
    assert [e["kind"] for e in events] == ["a", "journal_repaired", "b"]


def test_corrupt_middle_line_names_its_line(tmp_path: Path) -> None:
    path = tmp_path / "events.jsonl"
    path.write_bytes(_line("a") + b"garbage\n" + _line("b"))
    with pytest.raises(JournalError, match=r"events.jsonl: line 2 is corrupt"):
        JournalReader(path).read()
    # Found only once more lines arrive: the same error, with the same line number.
    path.write_bytes(_line("a") + b"garbage\n")
    reader = JournalReader(path)
    assert reader.read() == (False, [{"kind": "a"}])
    _append(path, _line("b"))
    with pytest.raises(JournalError, match="line 2 is corrupt"):
        reader.read()
    with pytest.raises(JournalError, match="line 2 is corrupt"):
        reader.read()  # still wrong on the next call: no half-read state was kept


def test_replaced_or_truncated_file_is_read_from_the_start(tmp_path: Path) -> None:
    path = tmp_path / "events.jsonl"
    path.write_bytes(_line("a") + _line("b"))
    reader = JournalReader(path)
    assert len(reader.read()[1]) == 2
    other = tmp_path / "new.jsonl"
    other.write_bytes(_line("x"))
    os.replace(other, path)  # a new inode
    assert reader.read()[1] == [{"kind": "x"}]
    assert reader.generation == 2
    with path.open("r+b") as fh:  # same inode, shorter
        fh.truncate(0)
    assert reader.read() == (True, [])
    assert reader.generation == 3


def test_missing_journal_raises_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        JournalReader(tmp_path / "events.jsonl").read()


def _session(root: Path) -> Session:
    return Session.create(root, procedure="journal", params={}, operator="t", devices={},
                          software_version="t")


@pytest.mark.slow
def test_saving_frames_parses_each_journal_line_once(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Before issue 39 every save re-parsed the whole journal: 200 frames cost ~20,000 parses."""
    session = _session(tmp_path)
    calls = [0]
    real = journal_mod.json.loads

    def counting(s: str | bytes) -> object:
        calls[0] += 1
        return real(s)

    monkeypatch.setattr(journal_mod.json, "loads", counting)
    pixels = np.zeros((4, 4), np.uint8)
    for i in range(200):
        step = f"s{i // 4:03d}"
        if i % 4 == 0:
            assert session.step_frames(step) == {}
        session.save_frame(step, f"f{i % 4}", pixels, {"bits": 8})
    lines = session.events_path.read_bytes().count(b"\n")
    assert lines == 201  # session_created + one frame_saved per frame
    assert lines - 1 <= calls[0] <= lines  # each line parsed once (the first by open)
    assert sorted(session.step_frames("s049")) == ["f0", "f1", "f2", "f3"]
    session.release()


def test_a_second_reader_sees_what_the_writer_appends(tmp_path: Path) -> None:
    writer = _session(tmp_path)
    reader = Session.open(writer.path)
    assert reader.step_frames("s") == {}
    writer.save_frame("s", "a", np.ones((2, 2), np.uint8), {"bits": 8})
    assert list(reader.step_frames("s")) == ["a"]
    writer.reject_frames("s", ["a"], "smudge")
    assert reader.step_frames("s") == {}
    assert list(reader.rejected_frames().values()) == ["smudge"]
    writer.release()


def test_session_names_a_corrupt_journal_line(tmp_path: Path) -> None:
    session = _session(tmp_path)
    session.release()
    _append(session.events_path, b"not json\n" + _line("step_completed", step_id="x"))
    with pytest.raises(SessionError, match=r"events.jsonl: line 2 is corrupt"):
        Session.open(session.path)


@pytest.mark.slow
def test_journal_benchmark_reports_flat_bookkeeping(tmp_path: Path) -> None:
    result = run_journal_benchmark(400, block=200, root=tmp_path)
    assert result.n_frames == 400 and len(result.ms_per_frame) == 2
    assert all(ms > 0 for ms in result.cpu_ms_per_frame)
    text = format_journal_benchmark(result)
    assert "201-400" in text and "last block / first block" in text
    with pytest.raises(ValueError, match="at least one block"):
        run_journal_benchmark(10, block=20, root=tmp_path)
