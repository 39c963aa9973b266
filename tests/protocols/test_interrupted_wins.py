"""Interrupted wins (issue 38): when the run is being stopped during a step, whatever the step
raises afterwards is the consequence of the stop, never the step's own failure.

The case from the issue, made deterministic: a radiometry run on the simulated bench, with the
stop signal delivered (to this process, through the real handler, as the terminal UI installs
it: the UI's callback sets the abort event) just before the measurement frame is grabbed. The
handler switches the LED off at once, so the frame is dark and the radiometry frame check
raises ``FrameContentError`` - which was journalled as ``step_failed`` with status "failed".
"""

from __future__ import annotations

import json
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from sim_runs import RAD_SMALL, yes

from benchlab.bench import Bench, BenchConfig
from benchlab.drivers import shutdown
from benchlab.protocols import RunAborted, RunInterrupted, resume_run, start_run
from benchlab.session import Session

pytestmark = pytest.mark.timeout(120)

#: The second grab of the run is position-15's measurement frame (its mask is the first).
MEASUREMENT_GRAB = 2


def _journal(path: Path) -> list[dict[str, Any]]:
    lines = (path / "events.jsonl").read_text(encoding="utf-8").splitlines()
    return [json.loads(line) for line in lines if line.strip()]


def _run_with(root: Path, before_grab: Callable[[Bench, threading.Event], None],
              abort: threading.Event) -> tuple[Path, BaseException, float]:
    """A radiometry run whose measurement grab is preceded by ``before_grab``; returns the
    session, what ``run()`` raised and the LED output after it."""
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        real_grab = bench.grab
        grabs: list[int] = []

        def grab(**kw: Any) -> Any:
            grabs.append(1)
            if len(grabs) == MEASUREMENT_GRAB:
                before_grab(bench, abort)
            return real_grab(**kw)

        bench.grab = grab  # type: ignore[method-assign]
        runner = start_run("radiometry", bench=bench, params=RAD_SMALL, root=root,
                           operator="test", prompt=yes, abort=abort)
        with pytest.raises(RunAborted) as caught:
            runner.run()
        assert bench.sim_led is not None
        lit = max(bench.sim_led.channel_output_ma(ch) for ch in range(1, 5))
    return Path(runner.session.path), caught.value, lit


def _signal_then_grab(bench: Bench, abort: threading.Event) -> None:
    signal.raise_signal(signal.SIGTERM)  # the handler runs before this returns


@pytest.mark.slow
def test_a_step_failing_after_a_stop_signal_is_interrupted_and_resumes(tmp_path: Path) -> None:
    abort = threading.Event()
    with shutdown.handling_signals(on_signal=lambda signum: abort.set()):  # as the TUI does
        path, exc, lit = _run_with(tmp_path, _signal_then_grab, abort)
    assert isinstance(exc, RunInterrupted)
    assert exc.signum == signal.SIGTERM and exc.exit_status == 143
    assert exc.step.id == "position-15"
    assert isinstance(exc.__cause__, Exception)
    assert type(exc.__cause__).__name__ == "FrameContentError"  # what the step raised after
    assert lit == 0.0
    events = _journal(path)
    assert [e["kind"] for e in events if e["kind"] in ("step_failed", "aborted")] == []
    (stop,) = [e for e in events if e["kind"] == "interrupted"]
    assert stop["step"] == "position-15" and stop["reason"] == "SIGTERM"
    assert stop["consequence"].startswith("FrameContentError: LED at 15 mm: measurement frame "
                                          "is no brighter inside the LED (0)")
    assert Session.open(path).status == "interrupted"

    # resume continues from the interrupted step and completes
    started: list[str] = []

    def progress(done: int, total: int, step: Any) -> None:
        if step is not None:
            started.append(step.id)

    with shutdown.handling_signals(), Bench.open(BenchConfig.load(None, simulate=True),
                                                 simulate=True) as bench:
        runner = resume_run(path, bench=bench, prompt=yes, progress=progress)
        outcome = runner.run()
    assert started[0] == "position-15"
    assert Session.open(path).status == "completed"
    assert outcome.results_path.is_dir() and outcome.summary["partial"] is False


def _abort_key_then_led_off(bench: Bench, abort: threading.Event) -> None:
    abort.set()  # the operator's abort key, no signal: the LED goes off as the run stops
    bench.led_off(1)


def test_a_step_failing_after_the_abort_key_is_an_abort(tmp_path: Path) -> None:
    with shutdown.handling_signals():
        path, exc, lit = _run_with(tmp_path, _abort_key_then_led_off, threading.Event())
    assert type(exc) is RunAborted and "aborted during step position-15" in str(exc)
    events = _journal(path)
    assert [e for e in events if e["kind"] in ("step_failed", "interrupted")] == []
    (stop,) = [e for e in events if e["kind"] == "aborted"]
    assert stop["step"] == "position-15"
    assert stop["consequence"].startswith("FrameContentError: ")
    assert Session.open(path).status == "aborted"
    assert lit == 0.0
