"""The stage's USB link drops mid-move (the simulator closes its pty, as a pulled cable does).

No stop can reach the controller, which finishes its move on its own: the error says so and
where the stage is going; the LEDs still go off; the error that stopped the work is the one
reported (the failed safe state is added to it, never put in its place), and a run journals
the failed step and ends "failed", resumable.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest
from sim_runs import RAD_SMALL, events, yes

from benchlab.bench import Bench, BenchConfig
from benchlab.drivers.apt.sim import SimulatedAptStage
from benchlab.drivers.apt.stage import AptStage
from benchlab.drivers.errors import DeviceLostError
from benchlab.protocols import StepFailed, start_run

pytestmark = pytest.mark.timeout(60)
LOST = "stage lost mid-move to 45 mm"


def _sim_bench() -> Any:
    return Bench.open(BenchConfig.load(None, simulate=True), simulate=True, time_scale=20.0)


@pytest.mark.slow
def test_driver_names_the_lost_move_and_the_stage_finishes_it_alone() -> None:
    with SimulatedAptStage(travel_mm=(0.0, 50.0), homed=True, time_scale=20.0) as sim:
        sim.faults.drop_at_mm = 20.0
        with pytest.raises(DeviceLostError) as info:
            with AptStage(sim.port, travel_mm=(0.0, 50.0), timeout_s=0.5) as stage:
                stage.move_to_mm(45.0)
        message = str(info.value)
        assert message.startswith(LOST) and "may still be moving" in message
        assert "could not be stopped" in message
        assert 20.0 <= sim.position_mm < 45.0 and sim.moving and not sim.connected
        deadline = time.monotonic() + 10
        while sim.moving:  # nobody can stop it: it runs to its target
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert sim.position_mm == pytest.approx(45.0, abs=1e-4)


@pytest.mark.usefixtures("quick_silence")
def test_bench_keeps_the_lost_stage_error_and_switches_the_led_off() -> None:
    with pytest.raises(DeviceLostError, match=LOST) as info:
        with _sim_bench() as bench:
            bench.home_stage()
            bench.led_on(1, 30.0)
            assert bench.sim_led.channel_output_ma(1) == 30.0
            bench.sim_stage.faults.drop_at_mm = 20.0
            bench.move_stage_mm(45.0)
    assert bench.sim_led.channel_output_ma(1) == 0.0  # LED off although the stage is gone
    notes = " ".join(getattr(info.value, "__notes__", []))
    assert "could not reach the safe state: stage: connection lost" in notes
    assert "(LEDs off)" in notes and "stage: stage:" not in notes


@pytest.mark.slow
@pytest.mark.usefixtures("quick_silence")
def test_run_fails_the_step_with_a_clear_error_journalled_and_leds_off(
    tmp_path: Path,
) -> None:
    with pytest.raises(StepFailed) as info:
        with _sim_bench() as bench:
            def progress(done: int, total: int, step: Any) -> None:
                if step is not None and step.id == "position-25":  # 18 -> 25 mm
                    bench.sim_stage.faults.drop_at_mm = 21.0

            runner = start_run("radiometry", bench=bench, params=RAD_SMALL, root=tmp_path,
                               prompt=yes, progress=progress)
            runner.run()
    failed = info.value
    assert failed.step.id == "position-25" and isinstance(failed.cause, DeviceLostError)
    assert str(failed.cause).startswith("stage lost mid-move to 25 mm")
    assert failed.unsafe.startswith("could not reach the safe state: stage:")
    assert str(failed).endswith("(LEDs off)")
    assert all(bench.sim_led.channel_output_ma(ch) == 0.0 for ch in range(1, 5))
    path = runner.session.path
    last = events(path)[-1]
    assert last["kind"] == "step_failed" and last["step"] == "position-25"
    assert last["error"].startswith("DeviceLostError: stage lost mid-move to 25 mm")
    assert last["safe_state"] == failed.unsafe
    assert json.loads((path / "session.json").read_text())["status"] == "failed"
