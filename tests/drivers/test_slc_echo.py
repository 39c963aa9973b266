"""SLC echo mode (ECHOON, device-protocols.md B.4 / SDK "Echo Mode") on the real pty simulator.

With echo on the controller sends each command line back as received, a ``>`` prompt for its
CR, the reply, then another ``>``. A controller left echoing by a previous program must open
and work; echo switched on mid-session is stripped (only an exact echo of the command just
sent) and switched off again; a controller that stays in echo is refused with the bytes named,
after its LEDs are switched off.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import serial

from benchlab.drivers.slc.controller import (
    SlcBadReplyError,
    SlcController,
    SlcEchoError,
)
from benchlab.drivers.slc.protocol import SlcMode, split_echo
from benchlab.drivers.slc.sim import SimulatedSlc

pytestmark = pytest.mark.timeout(30)
CEILINGS = {1: 100.0, 2: 100.0, 3: 100.0, 4: 100.0}


@pytest.fixture
def sim() -> Iterator[SimulatedSlc]:
    with SimulatedSlc() as s:
        yield s


def _all_dark(sim: SimulatedSlc) -> bool:
    return all(sim.channel_output_ma(ch) == 0.0 for ch in range(1, sim.channel_count + 1))


def _ask(port: serial.Serial, line: bytes) -> bytes:
    port.write(line + b"\n\r")
    return port.read(200)  # until the 0.3 s timeout: everything the controller sent back


# ---- the simulator's wire format -----------------------------------------------------------
@pytest.mark.slow
def test_simulator_echo_wire_format_and_it_persists_across_opens(sim: SimulatedSlc) -> None:
    with serial.Serial(sim.port, 9600, timeout=0.3) as port:  # a terminal program
        assert _ask(port, b"?MODE 1") == b"#0 \r\n"  # echo off: the reply alone
        assert _ask(port, b"ECHOON") == b"## \r\n>"  # echo on from now: prompt after reply
        assert _ask(port, b"?MODE 1") == b"?MODE 1\n\r>#0 \r\n>"
    assert sim.echo is True
    with serial.Serial(sim.port, 9600, timeout=0.3) as port:  # the next program's open
        assert _ask(port, b"mode 2 0") == b"mode 2 0\n\r>## \r\n>"  # echoed as received
        assert _ask(port, b"ECHOOFF") == b"ECHOOFF\n\r>"  # echoed; this firmware: no ack
        assert _ask(port, b"?MODE 1") == b"#0 \r\n"
    sim.echo, sim.echooff_ack = True, True
    with serial.Serial(sim.port, 9600, timeout=0.3) as port:
        assert _ask(port, b"ECHOOFF") == b"ECHOOFF\n\r>## \r\n"  # fw 3.1.8 acks it
        sim.echo = True
        assert _ask(port, b"RESET") == b"RESET\n\r>## \r\n"  # a reset ends echo (B.4)


@pytest.mark.slow
def test_simulator_faults_switch_echo_on_and_keep_it_on(sim: SimulatedSlc) -> None:
    sim.faults.echo_on_at = "?mode"
    sim.faults.echooff_ignored = 1
    with serial.Serial(sim.port, 9600, timeout=0.3) as port:
        assert _ask(port, b"MODE 1 0") == b"## \r\n"
        assert _ask(port, b"?MODE 1") == b"?MODE 1\n\r>#0 \r\n>"
        assert _ask(port, b"ECHOOFF") == b"ECHOOFF\n\r>>"  # ignored: still echoing
        assert _ask(port, b"ECHOOFF") == b"ECHOOFF\n\r>"
        assert _ask(port, b"?MODE 1") == b"#0 \r\n"


# ---- recognising an echo -------------------------------------------------------------------
@pytest.mark.parametrize(
    ("raw", "echo", "reply"),
    [
        (b"?MODE 1\n\r>#1 \r\n", b"?MODE 1\n\r", b"#1 \r\n"),
        (b">?MODE 1\n\r>#1 \r\n", b"?MODE 1\n\r", b"#1 \r\n"),  # a late prompt leads it
        (b"#1 \r\n", b"", b"#1 \r\n"),
        (b">#1 \r\n", b"", b"#1 \r\n"),  # a stray prompt is never part of a reply
        # Not the command sent (another channel, other case, other terminator): not an echo.
        (b"?MODE 2\n\r>#1 \r\n", b"", b"?MODE 2\n\r>#1 \r\n"),
        (b"?mode 1\n\r>#1 \r\n", b"", b"?mode 1\n\r>#1 \r\n"),
        (b"?MODE 1\r\n", b"", b"?MODE 1\r\n"),
    ],
)
def test_split_echo_only_takes_the_exact_command_line(raw: bytes, echo: bytes,
                                                      reply: bytes) -> None:
    assert split_echo("?MODE 1", raw) == (echo, reply)


# ---- the driver ------------------------------------------------------------------------------
def test_open_brings_a_controller_left_echoing_out_of_echo() -> None:
    sim = SimulatedSlc(echo=True)  # ECHOON left by a previous program
    sim.channels[1].mode, sim.channels[1].normal_iset = SlcMode.NORMAL, 20  # and light on
    with sim:
        with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5) as c:
            assert sim.echo is False and _all_dark(sim)
            assert c.device_info.serial == "04-251013-011" and c.channel_count == 4
            c.on(1, 40)
            assert c.get_current(1) == (100.0, 40.0) and c.is_on(1)
        assert ("dev", b"ECHOOFF\n\r>") in sim.transcript  # the echo of the driver's ECHOOFF
        assert sum(line == b"ECHOOFF\n\r" for line in sim.host_lines()) == 1
        assert _all_dark(sim)


def test_open_sends_echooff_again_when_the_first_did_not_take(sim: SimulatedSlc) -> None:
    sim.echo = True
    sim.faults.echooff_ignored = 1
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5) as c:
        assert c.device_info.module == "SLC-SA04-U/S" and sim.echo is False
        c.on(3, 25)
        assert c.get_current(3) == (100.0, 25.0)
    lines = sim.host_lines()
    assert lines[:4] == [b"ECHOOFF\n\r", b"DEVICEINFO\n\r", b"ECHOOFF\n\r", b"DEVICEINFO\n\r"]
    assert _all_dark(sim)


def test_controller_stuck_in_echo_is_refused_naming_the_bytes_after_leds_off() -> None:
    sim = SimulatedSlc(echo=True)
    sim.channels[0].mode, sim.channels[0].normal_iset = SlcMode.NORMAL, 50  # left lit
    sim.faults.echooff_ignored = 99
    with sim:
        assert sim.channel_output_ma(1) == 50.0
        c = SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5)
        with pytest.raises(SlcEchoError) as info:
            c.open()
        message = str(info.value)
        assert "still echoes commands after ECHOOFF sent 2 times" in message
        assert r"b'DEVICEINFO\n\r>Mightex LED Driver:3.1.8" in message  # the bytes, named
        assert info.value.command == "DEVICEINFO" and not c.is_open
        assert _all_dark(sim)  # switched off through the echo before giving up
        assert sim.host_lines()[-2:] == [b"MODE 4 0\n\r", b"?MODE 4\n\r"]


@pytest.mark.parametrize(
    ("verb", "call", "expect"),
    [
        ("?CURRENT", lambda c: c.get_current(1), (100.0, 40.0)),
        ("?MODE", lambda c: c.get_mode(1), SlcMode.NORMAL),
        ("CURRENT", lambda c: c.set_current(1, 30), None),
    ],
)
def test_echo_switched_on_mid_session_is_stripped_then_switched_off(
    sim: SimulatedSlc, verb: str, call, expect: object
) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5) as c:
        c.on(1, 40)
        sim.faults.echo_on_at = verb  # echo comes on as this command arrives
        assert call(c) == expect  # the reply behind the echo, never the echo itself
        assert sim.echo is True
        n = len(sim.host_lines())
        assert c.is_on(1) is True  # the next exchange switches echo off first ...
        assert sim.host_lines()[n:] == [b"ECHOOFF\n\r", b"DEVICEINFO\n\r", b"?MODE 1\n\r"]
        assert sim.echo is False  # ... and checked it
        assert sim.channel_output_ma(1) == (30.0 if verb == "CURRENT" else 40.0)
    assert _all_dark(sim)


def test_echo_that_cannot_be_switched_off_mid_session_fails_once_then_leds_go_off(
    sim: SimulatedSlc,
) -> None:
    with pytest.raises(SlcEchoError, match=r"b'DEVICEINFO\\n\\r>Mightex"):
        with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5) as c:
            c.on(2, 60)
            sim.faults.echo_on_at, sim.faults.echooff_ignored = "?MODE", 99
            assert c.is_on(2) is True
            c.get_current(2)  # ECHOOFF twice, still echoing: refused
    # close() still switched everything off, reading each reply behind its echo
    assert sim.echo is True and _all_dark(sim)
    assert sim.host_lines()[-2:] == [b"MODE 4 0\n\r", b"?MODE 4\n\r"]


def test_an_echo_of_another_command_is_not_taken_for_a_reply(sim: SimulatedSlc) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5) as c:
        c.on(1, 40)
        sim.faults.garbage = b"?MODE 2\n\r>#0 \r\n"  # an echo, but of another line
        # An LF CR ends a line too (issue 31, #9): the foreign echo is refused as a reply.
        with pytest.raises(SlcBadReplyError, match=r"got '\?MODE 2' \(command '\?MODE 1'\)"):
            c.is_on(1)
        assert c.is_on(1) is True
    assert _all_dark(sim)


def test_echo_without_its_reply_is_no_reply_value(sim: SimulatedSlc) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.3) as c:
        c.on(1, 40)
        with sim.lock:  # after the simulator finished answering MODE (no prompt after it)
            sim.echo = True
            sim.faults.no_reply = 1  # the echo and prompts come back, the reply does not
        with pytest.raises(SlcBadReplyError, match=r"unterminated reply b'\?MODE 1\\n\\r>>'"):
            c.is_on(1)
        assert c.get_current(1) == (100.0, 40.0)  # echo stripped, and switched off next
    assert sim.echo is False and _all_dark(sim)
