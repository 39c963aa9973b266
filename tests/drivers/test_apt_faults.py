"""APT safety rules and injected faults: right exception, stage stopped afterwards."""

from __future__ import annotations

import _thread
import threading
import time
from collections.abc import Iterator

import pytest
import serial

from benchlab.drivers.apt.protocol import Z8_COUNTS_PER_MM, Msg, StatusBits, short
from benchlab.drivers.apt.sim import UNACKED_UPDATE_LIMIT, SimulatedAptStage
from benchlab.drivers.apt.stage import (
    COMPLETION_TOLERANCE_COUNTS,
    AptBadReplyError,
    AptLimitSwitchError,
    AptMoveFaultError,
    AptNoReplyError,
    AptNotHomedError,
    AptStage,
)
from benchlab.drivers.errors import DeviceLostError, SafetyLimitError
from benchlab.drivers.simulation.pty_device import ManualClock

pytestmark = pytest.mark.timeout(30)
H = bytes.fromhex
STOP_IMMEDIATE = H("650401015001")


def received(sim: SimulatedAptStage, prefix_hex: str) -> None:
    deadline = time.monotonic() + 5
    while not any(b.startswith(H(prefix_hex)) for b in sim.host_messages()):
        assert time.monotonic() < deadline
        time.sleep(0.001)
    with sim.lock:
        pass


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


@pytest.fixture
def sim(clock: ManualClock) -> Iterator[SimulatedAptStage]:
    with SimulatedAptStage(clock=clock, travel_mm=(0.0, 50.0), homed=True) as s:
        yield s


def _open(sim: SimulatedAptStage, **kw) -> AptStage:
    kw.setdefault("travel_mm", (0.0, 50.0))
    return AptStage(sim.port, timeout_s=0.5, updates=False, **kw).open()


@pytest.mark.slow
def test_no_reply_names_the_request(sim: SimulatedAptStage) -> None:
    with _open(sim) as st:
        sim.faults.no_reply = 1
        with pytest.raises(AptNoReplyError, match="MOT_REQ_POSCOUNTER"):
            st.position_mm  # noqa: B018
        assert st.position_mm == 0.0  # the link is still usable afterwards
    assert not sim.moving


def test_garbage_before_a_reply_is_skipped(sim: SimulatedAptStage, clock: ManualClock) -> None:
    junk = b"\xde\xad\xbe\xef\x00\x11garbage\x81"
    with _open(sim) as st:
        st.move_to_mm(5.0, wait=False)
        received(sim, "5304")
        clock.advance(10)
        st.wait_for_move()
        sim.faults.garbage = junk
        assert st.position_mm == pytest.approx(5.0, abs=1e-4)
        assert st.dropped_bytes == len(junk)


def test_out_of_range_reply(sim: SimulatedAptStage) -> None:
    with _open(sim) as st:
        sim.faults.out_of_range = 1
        with pytest.raises(AptBadReplyError, match="impossible"):
            st.position_mm  # noqa: B018
        sim.faults.out_of_range = 1
        with pytest.raises(AptBadReplyError):
            st.status  # noqa: B018


def test_limit_switch_mid_move(sim: SimulatedAptStage, clock: ManualClock) -> None:
    sim.faults.limit_at_mm = 12.0
    with _open(sim) as st:
        st.move_to_mm(20.0, wait=False)
        received(sim, "5304")
        clock.advance(30)
        with pytest.raises(AptLimitSwitchError, match="limit switch hit at 12.0000 mm"):
            st.wait_for_move()
        assert not st.status.is_moving
    assert not sim.moving and sim.position_mm == pytest.approx(12.0)


def _move(st: AptStage, sim: SimulatedAptStage, clock: ManualClock, target_mm: float) -> None:
    n = len(sim.host_messages())
    st.move_to_mm(target_mm, wait=False)
    deadline = time.monotonic() + 5
    while len(sim.host_messages()) == n:  # the move is on its way before time jumps
        assert time.monotonic() < deadline
        time.sleep(0.001)
    clock.advance(60)
    st.wait_for_move()


@pytest.mark.parametrize(
    ("bits", "named"),
    [
        (StatusBits.POSITION_ERROR, "fault POSITION_ERROR"),
        (StatusBits.ERROR | StatusBits.OVERLOAD, "OVERLOAD|ERROR"),
    ],
)
def test_move_completed_with_a_fault_bit_is_an_error(
    sim: SimulatedAptStage, clock: ManualClock, bits: StatusBits, named: str
) -> None:
    with _open(sim) as st:
        sim.faults.completion_bits = bits
        with pytest.raises(AptMoveFaultError, match=named) as info:
            _move(st, sim, clock, 20.0)
        assert "move to 20.0 mm reported complete at 20.0000 mm" in str(info.value)
        _move(st, sim, clock, 30.0)  # the fault was one completion's: the next one is clean
        assert st.position_mm == pytest.approx(30.0, abs=1e-4)
    assert not sim.moving


