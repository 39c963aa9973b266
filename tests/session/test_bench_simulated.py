"""The bench assembly: configuration, the simulated bench through the real drivers, and the
safe state on every way out."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sim_runs import RAD_SMALL, events

from benchlab.bench import Bench, BenchConfig, BenchError
from benchlab.drivers.errors import DeviceError, SafetyLimitError
from benchlab.protocols import start_run
from benchlab.scenes.led import LedScene
from benchlab.session import Session


def _sim() -> BenchConfig:
    return BenchConfig.load(None, simulate=True)


def test_packaged_simulated_config_round_trips() -> None:
    cfg = _sim()
    assert cfg.led is not None and cfg.led.ceilings_ma == {1: 50.0}
    assert cfg.stage is not None and cfg.stage.travel_mm == (0.0, 50.0)
    assert cfg.stage.counts_per_mm == 34554.96
    assert BenchConfig.from_dict(cfg.to_dict()).to_dict() == cfg.to_dict()
    assert BenchConfig.load(None).led is None  # a real bench with no file: camera only


def test_identities_come_from_the_devices() -> None:
    with Bench.open(_sim(), simulate=True) as bench:
        ids = bench.identities()
    assert ids["simulated"] is True
    assert ids["camera"]["model"] == "MCE-B013-U" and ids["camera"]["serial"] == "SIM-130001"
    assert ids["camera"]["firmware"]
    assert ids["led"]["serial"] == bench.sim_led.serial
    assert ids["led"]["firmware"].endswith(bench.sim_led.firmware)
    assert ids["stage"]["serial"] == str(bench.sim_stage.serial)
    assert ids["stage"]["model"] == "KDC101"


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt])
def test_safe_state_on_exception_and_ctrl_c(exc: type[BaseException]) -> None:
    holder: dict[str, Any] = {}
    with pytest.raises(exc):
        with Bench.open(_sim(), simulate=True, time_scale=20.0) as bench:
            holder["bench"] = bench
            bench.home_stage()
            bench.led_on(1, 30.0)
            assert bench.sim_led.channel_output_ma(1) == 30.0
            bench.stage.move_to_mm(45.0, wait=False)  # ~1 s of wall time at 20x
            for _ in range(200):
                if bench.sim_stage.moving:
                    break
                time.sleep(0.005)
            assert bench.sim_stage.moving
            raise exc()
    bench = holder["bench"]
    assert bench.sim_led.channel_output_ma(1) == 0.0
    assert not bench.sim_stage.moving and bench.sim_stage.position_mm < 45.0


def test_limits_are_checked_before_anything_is_sent() -> None:
    with Bench.open(_sim(), simulate=True) as bench:
        sent = len(bench.sim_led.host_lines())
        with pytest.raises(SafetyLimitError):
            bench.led_on(1, 80.0)  # ceiling 50 mA
        assert len(bench.sim_led.host_lines()) == sent
        assert bench.sim_led.channel_output_ma(1) == 0.0
        bench.home_stage()
        with pytest.raises(DeviceError):
            bench.move_stage_mm(60.0)  # travel 0..50 mm
        assert not bench.sim_stage.moving


def test_confirmed_set_ups_change_what_the_camera_sees() -> None:
    with Bench.open(_sim(), simulate=True, noise=False) as bench:
        bench.configure_camera(bits=8)
        bench.mount("dark")
        dark, _ = bench.grab(exposure_ms=300.0, gain=1.0)
        bench.mount("usaf")
        usaf, meta = bench.grab(exposure_ms=300.0, gain=1.0)
        bench.mount(("radial", 2.0, "tangential"))
        radial, meta_r = bench.grab(exposure_ms=300.0, gain=1.0)
    assert dark.max() <= 1 and usaf.max() > 150
    assert meta["bench"]["target"] == "usaf" and meta["exposure_ms"] == 300.0
    assert meta_r["bench"]["target"] == ["radial", 2.0, "tangential"]
    assert not np.array_equal(usaf, radial)


def test_real_bench_needs_ports_before_opening_anything(tmp_path: Path) -> None:
    cfg = tmp_path / "bench.toml"
    cfg.write_text("[led]\nchannel = 1\n[stage]\ntravel_mm = [0, 25]\n")
    with pytest.raises(BenchError, match="led.port, stage.port required"):
        with Bench.open(BenchConfig.load(cfg)):
            pass


@pytest.mark.slow
def test_radiometry_without_a_stage_prompts_the_operator(tmp_path: Path) -> None:
    cfg = BenchConfig.from_dict({"led": {"channel": 1, "ceiling_ma": {"1": 50.0}}})
    asked: list[str] = []

    def prompt(step: Any, message: str) -> bool:
        asked.append(message)
        return True

    with Bench.open(cfg, simulate=True, noise=False) as bench:
        assert not bench.has_stage
        outcome = start_run("radiometry", bench=bench, params=RAD_SMALL, root=tmp_path,
                            prompt=prompt).run()
    assert [m for m in asked if m.startswith("Move the LED")] == [
        "Move the LED to field position 15 mm.", "Move the LED to field position 18 mm.",
        "Move the LED to field position 25 mm."]
    rows = outcome.tables["table_4_16"]
    led = LedScene()
    plateau = [led.expected_plateau_dn8(r["position_mm"], 20.0, 375.0) for r in rows]
    assert plateau[1] == max(plateau)  # 18 mm is the brightest position, as in the thesis
    assert rows[1]["measured_normalised"] == 1.0
    session = Session.open(outcome.session_path)
    assert "stage" not in session.meta["devices"]
    assert sum(e["kind"] == "prompt" for e in events(outcome.session_path)) == 4


@pytest.mark.slow
def test_in_process_simulators_may_answer_late_on_a_loaded_cpu() -> None:
    """A simulator thread starved for 1.5 s (a busy CPU, issue 30) delays its reply past a real
    device's 1 s; the simulated bench waits for it instead of failing the step."""
    with Bench.open(_sim(), simulate=True) as bench:
        assert bench.sim_led is not None and bench.sim_stage is not None
        bench.sim_led.faults.late_reply, bench.sim_led.faults.late_reply_s = 1, 1.5
        t0 = time.monotonic()
        bench.led_on(1, 20.0)
        assert time.monotonic() - t0 >= 1.4
        assert bench.sim_led.channel_output_ma(1) == 20.0
        bench.sim_stage.faults.late_reply, bench.sim_stage.faults.late_reply_s = 1, 2.5
        bench.home_stage()
        assert bench.sim_stage.position_mm == 0.0
