"""The command line end to end: run, kill -9 mid-run, resume, analyze SESSION, report."""

from __future__ import annotations

import json
import signal
import sys
from collections import Counter
from pathlib import Path

import pytest
from sim_runs import MTF_SMALL, RAD_SMALL, events, only_session, signal_mid_run

from benchlab.cli.main import main
from benchlab.scenes.world import SimWorld
from benchlab.session import Session


@pytest.mark.slow
def test_kill_9_mid_run_then_resume(tmp_path: Path) -> None:
    status, _, _ = signal_mid_run(["run", "mtf", "--simulate", "--yes"], tmp_path,
                                  after_steps=10, sig=signal.SIGKILL)
    assert status == -signal.SIGKILL
    path = only_session(tmp_path)
    session = Session.open(path)
    # session.json still says "running", but its writer is dead: the truth is "interrupted"
    assert json.loads((path / "session.json").read_text())["status"] == "running"
    assert session.latest_results() is None and session.status == "interrupted"
    before = session.frames()
    assert before and session.verify_frames() == []

    assert main(["resume", str(path), "--simulate", "--yes"]) == 0
    session = Session.open(path)
    assert session.status == "completed"
    evs = events(path)
    done = Counter(e["step_id"] for e in evs if e["kind"] == "step_completed")
    assert len(done) == 34 and max(done.values()) == 1
    saved = Counter(e["file"] for e in evs if e["kind"] == "frame_saved")
    assert len(saved) == 15 and max(saved.values()) == 1
    assert {k: v for k, v in session.frames().items() if k in before} == before
    rows = json.loads((path / "results" / "v1" / "radial_view_modulation.json").read_text())
    world = SimWorld()
    for row in rows[:3]:  # the well-sampled frequencies, as in the uninterrupted run
        f = row["object_lp_per_mm"]
        for o in ("sagittal", "tangential"):
            truth = world.radial_scene(f, o).truth_modulation()
            assert row[f"{o}_modulation"] == pytest.approx(truth, abs=0.05)


@pytest.mark.slow
def test_run_analyze_report_commands(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "200")  # a wide terminal: each table row on one line
    assert main(["run", "mtf", "--simulate", "--yes", "--out", str(tmp_path),
                 "--params", str(MTF_SMALL), "--operator", "ana"]) == 0
    out = capsys.readouterr()
    assert "Table 4.11" in out.out and "Table 4.12" in out.out and "wall time" in out.out
    # The slanted edges and their cross-check with the bars are printed, not only saved.
    edges = out.out.split("Slanted edges (ISO 12233 e-SFR)")[1].split("\n\n")[0]
    assert len(edges.splitlines()) == 1 + 1 + 12 and edges.count(" ok") == 12
    checks = out.out.split("Bars vs slanted edge (the set's predicted reading")[1].split(
        "\n\n")[0]
    rows = checks.splitlines()[2:]
    assert len(rows) == 4  # G1E5, G2E1 x S, T
    for row in rows:  # the printed verdict follows the printed numbers (histogram bars here:
        # no chart reading, so no predicted reading and the Coltman comparison decides)
        cells = row.split()
        assert cells[4] == "N/A", row
        off = abs(float(cells[5]) - float(cells[6]))
        assert (cells[9] == "agree") == (off <= 0.05 + 5e-4), row
        assert cells[10] == "(Coltman)" if cells[9] == "agree" else "(Coltman)" in row, row
    assert "[--yes]" in out.err  # the manual prompts were shown and answered
    path = only_session(tmp_path)
    assert Session.open(path).meta["operator"] == "ana"
    assert main(["analyze", str(path), "--estimator", "sinefit"]) == 0
    again = capsys.readouterr().out
    assert "frames verified unchanged" in again and "Slanted edges (ISO 12233 e-SFR)" in again
    assert main(["report", str(path), "--out", str(tmp_path / "r.html")]) == 0
    text = (tmp_path / "r.html").read_text()
    assert "Table 4.11" in text and "data:image/png;base64," in text


@pytest.mark.slow
def test_radiometry_command_and_resume_of_a_finished_session(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "radiometry", "--simulate", "--yes", "--out", str(tmp_path),
                 "--params", str(RAD_SMALL)]) == 0
    assert "Table 4.16" in capsys.readouterr().out
    path = only_session(tmp_path)
    assert main(["resume", str(path), "--simulate", "--yes"]) == 0  # nothing left to do
    assert [p.name for p in (path / "results").iterdir()] == ["v1"]


def test_manual_prompt_without_terminal_or_yes_is_a_clean_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys.stdin, "isatty", lambda: False, raising=False)
    assert main(["run", "mtf", "--simulate", "--out", str(tmp_path),
                 "--params", str(MTF_SMALL)]) == 1
    err = capsys.readouterr().err
    assert "pass --yes" in err and "benchlab resume" in err


def test_unknown_estimator_is_a_clean_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "radiometry", "--simulate", "--yes", "--out", str(tmp_path),
                 "--params", str(RAD_SMALL), "--estimator", "guesswork"]) == 2  # usage
    assert "unknown estimator 'guesswork'" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
def test_real_ctrl_c_mid_radiometry_then_resume(tmp_path: Path) -> None:
    status, _, err = signal_mid_run(["run", "radiometry", "--simulate", "--yes"], tmp_path,
                                    after_steps=2, sig=signal.SIGINT)
    assert status == 130
    assert "benchlab resume" in err
    path = only_session(tmp_path)
    assert Session.open(path).status == "interrupted"
    assert main(["resume", str(path), "--simulate", "--yes"]) == 0
    session = Session.open(path)
    assert session.status == "completed" and session.verify_frames() == []
    saved = Counter(e["file"] for e in events(path) if e["kind"] == "frame_saved")
    assert len(saved) == 10 and max(saved.values()) == 1
