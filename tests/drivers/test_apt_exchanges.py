"""Byte-exact APT exchanges: the real driver against the simulated KDC101 over a real pty."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator

import pytest

from benchlab.drivers.apt.protocol import DcStatus, HwInfo, StatusBits, Units, VelParamsRaw
from benchlab.drivers.apt.sim import SimulatedAptStage
from benchlab.drivers.apt.stage import AptStage
from benchlab.drivers.simulation.pty_device import ManualClock

pytestmark = pytest.mark.timeout(30)
Z8 = Units(34554.96)
H = bytes.fromhex
IDLE_HOMED = StatusBits.MOTOR_CONNECTED | StatusBits.ENABLED | StatusBits.HOMED


def dev_long(header_hex: str, payload: bytes) -> tuple[str, bytes]:
    return ("dev", H(header_hex) + payload)


@contextlib.contextmanager
def pump(clock: ManualClock, step_s: float = 0.5) -> Iterator[None]:
    """Advance simulated time in the background while a blocking driver call runs."""
    stop = threading.Event()

    def run() -> None:
        while not stop.is_set():
            clock.advance(step_s)
            time.sleep(0.002)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    try:
        yield
    finally:
        stop.set()
        t.join()


def received(sim: SimulatedAptStage, frame_hex_prefix: str) -> None:
    """Block until the simulator has processed a host frame starting with these bytes."""
    prefix = H(frame_hex_prefix)
    deadline = time.monotonic() + 5
    while not any(b.startswith(prefix) for b in sim.host_messages()):
        assert time.monotonic() < deadline, f"simulator never got {frame_hex_prefix}"
        time.sleep(0.001)
    with sim.lock:  # the frame is logged before it is handled; the lock spans both
        pass


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


@pytest.fixture
def sim(clock: ManualClock) -> Iterator[SimulatedAptStage]:
    with SimulatedAptStage(clock=clock, travel_mm=(0.0, 50.0), homed=True) as s:
        yield s


@pytest.fixture
def stage(sim: SimulatedAptStage) -> Iterator[AptStage]:
    st = AptStage(sim.port, travel_mm=(0.0, 50.0), timeout_s=1.0, updates=False).open()
    sim.transcript.clear()
    yield st
    st.close()


def test_open_and_close_sequences(sim: SimulatedAptStage) -> None:
    with AptStage(sim.port, travel_mm=(0.0, 50.0), updates=False) as st:
        assert (st.info.serial, st.info.model, st.info.firmware_str) == (27000001, "KDC101",
                                                                         "3.0.10")
        assert st.info.stage_id == 8  # MTS50-Z8
        assert st.is_homed
        opened = list(sim.transcript)
    info = HwInfo(27000001, "KDC101", 16, (3, 0, 10), 1, 0, 1, 8).pack()
    vel = VelParamsRaw(396, 1545963).pack()
    at_zero = DcStatus(0, 0, 0, IDLE_HOMED | StatusBits.REV_HW_LIMIT).pack()
    assert opened == [
        ("host", H("180000005001")),  # HW_NO_FLASH_PROGRAMMING
        ("host", H("050000005001")), dev_long("060054008150", info),
        ("host", H("100201015001")),  # enable channel 1
        ("host", H("140401005001")), dev_long("15040e008150", vel),
        ("host", H("900401005001")), dev_long("91040e008150", at_zero),
    ]
    assert sim.transcript[len(opened):] == [
        ("host", H("650401015001")), dev_long("66040e008150", at_zero),  # stop on close
        ("host", H("120000005001")),  # stop update messages
        ("host", H("020000005001")),  # HW_DISCONNECT
    ]


def test_identify(sim: SimulatedAptStage, stage: AptStage) -> None:
    stage.identify()
    stage.position_mm  # noqa: B018 - a round trip guarantees the identify was processed
    assert sim.transcript[0] == ("host", H("230201005001"))
    assert sim.identify_count == 1


def test_enable_disable_and_query(sim: SimulatedAptStage, stage: AptStage) -> None:
    stage.enable(False)
    assert stage.is_enabled() is False
    stage.enable(True)
    assert stage.is_enabled() is True
    disabled = (IDLE_HOMED & ~StatusBits.ENABLED) | StatusBits.REV_HW_LIMIT
    assert sim.transcript == [
        ("host", H("100201025001")),  # disabling halts the motor: MOVE_STOPPED follows
        dev_long("66040e008150", DcStatus(0, 0, 0, disabled).pack()),
        ("host", H("110201005001")), ("dev", H("120201020150")),
        ("host", H("100201015001")),
        ("host", H("110201005001")), ("dev", H("120201010150")),
    ]


def test_position_and_status_requests(sim: SimulatedAptStage, stage: AptStage,
                                      clock: ManualClock) -> None:
    stage.move_to_mm(12.5, wait=False)
    received(sim, "5304")
    clock.advance(30)
    stage.wait_for_move()
    sim.transcript.clear()
    assert stage.position_mm == pytest.approx(12.5, abs=1e-6)
    bits = stage.status_bits
    status = stage.status
    counts = Z8.counts(12.5)
    assert bits == IDLE_HOMED and status.bits == IDLE_HOMED and not status.is_moving
    assert sim.transcript == [
        ("host", H("110401005001")), dev_long("120406008150", H("0100") + counts.to_bytes(4,
                                                                                 "little")),
        ("host", H("290401005001")), dev_long("2a0406008150", H("0100") + int(
            IDLE_HOMED).to_bytes(4, "little")),
        ("host", H("900401005001")), dev_long("91040e008150",
                                              DcStatus(counts, 0, 0, IDLE_HOMED).pack()),
    ]


def test_velocity_params(sim: SimulatedAptStage, stage: AptStage) -> None:
    stage.set_velocity_params(1.0, 0.5)
    v = stage.get_velocity_params()
    assert v.max_velocity_mm_s == pytest.approx(1.0, rel=1e-6)
    assert v.acceleration_mm_s2 == pytest.approx(0.5, rel=1e-2)  # 132 raw units per 0.5 mm/s^2
    raw = VelParamsRaw(Z8.acc_raw(0.5), Z8.vel_raw(1.0)).pack()
    assert sim.transcript == [
        ("host", H("13040e00d001") + raw),
        ("host", H("140401005001")), dev_long("15040e008150", raw),
    ]
    assert sim.velocity_mm_s == pytest.approx(1.0, rel=1e-6)


def test_move_absolute_completes_after_travel_time(sim: SimulatedAptStage, stage: AptStage,
                                                  clock: ManualClock) -> None:
    stage.move_to_mm(10.0, wait=False)
    received(sim, "5304")
    # 10 mm at 2 mm/s with 1.5 mm/s^2 ramps: 10/2 + 2/1.5 = 6.333 s of simulated time.
    clock.advance(6.3)
    assert sim.moving
    assert stage.status.is_moving  # the round trip also proves no completion was sent yet
    assert not any(b[:2] == H("6404") for _, b in sim.transcript)
    clock.advance(0.05)
    status = stage.wait_for_move(timeout_s=5)
    assert status is not None and status.position_mm == pytest.approx(10.0, abs=1 / 34554)
    assert sim.transcript[0] == ("host", H("53040600d00101 00ce450500".replace(" ", "")))
    assert sim.transcript[-1] == dev_long("64040e008150",
                                          DcStatus(345550, 0, 0, IDLE_HOMED).pack())
    assert sim.position_mm == pytest.approx(10.0, abs=1 / 34554)


def test_move_relative(sim: SimulatedAptStage, stage: AptStage, clock: ManualClock) -> None:
    stage.move_to_mm(10.0, wait=False)
    received(sim, "5304")
    clock.advance(10)
    stage.wait_for_move()
    sim.transcript.clear()
    stage.move_by_mm(-1.0, wait=False)
    received(sim, "4804")
    clock.advance(5)
    status = stage.wait_for_move()
    assert status is not None and status.position_mm == pytest.approx(9.0, abs=1e-4)
    assert sim.transcript[:3] == [
        ("host", H("110401005001")), dev_long("120406008150", H("0100") + H("ce450500")),
        ("host", H("48040600d0010100057 9ffff".replace(" ", ""))),
    ]


def test_home_waits_for_homed(clock: ManualClock) -> None:
    sim = SimulatedAptStage(clock=clock, travel_mm=(0.0, 50.0), initial_position_mm=7.0)
    sim.start()
    try:
        with AptStage(sim.port, travel_mm=(0.0, 50.0), updates=False) as st:
            assert not st.is_homed
            assert st.position_mm == 0.0  # counter reads 0 at power-up wherever it is
            sim.transcript.clear()
            with pump(clock):
                st.home()
            assert st.is_homed and st.position_mm == 0.0
            assert sim.position_mm == 0.0 and sim.homed
            # The home parameters first: the wait follows the home velocity (issue 36).
            assert sim.transcript[0] == ("host", H("410401005001"))
            assert sim.transcript[1][1][:6] == H("42040e008150")
            assert sim.transcript[2:4] == [("host", H("430401005001")),
                                           ("dev", H("440401000150"))]
    finally:
        sim.stop()


@pytest.mark.parametrize(("immediate", "p2"), [(True, "01"), (False, "02")])
def test_stop(sim: SimulatedAptStage, stage: AptStage, clock: ManualClock, immediate: bool,
              p2: str) -> None:
    stage.move_to_mm(20.0, wait=False)
    received(sim, "5304")
    clock.advance(4.0)
    with pump(clock, 0.05):
        stage.stop(immediate=immediate)
    assert not sim.moving
    assert sim.transcript[1] == ("host", H(f"650401{p2}5001"))
    assert sim.transcript[-1][1][:6] == H("66040e008150")
    stopped_at = DcStatus.unpack(sim.transcript[-1][1][6:]).position_counts
    assert 0 < Z8.mm(stopped_at) < 20.0


def test_keepalive_sent_while_updates_flow(clock: ManualClock) -> None:
    sim = SimulatedAptStage(clock=clock, travel_mm=(0.0, 50.0), homed=True)
    sim.update_min_wall_s = 0.0
    sim.start()
    try:
        with AptStage(sim.port, travel_mm=(0.0, 50.0)) as st, pump(clock, 0.1):
            deadline = time.monotonic() + 10
            while H("920400005001") not in sim.host_messages(keepalives=True):
                assert time.monotonic() < deadline, "no keep-alive sent"
                time.sleep(0.005)
            for _ in range(20):  # requests keep working with updates interleaved
                assert st.position_mm == 0.0
        host = sim.host_messages()
        assert H("110000005001") in host  # HW_START_UPDATEMSGS
        assert H("920400005001") not in host  # kept out of sequences: sent on a timer
    finally:
        sim.stop()


@pytest.mark.parametrize("how", ["stop", "safe-stop"])
def test_a_stop_nobody_waited_for_does_not_end_the_next_move(
    sim: SimulatedAptStage, stage: AptStage, clock: ManualClock, how: str
) -> None:
    """``stop(wait=False)`` (the abort watcher) and the error-path stop leave a MOVE_STOPPED
    on its way; a move sent before it arrived took it for its own end: the driver raised
    "move stopped" while the carriage ran on to the target (review). The next move now waits
    until the stage stands still, and ends only with its own completion."""
    stage.move_to_mm(10.0, wait=False)
    received(sim, "5304")
    clock.advance(1.0)
    assert sim.moving
    if how == "stop":
        stage.stop(immediate=True, wait=False)
    else:
        stage._safe_stop()
    stage.move_to_mm(20.0, wait=False)  # sent while that MOVE_STOPPED may be in flight
    with pump(clock):
        status = stage.wait_for_move(timeout_s=5.0)
    assert status is not None and status.position_mm == pytest.approx(20.0, abs=1e-3)
    assert not sim.moving and sim.position_mm == pytest.approx(20.0, abs=1e-3)
