"""Linear-stage contract: every LinearStage implementation behaves the same (simulator always,
hardware on opt-in; see tests/device_implementations.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from device_implementations import STAGES, Implementation, stage_travel_mm

from benchlab.drivers.errors import SafetyLimitError, SettingOutOfRangeError
from benchlab.drivers.interfaces import LinearStage

pytestmark = pytest.mark.timeout(120)
#: Position agreement after a completed move (a few encoder counts).
TOL_MM = 0.002


@pytest.fixture(params=STAGES, ids=str)
def stage(request: pytest.FixtureRequest) -> Iterator[LinearStage]:
    impl: Implementation[LinearStage] = request.param
    with impl.opener() as st:
        st.home()
        yield st


def test_identity_and_travel(stage: LinearStage) -> None:
    assert isinstance(stage, LinearStage)
    ident = stage.identity
    assert ident.model and ident.serial and ident.firmware and ident.port
    assert stage.travel_mm == stage_travel_mm()


def test_home_then_move_reaches_the_target(stage: LinearStage) -> None:
    lo, _ = stage.travel_mm
    assert stage.is_homed
    assert stage.position_mm == pytest.approx(lo, abs=TOL_MM)
    stage.move_to_mm(lo + 1.25)
    assert stage.position_mm == pytest.approx(lo + 1.25, abs=TOL_MM)
    assert not stage.is_moving


@pytest.mark.parametrize("offset_mm", [-0.01, 1000.0])
def test_target_outside_travel_is_refused_and_nothing_moves(stage: LinearStage,
                                                             offset_mm: float) -> None:
    lo, hi = stage.travel_mm
    target = lo + offset_mm if offset_mm < 0 else hi + offset_mm
    before = stage.position_mm
    with pytest.raises(SafetyLimitError, match="outside travel"):
        stage.move_to_mm(target)
    assert not stage.is_moving
    assert stage.position_mm == pytest.approx(before, abs=TOL_MM)


@pytest.mark.parametrize("target", [float("nan"), float("inf"), "3"])
def test_non_numeric_target_is_refused(stage: LinearStage, target: float) -> None:
    with pytest.raises(SettingOutOfRangeError):
        stage.move_to_mm(target)
    assert not stage.is_moving


def test_stop_ends_a_move_early(stage: LinearStage) -> None:
    lo, hi = stage.travel_mm
    stage.set_velocity_mm_s(0.5)
    stage.move_to_mm(min(hi, lo + 5.0), wait=False)
    stage.stop(immediate=True)
    assert not stage.is_moving
    assert lo - TOL_MM <= stage.position_mm < min(hi, lo + 5.0)


def test_velocity_is_set_and_checked(stage: LinearStage) -> None:
    stage.set_velocity_mm_s(1.0)
    assert stage.velocity_mm_s == pytest.approx(1.0, rel=1e-3)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(SettingOutOfRangeError):
            stage.set_velocity_mm_s(bad)
    assert stage.velocity_mm_s == pytest.approx(1.0, rel=1e-3)


def test_negative_timeout_is_refused(stage: LinearStage) -> None:
    with pytest.raises(SettingOutOfRangeError, match="timeout_s"):
        stage.move_to_mm(stage.travel_mm[0] + 1.0, timeout_s=-1.0)
