"""``benchlab analyze SESSION... / --all ROOT``: batch re-analysis on a pool or a dask cluster."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from many_sessions_helpers import copy_session, real_session, results_files

from benchlab.cli.main import main
from benchlab.cli.runs import batch as cli_batch
from benchlab.protocols import batch
from benchlab.protocols.batch import BatchError, run_batch
from benchlab.protocols.runs import reanalyze
from benchlab.storage import sha256_file


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return real_session(tmp_path_factory.mktemp("source"))


def _frame_hashes(session: Path) -> dict[str, str]:
    return {p.name: sha256_file(p) for p in sorted((session / "frames").iterdir())}


@pytest.mark.slow
def test_batch_equals_single_session_analysis(source: Path, tmp_path: Path) -> None:
    batch = [copy_session(source, tmp_path / "batch" / f"s{i}") for i in range(2)]
    single = copy_session(source, tmp_path / "single" / "s")
    before = _frame_hashes(single)
    out = reanalyze(single, estimator="sinefit")
    report = run_batch(batch, estimator="sinefit", jobs=2)
    assert [i.outcome for i in report.items] == ["analysed"] * 2
    expected = results_files(out)
    assert set(expected) >= {"summary.json", "forward_view_modulation.csv",
                             "forward_view_modulation.json"}
    for session, item in zip(batch, report.items, strict=True):
        assert Path(item.results) == session / "results" / "v2"
        assert results_files(session / "results" / "v2") == expected  # same files, same numbers
        assert _frame_hashes(session) == before  # frames never touched
        assert sorted(p.name for p in (session / "results").iterdir()) == ["v1", "v2"]
    assert report.jobs == 2 and "2 local processes" in report.executor


def test_a_failing_session_mid_batch_does_not_stop_the_others(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "root"
    good = [copy_session(source, root / f"a{i}") for i in range(2)]
    bad = copy_session(source, root / "b-tampered")
    frame = sorted((bad / "frames").iterdir())[0]
    data = frame.read_bytes()
    frame.unlink()  # break the hard link: only this copy changes
    frame.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))
    running = copy_session(source, root / "c-incomplete")  # interrupted before its last frame
    meta = json.loads((running / "session.json").read_text())
    (running / "session.json").write_text(json.dumps({**meta, "status": "interrupted"}))
    lines = (running / "events.jsonl").read_text().splitlines(keepends=True)
    last = max(i for i, line in enumerate(lines) if '"step_id": "radial-' in line
               and '"step_completed"' in line)
    (running / "events.jsonl").write_text("".join(lines[:last] + lines[last + 1:]))
    later = [copy_session(source, root / f"d{i}") for i in range(2)]
    (root / "not-a-session").mkdir()

    code = main(["analyze", "--all", str(root), "--jobs", "2"])
    out = capsys.readouterr().out
    assert code == 1
    assert "6 sessions: 4 analysed, 1 skipped, 1 failed" in out  # the plain folder: none
    lines = {line.split()[0]: line for line in out.splitlines()[1:] if line.strip()}
    assert "failed" in lines["b-tampered"] and "frames changed" in lines["b-tampered"]
    assert "skipped" in lines["c-incomplete"] and "acquisition incomplete" in lines["c-incomplete"]
    for s in good + later:  # the run's own results again: matched v1, no new version
        assert "analysed  v1" in lines[s.name] and not (s / "results" / "v2").exists()
    assert not (bad / "results" / "v2").exists() and not (running / "results" / "v2").exists()


def test_named_sessions_json_and_a_non_session(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    a = copy_session(source, tmp_path / "a")
    plain = tmp_path / "plain"
    plain.mkdir()
    assert main(["analyze", str(a), str(plain), str(a), "--json", "--jobs", "1"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["sessions"]) == 2  # a session named twice is analysed once
    assert (doc["analysed"], doc["skipped"], doc["failed"]) == (1, 1, 0)
    outcomes = {Path(s["session"]).name: s for s in doc["sessions"]}
    assert outcomes["plain"]["reason"].startswith("not a session folder")
    assert outcomes["a"]["worker_peak_kib"] > 0 and outcomes["a"]["cpu_seconds"] > 0

    monkeypatch.setattr(cli_batch, "MAX_LISTED_ANALYSED", 1)  # a big batch: skips listed only
    assert main(["analyze", str(a), str(plain), "--jobs", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[:2] for line in lines[1:] if line.strip()][0] == ["plain", "skipped"]
    assert not any(line.startswith("a ") for line in lines)
    assert "2 sessions: 1 analysed, 1 skipped, 0 failed" in lines[-1]


def test_bad_batch_inputs_are_clean_errors(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    a = copy_session(source, tmp_path / "a")
    assert main(["analyze"]) == 2  # usage: nothing to analyse
    assert "needs an image, a session folder, or --all ROOT" in capsys.readouterr().err
    with pytest.raises(SystemExit) as usage:  # a usage error, exit 2, before any work
        main(["analyze", str(a), str(a), "--jobs", "0"])
    assert usage.value.code == 2
    assert "argument --jobs: must be >= 1, got 0" in capsys.readouterr().err
    assert main(["analyze", "--all", str(tmp_path / "nowhere")]) == 1
    assert "no such folder of sessions" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["analyze", "--all", str(empty)]) == 1
    assert "no sessions to analyse" in capsys.readouterr().err
    assert main(["analyze", str(a), str(a), "--roi", "1,2,3,4"]) == 2  # usage
    assert "only --estimator applies" in capsys.readouterr().err
    assert main(["analyze", str(a), str(a), "--estimator", "nope"]) == 2  # a usage error
    assert "unknown estimator" in capsys.readouterr().err
    assert sorted(p.name for p in (a / "results").iterdir()) == ["v1"]  # nothing written
    monkeypatch.setattr(batch, "SCHEDULER_TIMEOUT_S", 0.5)
    with pytest.raises(BatchError, match="cannot connect"):
        run_batch([a], scheduler="tcp://127.0.0.1:1")  # nothing listens there


def test_dask_scheduler_runs_the_same_analysis(source: Path, tmp_path: Path) -> None:
    import distributed  # the dask extra, installed with the test extra

    sessions = [copy_session(source, tmp_path / f"s{i}") for i in range(2)]
    single = copy_session(source, tmp_path / "single")
    expected = results_files(reanalyze(single))
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  protocol="tcp", host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        report = run_batch(sessions, scheduler=cluster.scheduler_address)
    assert report.executor.startswith("dask scheduler tcp://127.0.0.1")
    assert [i.outcome for i in report.items] == ["analysed", "analysed"]
    for s, item in zip(sessions, report.items, strict=True):
        assert Path(item.results).parent == s / "results"
        assert results_files(Path(item.results)) == expected


@pytest.mark.slow
def test_benchmark_batch_prints_its_figures_and_the_flush_policies(
        source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["benchmark", "batch", "--sessions", "2", "--jobs", "1", "--source",
                 str(source), "--workdir", str(tmp_path), "--fsync-repeats", "1"]) == 0
    out = capsys.readouterr().out
    assert "2 (2 analysed, 0 failed)" in out and "extrapolated to 10,000" in out
    rows = {line.split("  ")[0]: line for line in out.splitlines() if line.startswith("flush")}
    assert set(rows) == {"flush per-file", "flush per-version", "flush syncfs (default)"}
    calls = {k: int(v.split("  ", 1)[1].split()[0]) for k, v in rows.items()}
    # one file-system flush per version instead of one fsync per file (and folder)
    assert calls["flush syncfs (default)"] < calls["flush per-version"] < calls["flush per-file"]
    assert list(tmp_path.iterdir()) == []  # the fabricated sessions are removed


def test_benchmark_batch_fsync_repeats_zero_skips_the_comparison() -> None:
    """``--fsync-repeats 0`` is what the help offers to skip the flush comparison."""
    from benchlab.cli.main import build_parser

    args = build_parser().parse_args(["benchmark", "batch", "--fsync-repeats", "0"])
    assert args.fsync_repeats == 0
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["benchmark", "batch", "--fsync-repeats", "-1"])
    assert exc.value.code == 2
