"""Injected SLC faults map to distinct exceptions naming the command; LEDs end up off."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from benchlab.drivers.errors import DeviceLostError, DeviceTimeoutError
from benchlab.drivers.slc.controller import (
    SlcAckInsteadOfDataError,
    SlcArgumentError,
    SlcBadReplyError,
    SlcController,
    SlcExecutionError,
    SlcNoReplyError,
    SlcUnknownCommandError,
)
from benchlab.drivers.slc.protocol import SlcMode
from benchlab.drivers.slc.sim import SimulatedSlc

pytestmark = pytest.mark.timeout(30)
CEILINGS = {1: 100.0, 2: 100.0, 3: 100.0, 4: 100.0}


@pytest.fixture
def sim() -> Iterator[SimulatedSlc]:
    with SimulatedSlc() as s:
        yield s


def _all_dark(sim: SimulatedSlc) -> bool:
    return all(sim.channel_output_ma(ch) == 0.0 for ch in range(1, 5))


@pytest.mark.parametrize(
    ("inject", "call", "exc", "command"),
    [
        (lambda f: setattr(f, "no_reply", 1), lambda c: c.get_current(1), SlcNoReplyError,
         "?CURRENT 1"),
        (lambda f: setattr(f, "garbage", b"\x00\xfe%%"), lambda c: c.get_mode(1),
         SlcBadReplyError, "?MODE 1"),
        (lambda f: setattr(f, "garbage", b"@@@ \r\n"), lambda c: c.set_current(1, 20),
         SlcBadReplyError, "CURRENT 1 20"),
        (lambda f: setattr(f, "garbage", b"## \r\n"), lambda c: c.get_mode(1),
         SlcAckInsteadOfDataError, "?MODE 1"),
        (lambda f: setattr(f, "out_of_range", 1), lambda c: c.get_current(1), SlcBadReplyError,
         "?CURRENT 1"),
        (lambda f: setattr(f, "out_of_range", 1), lambda c: c.get_mode(1), SlcBadReplyError,
         "?MODE 1"),
        (lambda f: setattr(f, "exec_error", 1), lambda c: c.set_current(1, 30),
         SlcExecutionError, "CURRENT 1 30"),
        (lambda f: f.undefined.add("CURRENT"), lambda c: c.set_current(1, 30),
         SlcUnknownCommandError, "CURRENT 1 30"),
    ],
)
def test_fault_raises_named_error_and_leaves_leds_off(sim, inject, call, exc, command) -> None:
    with pytest.raises(exc) as info:
        with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.3) as c:
            c.on(1, 40)
            assert sim.channel_output_ma(1) == 40.0
            inject(sim.faults)
            call(c)
    assert info.value.command == command
    assert repr(command) in str(info.value)
    assert _all_dark(sim)
    assert sim.host_lines()[-2:] == [b"MODE 4 0\n\r", b"?MODE 4\n\r"]


def test_argument_out_of_range_reply(sim: SimulatedSlc) -> None:
    sim.normal_max_ma = 30  # the controller's own limit is below the configured ceiling
    with pytest.raises(SlcArgumentError, match="NORMAL 1 100 40"):
        with SlcController(sim.port, ceilings_ma=CEILINGS) as c:
            c.on(1, 40)
    assert _all_dark(sim)


@pytest.mark.slow
def test_silence_is_a_timeout_error(sim: SimulatedSlc) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=1.0) as c:
        sim.faults.no_reply = 1
        with pytest.raises(DeviceTimeoutError):
            c.off(2)


def test_dropped_connection_is_reported_and_says_leds_may_be_lit(sim: SimulatedSlc) -> None:
    with pytest.raises(DeviceLostError) as info:
        with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.3) as c:
            c.on(1, 40)
            sim.faults.drop_on_command = "?CURRENT"
            c.get_current(1)
    assert "?CURRENT 1" in str(info.value)
    notes = " ".join(getattr(info.value, "__notes__", []))
    assert "may still be lit" in notes
    # Honest physics: an SLC keeps its output when the link drops; the driver says so.
    assert sim.channel_output_ma(1) == 40.0


def test_exception_in_context_switches_off(sim: SimulatedSlc) -> None:
    with pytest.raises(RuntimeError):
        with SlcController(sim.port, ceilings_ma=CEILINGS) as c:
            c.on(1, 40)
            c.on(2, 60)
            raise RuntimeError("procedure failed")
    assert _all_dark(sim)


_CHILD = """
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)  # as started from a terminal
from benchlab.drivers.slc.controller import SlcController
c = SlcController(sys.argv[1], ceilings_ma={1: 100}).open()
c.on(1, 55)
print("on", flush=True)
if sys.argv[2] == "wait":
    while True:
        time.sleep(0.05)