def test_move_completed_away_from_the_target_is_an_error(
    sim: SimulatedAptStage, clock: ManualClock
) -> None:
    with _open(sim) as st:
        sim.faults.stop_short_mm = 0.01  # ~346 counts short, yet MOVE_COMPLETED
        with pytest.raises(AptMoveFaultError, match=r"-34[56] counts from the target"):
            _move(st, sim, clock, 20.0)
        assert sim.position_mm == pytest.approx(19.99, abs=1e-4)
        sim.faults.stop_short_mm = 0.01
        st.move_by_mm(-5.0, wait=False)  # relative: checked against its end point, 14.99 mm
        received(sim, "4804")
        clock.advance(60)
        with pytest.raises(AptMoveFaultError, match=r"\+34[56] counts from the target"):
            st.wait_for_move()
        assert sim.position_mm == pytest.approx(15.0, abs=1e-4)


def test_a_limit_switch_pressed_is_named_only_when_the_carriage_is_off_target(
    sim: SimulatedAptStage, clock: ManualClock
) -> None:
    """Real switches are pressed over a zone at each end of travel: a move that ends on its
    target with a switch pressed is a success (it used to fail whenever the target was more
    than 5 counts from the configured end); short of the target, the switch is named."""
    with _open(sim) as st:
        sim.faults.completion_bits = StatusBits.FWD_HW_LIMIT
        _move(st, sim, clock, 20.0)  # on target, switch zone reported: fine
        assert st.position_mm == pytest.approx(20.0, abs=1e-4)
        sim.faults.completion_bits = StatusBits.REV_HW_LIMIT
        sim.faults.stop_short_mm = 0.01
        with pytest.raises(AptMoveFaultError, match="re-reads over 0.25 s, reverse limit "
                                                    "switch engaged"):
            _move(st, sim, clock, 30.0)


def test_completion_within_a_few_counts_and_at_the_travel_ends_is_success(
    sim: SimulatedAptStage, clock: ManualClock
) -> None:
    with _open(sim) as st:
        sim.faults.stop_short_mm = (COMPLETION_TOLERANCE_COUNTS - 1) / Z8_COUNTS_PER_MM
        _move(st, sim, clock, 20.0)
        assert sim.position_mm < 20.0  # it did stop short, within the servo's few counts
        _move(st, sim, clock, 50.0)  # the forward switch sits at this end of travel
        assert st.status.at_forward_limit
        _move(st, sim, clock, 0.0)
        assert st.status.at_reverse_limit


def test_physical_end_of_travel_trips_the_limit_switch(clock: ManualClock) -> None:
    sim = SimulatedAptStage(clock=clock, travel_mm=(0.0, 25.0), homed=True)  # a Z825...
    sim.start()
    try:
        with _open(sim, travel_mm=(0.0, 50.0)) as st:  # ...configured as an MTS50 by mistake
            st.move_to_mm(30.0, wait=False)
            received(sim, "5304")
            clock.advance(60)
            with pytest.raises(AptLimitSwitchError):
                st.wait_for_move()
            assert st.status.at_forward_limit
        assert sim.position_mm == pytest.approx(25.0) and not sim.moving
    finally:
        sim.stop()


def test_dropped_connection_mid_move(sim: SimulatedAptStage, clock: ManualClock) -> None:
    with pytest.raises(DeviceLostError) as info:
        with _open(sim) as st:
            st.move_to_mm(10.0, wait=False)
            received(sim, "5304")
            sim.drop_connection()
            st.wait_for_move(timeout_s=5)
    assert "could not be stopped" in " ".join(getattr(info.value, "__notes__", []))
    # The cube finishes its profiled move on its own, as a real KDC101 does.
    clock.advance(30)
    assert not sim.moving and sim.position_mm == pytest.approx(10.0, abs=1e-4)


def test_move_timeout_stops_the_stage(sim: SimulatedAptStage, clock: ManualClock) -> None:
    with _open(sim) as st:
        clock.advance(0)  # simulated time stands still: the move never completes
        with pytest.raises(AptNoReplyError, match="completion"):
            st.move_to_mm(20.0, timeout_s=0.2)
        received(sim, "650401")
        assert sim.host_messages()[-1] == STOP_IMMEDIATE
        assert not sim.moving


def test_exception_in_context_stops_the_stage(sim: SimulatedAptStage) -> None:
    with pytest.raises(RuntimeError):
        with _open(sim) as st:
            st.move_to_mm(20.0, wait=False)
            raise RuntimeError("procedure failed")
    assert not sim.moving
    assert STOP_IMMEDIATE in sim.host_messages()


@pytest.mark.usefixtures("terminal_sigint")
def test_ctrl_c_while_waiting_stops_the_stage(sim: SimulatedAptStage) -> None:
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("needs the main thread")
    with _open(sim) as st:
        timer = threading.Timer(0.1, _thread.interrupt_main)
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            st.move_to_mm(20.0, timeout_s=10)
        timer.join()
        received(sim, "650401")
        assert not sim.moving


