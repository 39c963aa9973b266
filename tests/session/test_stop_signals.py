"""SIGINT, SIGTERM and SIGHUP stop every command and the TUI safely (issue 10, item 1).

Each test runs the real ``benchlab`` program in a subprocess against the serial simulators
living in *this* process, and reads the device state from the simulators themselves - not
through the driver that was killed.
"""

from __future__ import annotations

import fcntl
import json
import os
import pty
import re
import signal
import struct
import subprocess
import sys
import termios
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from benchlab.drivers.apt.sim import SimulatedAptStage
from benchlab.drivers.slc.sim import SimulatedSlc
from benchlab.session import Session

ROOT = Path(__file__).resolve().parents[2]
RAD_SMALL = ROOT / "fixtures" / "params" / "radiometry-small.toml"
MTF_SMALL = ROOT / "fixtures" / "params" / "mtf-small.toml"
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]
ANSI_CSI = re.compile(rb"\x1b\[[0-9;?]*[ -/]*[@-~]")  # colours, cursor moves


def _wait(predicate: Callable[[], bool], what: str, proc: subprocess.Popen | None = None,
          timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"the program ended (status {proc.returncode}) before {what}")
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


def _benchlab(*args: str, **kw: object) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "benchlab.cli.main", *args],
                            text=True, **kw)  # type: ignore[call-overload]


class _Status(int):
    """An exit status that shows the program's stderr when an assertion on it fails."""

    stderr = ""

    def __repr__(self) -> str:
        return f"{int(self)} (stderr: {self.stderr[-1500:]!r})"


def _stopped_within(proc: subprocess.Popen[str], timeout_s: float = 30.0) -> int:
    try:
        _, err = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
    status = _Status(proc.returncode)
    status.stderr = err or ""
    return status


def _stage_still(stage: SimulatedAptStage) -> bool:
    before = stage.position_mm
    time.sleep(0.3)
    return not stage.moving and stage.position_mm == before


@pytest.fixture
def led() -> Iterator[SimulatedSlc]:
    with SimulatedSlc() as sim:
        yield sim


@pytest.fixture
def stage() -> Iterator[SimulatedAptStage]:
    """Real-time motion: a move lasts long enough to be interrupted."""
    with SimulatedAptStage(travel_mm=(0.0, 50.0), homed=True, time_scale=1.0) as sim:
        yield sim


@pytest.fixture
def fast_stage() -> Iterator[SimulatedAptStage]:
    """200x motion: moves take milliseconds, the run gets to its LED quickly."""
    with SimulatedAptStage(travel_mm=(0.0, 50.0), homed=True, time_scale=200.0) as sim:
        yield sim


def _expected_status(sig: signal.Signals) -> int:
    return 128 + int(sig)


