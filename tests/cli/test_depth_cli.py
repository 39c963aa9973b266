"""benchlab run depth from the command line: kill -9 mid-sweep then resume; bad parameters
refused before any session or device; benchmark depth registered."""

from __future__ import annotations

import signal
from collections import Counter
from pathlib import Path

import pytest
from sim_runs import FIXTURES, events, only_session, signal_mid_run

from benchlab.cli.main import build_parser, main
from benchlab.session import Session

SMALL = FIXTURES / "depth-small.toml"
RUN = ["run", "depth", "--simulate", "--yes", "--params", str(SMALL)]


@pytest.mark.slow
def test_kill_9_mid_sweep_then_resume_repeats_no_position(tmp_path: Path) -> None:
    status, _, _ = signal_mid_run(RUN, tmp_path, after_steps=6,  # setup, mount-0, 4 positions
                                  sig=signal.SIGKILL)
    assert status == -signal.SIGKILL
    path = only_session(tmp_path)
    assert Session.open(path).status == "interrupted"
    before = Session.open(path).frames()
    assert main(["resume", str(path), "--simulate", "--yes"]) == 0
    evs = events(path)
    done = Counter(e["step_id"] for e in evs if e["kind"] == "step_completed")
    assert len(done) == 1 + 2 + 11 + 1 and max(done.values()) == 1
    saved = Counter(e["file"] for e in evs if e["kind"] == "frame_saved")
    assert len(saved) == 11 and max(saved.values()) == 1
    assert {k: v for k, v in Session.open(path).frames().items() if k in before} == before
    assert (path / "results" / "v1" / "depth_of_field.json").is_file()


def test_bad_parameters_are_refused_before_any_session(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('procedure = "depth"\n[sweep]\nstep_mm = 0\nstage_start_mm = 80\n')
    out = tmp_path / "sessions"
    assert main(["run", "depth", "--simulate", "--yes", "--params", str(bad), "--out",
                 str(out)]) != 0
    err = capsys.readouterr().err
    assert "sweep.step_mm" in err and "sweep.stage_start_mm: 80 mm is outside the stage travel" \
        in err
    assert not out.exists() or not any(out.iterdir())


def test_benchmark_depth_is_a_command() -> None:
    args = build_parser().parse_args(["benchmark", "depth", "--seeds", "2",
                                      "--variants", "nominal"])
    assert args.seeds == 2 and args.variants == "nominal"


@pytest.mark.slow
def test_ctrl_c_mid_sweep_leaves_the_bench_safe_and_resumable(tmp_path: Path) -> None:
    status, out, err = signal_mid_run(RUN, tmp_path, after_steps=4, sig=signal.SIGINT)
    assert status == 130
    assert "bench left safe" in out + err and "benchlab resume" in out + err
    path = only_session(tmp_path)
    assert Session.open(path).status == "interrupted"
    assert main(["resume", str(path), "--simulate", "--yes"]) == 0
    saved = Counter(e["file"] for e in events(path) if e["kind"] == "frame_saved")
    assert len(saved) == 11 and max(saved.values()) == 1
