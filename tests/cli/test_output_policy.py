"""One output policy for every file the CLI writes (issue 38, :mod:`benchlab.cli.output`).

Every output-file option, found by walking the real parsers, is run against an existing file
of the user's and against each kind of session file: the command exits 2 naming the file, and
the bytes of the file and of the whole session folder are unchanged. With ``--force`` the
user's file is replaced; a session's own files are refused even then.
"""

from __future__ import annotations

import argparse
import hashlib
import re
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from acceptance_sessions import limit, spec
from sim_runs import MTF_SMALL, run_sim

from benchlab.cli.main import build_parser, main
from benchlab.cli.output import OutputFile, session_part

#: Options that take a value and say they write, but name a folder benchlab fills with new
#: sessions or files of its own (never replacing one): not output files.
NOT_OUTPUT_FILES = {
    ("run", "--out"): "the sessions folder a new session is created in",
    ("benchmark characterise", "--keep"): "a folder for the benchmark's new sessions",
}
#: Flags that name an output file wherever they appear.
OUTPUT_FLAGS = {"--out", "--csv", "--plot", "--html", "--report", "--trace-io"}
_WRITES = re.compile(r"\b(write|writes|save|saves)\b", re.IGNORECASE)


def _parsers(parser: argparse.ArgumentParser, path: str = ""
             ) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, f"{path} {name}".strip())


def _output_like() -> dict[tuple[str, str], argparse.Action]:
    found = {}
    for path, parser in _parsers(build_parser()):
        for action in parser._actions:
            if not action.option_strings or action.nargs == 0:
                continue
            flag = max(action.option_strings, key=len)
            if set(action.option_strings) & OUTPUT_FLAGS or _WRITES.search(action.help or ""):
                found[(path, flag)] = action
    return found


def test_every_output_option_goes_through_the_policy() -> None:
    found = _output_like()
    unmarked = sorted(k for k, a in found.items()
                      if not isinstance(a, OutputFile) and k not in NOT_OUTPUT_FILES)
    assert unmarked == [], "add these with benchlab.cli.output.add_output_option"
    marked = {k for k, a in found.items() if isinstance(a, OutputFile)}
    assert marked == set(COMMANDS), "every output option has its case below"
    for path, parser in _parsers(build_parser()):
        if any(isinstance(a, OutputFile) for a in parser._actions):
            assert "--force" in parser._option_string_actions, path


# ---- every output option against existing files -----------------------------------------------
class Bench:
    """A sessions folder with one completed simulated MTF session (frames, results and a
    stored verdict)."""

    def __init__(self, tmp_path: Path) -> None:
        self.root = tmp_path / "sessions"
        self.session = run_sim("mtf", self.root, MTF_SMALL, sample="OBJ-1",
                               lot="L1").session_path
        self.spec = spec(tmp_path, limit(0.3, where='{ element = "G1E5" }'))
        assert main(["verify", str(self.session), "--spec", str(self.spec)]) == 0
        self.frame = self.session / "frames" / "forward__forward.tiff"
        assert self.frame.is_file()
        self.mine = tmp_path / "keep.png"  # the user's own file
        self.mine.write_bytes(b"my file, not benchlab's")

    def session_files(self) -> list[Path]:
        s = self.session
        return [s / "session.json", s / "events.jsonl", self.frame,
                s / "results" / "v1" / "summary.json", s / "verdicts" / "v1.json"]


Argv = Callable[[Bench, Path], list[str]]
#: (command, flag) -> the command line writing to a target; names match the parsers.
COMMANDS: dict[tuple[str, str], Argv] = {
    ("", "--trace-io"): lambda b, t: ["--trace-io", str(t), "sessions", "list", "--root",
                                      str(b.root)],
    ("report", "--out"): lambda b, t: ["report", str(b.session), "--out", str(t)],
    ("certificate", "--out"): lambda b, t: ["certificate", str(b.session), "--out", str(t)],
    ("lot", "--html"): lambda b, t: ["lot", "L1", "--spec", str(b.spec), "--root", str(b.root),
                                     "--html", str(t)],
    ("sessions list", "--csv"): lambda b, t: ["sessions", "list", "--root", str(b.root),
                                              "--csv", str(t)],
    ("sessions trend", "--csv"): lambda b, t: [
        "sessions", "trend", "--root", str(b.root), "--view", "forward", "--element", "G1E5",
        "--orientation", "S", "--plot", "", "--csv", str(t)],
    ("sessions trend", "--plot"): lambda b, t: [
        "sessions", "trend", "--root", str(b.root), "--view", "forward", "--element", "G1E5",
        "--orientation", "S", "--plot", str(t)],
    ("find-chart", "--plot"): lambda b, t: ["find-chart", str(b.frame), "--plot", str(t)],
    ("sfr", "--plot"): lambda b, t: ["sfr", str(b.frame), "--roi", "0,0,40,40", "--plot",
                                     str(t)],
    ("doctor", "--report"): lambda b, t: ["doctor", "--simulate", "--yes", "--report", str(t)],
    ("unwrap", "--out"): lambda b, t: ["unwrap", str(b.frame), "--out", str(t)],
    ("perspective", "--out"): lambda b, t: [
        "perspective", str(b.frame), "--yaw-deg", "0", "--pitch-deg", "0", "--fov-deg", "90",
        "--size", "64x48", "--out", str(t)],
    ("config init", "--path"): lambda b, t: ["config", "init", "--path", str(t)],
    ("calibrate radial", "--out"): lambda b, t: [
        "calibrate", "radial", str(b.frame), "--object-lp-per-mm", "1", "--depth-mm", "19.88",
        "--out", str(t)],
}
#: Cases that also run to completion with --force over the user's file (cheap ones).
FORCE_COMPLETES = {("report", "--out"), ("certificate", "--out"), ("lot", "--html"),
                   ("sessions list", "--csv"), ("sessions trend", "--csv"),
                   ("sessions trend", "--plot"), ("", "--trace-io")}


