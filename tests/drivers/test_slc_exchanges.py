"""Byte-exact SLC exchanges: the real driver against the simulator over a real pty."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from benchlab.drivers.errors import SafetyLimitError, SettingOutOfRangeError
from benchlab.drivers.slc.controller import (
    SlcController,
    SlcMode,
    parse_current_reply,
    parse_device_info,
)
from benchlab.drivers.slc.sim import SimulatedSlc

pytestmark = pytest.mark.timeout(30)

CEILINGS = {1: 100.0, 2: 200.0, 3: 50.0, 4: 1000.0}
DEVICEINFO_REPLY = (b"Mightex LED Driver:3.1.8 Device Module No.:SLC-SA04-U/S "
                    b"Device Serial No.:04-251013-011 \r\n")


def _off_and_verify(channels: int) -> list[tuple[str, bytes]]:
    out: list[tuple[str, bytes]] = []
    for ch in range(1, channels + 1):
        out += [("host", f"MODE {ch} 0\n\r".encode()), ("dev", b"## \r\n"),
                ("host", f"?MODE {ch}\n\r".encode()), ("dev", b"#0 \r\n")]
    return out


@pytest.fixture
def sim() -> Iterator[SimulatedSlc]:
    with SimulatedSlc() as s:
        yield s


@pytest.fixture
def slc(sim: SimulatedSlc) -> Iterator[SlcController]:
    c = SlcController(sim.port, ceilings_ma=CEILINGS, timeout_s=0.5).open()
    sim.transcript.clear()
    yield c
    c.close()


def test_open_sends_echooff_deviceinfo_then_switches_all_off(sim: SimulatedSlc) -> None:
    with SlcController(sim.port, ceilings_ma=CEILINGS) as c:
        assert c.device_info.driver_version == "3.1.8"
        assert c.device_info.module == "SLC-SA04-U/S"
        assert c.device_info.serial == "04-251013-011"
        assert c.channel_count == 4
        opened = list(sim.transcript)
    assert opened == [
        ("host", b"ECHOOFF\n\r"),  # not acknowledged by this firmware; the driver does not wait
        ("host", b"DEVICEINFO\n\r"), ("dev", DEVICEINFO_REPLY),
        *_off_and_verify(4),
    ]
    assert sim.transcript[len(opened):] == _off_and_verify(4)  # close: explicit, verified off


def test_echooff_ack_is_tolerated(sim: SimulatedSlc) -> None:
    sim.echooff_ack = True
    with SlcController(sim.port, ceilings_ma=CEILINGS) as c:
        assert c.get_mode(1) is SlcMode.DISABLE
    assert sim.transcript[:2] == [("host", b"ECHOOFF\n\r"), ("dev", b"## \r\n")]


def test_on_sends_normal_with_ceiling_then_mode(sim: SimulatedSlc, slc: SlcController) -> None:
    slc.on(2, 75.0)
    assert sim.transcript == [
        ("host", b"NORMAL 2 200 75\n\r"), ("dev", b"## \r\n"),
        ("host", b"MODE 2 1\n\r"), ("dev", b"## \r\n"),
    ]
    assert sim.channel_output_ma(2) == 75.0


def test_off(sim: SimulatedSlc, slc: SlcController) -> None:
    slc.on(1, 10)
    sim.transcript.clear()
    slc.off(1)
    assert sim.transcript == [("host", b"MODE 1 0\n\r"), ("dev", b"## \r\n")]
    assert sim.channel_output_ma(1) == 0.0


def test_set_and_get_current(sim: SimulatedSlc, slc: SlcController) -> None:
    slc.set_normal(3, 50, 20)
    slc.set_current(3, 30)
    assert slc.get_current(3) == (50.0, 30.0)
    assert sim.transcript == [
        ("host", b"NORMAL 3 50 20\n\r"), ("dev", b"## \r\n"),
        ("host", b"CURRENT 3 30\n\r"), ("dev", b"## \r\n"),
        ("host", b"?CURRENT 3\n\r"), ("dev", b"#5 81 480 972 1468 1964 8 -72 8000 0 50 30 \r\n"),
    ]


def test_set_mode_normal_checks_stored_currents_first(sim: SimulatedSlc,
                                                      slc: SlcController) -> None:
    slc.set_mode(1, SlcMode.NORMAL)  # factory NORMAL set: Imax 20, Iset 10 - within 100 mA
    assert slc.get_mode(1) is SlcMode.NORMAL
    assert sim.transcript == [
        ("host", b"?CURRENT 1\n\r"), ("dev", b"#5 81 480 972 1468 1964 8 -72 8000 0 20 10 \r\n"),
        ("host", b"MODE 1 1\n\r"), ("dev", b"## \r\n"),
        ("host", b"?MODE 1\n\r"), ("dev", b"#1 \r\n"),
    ]
    assert sim.channel_output_ma(1) == 10.0


def test_set_mode_normal_refused_when_stored_current_above_ceiling(sim: SimulatedSlc) -> None:
    sim.channels[2].normal_imax, sim.channels[2].normal_iset = 900, 800  # left by someone else
    with SlcController(sim.port, ceilings_ma=CEILINGS) as c:
        sim.transcript.clear()
        with pytest.raises(SafetyLimitError):
            c.set_mode(3, SlcMode.NORMAL)
        assert [b for w, b in sim.transcript if w == "host"] == [b"?CURRENT 3\n\r"]
        assert sim.channel_output_ma(3) == 0.0


@pytest.mark.parametrize("mode", [SlcMode.STROBE, SlcMode.TRIGGER])
def test_unchecked_modes_are_refused(sim: SimulatedSlc, slc: SlcController, mode: SlcMode) -> None:
    with pytest.raises(SettingOutOfRangeError):
        slc.set_mode(1, mode)
    assert sim.transcript == []


def test_ceiling_and_channel_checks_send_nothing(sim: SimulatedSlc, slc: SlcController) -> None:
    with pytest.raises(SafetyLimitError):
        slc.on(3, 50.5)
    with pytest.raises(SafetyLimitError):
        slc.set_normal(1, 101, 10)
    with pytest.raises(SettingOutOfRangeError):
        slc.set_current(1, float("nan"))
    with pytest.raises(SettingOutOfRangeError):
        slc.on(5, 1)
    with pytest.raises(SettingOutOfRangeError):
        slc.set_normal(1, 10, 20)  # Iset above Imax
    assert sim.transcript == []


def test_channel_without_ceiling_is_refused(sim: SimulatedSlc) -> None:
    with SlcController(sim.port, ceilings_ma={1: 100}) as c:
        sim.transcript.clear()
        with pytest.raises(SafetyLimitError, match="no configured ceiling"):
            c.on(2, 1)
        assert sim.transcript == []


def test_a_current_between_steps_is_refused_before_any_byte(
        sim: SimulatedSlc, slc: SlcController) -> None:
    assert slc.current_step_ma(1) == 1.0 and slc.max_current_ma(1) == 100.0
    with pytest.raises(SettingOutOfRangeError, match=r"99.9 mA cannot be set.*1 mA steps "
                       r"\(nearest: 99 or 100 mA\); nothing sent"):
        slc.on(1, 99.9)
    with pytest.raises(SettingOutOfRangeError, match="1 mA steps"):
        slc.set_current(1, 0.5)
    assert sim.transcript == [] and sim.channel_output_ma(1) == 0.0
    slc.on(1, 99.0)
    assert ("host", b"NORMAL 1 100 99\n\r") in sim.transcript


def test_deci_milliamp_family_scales_currents() -> None:
    sim = SimulatedSlc(channels=2, module="SLC-FA02-U", normal_max_ma=1000)
    sim.start()
    try:
        with SlcController(sim.port, ceilings_ma={1: 80.0}) as c:
            sim.transcript.clear()
            c.on(1, 12.5)
            assert c.get_current(1) == (80.0, 12.5)
            assert sim.transcript[0] == ("host", b"NORMAL 1 800 125\n\r")
    finally:
        sim.stop()


@pytest.fixture
def ca_sim() -> Iterator[SimulatedSlc]:
    s = SimulatedSlc(module="SLC-CA04-MU")  # 5 mA current steps (B.7)
    s.start()
    yield s
    s.stop()


def test_ca_simulator_drives_the_nearest_5_ma_step(ca_sim: SimulatedSlc) -> None:
    import serial

    with serial.Serial(ca_sim.port, 9600, timeout=1.0) as ser:
        def ask(line: bytes) -> bytes:
            ser.write(line + b"\n\r")
            return ser.read_until(b"\r\n")

        assert ask(b"NORMAL 1 123 123") == b"## \r\n"
        assert ask(b"MODE 1 1") == b"## \r\n"
        assert ca_sim.channel_output_ma(1) == 125.0  # above the 123 asked for
        assert ask(b"?CURRENT 1").endswith(b" 125 125 \r\n")
        assert ask(b"CURRENT 1 122") == b"## \r\n"
        assert ca_sim.channel_output_ma(1) == 120.0
        assert ask(b"CURRENT 1 127") == b"## \r\n"
        assert ca_sim.channel_output_ma(1) == 125.0


def test_ca_family_refuses_a_current_between_its_5_ma_steps(ca_sim: SimulatedSlc) -> None:
    with SlcController(ca_sim.port, ceilings_ma={1: 123.0, 2: 100.0}) as c:
        assert c.current_step_ma(1) == 5.0
        assert c.max_current_ma(1) == 120.0 and c.max_current_ma(3) is None
        ca_sim.transcript.clear()
        for bad_ma in (3.0, 0.5, 122.0):  # 3 mA used to be sent as 0: nothing lit, no word
            with pytest.raises(SettingOutOfRangeError, match=r"5 mA steps \(nearest: "):
                c.on(1, bad_ma)
        with pytest.raises(SettingOutOfRangeError, match=r"nearest: 0 or 5 mA"):
            c.on(1, 3.0)
        with pytest.raises(SafetyLimitError, match="ceiling"):
            c.on(1, 125)  # on a step but above the 123 mA ceiling
        assert ca_sim.transcript == [] and ca_sim.channel_output_ma(1) == 0.0
        c.on(1, 120)  # Imax = the ceiling rounded down to the step: never 125
        assert ("host", b"NORMAL 1 120 120\n\r") in ca_sim.transcript
        assert ca_sim.channel_output_ma(1) == 120.0
        with pytest.raises(SettingOutOfRangeError, match="5 mA steps"):
            c.set_current(1, 119.9)
        c.set_current(1, 5)
        assert ca_sim.channel_output_ma(1) == 5.0 and c.get_current(1) == (120.0, 5.0)
        c.on(2, 100)
        assert ca_sim.channel_output_ma(2) == 100.0
    assert ca_sim.channel_output_ma(1) == 0.0


def test_ca_mu_module_drives_1200_ma_and_has_no_trigger_mode() -> None:
    sim = SimulatedSlc(module="SLC-CA04-MU")
    sim.start()
    try:
        with SlcController(sim.port, ceilings_ma={1: 1500.0}) as c:
            assert c.ceiling_ma(1) == 1200.0 and c.max_current_ma(1) == 1200.0
            c.on(1, 1200)
            assert sim.channel_output_ma(1) == 1200.0
        import serial

        with serial.Serial(sim.port, 9600, timeout=1.0) as ser:
            ser.write(b"TRIGGER 1 100 0\n\r")
            assert ser.read_until(b"\r\n") == b"    TRIGGER is not defined \r\n"
    finally:
        sim.stop()
    assert SimulatedSlc(module="SLC-CA04-U").normal_max_ma == 1000
    assert SimulatedSlc(module="SLC-FA04-U").normal_max_ma == 1000  # 100.0 mA in 0.1 mA units


def test_channel_count_probed_when_module_missing() -> None:
    sim = SimulatedSlc(channels=3, module="")  # SDK example: no module field
    sim.start()
    try:
        with SlcController(sim.port, ceilings_ma={}) as c:
            assert c.channel_count == 3
            assert c.device_info.module == ""
        probes = [b for w, b in sim.transcript if w == "host" and b.startswith(b"?MODE")]
        assert probes[:4] == [b"?MODE 1\n\r", b"?MODE 2\n\r", b"?MODE 3\n\r", b"?MODE 4\n\r"]
    finally:
        sim.stop()


def test_parsers() -> None:
    assert parse_current_reply("?CURRENT 1", "5 81 480 972 1468 1964 8 -72 8000 0 1000 10") == (
        1000, 10)
    assert parse_current_reply("?CURRENT 1", "0 0 1000 500") == (1000, 500)
    info = parse_device_info("PhotonEdge LED Driver:1.1.5 Device Serial No.:04-060510-001")
    assert (info.driver_version, info.module, info.serial) == ("1.1.5", "", "04-060510-001")


def test_simulator_answers_unknown_and_out_of_range_like_firmware(sim: SimulatedSlc) -> None:
    import serial

    with serial.Serial(sim.port, 9600, timeout=1) as ser:
        for cmd, reply in [(b"FOO 1", b"    FOO is not defined \r\n"), (b"MODE 9 1", b"#? \r\n"),
                           (b"mode 1 7", b"#? \r\n"), (b"?STROBE 1", b"#20 0 \r\n"),
                           (b"TRIGGER 1 3501 2", b"## \r\n"), (b"?TRIGGER 1", b"#3500 2 \r\n"),
                           (b"STORE", b"## \r\n")]:
            ser.write(cmd + b"\n\r")
            assert ser.read_until(b"\r\n") == reply


def test_session_matches_recorded_transcript(sim: SimulatedSlc) -> None:
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "fixtures" / "serial" / "slc_open_close.txt"
    expected = []
    for line in path.read_text().splitlines():
        if line[:2] in ("> ", "< "):
            data = line[2:].replace("\\n", "\n").replace("\\r", "\r").encode()
            expected.append(("host" if line[0] == ">" else "dev", data))
    with SlcController(sim.port, ceilings_ma=CEILINGS) as c:
        c.on(1, 50)
        assert c.get_current(1) == (100.0, 50.0)
    assert sim.transcript == expected


def test_simulator_profiles_are_multi_line(sim: SimulatedSlc) -> None:
    import serial

    with serial.Serial(sim.port, 9600, timeout=1) as ser:
        ser.write(b"?TRIGP 1\n\r")
        assert ser.read_until(b"0 0 \r\n") == b"#10 20 \r\n0 0 \r\n"  # RESTOREDEF default
        for cmd in (b"STROBE 1 500 3", b"STRP 1 0 400 1000", b"STRP 1 1 0 0", b"TRIGP 2 0 99 5"):
            ser.write(cmd + b"\n\r")
            assert ser.read_until(b"\r\n") == b"## \r\n"
        ser.write(b"?STRP 1\n\r")
        assert ser.read_until(b"0 0 \r\n") == b"#400 1000 \r\n0 0 \r\n"
        ser.write(b"?TRIGP 2\n\r")  # 99 mA clamped to the TRIGGER Imax of 10 mA
        assert ser.read_until(b"0 0 \r\n") == b"#10 5 \r\n0 0 \r\n"


@pytest.mark.parametrize("ending", [b"\r\n", b"\n\r"])
def test_difference_9_replies_ending_lf_cr_are_accepted(ending: bytes) -> None:
    """Vendor examples show reply lines ending LF CR as well as CR LF (issue 31, #9)."""
    sim = SimulatedSlc(channels=2, reply_end=ending)
    sim.start()
    try:
        with SlcController(sim.port, ceilings_ma={1: 50.0}, timeout_s=0.3) as c:
            assert c.device_info.serial == "04-251013-011"
            c.on(1, 20)
            assert c.get_current(1) == (50.0, 20.0) and c.is_on(1)
            assert sim.transcript[-1][1].endswith(b" " + ending)
    finally:
        sim.stop()
