"""Issue 31, differences 6, 7, 8 and 10: APT keep-alive on a timer, completion settling, the
Z8 scale chosen by the actuator, the vendor's open routine."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest

from benchlab.drivers.apt import stage as stage_mod
from benchlab.drivers.apt.protocol import (
    Z8_ALT_COUNTS_PER_MM,
    Z8_COUNTS_PER_MM,
    Msg,
    actuator_counts_per_mm,
    short,
)
from benchlab.drivers.apt.sim import UNACKED_UPDATE_LIMIT, SimulatedAptStage
from benchlab.drivers.apt.stage import AptMoveFaultError, AptStage
from benchlab.drivers.simulation.pty_device import ManualClock

pytestmark = pytest.mark.timeout(30)
KEEPALIVE = short(Msg.MOT_ACK_DCSTATUSUPDATE).pack()


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


@pytest.fixture
def sim(clock: ManualClock) -> Iterator[SimulatedAptStage]:
    with SimulatedAptStage(clock=clock, travel_mm=(0.0, 50.0), homed=True) as s:
        yield s


def _open(sim: SimulatedAptStage, **kw: Any) -> AptStage:
    kw.setdefault("travel_mm", (0.0, 50.0))
    kw.setdefault("updates", False)
    return AptStage(sim.port, timeout_s=0.5, **kw).open()


def _wait(cond: Any, seconds: float = 5.0) -> None:
    deadline = time.monotonic() + seconds
    while not cond():
        assert time.monotonic() < deadline
        time.sleep(0.005)


@pytest.mark.slow
def test_difference_6_keepalive_on_a_timer_even_without_updates(sim: SimulatedAptStage) -> None:
    with _open(sim) as st:
        st.keepalive_period_s = 0.05
        _wait(lambda: sim.host_messages(keepalives=True).count(KEEPALIVE) >= 3)


def test_difference_6_move_completions_count_toward_the_limit(
    sim: SimulatedAptStage, clock: ManualClock
) -> None:
    """Without a keep-alive the 51st unsolicited message (here a MOVE_COMPLETED) never comes."""
    with _open(sim) as st:
        st.keepalive_period_s = 3600.0  # as if only status updates triggered it (none flow)
        with sim.lock:
            sim._unacked = UNACKED_UPDATE_LIMIT
        st.move_to_mm(1.0, wait=False)
        _wait(lambda: any(b[:2] == bytes((0x53, 0x04)) for b in sim.host_messages()))
        clock.advance(60)
        _wait(lambda: sim.suppressed_messages == 1)
        st.stop(immediate=True)


def test_difference_6_a_stalled_cube_is_restarted(clock: ManualClock) -> None:
    sim = SimulatedAptStage(clock=clock, travel_mm=(0.0, 50.0), homed=True)
    sim.update_min_wall_s = 0.0
    sim.start()
    try:
        with _open(sim, updates=True) as st:
            st.keepalive_period_s = 0.05
            with sim.lock:
                sim._unacked = UNACKED_UPDATE_LIMIT  # stalled: no update reaches the host
            assert not sim.updates_flowing
            _wait(lambda: sim.updates_flowing)  # the timer's next keep-alive restarts it
    finally:
        sim.stop()


def test_difference_7_a_completion_while_settling_is_re_read(
    sim: SimulatedAptStage, clock: ManualClock
) -> None:
    with _open(sim) as st:
        sim.faults.settle_short_mm = 0.002  # 69 counts short when MOVE_COMPLETED goes out
        sim.faults.settle_reads = 2
        st.move_to_mm(10.0, wait=False)
        _wait(lambda: any(b[:2] == bytes((0x53, 0x04)) for b in sim.host_messages()))
        clock.advance(60)
        status = st.wait_for_move()
        assert status is not None and status.position_mm == pytest.approx(10.0, abs=1e-4)


def test_difference_7_still_off_after_settling_is_a_fault(
    sim: SimulatedAptStage, clock: ManualClock
) -> None:
    with _open(sim) as st:
        sim.faults.stop_short_mm = 0.01
        st.move_to_mm(10.0, wait=False)
        _wait(lambda: any(b[:2] == bytes((0x53, 0x04)) for b in sim.host_messages()))
        clock.advance(60)
        with pytest.raises(AptMoveFaultError,
                           match="counts from the target after 5 position re-reads"):
            st.wait_for_move()


def test_difference_8_both_z8_scales_by_actuator_name() -> None:
    assert actuator_counts_per_mm("Z8") == Z8_COUNTS_PER_MM == 34554.96
    assert actuator_counts_per_mm("Z8-34304") == Z8_ALT_COUNTS_PER_MM == 34304.0
    assert abs(Z8_COUNTS_PER_MM / Z8_ALT_COUNTS_PER_MM - 1) == pytest.approx(0.0073, abs=1e-4)
    with pytest.raises(ValueError, match="known are Z8, Z8-34304, Z6"):
        actuator_counts_per_mm("Z9")


def test_difference_8_the_actuator_setting_reaches_the_stage() -> None:
    from benchlab.bench import BenchConfig, BenchConfigError

    cfg = BenchConfig.from_dict({"stage": {"actuator": "Z8-34304"}})
    assert cfg.stage is not None and cfg.stage.counts_per_mm == 34304.0
    assert BenchConfig.from_dict({"stage": {}}).stage.counts_per_mm == 34554.96  # type: ignore
    with pytest.raises(BenchConfigError, match="stage.actuator"):
        BenchConfig.from_dict({"stage": {"actuator": "Z8", "counts_per_mm": 34304.0}})


def test_difference_10_open_pulses_rts_and_purges(
    sim: SimulatedAptStage, monkeypatch: pytest.MonkeyPatch
) -> None:
    events: list[str] = []
    real_open = stage_mod.open_serial

    def spying_open(*args: Any, **kwargs: Any) -> Any:
        port = real_open(*args, **kwargs)
        cls = type(port)

        class Spy(cls):  # type: ignore[misc, valid-type]
            @property  # type: ignore[override]
            def rts(self) -> bool:
                return True

            @rts.setter
            def rts(self, value: bool) -> None:
                events.append(f"rts {int(value)}")

            def reset_input_buffer(self) -> None:
                events.append("purge in")
                super().reset_input_buffer()

            def reset_output_buffer(self) -> None:
                events.append("purge out")
                super().reset_output_buffer()

        port.__class__ = Spy
        return port

    monkeypatch.setattr(stage_mod, "open_serial", spying_open)
    with _open(sim):
        pass
    assert events[:4] == ["rts 1", "purge in", "purge out", "rts 0"]
