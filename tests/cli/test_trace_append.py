"""``benchlab --trace-io FILE`` onto an existing file (issue 38): refused without ``--append``
or ``--force``; ``--append`` adds a recording to a cassette of the same format and to nothing
else (a frame, a session file, a cassette under the other kind of name), naming the file."""

from __future__ import annotations

import gzip
import hashlib
from pathlib import Path

import pytest
from acceptance_sessions import make_session

from benchlab.cli.main import build_parser, main, with_tui
from benchlab.drivers.trace import io_trace
from benchlab.drivers.trace.cassette import last_event_number, load


@pytest.fixture(autouse=True)
def _no_trace_left() -> object:
    yield
    io_trace.stop()


def _snap(tmp_path: Path, cassette: Path, *extra: str, name: str = "a.tiff") -> int:
    return main([*extra, "--trace-io", str(cassette), "snap", "--simulate", "--seed", "3",
                 "--exposure-ms", "5", "--gain", "1", str(tmp_path / name)])


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_an_existing_cassette_is_refused_without_append_or_force(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cassette = tmp_path / "bench.jsonl"
    assert _snap(tmp_path, cassette) == 0
    before = _digest(cassette)
    capsys.readouterr()
    assert _snap(tmp_path, cassette, name="b.tiff") == 2
    err = capsys.readouterr().err
    assert f"--trace-io {cassette}: already exists; nothing written" in err
    assert _digest(cassette) == before and not (tmp_path / "b.tiff").exists()
    assert _snap(tmp_path, cassette, "--append", "--force", name="b.tiff") == 2
    assert "--append and --force: give one" in capsys.readouterr().err
    assert _digest(cassette) == before


@pytest.mark.slow
@pytest.mark.parametrize("name", ["bench.jsonl", "bench.jsonl.gz"])
def test_append_adds_a_numbered_recording_to_a_cassette(
        tmp_path: Path, name: str, capsys: pytest.CaptureFixture[str]) -> None:
    cassette = tmp_path / name
    assert _snap(tmp_path, cassette) == 0
    first = load(cassette)
    first_bytes = cassette.read_bytes()
    last = last_event_number(cassette)
    assert last == first[-1].n == len(first)
    assert _snap(tmp_path, cassette, "--append", name="b.tiff") == 0, capsys.readouterr().err
    assert cassette.read_bytes().startswith(first_bytes)  # nothing recorded is rewritten
    both = load(cassette)
    assert both[:len(first)] == first
    added = both[len(first):]
    # the same command sent the same bytes; its exchanges numbered on after the note line
    assert [(e.device, e.direction, e.data) for e in added if e.direction == ">"] == \
        [(e.device, e.direction, e.data) for e in first if e.direction == ">"]
    assert added[0].n == last + 2 and [e.n for e in both] == sorted({e.n for e in both})
    text = (gzip.decompress(cassette.read_bytes()) if name.endswith(".gz")
            else cassette.read_bytes()).decode("ascii")
    (note,) = [line for line in text.splitlines() if "recording appended" in line]
    assert f'"n": {last + 1}' in note


def test_append_is_refused_onto_anything_but_a_cassette_of_its_format(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    session = make_session(tmp_path / "sessions", "s1", serial="SN1")
    plain, packed = tmp_path / "plain.jsonl", tmp_path / "packed.jsonl.gz"
    assert _snap(tmp_path, plain, name="frame.tiff") == 0
    assert _snap(tmp_path, packed, name="b.tiff") == 0
    frame = tmp_path / "frame.tiff"
    lookalike = tmp_path / "session-copy.json"
    lookalike.write_bytes((session / "session.json").read_bytes())
    wrong_kind = {tmp_path / "plain-named.jsonl.gz": plain.read_bytes(),  # plain text, .gz name
                  tmp_path / "packed-named.jsonl": packed.read_bytes()}  # gzip, plain name
    for path, data in wrong_kind.items():
        path.write_bytes(data)
    cut = tmp_path / "cut.jsonl.gz"  # a gzip cassette cut short (a copy that did not finish)
    cut.write_bytes(packed.read_bytes()[: packed.stat().st_size // 2])
    session_files = sorted(p for p in session.rglob("*") if p.is_file())
    before = {p: _digest(p) for p in [frame, lookalike, cut, *wrong_kind, *session_files]}
    capsys.readouterr()
    for target in [frame, lookalike, cut, *wrong_kind]:
        assert _snap(tmp_path, target, "--append", name="c.tiff") == 2, target
        err = capsys.readouterr().err
        assert f"--trace-io {target}: not a cassette of this format (" in err, err
        assert "nothing written" in err
    for target in (session / "session.json", session / "events.jsonl"):
        assert _snap(tmp_path, target, "--append", name="c.tiff") == 2, target
        assert f"--trace-io {target}: is part of the " in capsys.readouterr().err
    assert {p: _digest(p) for p in before} == before
    assert not (tmp_path / "c.tiff").exists()  # refused before the command ran


@pytest.mark.parametrize(("argv", "expected"), [
    (["--append", "--trace-io", "c.jsonl", "--simulate"],
     ["--append", "--trace-io", "c.jsonl", "tui", "--simulate"]),
    (["--trace-io=c.jsonl.gz", "--force", "--simulate", "--sessions", "s"],
     ["--trace-io=c.jsonl.gz", "--force", "tui", "--simulate", "--sessions", "s"]),
    (["--simulate"], ["tui", "--simulate"]), ([], ["tui"]),
    (["--trace-io", "c.jsonl", "snap", "x.tiff"], ["--trace-io", "c.jsonl", "snap", "x.tiff"]),
    (["--help"], ["--help"]), (["--log-level", "info"], ["--log-level", "info"]),
])
def test_the_terminal_ui_is_recorded_too(argv: list[str], expected: list[str]) -> None:
    """``benchlab --append --trace-io FILE --simulate`` records the terminal UI's exchanges
    (before, the UI's options after ``--trace-io FILE`` were refused as unknown)."""
    assert with_tui(argv) == expected
    if "tui" in expected:
        args = build_parser().parse_args(expected)
        assert args.command == "tui" and args.simulate == ("--simulate" in argv)
