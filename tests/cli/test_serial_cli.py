"""The serial CLI commands, end to end through the real drivers and simulators."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from benchlab.cli.devices.serial import list_serial_devices
from benchlab.cli.main import main
from benchlab.drivers.apt.stage import AptStage
from benchlab.drivers.slc.controller import SlcController

pytestmark = pytest.mark.timeout(60)


def test_led_on_then_off_on_exit(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["led", "--simulate", "--channel", "1", "--current-ma", "40", "--on",
               "--for-s", "0"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "led channel 1 on at 40 mA (ceiling 50 mA)" in out  # the simulated bench's ceiling
    assert out.strip().endswith("led channel 1 off")


def test_led_over_ceiling_is_an_error(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["led", "--simulate", "--current-ma", "60", "--on", "--for-s", "0"])
    assert rc == 1
    assert "exceeds the ceiling 50.0 mA; nothing sent" in capsys.readouterr().err


def test_led_current_between_the_controllers_steps_is_an_error(
        capsys: pytest.CaptureFixture[str]) -> None:
    from benchlab.drivers.slc.sim import SimulatedSlc

    sim = SimulatedSlc(module="SLC-CA04-MU")  # 5 mA steps
    port = sim.start()
    try:
        rc = main(["led", "--port", port, "--ceiling-ma", "100", "--current-ma", "3", "--on",
                   "--for-s", "0"])
        assert rc == 1 and sim.channel_output_ma(1) == 0.0
        assert capsys.readouterr().err.startswith(
            "benchlab: error: LED channel 1: 3 mA cannot be set, the LED controller drives 5 mA"
            " steps (nearest: 0 or 5 mA); nothing sent")
        assert main(["led", "--port", port, "--ceiling-ma", "100", "--current-ma", "5", "--on",
                     "--for-s", "0"]) == 0
        assert "led channel 1 on at 5 mA" in capsys.readouterr().out
    finally:
        sim.stop()


def test_led_needs_port_or_simulate(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["led", "--off"]) == 1
    assert "--port" in capsys.readouterr().err


@pytest.mark.slow
def test_stage_commands(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["stage", "--simulate", "where"]) == 0
    assert "position 0.0000 mm, homed yes" in capsys.readouterr().out
    assert main(["stage", "--simulate", "--travel-mm", "0", "50", "move", "32"]) == 0
    assert "position 32.0000 mm" in capsys.readouterr().out
    assert main(["stage", "--simulate", "home"]) == 0
    assert "homed yes" in capsys.readouterr().out
    assert main(["stage", "--simulate", "move", "55"]) == 1  # the simulated bench's 0..50
    assert "outside travel [0.0, 50.0] mm; nothing sent" in capsys.readouterr().err
    assert main(["stage", "--simulate", "--travel-mm", "0", "25", "move", "30"]) == 1
    assert "outside travel [0.0, 25.0] mm; nothing sent" in capsys.readouterr().err


def test_simulate_serves_until_interrupted() -> None:
    child = subprocess.Popen([sys.executable, "-m", "benchlab.cli.main", "simulate", "--homed",
                              "--time-scale", "100"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        kind1, led_port = child.stdout.readline().split()
        kind2, stage_port = child.stdout.readline().split()
        assert (kind1, kind2) == ("led", "stage")
        assert led_port.startswith("/dev/pts/") and stage_port.startswith("/dev/pts/")
        with SlcController(led_port, ceilings_ma={1: 100}) as slc:
            slc.on(1, 20)
            assert slc.get_current(1) == (100.0, 20.0)
        with AptStage(stage_port, travel_mm=(0.0, 50.0)) as stage:
            stage.move_to_mm(18.0)
            assert stage.position_mm == pytest.approx(18.0, abs=1e-4)
    finally:
        os.kill(child.pid, signal.SIGINT)
        assert child.wait(timeout=20) == 0


def test_list_serial_devices_simulated() -> None:
    rows = list_serial_devices(simulate=True)
    assert [r["kind"] for r in rows] == ["led", "stage"]
    for r in rows:
        assert set(r) == {"kind", "model", "serial", "firmware", "port"}
    assert rows[0]["model"] == "SLC-SA04-U/S" and rows[0]["firmware"] == "3.1.8"
    assert rows[1]["model"] == "KDC101" and rows[1]["serial"] == "27000001"


def test_list_serial_devices_hardware_does_not_fail() -> None:
    assert isinstance(list_serial_devices(simulate=False), list)


def test_benchmark_serial(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["benchmark", "serial", "--repeat", "3"]) == 0
    out = capsys.readouterr().out
    assert "SLC ?CURRENT round trip" in out and "APT 17 mm move" in out


def test_missing_values_are_usage_errors_before_any_device_opens(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``led --on`` without a current and ``stage move`` without a position cannot be meant:
    exit 2, and the port named is never opened (it does not exist)."""
    assert main(["led", "--port", "/nonexistent/ttyUSB9", "--on"]) == 2
    assert "led --on needs --current-ma" in capsys.readouterr().err
    assert main(["stage", "--port", "/nonexistent/ttyUSB9", "move"]) == 2
    assert "stage move needs a position in mm" in capsys.readouterr().err


def test_simulate_led_echo_starts_the_controller_echoing() -> None:
    import serial

    child = subprocess.Popen([sys.executable, "-m", "benchlab.cli.main", "simulate",
                              "--led-echo"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        _, led_port = child.stdout.readline().split()
        child.stdout.readline()
        with serial.Serial(led_port, 9600, timeout=0.3) as port:  # a terminal program
            port.write(b"?MODE 1\n\r")
            assert port.read(100) == b"?MODE 1\n\r>#0 \r\n>"
        with SlcController(led_port, ceilings_ma={1: 100}) as slc:  # echo switched off
            slc.on(1, 20)
            assert slc.get_current(1) == (100.0, 20.0)
    finally:
        os.kill(child.pid, signal.SIGINT)
        assert child.wait(timeout=20) == 0
