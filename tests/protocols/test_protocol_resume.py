"""Interrupted runs (exception, Ctrl-C, abort, crash after a frame was saved) resume to the
same results as uninterrupted ones; nothing acquired is repeated or lost."""

from __future__ import annotations

import threading
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from sim_runs import MTF_SMALL, events, only_session, run_sim, tables_of, yes

from benchlab.bench import Bench, BenchConfig
from benchlab.protocols import RunAborted, StepFailed, resume_run, start_run
from benchlab.session import Session


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """An uninterrupted noise-free run: what every resumed run must reproduce exactly."""
    outcome = run_sim("mtf", tmp_path_factory.mktemp("ref"), MTF_SMALL, noise=False)
    return tables_of(outcome.results_path)


def _interrupt(root: Path, exc_type: type[BaseException], **hooks: Any) -> Path:
    """Start a noise-free run and let ``hooks`` interrupt it; returns the session folder."""
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True, noise=False) as bench:
        runner = start_run("mtf", bench=bench, params=MTF_SMALL, root=root,
                           **{"prompt": yes, **hooks})
        with pytest.raises(exc_type):
            runner.run()
    return runner.session.path


def _resume(path: Path) -> Any:
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True, noise=False) as bench:
        return resume_run(path, bench=bench, prompt=yes).run()


def _check_nothing_repeated(path: Path) -> None:
    evs = events(path)
    done = Counter(e["step_id"] for e in evs if e["kind"] == "step_completed")
    assert done and max(done.values()) == 1
    saved = Counter(e["file"] for e in evs if e["kind"] == "frame_saved")
    assert len(saved) == 5 and max(saved.values()) == 1  # forward + 2 x 2 radial, once each
    assert Session.open(path).verify_frames() == []


@pytest.mark.slow
def test_exception_at_a_step_then_resume(tmp_path: Path, reference: dict[str, Any]) -> None:
    def prompt(step: Any, message: str) -> bool:
        if step.id == "roll-2-sagittal":
            raise RuntimeError("operator tripped over the cable")
        return True

    path = _interrupt(tmp_path, StepFailed, prompt=prompt)
    assert Session.open(path).status == "failed"
    evs = events(path)
    assert any(e["kind"] == "step_failed" and e["step"] == "roll-2-sagittal" for e in evs)
    before = Session.open(path).frames()
    assert len(before) == 3  # forward + 0.5 lp/mm S and T
    outcome = _resume(path)
    assert tables_of(outcome.results_path) == reference
    _check_nothing_repeated(path)
    assert {k: v for k, v in Session.open(path).frames().items() if k in before} == before


def test_ctrl_c_then_resume(tmp_path: Path, reference: dict[str, Any]) -> None:
    def prompt(step: Any, message: str) -> bool:
        if step.id == "radial-setup":
            raise KeyboardInterrupt
        return True

    path = _interrupt(tmp_path, KeyboardInterrupt, prompt=prompt)
    assert any(e["kind"] == "interrupted" for e in events(path))
    assert Session.open(path).status == "interrupted"
    outcome = _resume(path)
    assert tables_of(outcome.results_path) == reference
    _check_nothing_repeated(path)


def test_abort_event_then_resume(tmp_path: Path, reference: dict[str, Any]) -> None:
    abort = threading.Event()

    def progress(done: int, total: int, step: Any) -> None:
        if step is not None and step.id == "radial-2-tangential":
            abort.set()  # as an abort key pressed in another thread would

    with pytest.raises(RunAborted):
        with Bench.open(BenchConfig.load(None, simulate=True), simulate=True,
                        noise=False) as bench:
            runner = start_run("mtf", bench=bench, params=MTF_SMALL, root=tmp_path, prompt=yes,
                               progress=progress, abort=abort)
            runner.run()
    path = only_session(tmp_path)
    assert any(e["kind"] == "aborted" for e in events(path))
    assert "radial-2-tangential" not in Session.open(path).completed_steps()
    assert tables_of(_resume(path).results_path) == reference
    _check_nothing_repeated(path)


def test_crash_after_a_frame_was_saved_reuses_it(tmp_path: Path, reference: dict[str, Any]) -> None:
    """A crash between the frame's flush and the step's journal line loses nothing and
    acquires nothing twice."""

    def on_result(step: Any, data: Any) -> None:
        if step.id == "radial-2-sagittal":
            raise OSError("analysis process died")

    path = _interrupt(tmp_path, StepFailed, on_result=on_result)
    session = Session.open(path)
    assert "radial-2-sagittal" in {n.split("__")[0] for n in
                                   (Path(f).stem for f in session.frames())}
    assert "radial-2-sagittal" not in session.completed_steps()
    assert tables_of(_resume(path).results_path) == reference
    assert any(e["kind"] == "frame_reused" and e["step"] == "radial-2-sagittal"
               for e in events(path))
    _check_nothing_repeated(path)


def test_retry_in_the_same_process_continues_at_the_failed_step(
    tmp_path: Path, reference: dict[str, Any]
) -> None:
    failures = {"thread": 1}

    def prompt(step: Any, message: str) -> bool:
        if failures.get(step.id):
            failures[step.id] -= 1
            raise RuntimeError("not yet")
        return True

    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True, noise=False) as bench:
        runner = start_run("mtf", bench=bench, params=MTF_SMALL, root=tmp_path, prompt=prompt)
        with pytest.raises(StepFailed) as info:
            runner.run()
        assert info.value.step.id == "thread"
        outcome = runner.run()  # the retry
    assert tables_of(outcome.results_path) == reference
    _check_nothing_repeated(outcome.session_path)


def test_declined_prompt_aborts_cleanly(tmp_path: Path) -> None:
    path = _interrupt(tmp_path, RunAborted, prompt=lambda step, message: step.id != "focus")
    assert Session.open(path).completed_steps() == {"setup", "thread"}


@pytest.mark.slow
def test_a_failure_while_restoring_on_resume_is_a_failed_step(
    tmp_path: Path, reference: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Resume re-establishes the completed steps' set-up first (camera settings, target,
    stage); a device error there used to leave session.json at "running" with nothing in
    the journal. It is a failed step: status "failed", a step_failed event, resumable."""
    from benchlab.drivers.errors import DeviceError

    def prompt(step: Any, message: str) -> bool:
        if step.id == "roll-2-sagittal":
            raise RuntimeError("operator tripped over the cable")
        return True

    path = _interrupt(tmp_path, StepFailed, prompt=prompt)

    def lost(self: Bench, **kw: Any) -> None:
        raise DeviceError("camera: no reply (unplugged?)")

    with monkeypatch.context() as m:
        m.setattr(Bench, "configure_camera", lost)
        with pytest.raises(StepFailed, match="unplugged"):
            _resume(path)
    assert Session.open(path).status == "failed"
    failed = [e for e in events(path) if e["kind"] == "step_failed"]
    assert failed[-1]["error"].startswith("restoring: DeviceError: camera: no reply")
    outcome = _resume(path)  # the camera back: the run completes as if never interrupted
    assert tables_of(outcome.results_path) == reference