# ---- benchlab led ----------------------------------------------------------------------------
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_led_switches_off_on_every_stop_signal(led: SimulatedSlc, sig: signal.Signals) -> None:
    proc = _benchlab("led", "--port", led.port, "--channel", "2", "--ceiling-ma", "100",
                     "--current-ma", "50", "--on",
                     stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None
    assert "on at 50 mA" in proc.stdout.readline()
    assert led.channel_output_ma(2) == 50.0
    proc.send_signal(sig)
    status = _stopped_within(proc)
    # Ctrl-C is the documented end of "held until Ctrl-C"; TERM and HUP report the signal.
    assert status == (0 if sig == signal.SIGINT else _expected_status(sig))
    assert [led.channel_output_ma(ch) for ch in range(1, 5)] == [0.0] * 4
    assert b"MODE 2 0\n\r" in led.host_lines()


# ---- benchlab stage --------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_stage_stops_on_every_stop_signal(stage: SimulatedAptStage, sig: signal.Signals) -> None:
    proc = _benchlab("stage", "--port", stage.port, "--travel-mm", "0", "50", "move", "40",
                     stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _wait(lambda: stage.moving and stage.position_mm > 0.05, "the stage to move", proc)
    proc.send_signal(sig)
    assert _stopped_within(proc) == _expected_status(sig)
    assert _stage_still(stage)
    assert stage.position_mm < 5.0  # stopped where it was, far from 40 mm


# ---- benchlab run ----------------------------------------------------------------------------
def _bench_file(tmp_path: Path, led: SimulatedSlc, stage: SimulatedAptStage) -> Path:
    path = tmp_path / "bench.toml"
    path.write_text(
        f'[camera]\nserial = ""\n[led]\nport = "{led.port}"\nchannel = 1\n'
        f'[led.ceiling_ma]\n1 = 50.0\n[stage]\nport = "{stage.port}"\n'
        'travel_mm = [0.0, 50.0]\nvelocity_mm_s = 2.0\n', encoding="utf-8")
    return path


def _journal(session: Path) -> list[dict]:
    lines = (session / "events.jsonl").read_text(encoding="utf-8").splitlines()
    return [json.loads(line) for line in lines if line.strip()]


def _only_session(root: Path) -> Path:
    found = [p for p in root.iterdir() if (p / "session.json").is_file()]
    assert len(found) == 1, found
    return found[0]


def _assert_interrupted(root: Path, sig: signal.Signals) -> None:
    path = _only_session(root)
    assert Session.open(path).status == "interrupted"
    reasons = [e.get("reason") for e in _journal(path) if e["kind"] == "interrupted"]
    assert reasons == [sig.name]


@pytest.mark.slow
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_run_radiometry_led_on_then_signal(
    tmp_path: Path, led: SimulatedSlc, fast_stage: SimulatedAptStage, sig: signal.Signals
) -> None:
    stage = fast_stage
    out = tmp_path / "sessions"
    out.mkdir()
    proc = _benchlab("run", "radiometry", "--simulate", "--yes", "--config",
                     str(_bench_file(tmp_path, led, stage)), "--params", str(RAD_SMALL),
                     "--out", str(out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _wait(lambda: led.channel_output_ma(1) > 0, "the LED to be switched on", proc, 60)
    proc.send_signal(sig)
    assert _stopped_within(proc) == _expected_status(sig)
    assert [led.channel_output_ma(ch) for ch in range(1, 5)] == [0.0] * 4
    assert _stage_still(stage)
    _assert_interrupted(out, sig)


@pytest.mark.slow
def test_run_radiometry_stage_moving_then_sigterm(
    tmp_path: Path, led: SimulatedSlc, stage: SimulatedAptStage
) -> None:
    out = tmp_path / "sessions"
    out.mkdir()
    proc = _benchlab("run", "radiometry", "--simulate", "--yes", "--config",
                     str(_bench_file(tmp_path, led, stage)), "--params", str(RAD_SMALL),
                     "--out", str(out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _wait(lambda: stage.moving, "the stage to move", proc, 60)
    proc.send_signal(signal.SIGTERM)
    assert _stopped_within(proc) == 143
    assert _stage_still(stage)
    assert stage.position_mm < 14.0  # short of the first field position (15 mm)
    _assert_interrupted(out, signal.SIGTERM)


@pytest.mark.slow
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_run_mtf_signal_mid_run(
    tmp_path: Path, led: SimulatedSlc, stage: SimulatedAptStage, sig: signal.Signals
) -> None:
    out = tmp_path / "sessions"
    out.mkdir()
    proc = _benchlab("run", "mtf", "--simulate", "--yes", "--config",
                     str(_bench_file(tmp_path, led, stage)), "--params", str(MTF_SMALL),
                     "--out", str(out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)

    def acquiring() -> bool:
        found = [p for p in out.iterdir() if (p / "events.jsonl").is_file()]
        return bool(found) and any(e["kind"] == "frame_saved" for e in _journal(found[0]))

    _wait(acquiring, "the first frame", proc, 60)
    proc.send_signal(sig)
    assert _stopped_within(proc) == _expected_status(sig)
    assert led.channel_output_ma(1) == 0.0 and _stage_still(stage)
    _assert_interrupted(out, sig)


# ---- the terminal UI -------------------------------------------------------------------------
def _spawn_tui(args: list[str], cwd: Path) -> tuple[subprocess.Popen[bytes], int]:
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 30, 100, 0, 0))
    env = {**os.environ, "TERM": "xterm-256color"}
    proc = subprocess.Popen([sys.executable, "-m", "benchlab.cli.main", *args], stdin=slave,
                            stdout=slave, stderr=slave, cwd=cwd, env=env, start_new_session=True)
    os.close(slave)
    return proc, master


class _Screen:
    """Drains the TUI's output so it never blocks on a full pty."""

    def __init__(self, master: int) -> None:
        self.master = master
        self.data = b""
        os.set_blocking(master, False)

    def pump(self) -> None:
        try:
            while chunk := os.read(self.master, 65536):
                self.data += chunk
        except (BlockingIOError, OSError):
            pass

    def press(self, key: bytes, then_shows: str, proc: subprocess.Popen[bytes]) -> None:
        """Send a key and wait until the screen draws ``then_shows`` (a key sent while a
        screen is still switching goes to the old one)."""
        mark = len(self.data)
        os.write(self.master, key)

        def shown() -> bool:
            self.pump()
            return then_shows.encode() in ANSI_CSI.sub(b"", self.data[mark:])

        _wait(shown, f"{then_shows!r} after the key {key!r}", proc)


@pytest.mark.slow
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_tui_mid_radiometry_signal(
    tmp_path: Path, led: SimulatedSlc, fast_stage: SimulatedAptStage, sig: signal.Signals
) -> None:
    stage = fast_stage
    sessions = tmp_path / "sessions"
    sessions.mkdir()
    proc, master = _spawn_tui(
        ["--simulate", "--config", str(_bench_file(tmp_path, led, stage)), "--sessions",
         str(sessions), "--radiometry-params", str(RAD_SMALL)], tmp_path)
    screen = _Screen(master)
    try:
        def seen(text: bytes) -> Callable[[], bool]:
            def check() -> bool:
                screen.pump()
                return text in screen.data
            return check

        _wait(seen(b"connected (simulated)"), "the bench to connect", proc, 60)
        screen.press(b"3", "Table 4.10 steps", proc)  # the Run screen, MTF chosen
        screen.press(b"p", "Radiometry (section 4.4)", proc)
        os.write(master, b"s")
        last_key = [time.monotonic()]

        def led_on() -> bool:
            screen.pump()
            if time.monotonic() - last_key[0] > 0.3:
                os.write(master, b"y")  # confirms the manual set-up prompt when it is shown
                last_key[0] = time.monotonic()
            return led.channel_output_ma(1) > 0

        _wait(led_on, "the LED to be switched on", proc, 60)
        proc.send_signal(sig)
        deadline = time.monotonic() + 30
        while proc.poll() is None and time.monotonic() < deadline:
            screen.pump()
            time.sleep(0.05)
        assert proc.poll() == _expected_status(sig), screen.data[-2000:]
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
    assert [led.channel_output_ma(ch) for ch in range(1, 5)] == [0.0] * 4
    assert _stage_still(stage)
    _assert_interrupted(sessions, sig)


@pytest.mark.slow
@pytest.mark.parametrize("how", ["SIGTERM", "SIGHUP", "q"])
def test_tui_stage_homing_stops_when_the_app_quits(
    tmp_path: Path, led: SimulatedSlc, how: str
) -> None:
    """Homing from the Devices screen (h) holds the device lock for the whole move: a quit
    (key or signal) must stop the carriage at once, not wait for it to reach the switch."""
    stage = SimulatedAptStage(travel_mm=(0.0, 50.0), homed=False, time_scale=1.0,
                              initial_position_mm=40.0)
    stage.start()
    proc, master = _spawn_tui(["--simulate", "--config", str(_bench_file(tmp_path, led, stage)),
                               "--sessions", str(tmp_path / "sessions")], tmp_path)
    screen = _Screen(master)
    try:
        def connected() -> bool:
            screen.pump()
            return b"connected (simulated)" in screen.data

        _wait(connected, "the bench to connect", proc, 60)
        os.write(master, b"h")  # the Devices screen is the first one shown
        _wait(lambda: stage.moving and stage.position_mm < 39.8, "the stage to home", proc)
        if how == "q":
            os.write(master, b"q")
        else:
            proc.send_signal(getattr(signal, how))
        deadline = time.monotonic() + 15
        while proc.poll() is None and time.monotonic() < deadline:
            screen.pump()
            time.sleep(0.05)
        want = 0 if how == "q" else _expected_status(getattr(signal, how))
        assert proc.poll() == want, screen.data[-2000:]
        assert _stage_still(stage)
        assert stage.position_mm > 30.0  # stopped near where it was (2 mm/s), not homed
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
        stage.stop()
