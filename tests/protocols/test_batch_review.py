"""Batch re-analysis and the catalogue commands: one session named twice (by different
spellings) is analysed once; options that cannot be meant are usage errors (exit 2) before
any work; the footer says only what is true."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from many_sessions_helpers import copy_session, real_session

from benchlab.catalog.index import CATALOG_FILE
from benchlab.cli.main import main
from benchlab.protocols.batch import run_batch


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return real_session(tmp_path_factory.mktemp("source"))


def _versions(session: Path) -> list[str]:
    return sorted(p.name for p in (session / "results").iterdir())


def _analyses(session: Path) -> int:
    """Re-analyses the session's journal records (each starts with this event)."""
    lines = (session / "events.jsonl").read_text().splitlines()
    return sum(json.loads(line).get("kind") == "reanalysis_started" for line in lines if line)


@pytest.mark.slow
def test_one_session_named_by_several_spellings_is_analysed_once(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "root"
    s = copy_session(source, root / "s")
    os.symlink(s, tmp_path / "link")
    report = run_batch([root / "s", root / "." / "s", tmp_path / "link",
                        root / "s" / ".." / "s"], jobs=2)
    assert [(i.session, i.outcome) for i in report.items] == [(str(root / "s"), "analysed")]
    assert _analyses(s) == 1  # (its results repeat the run's: matched v1, no version added)
    assert _versions(s) == ["v1"]
    # The reviewer's command: --all ROOT and ROOT/that_session, two workers.
    code = main(["analyze", "--all", str(root), str(root / "s"), "--jobs", "2", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and (out["analysed"], out["failed"]) == (1, 0)
    assert _analyses(s) == 2


def test_image_options_for_sessions_are_usage_errors_before_any_work(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "root"
    a, b = copy_session(source, root / "a"), copy_session(source, root / "b")
    for argv, named in (
        (["analyze", "--all", str(root), "--roi", "1,2,3,4"], "--roi"),
        (["analyze", "--all", str(root), "--chart", "usaf"], "--chart"),
        (["analyze", str(a), str(b), "--linearise", "cal.json"], "--linearise"),
        (["analyze", str(a), "--chart", "usaf"], "--chart"),  # one session
        (["analyze", str(a), "--linearise", "cal.json"], "--linearise"),
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("benchlab: error: ") and named in err and "one image" in err
    assert _versions(a) == _versions(b) == ["v1"]  # nothing analysed


def test_catalogue_options_that_cannot_be_meant_exit_2_before_any_work(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "root"
    copy_session(source, root / "s0")
    assert not (root / CATALOG_FILE).exists()
    trend = ["sessions", "trend", "--root", str(root), "--view", "radial"]
    for argv, message in (
        (["sessions", "list", "--root", str(root), "--sort", "bogus"], "--sort 'bogus'"),
        (["sessions", "list", "--root", str(root), "--since", "yesterday"],
         "--since 'yesterday'"),
        ([*trend, "--freq", "-3"], "--freq must be a number > 0"),
        ([*trend, "--freq", "nan"], "--freq must be a number > 0"),
        ([*trend, "--freq", "70", "--orientation", "Q"], "--orientation 'Q'"),
        (trend, "trend needs --element or --freq"),
        ([*trend, "--element", "2lp", "--since", "soon"], "--since 'soon'"),
    ):
        assert main(argv) == 2, argv
        assert message in capsys.readouterr().err
        assert not (root / CATALOG_FILE).exists()  # checked before the catalogue is opened
    assert main(["sessions", "list", "--root", str(root), "--sort", "sample"]) == 0
    assert (root / CATALOG_FILE).exists()


def _tamper(session: Path) -> None:
    frame = sorted((session / "frames").iterdir())[0]
    data = frame.read_bytes()
    frame.unlink()  # break the hard link: only this copy changes
    frame.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))


def test_footer_claims_verified_frames_only_for_the_sessions_analysed(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good, bad = copy_session(source, tmp_path / "good"), copy_session(source, tmp_path / "bad")
    _tamper(bad)
    assert main(["analyze", str(good), str(bad), "--jobs", "2"]) == 1
    footer = capsys.readouterr().out.strip().splitlines()[-1]
    assert footer.startswith("2 sessions: 1 analysed, 0 skipped, 1 failed")
    assert footer.endswith("(frames of the session analysed verified unchanged)")
    bad2 = copy_session(source, tmp_path / "bad2")
    _tamper(bad2)
    assert main(["analyze", str(bad), str(bad2), "--jobs", "2"]) == 1
    footer = capsys.readouterr().out.strip().splitlines()[-1]
    assert footer.startswith("2 sessions: 0 analysed, 0 skipped, 2 failed")
    assert "verified" not in footer  # their frames changed: nothing verified unchanged


@pytest.mark.slow
def test_partial_results_are_marked_on_every_table_and_verdict(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import re

    from benchlab.report.render import render_report

    s = copy_session(source, tmp_path / "s")
    meta = json.loads((s / "session.json").read_text())
    (s / "session.json").write_text(json.dumps({**meta, "status": "interrupted"}))
    lines = (s / "events.jsonl").read_text().splitlines(keepends=True)
    last = max(i for i, line in enumerate(lines) if '"step_id": "radial-' in line
               and '"step_completed"' in line)
    (s / "events.jsonl").write_text("".join(lines[:last] + lines[last + 1:]))
    assert main(["analyze", str(s)]) == 0
    capsys.readouterr()
    text = render_report(s)
    titles = re.findall(r"<h3>(Table[^<]*)</h3>", text)
    assert titles and all(t.endswith(" [PARTIAL]") for t in titles)
    verdicts = re.findall(r"<li class='verdict'>(.*?)</li>", text)
    assert verdicts and all(v.endswith("[PARTIAL]") for v in verdicts)
    finished = render_report(source)
    assert "[PARTIAL]" not in finished and "PARTIAL" not in finished
