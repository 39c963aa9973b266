"""Property: no sequence of API calls sends the stage outside its configured travel."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchlab.drivers.apt.protocol import Msg, unpack_position
from benchlab.drivers.apt.sim import SimulatedAptStage
from benchlab.drivers.apt.stage import AptStage
from benchlab.drivers.errors import DeviceError

TRAVEL_MM = (2.0, 40.0)  # soft limits well inside the MTS50's physical 0..50 mm
CPM = 34554.96

distances = st.one_of(st.floats(min_value=-70, max_value=70, allow_nan=False),
                      st.sampled_from([0.0, 1e-6, 38.0, 38.00003, float("nan"), -float("inf")]))
targets = st.one_of(st.floats(min_value=-20, max_value=70, allow_nan=False),
                    st.sampled_from([2.0, 40.0, 1.99999, 40.00002, 50.0, float("inf")]))
ops = st.one_of(st.tuples(st.just("move_to_mm"), targets),
                st.tuples(st.just("move_by_mm"), distances))


@pytest.fixture(scope="module")
def rig():
    sim = SimulatedAptStage(travel_mm=(0.0, 50.0), homed=True, time_scale=20000.0,
                            initial_position_mm=0.0)
    sim.start()
    stage = AptStage(sim.port, travel_mm=TRAVEL_MM, timeout_s=2.0, updates=False).open()
    stage.move_to_mm(10.0)
    yield sim, stage
    stage.close()
    sim.stop()


@pytest.mark.timeout(60)
@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sequence=st.lists(ops, max_size=6))
def test_no_target_outside_travel(rig, sequence) -> None:
    sim, stage = rig
    lo, hi = TRAVEL_MM
    start = len(sim.transcript)
    for name, value in sequence:
        try:
            getattr(stage, name)(value)
        except (DeviceError, ValueError):
            pass
        assert lo - 1e-9 <= sim.position_mm <= hi + 1e-9
    for who, frame in sim.transcript[start:]:
        if who == "host" and frame[:2] == Msg.MOT_MOVE_ABSOLUTE.to_bytes(2, "little"):
            counts = unpack_position(frame[6:])[1]
            assert lo * CPM <= counts <= hi * CPM
