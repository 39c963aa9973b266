"""Issue 36, point 10: a completed move lands within a bench-file tolerance (default 30
counts, not 5), homing waits as long as the controller's own home velocity needs, and a
stage section without travel_mm gets its actuator's travel."""

from __future__ import annotations

import time
import tomllib
from typing import Any

import pytest

from benchlab.bench import BenchConfig, BenchConfigError
from benchlab.drivers.apt.protocol import COMPLETION_TOLERANCE_COUNTS, Z8_COUNTS_PER_MM
from benchlab.drivers.apt.sim import SimulatedAptStage
from benchlab.drivers.apt.stage import AptMoveFaultError, AptNoReplyError, AptStage

pytestmark = pytest.mark.timeout(30)


def _open(sim: SimulatedAptStage, **kw: Any) -> AptStage:
    return AptStage(sim.port, travel_mm=(0.0, 25.0), timeout_s=0.5, updates=False, **kw).open()


def test_a_stage_parking_12_counts_off_completes_within_the_default_tolerance() -> None:
    assert COMPLETION_TOLERANCE_COUNTS == 30
    with SimulatedAptStage(travel_mm=(0.0, 25.0), homed=True, time_scale=500.0) as sim:
        sim.faults.park_off_counts = 12
        with _open(sim) as st:
            st.move_to_mm(5.0)
            assert round((st.position_mm - 5.0) * Z8_COUNTS_PER_MM) == 12
        with _open(sim, completion_tolerance_counts=10) as st, pytest.raises(
                AptMoveFaultError, match="12 counts from the target"):
            st.move_to_mm(6.0)


def test_the_homing_timeout_follows_the_controllers_home_velocity() -> None:
    with SimulatedAptStage(travel_mm=(0.0, 25.0), time_scale=500.0,
                           home_velocity_mm_s=0.5, initial_position_mm=10.0) as sim:
        with _open(sim) as st:
            home = st.get_home_params()
            assert home.velocity_mm_s == pytest.approx(0.5, rel=1e-6)
            # 2 spans at 0.5 mm/s (not at the 2 mm/s move velocity), plus half
            assert st.home_timeout_s(home) == pytest.approx(1.5 * (50 / 0.5 + 0.5 / 1.5),
                                                        rel=1e-4)
            st.home()
            assert st.is_homed


def test_homing_that_never_ends_times_out_and_stops_the_stage() -> None:
    with SimulatedAptStage(travel_mm=(0.0, 25.0), time_scale=500.0,
                           initial_position_mm=10.0) as sim:
        sim.faults.home_never = True
        with _open(sim) as st:
            with pytest.raises(AptNoReplyError, match="move/home completion"):
                st.home(timeout_s=0.3)
            assert not st.is_homed
            deadline = time.monotonic() + 5.0
            while sim.moving:  # the driver's stop reaches the cube
                assert time.monotonic() < deadline
                time.sleep(0.01)


def _stage(text: str) -> Any:
    return BenchConfig.from_dict(tomllib.loads(text), "bench.toml").stage


def test_a_stage_section_without_travel_gets_its_actuators_travel() -> None:
    assert _stage("[stage]\n").travel_mm == (0.0, 25.0)  # a Z825, not 50 mm
    assert _stage('[stage]\nactuator = "Z6"\n').travel_mm == (0.0, 6.0)
    assert _stage("[stage]\ntravel_mm = [0.0, 50.0]\n").travel_mm == (0.0, 50.0)
    assert _stage("[stage]\ntolerance_counts = 12\n").tolerance_counts == 12
    with pytest.raises(BenchConfigError, match="stage.tolerance_counts"):
        _stage("[stage]\ntolerance_counts = 0\n")


def test_the_camera_facts_of_the_bench_file_make_its_profile() -> None:
    cam = BenchConfig.from_dict(tomllib.loads(
        '[camera]\ntrailer_order = "column_row"\ntimestamp_unit_ms = 0.1\n'
        "bit_depths = [8, 10]\n"), "bench.toml").camera
    spec = cam.profile()
    assert (spec.trailer_order, spec.timestamp_unit_ms, spec.bit_depths) == (
        "column_row", 0.1, (8, 10))
    for bad, field in (('trailer_order = "rows"', "camera.trailer_order"),
                       ("timestamp_unit_ms = 0.5", "camera.timestamp_unit_ms"),
                       ("bit_depths = [8, 14]", "camera.bit_depths")):
        with pytest.raises(BenchConfigError, match=field.replace(".", r"\.")):
            BenchConfig.from_dict(tomllib.loads(f"[camera]\n{bad}\n"), "bench.toml")
