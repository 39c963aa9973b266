"""Issue 36, point 9, on a bench without a simulator behind it: the scale step asks to zero the
dial gauge, moves relative to home, takes the nearer known scale from the reading, and says
plainly when no reading was given."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from benchlab.bench import BenchConfig, StageConfig
from benchlab.cli.devices.doctor import Doctor
from benchlab.drivers.apt.sim import SimulatedAptStage
from benchlab.drivers.apt.stage import AptStage

pytestmark = pytest.mark.timeout(30)


@pytest.fixture
def stage() -> Iterator[tuple[SimulatedAptStage, AptStage]]:
    with SimulatedAptStage(counts_per_mm=34304.0, travel_mm=(0.0, 25.0), homed=True,
                           time_scale=500.0) as sim, AptStage(
            sim.port, travel_mm=(0.0, 25.0), updates=False) as st:
        yield sim, st


def _doctor(reading: float | None, asked: list[str]) -> Doctor:
    cfg = BenchConfig(stage=StageConfig(port="(test)", travel_mm=(0.0, 25.0)))

    def ask(question: str) -> bool:
        asked.append(question)
        return True

    return Doctor(cfg, False, ask, lambda q: (asked.append(q), reading)[1], say=lambda s: None)


def test_a_gauge_reading_settles_the_scale(stage: tuple[SimulatedAptStage, AptStage]) -> None:
    sim, st = stage
    asked: list[str] = []
    doctor = _doctor(20 * 34554.96 / 34304.0, asked)  # the carriage really moved this far
    doctor.check_scale(st)
    assert asked[0] == "zero the dial gauge against the carriage now; done?"
    assert asked[1] == "move the stage 20 mm forward from home, to measure the scale?"
    assert sim.position_mm == pytest.approx(20.1463, abs=1e-3)  # relative to home
    [check] = doctor.checks
    assert check.status == "FAIL" and "this is Z8-34304 (34304)" in check.detail
    assert "a 0.01 mm gauge error over 20.146 mm is 0.05 %" in check.detail
    assert doctor.learned == {("stage", "actuator"): "Z8-34304"}


def test_without_a_reading_the_scale_is_said_not_measured(
    stage: tuple[SimulatedAptStage, AptStage]
) -> None:
    doctor = _doctor(None, [])
    doctor.check_scale(stage[1])
    [check] = doctor.checks
    assert (check.status, check.detail) == (
        "skip", "the scale was NOT measured (no dial gauge reading given)")
    assert not doctor.learned
