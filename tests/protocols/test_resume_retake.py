"""``benchlab resume SESSION --retake STEP[,STEP...]``: a step of an existing session taken
again. The old frames are kept (bytes unchanged) beside the new ``.take<N>`` ones; one journal
line makes the new take current; a stopped retake leaves the previous take current and says
so; a completed session stays completed; the bench is left safe on every exit path."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from sim_runs import MTF_SMALL, RAD_SMALL, events, run_sim, tables_of, yes

from benchlab.bench import Bench, BenchConfig
from benchlab.protocols import RunAborted, resume_run, start_run
from benchlab.protocols.radiometry import reading_mask_of
from benchlab.protocols.runs import RetakeUsageError
from benchlab.scenes.led import LedScene
from benchlab.session import Session


def _cli(*args: str, **kw: Any) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "benchlab.cli.main", *args], text=True,
                          capture_output=True, timeout=120, **kw)


def _bumped_session(root: Path) -> Path:
    """A completed radiometry session whose 18 mm frames were taken with the fibre bumped
    (half the light reached the LED)."""
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        real_on = bench.led_on

        def progress(done: int, total: int, step: Any) -> None:
            bumped = step is not None and step.id == "position-18"
            bench.led_on = ((lambda ch, ma: real_on(ch, ma / 2)) if bumped  # type: ignore
                            else real_on)

        runner = start_run("radiometry", bench=bench, params=RAD_SMALL, root=root,
                           prompt=yes, progress=progress)
        runner.run()
    return runner.session.path


def _snapshot(path: Path) -> dict[str, str]:
    """sha256 of every file of the session folder (what "nothing changed" means)."""
    return {p.relative_to(path).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(path.rglob("*")) if p.is_file() and p.name != "owner.lock"}


def _row18(results: Path) -> dict[str, Any]:
    rows = json.loads((results / "relative_radiometry.json").read_text())
    return next(r for r in rows if r["position_mm"] == 18.0)


def _truth18(session: Session) -> float:
    mask, _ = session.load_frame("position-18", "mask")
    meas, _ = session.load_frame("position-18", "measurement")
    return LedScene().expected_mean_dn8(reading_mask_of(mask, meas, 0.5), 18.0, 20.0, 375.0)


@pytest.fixture(scope="module")
def retaken(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str],
                                                                 subprocess.CompletedProcess[str]]:
    path = _bumped_session(tmp_path_factory.mktemp("retake"))
    before = _snapshot(path)
    done = _cli("resume", str(path), "--simulate", "--yes", "--retake", "position-18",
                "--reason", "fibre bumped")
    return path, before, done


@pytest.mark.slow
def test_retake_of_a_completed_session_in_a_real_process(
        retaken: tuple[Path, dict[str, str], subprocess.CompletedProcess[str]]) -> None:
    path, before, done = retaken
    assert done.returncode == 0, done.stderr
    assert "retake r1 adopted: position-18 take 2 current" in done.stdout
    session = Session.open(path)
    assert session.status == "completed" and session.results_stale() is None
    # the old frames: same bytes, same names; the new ones beside them
    after = _snapshot(path)
    assert {f: h for f, h in after.items() if f.startswith("frames/")} == {
        **{f: h for f, h in before.items() if f.startswith("frames/")},
        **{f: after[f] for f in ("frames/position-18__mask.take2.tiff",
                                 "frames/position-18__measurement.take2.tiff")}}
    assert {f: h for f, h in after.items() if f.startswith("results/v1/")} == {
        f: h for f, h in before.items() if f.startswith("results/v1/")}
    assert session.step_frames("position-18") == {
        "mask": path / "frames/position-18__mask.take2.tiff",
        "measurement": path / "frames/position-18__measurement.take2.tiff"}
    assert session.current_take("position-18") == 2 and session.current_take("position-15") == 1
    assert session.verify_frames() == []  # the superseded take is still hash-checked
    assert session.rejected_frames() == {
        "frames/position-18__mask.tiff": "superseded by retake r1: fibre bumped",
        "frames/position-18__measurement.tiff": "superseded by retake r1: fibre bumped"}


@pytest.mark.slow
def test_the_new_take_is_analysed_and_recorded(
        retaken: tuple[Path, dict[str, str], subprocess.CompletedProcess[str]]) -> None:
    path, _, _ = retaken
    session = Session.open(path)
    old, new = _row18(path / "results" / "v1"), _row18(path / "results" / "v2")
    truth = _truth18(session)  # of the current (new) frames
    assert new["measured_mean_gray"] == pytest.approx(truth, abs=1.0)
    assert old["measured_mean_gray"] < 0.7 * truth  # the bumped take read half the light
    meta = session.meta
    assert meta["takes"]["position-18"] == {
        "take": 2, "retake": "r1", "reason": "fibre bumped",
        "frames": ["frames/position-18__mask.take2.tiff",
                   "frames/position-18__measurement.take2.tiff"]}
    assert meta["retake"]["status"] == "adopted"
    assert meta["retake"]["previous_status"] == "completed"
    (adopt,) = [e for e in events(path) if e["kind"] == "retake_adopted"]
    assert adopt["files"] == ["frames/position-18__mask.tiff",
                              "frames/position-18__measurement.tiff"]
    assert adopt["takes"] == {"position-18": 2} and "fibre bumped" in adopt["reason"]
    kinds = [e["kind"] for e in events(path)]
    assert kinds.index("retake_started") < kinds.index("retake_adopted") \
        < len(kinds) - 1 - kinds[::-1].index("results_written")
    (r,) = session.retakes()
    assert (r["id"], r["steps"], r["status"], r["current"]) == (
        "r1", ["position-18"], "adopted", {"position-18": 2})


@pytest.mark.slow
def test_unknown_or_untaken_step_is_a_usage_error_and_changes_nothing(tmp_path: Path) -> None:
    path = run_sim("radiometry", tmp_path, RAD_SMALL).session_path
    before = _snapshot(path)
    bad = _cli("resume", str(path), "--simulate", "--yes", "--retake", "position-18,postion-25")
    assert bad.returncode == 2
    assert bad.stderr.startswith("benchlab: error: --retake: unknown step 'postion-25'")
    assert "valid steps of " in bad.stderr
    assert "position-15, position-18, position-25" in bad.stderr
    assert "Traceback" not in bad.stderr
    for args in (["--retake", "analysis"], ["--retake", ""], ["--reason", "x"]):
        other = _cli("resume", str(path), "--simulate", "--yes", *args)
        assert other.returncode == 2 and other.stderr.startswith("benchlab: error:"), args
    assert _snapshot(path) == before
    helped = _cli("resume", "--help")
    assert "--retake STEP[,STEP...]" in helped.stdout and "--reason TEXT" in helped.stdout
    # a step the (unfinished) session has not taken yet: plain resume takes it
    session = Session.open(path)
    with pytest.raises(RetakeUsageError, match="not an acquisition step"):
        resume_run(path, bench=None, retake=["setup"])  # type: ignore[arg-type]
    journal = path / "events.jsonl"
    journal.write_text("".join(line + "\n" for line in journal.read_text().splitlines()
                               if '"step_id": "position-25"' not in line))
    with pytest.raises(RetakeUsageError, match="position-25 has not been taken yet"):
        resume_run(path, bench=None, retake=["position-25"])  # type: ignore[arg-type]
    assert session.status == "completed"


def _wait_for(path: Path, kind: str, proc: subprocess.Popen[str], timeout_s: float = 60) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if any(e["kind"] == kind and e.get("retake") for e in events(path)):
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.005)
    raise AssertionError(f"no {kind} of a retake in {timeout_s} s")


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_stopped_retake_leaves_the_previous_take_current(tmp_path: Path, sig: int) -> None:
    """Stopped (SIGTERM: the shutdown path; SIGKILL: nothing runs) after the retake's first
    frame: the previous takes stay current, the session stays completed, results unchanged;
    a second retake then makes its own take current."""
    path = _bumped_session(tmp_path)
    before = _snapshot(path)
    proc = subprocess.Popen([sys.executable, "-m", "benchlab.cli.main", "resume", str(path),
                             "--simulate", "--yes", "--retake", "position-18,position-25"],
                            text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _wait_for(path, "frame_saved", proc)  # the retake's first frame is on disk
    os.kill(proc.pid, sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode != 0
    session = Session.open(path)
    assert session.status == "completed"
    assert session.step_frames("position-18") == {
        "mask": path / "frames/position-18__mask.tiff",
        "measurement": path / "frames/position-18__measurement.tiff"}
    assert (path / "frames/position-18__mask.take2.tiff").is_file()  # kept, not current
    (r,) = session.retakes()
    assert r["status"] == "interrupted"
    assert session.latest_results() == path / "results" / "v1"
    assert session.results_stale() is None
    assert {f: h for f, h in _snapshot(path).items() if f in before and f != "session.json"
            and f != "events.jsonl"} == {f: h for f, h in before.items()
                                         if f not in ("session.json", "events.jsonl")}
    if sig == signal.SIGTERM:
        assert "retake r1 stopped: the previous takes of position-18, position-25 stay " \
               "current" in err
        assert session.meta["retake"]["status"] == "interrupted"
        assert any(e["kind"] == "retake_stopped" for e in events(path))
    again = _cli("resume", str(path), "--simulate", "--yes")  # nothing to resume: complete
    assert again.returncode == 0 and "nothing to resume" in again.stdout
    retake = _cli("resume", str(path), "--simulate", "--yes", "--retake", "position-18")
    assert retake.returncode == 0, retake.stderr
    session = Session.open(path)
    current = session.step_frames("position-18")["mask"].name
    assert current in ("position-18__mask.take2.tiff", "position-18__mask.take3.tiff")
    assert current != "position-18__mask.tiff" and session.verify_frames() == []
    assert [r["status"] for r in session.retakes()] == ["interrupted", "adopted"]
    assert _row18(session.latest_results()  # type: ignore[arg-type]
                  )["measured_mean_gray"] == pytest.approx(_truth18(session), abs=1.0)


@pytest.mark.slow
def test_abort_mid_retake_leaves_the_bench_safe_and_the_old_take(tmp_path: Path) -> None:
    path = _bumped_session(tmp_path)
    abort = threading.Event()
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True,
                    time_scale=5.0) as bench:
        def progress(done: int, total: int, step: Any) -> None:
            if step is not None and step.id == "position-25":
                threading.Timer(0.3, abort.set).start()  # the abort key, mid-move

        runner = resume_run(path, bench=bench, prompt=yes, progress=progress, abort=abort,
                            retake=["position-18", "position-25"], retake_reason="test")
        with pytest.raises(RunAborted):
            runner.run()
        assert all(bench.sim_led.channel_output_ma(ch) == 0.0 for ch in range(1, 5))
        assert not bench.sim_stage.moving
    session = Session.open(path)
    assert session.status == "completed"
    assert session.meta["retake"]["status"] == "aborted"
    assert session.step_frames("position-18")["mask"].name == "position-18__mask.tiff"
    assert session.latest_results() == path / "results" / "v1"


@pytest.mark.slow
def test_mtf_retake_sets_the_bench_up_again_and_reproduces_the_results(
        tmp_path: Path) -> None:
    """Noise-free: retaking the forward frame and one radial roll (their set-ups replayed,
    the operator asked to set each up again) gives the same tables as the first take."""
    first = run_sim("mtf", tmp_path, MTF_SMALL, noise=False)
    asked: list[str] = []

    def prompt(step: Any, message: str) -> bool:
        asked.append(message)
        return True

    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True, noise=False) as bench:
        out = resume_run(first.session_path, bench=bench, prompt=prompt,
                         retake=["radial-2-sagittal", "forward"]).run()
    assert tables_of(out.results_path) == tables_of(first.results_path)
    assert out.results_path.name == "v2"
    assert any(m.startswith("Before radial-2-sagittal: set up as at 'Roll the 2 lp/mm")
               for m in asked), asked
    assert asked[0].startswith("Retake of forward: set up as at 'Thread the prototype")
    session = Session.open(first.session_path)
    assert session.current_take("forward") == session.current_take("radial-2-sagittal") == 2
    assert session.current_take("radial-0.5-sagittal") == 1 and session.status == "completed"
    # unwrap reads each radial step's current take once (never the superseded one)
    from benchlab.radial_views import load_view_tiff, unwrap_session

    rows = tables_of(unwrap_session(first.session_path, px_per_mm=6.0))["unwrap"]
    assert sorted(r["step_id"] for r in rows) == [
        "radial-0.5-sagittal", "radial-0.5-tangential", "radial-2-sagittal",
        "radial-2-tangential"]
    (retaken,) = [r for r in rows if r["step_id"] == "radial-2-sagittal"]
    _, _, meta = load_view_tiff(session.latest_results() / retaken["file"])  # type: ignore
    assert meta["source"] == "frames/radial-2-sagittal__radial.take2.tiff"


@pytest.mark.slow
def test_results_are_stale_until_reanalysed(tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """The retake was adopted but its analysis failed: the session is still completed (its
    frames are whole), its results say they are stale - in the report too - until
    ``benchlab analyze`` writes a version from the current takes."""
    from benchlab.protocols import StepFailed, reanalyze
    from benchlab.protocols.radiometry import RadiometryProcedure
    from benchlab.report.render import render_report

    path = _bumped_session(tmp_path)
    real = RadiometryProcedure.analyze

    def broken(self: Any, session: Any, estimator: Any) -> Path:
        raise OSError("disk full")

    monkeypatch.setattr(RadiometryProcedure, "analyze", broken)
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        with pytest.raises(StepFailed, match="disk full"):
            resume_run(path, bench=bench, prompt=yes, retake=["position-18"],
                       retake_reason="fibre bumped").run()
    monkeypatch.setattr(RadiometryProcedure, "analyze", real)
    session = Session.open(path)
    assert session.status == "completed" and session.current_take("position-18") == 2
    stale = session.results_stale()
    assert stale is not None and "results v1 predate retake r1 of position-18" in stale
    page = render_report(path)
    assert "results STALE" in page and "position-18 take 2 current - fibre bumped" in page
    told = _cli("resume", str(path), "--simulate")
    assert told.returncode == 0 and "results are stale: results v1 predate retake r1" \
        in told.stdout
    v2 = reanalyze(path)
    assert session.results_stale() is None
    assert _row18(v2)["measured_mean_gray"] == pytest.approx(_truth18(session), abs=1.0)


@pytest.mark.slow
@pytest.mark.usefixtures("quick_silence")
def test_retake_while_resuming_an_unfinished_session(tmp_path: Path) -> None:
    """Stopped before 25 mm; resumed with --retake position-15: 15 mm taken again, 25 mm
    taken for the first time, then analysed; a killed retake's record is never "running" for
    a process that holds the session without running it."""
    from benchlab.protocols import StepFailed

    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        def progress(done: int, total: int, step: Any) -> None:
            if step is not None and step.id == "position-25":
                bench.sim_led.faults.no_reply = 1

        runner = start_run("radiometry", bench=bench, params=RAD_SMALL, root=tmp_path,
                           prompt=yes, progress=progress)
        with pytest.raises(StepFailed):
            runner.run()
    path = runner.session.path
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        out = resume_run(path, bench=bench, prompt=yes, retake=["position-15"]).run()
    session = Session.open(path)
    assert session.status == "completed" and out.results_path.name == "v1"
    assert {s: session.current_take(s) for s in ("position-15", "position-18",
                                                 "position-25")} == {
        "position-15": 2, "position-18": 1, "position-25": 1}
    assert session.meta["retake"]["previous_status"] == "failed"
    session.hold()
    try:  # a retake journalled as started, never ended (kill -9): not running for a holder
        session.log_event("retake_started", retake="r9", steps=["position-18"])
        assert session.retakes()[-1]["status"] == "interrupted"
    finally:
        session.release()