def _tree_digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and p.name != "owner.lock"}


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Bench:
    return Bench(tmp_path_factory.mktemp("policy"))


def _force(argv: list[str], key: tuple[str, str]) -> list[str]:
    return ["--force", *argv] if key == ("", "--trace-io") else [*argv, "--force"]


@pytest.mark.parametrize("key", sorted(COMMANDS), ids=" ".join)
def test_no_output_option_replaces_a_file_or_writes_into_a_session(
    bench: Bench, key: tuple[str, str], capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(bench.mine.parent)
    argv = COMMANDS[key]
    before = _tree_digest(bench.session)
    mine = bench.mine.read_bytes()
    capsys.readouterr()
    for target in [bench.mine, *bench.session_files()]:
        assert main(argv(bench, target)) == 2, target
        err = capsys.readouterr().err
        assert f"{target}: " in err and "nothing written" in err, err
        if target != bench.mine:  # a session's own files: --force does not apply
            assert main(_force(argv(bench, target), key)) == 2, target
            assert "is part of" in capsys.readouterr().err
    assert bench.mine.read_bytes() == mine
    assert _tree_digest(bench.session) == before
    if key in FORCE_COMPLETES:
        mine_copy = bench.mine.with_name(f"forced-{abs(hash(key))}.out")
        mine_copy.write_bytes(mine)
        assert main(_force(argv(bench, mine_copy), key)) == 0, capsys.readouterr().err
        assert mine_copy.read_bytes() != mine
        assert not list(mine_copy.parent.glob(f".{mine_copy.name}.*.tmp"))  # renamed in place
    assert _tree_digest(bench.session) == before


def test_a_link_into_a_session_is_refused(bench: Bench, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    link = tmp_path / "innocent.html"
    link.symlink_to(bench.session / "session.json")
    before = (bench.session / "session.json").read_bytes()
    assert main(["report", str(bench.session), "--out", str(link), "--force"]) == 2
    assert f"session {bench.session}" in capsys.readouterr().err
    assert (bench.session / "session.json").read_bytes() == before


@pytest.mark.slow
def test_default_outputs_are_not_replaced_either(bench: Bench, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """``sessions trend`` writes trend.png in the current folder by default: an existing one
    is kept, and the folder it wrote to is said."""
    monkeypatch.chdir(tmp_path)
    trend = ["sessions", "trend", "--root", str(bench.root), "--view", "forward", "--element",
             "G1E5", "--orientation", "S"]
    (tmp_path / "trend.png").write_bytes(b"last week's plot")
    assert main(trend) == 2
    assert "--plot trend.png: already exists" in capsys.readouterr().err
    assert (tmp_path / "trend.png").read_bytes() == b"last week's plot"
    assert main([*trend, "--force"]) == 0
    assert f"plot: {tmp_path / 'trend.png'}" in capsys.readouterr().err
    assert (tmp_path / "trend.png").read_bytes().startswith(b"\x89PNG")
    report = bench.session / "report.html"  # report's default, beside the session's files
    assert main(["report", str(bench.session)]) == 0
    first = report.read_bytes()
    assert main(["report", str(bench.session)]) == 2
    assert f"report {report}: already exists" in capsys.readouterr().err
    assert report.read_bytes() == first
    assert main(["report", str(bench.session), "--force"]) == 0
    report.unlink()


def test_which_paths_belong_to_a_session(bench: Bench, tmp_path: Path) -> None:
    s = bench.session
    assert session_part(s / "frames" / "new.tiff") == f"frames/ of session {s}"
    assert session_part(s / "results" / "v9" / "x.json") == f"results/ of session {s}"
    assert session_part(s / "events.jsonl") == f"the events.jsonl of session {s}"
    assert session_part(bench.root / "catalog.sqlite-wal") == \
        f"the sessions catalogue of {bench.root}"
    # the session folder's other files are the user's to name (reports, certificates)
    assert session_part(s / "report.html") is None
    assert session_part(s / "notes" / "session.json") is None  # not the session's own file
    assert session_part(tmp_path / "session.json") is None


def test_snap_never_adds_a_frame_to_a_session(bench: Bench,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """``snap OUT`` (a positional: a new frame, never replaced) refuses a session's frames/,
    where a frame nobody journalled would pass for an acquired one."""
    before = _tree_digest(bench.session)
    target = bench.session / "frames" / "extra__forward.tiff"
    assert main(["snap", "--simulate", "--exposure-ms", "10", "--gain", "1", str(target)]) == 2
    assert f"snap {target}: is part of frames/ of session" in capsys.readouterr().err
    assert not target.exists() and _tree_digest(bench.session) == before