def test_moves_refused_before_homing_unless_allowed(clock: ManualClock) -> None:
    sim = SimulatedAptStage(clock=clock, travel_mm=(0.0, 50.0), initial_position_mm=30.0)
    sim.start()
    try:
        with _open(sim) as st:
            sent = len(sim.host_messages())
            with pytest.raises(AptNotHomedError):
                st.move_to_mm(5.0)
            with pytest.raises(AptNotHomedError):
                st.move_by_mm(1.0)
            assert len(sim.host_messages()) == sent
        with _open(sim, allow_unhomed=True) as st:
            st.move_by_mm(2.0, wait=False)
            received(sim, "4804")
            clock.advance(10)
            st.wait_for_move()
            assert st.position_mm == pytest.approx(2.0, abs=1e-4)
        assert sim.position_mm == pytest.approx(32.0, abs=1e-4)
    finally:
        sim.stop()


def test_travel_limits_checked_before_sending(sim: SimulatedAptStage) -> None:
    with _open(sim, travel_mm=(0.0, 25.0)) as st:
        sent = len(sim.host_messages())
        for bad in (25.0001, -0.0001, float("nan"), float("inf")):
            with pytest.raises((SafetyLimitError, ValueError)):
                st.move_to_mm(bad)
        with pytest.raises(SafetyLimitError):
            st.move_by_mm(-0.5)  # from 0 mm
        assert sim.host_messages()[sent:] == [H("110401005001")]  # only the position read


def test_updates_stop_after_fifty_without_keepalive() -> None:
    sim = SimulatedAptStage(time_scale=1000.0, travel_mm=(0.0, 50.0), homed=True)
    sim.update_min_wall_s = 0.0
    sim.start()
    try:
        with serial.Serial(sim.port, 115200, timeout=0.3) as ser:
            ser.write(short(Msg.HW_START_UPDATEMSGS).pack())
            data = b""
            while chunk := ser.read(4096):  # until the cube falls silent
                data += chunk
            assert len(data) == UNACKED_UPDATE_LIMIT * 20
            assert data[:6] == H("91040e008150")
            ser.write(short(Msg.MOT_ACK_DCSTATUSUPDATE).pack())
            assert ser.read(20)[:6] == H("91040e008150")  # flowing again
            ser.write(short(Msg.HW_STOP_UPDATEMSGS).pack())
    finally:
        sim.stop()


def test_stop_when_idle_tolerates_a_silent_cube(sim: SimulatedAptStage) -> None:
    with _open(sim) as st:
        sim.faults.no_reply = 1  # the stop is swallowed: no MOVE_STOPPED comes back
        st.stop(immediate=True, timeout_s=0.2)  # idle per the status bits: not an error
        assert sim.host_messages()[-1] == H("900401005001")


def test_unsolicited_messages_before_a_reply_are_routed(sim: SimulatedAptStage) -> None:
    from benchlab.drivers.apt.protocol import HOST, UNIT, DcStatus, StatusBits, long

    unsolicited = (
        short(Msg.MOT_MOVE_HOMED, 1, dest=HOST, source=UNIT).pack()
        + long(Msg.MOT_GET_DCSTATUSUPDATE, DcStatus(0, 0, 0, StatusBits.ENABLED).pack(),
               dest=HOST, source=UNIT).pack()
    )
    with _open(sim) as st:
        assert st.is_homed
        sim.faults.garbage = unsolicited  # emitted between our request and its reply
        assert st.position_mm == 0.0
        assert st.dropped_bytes == 0  # valid frames, routed rather than discarded
        assert not st.is_homed  # the unsolicited status (saying 'not homed') was applied


def test_reply_late_but_within_timeout_is_the_answer(sim: SimulatedAptStage) -> None:
    with _open(sim) as st:
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.2
        t0 = time.monotonic()
        assert st.position_mm == 0.0
        assert time.monotonic() - t0 >= 0.2  # the fault really delayed it


@pytest.mark.slow
def test_reply_after_the_timeout_is_not_taken_for_a_later_request(
    sim: SimulatedAptStage, clock: ManualClock
) -> None:
    with _open(sim) as st:  # timeout 0.5 s
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.6
        with pytest.raises(AptNoReplyError, match="MOT_REQ_POSCOUNTER"):
            st.position_mm  # noqa: B018
        _move(st, sim, clock, 10.0)
        time.sleep(0.4)  # the late GET_POSCOUNTER (0 counts) arrives before the next request
        assert st.position_mm == pytest.approx(10.0, abs=1e-4)


@pytest.mark.slow
def test_a_late_reply_is_not_taken_for_the_next_request_of_its_kind(
    sim: SimulatedAptStage, clock: ManualClock
) -> None:
    """A position request times out; its reply comes later, after the next position request
    was sent - it used to be taken for that one's answer (0.0 mm after a move to 10 mm). The
    next request of the kind now first waits out the late reply."""
    with _open(sim) as st:
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.8  # timeout 0.5 s
        with pytest.raises(AptNoReplyError, match="MOT_REQ_POSCOUNTER"):
            st.position_mm  # noqa: B018
        _move(st, sim, clock, 10.0)
        clock.advance(60)
        st.wait_for_move()
        # This request's own reply is slow too (0.3 s): the old one (0.0 mm) comes first.
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.3
        assert st.position_mm == pytest.approx(10.0, abs=1e-4)  # not the late 0.0
        assert st.position_mm == pytest.approx(10.0, abs=1e-4)