"""


def _run_child(sim: SimulatedSlc, mode: str) -> subprocess.Popen[str]:
    child = subprocess.Popen([sys.executable, "-c", _CHILD, sim.port, mode],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert child.stdout is not None
    assert child.stdout.readline().strip() == "on"
    return child


def test_interpreter_exit_switches_off(sim: SimulatedSlc) -> None:
    child = _run_child(sim, "exit")
    assert child.wait(timeout=20) == 0
    assert _all_dark(sim)
    assert sim.host_lines()[-8:] == [
        line for ch in range(1, 5) for line in (f"MODE {ch} 0\n\r".encode(),
                                                f"?MODE {ch}\n\r".encode())]


def test_ctrl_c_switches_off(sim: SimulatedSlc) -> None:
    child = _run_child(sim, "wait")
    assert sim.channel_output_ma(1) == 55.0
    os.kill(child.pid, signal.SIGINT)
    child.wait(timeout=20)
    assert child.returncode != 0  # KeyboardInterrupt still ends the program
    deadline = time.monotonic() + 5
    while not _all_dark(sim) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert _all_dark(sim)
    assert b"MODE 1 0\n\r" in sim.host_lines()


# ---- late replies: answered after the host's timeout -----------------------------------------
def test_late_reply_is_not_taken_for_the_next_commands_reply(sim: SimulatedSlc) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.3) as c:
        c.on(1, 40)
        # "#1" comes 150 ms after the 0.3 s timeout (a margin a loaded machine keeps), and
        # within the next exchange's wait for a late reply (one timeout more).
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.45
        with pytest.raises(SlcNoReplyError, match=r"\?MODE 1"):
            c.is_on(1)
        # The late "#1" must not answer "?MODE 2": channel 2 is dark.
        assert c.is_on(2) is False
        assert sim.channel_output_ma(2) == 0.0
        assert c.get_current(1) == (100.0, 40.0)
        assert c.is_on(1) is True
    assert _all_dark(sim)


def test_late_reply_to_a_command_it_executed(sim: SimulatedSlc) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.3) as c:
        c.on(1, 40)
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.4
        with pytest.raises(SlcNoReplyError, match="MODE 1 0"):
            c.off(1)
        assert sim.channel_output_ma(1) == 0.0  # executed, only its "##" was late
        assert c.is_on(1) is False  # the late "##" is not taken as the query's reply
        c.on(2, 30)
        assert sim.channel_output_ma(2) == 30.0
        assert c.get_current(2) == (100.0, 30.0)


def test_reply_late_but_within_timeout_is_the_answer(sim: SimulatedSlc) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5) as c:
        c.on(1, 40)
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.15
        t0 = time.monotonic()
        assert c.get_current(1) == (100.0, 40.0)
        assert time.monotonic() - t0 >= 0.15  # the fault really delayed it
        assert c.is_on(2) is False


def test_simulator_busy_with_a_late_reply_answers_later_commands_in_order(
    sim: SimulatedSlc,
) -> None:
    import serial

    sim.channels[0].mode = SlcMode.NORMAL
    sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.3
    with serial.Serial(sim.port, 9600, timeout=1.0) as ser:
        t0 = time.monotonic()
        ser.write(b"?MODE 1\n\r?MODE 2\n\r")
        first = ser.read_until(b"\r\n")
        assert time.monotonic() - t0 >= 0.3
        assert (first, ser.read_until(b"\r\n")) == (b"#1 \r\n", b"#0 \r\n")


@pytest.mark.slow
def test_reply_later_than_the_next_commands_wait_is_not_taken_for_its_reply(
    sim: SimulatedSlc,
) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5) as c:
        c.on(1, 40)
        # "#1" comes 1.3 s late: after the timeout (0.5 s) and after the next exchange's wait
        # for it (to ~1.08 s), while that exchange waits for its own reply (to ~1.58 s).
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 1.3
        with pytest.raises(SlcNoReplyError, match=r"\?MODE 1"):
            c.is_on(1)
        with pytest.raises(SlcBadReplyError, match=r"two replies, the first b'#1 \\r\\n'"):
            c.is_on(2)  # read "#1", then its own "#0" followed: refused, not answered True
        assert c.is_on(2) is False and c.is_on(1) is True  # and the line is in step again


@pytest.mark.parametrize("how", ["late_echooff_ack", "late_reply"])
def test_echooff_ack_arriving_late_at_open_is_skipped(sim: SimulatedSlc, how: str) -> None:
    # The ack comes after the driver's 0.1 s wait for it, while DEVICEINFO is already sent:
    # it used to be read as DEVICEINFO's reply (open failed: "expected a bare text line").
    if how == "late_echooff_ack":
        sim.faults.late_echooff_ack_s = 0.3
    else:  # the generic fault on the first command, with the fw 3.1.8 ack
        sim.echooff_ack = True
        sim.faults.late_reply, sim.faults.late_reply_s = 1, 0.3
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=1.0) as c:
        assert c.device_info.serial == "04-251013-011" and c.channel_count == 4
        c.on(1, 40)  # every later reply belongs to its own command
        assert c.get_current(1) == (100.0, 40.0) and c.is_on(1)
    assert (("dev", b"## \r\n") in sim.transcript) and _all_dark(sim)


def test_echooff_ack_later_than_the_timeout_resynchronises_open(sim: SimulatedSlc) -> None:
    sim.faults.late_echooff_ack_s = 0.7  # DEVICEINFO times out (0.5 s) behind it
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5) as c:
        assert c.device_info.serial == "04-251013-011"
        c.on(2, 30)
        assert c.get_current(2) == (100.0, 30.0)
    assert sum(b == b"DEVICEINFO\n\r" for b in sim.host_lines()) == 2 and _all_dark(sim)
