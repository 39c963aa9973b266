"""Property: no sequence of API calls puts a current above its ceiling on the wire."""

from __future__ import annotations

import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchlab.drivers.errors import DeviceError
from benchlab.drivers.slc.controller import SlcController, SlcMode
from benchlab.drivers.slc.sim import SimulatedSlc

CEILINGS = {1: 100.0, 2: 20.5, 3: 0.0}  # channel 4 deliberately has no ceiling

currents = st.one_of(
    st.floats(min_value=-50, max_value=2000, allow_nan=False),
    st.sampled_from([0.0, 20.5, 20.6, 100.0, 100.4, 1000.0, float("nan"), float("inf")]),
)
channels = st.integers(min_value=0, max_value=5)
ops = st.one_of(
    st.tuples(st.just("on"), channels, currents),
    st.tuples(st.just("set_current"), channels, currents),
    st.tuples(st.just("set_normal"), channels, currents, currents),
    st.tuples(st.just("set_mode"), channels, st.sampled_from(list(SlcMode))),
    st.tuples(st.just("off"), channels),
)


@pytest.fixture(scope="module")
def rig():
    sim = SimulatedSlc()
    sim.start()
    # Someone left channel 2 with a big NORMAL set stored in the controller.
    sim.channels[1].normal_imax, sim.channels[1].normal_iset = 900, 500
    c = SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5).open()
    yield sim, c
    c.close()
    sim.stop()


@pytest.mark.timeout(60)
@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sequence=st.lists(ops, max_size=8))
def test_no_current_above_ceiling_reaches_the_wire(rig, sequence) -> None:
    sim, c = rig
    sim.transcript.clear()
    for op in sequence:
        try:
            getattr(c, op[0])(*op[1:])
        except (DeviceError, ValueError):
            pass  # refusals are fine; what matters is what was sent and what is lit
        for ch in range(1, 5):
            assert sim.channel_output_ma(ch) <= CEILINGS.get(ch, 0.0)
    for line in sim.host_lines():
        m = re.fullmatch(rb"(NORMAL|CURRENT) (\d+) (.*)\n\r", line)
        if m:
            ch = int(m.group(2))
            for value in m.group(3).split():
                assert int(value) <= CEILINGS[ch], line
