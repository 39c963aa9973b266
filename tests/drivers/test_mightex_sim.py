"""Firmware simulator: clocks, the frame buffer, scenes and bench state."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.drivers.errors import DeviceTimeoutError
from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.camera import MightexCamera
from benchlab.drivers.mightex.sim import (
    ManualClock,
    RealTimeClock,
    SimCameraBackend,
    SimulatedCamera,
    VirtualClock,
    bar_target_scene,
    flat_field_scene,
)
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8


def _open(sim: SimulatedCamera) -> MightexCamera:
    return MightexCamera.open(backend=SimCameraBackend([sim]))


def test_manual_clock_fills_the_buffer_at_the_frame_period() -> None:
    clock = ManualClock()
    sim = SimulatedCamera(clock=clock, noise=False)
    with _open(sim) as cam:
        cam.configure(width=64, height=16, buffer_count=4)
        cam.set_exposure_ms(50.0)  # period = exposure (longer than frame time and readout)
        assert sim.period_s == pytest.approx(0.05)
        assert cam.buffer_status().frames == 0
        with pytest.raises(DeviceTimeoutError):
            cam.grab(timeout_s=0)  # a manual clock never jumps
        clock.advance(0.125)
        assert cam.buffer_status().frames == 2  # ready at 50 and 100 ms
        sim.command_log.clear()
        first = cam.grab()
        assert first.meta.timestamp_ms == 100  # the newest; the 50 ms frame cleared unread
        assert list(sim.command_log) == [bytes.fromhex(h) for h in (
            "33 01 00", "35 01 01", "33 01 00", "34 01 01")]
        assert cam.buffer_status().frames == 0 and cam.skipped_frames == 1
        clock.advance(10.0)  # 200 periods: the ring buffer keeps the newest 4
        assert cam.buffer_status().frames == 4
        assert cam.grab().meta.timestamp_ms == 10_100  # the last of 10.050 .. 10.100 s
        assert cam.buffer_status().frames == 0 and cam.skipped_frames == 4
        with pytest.raises(DeviceTimeoutError):
            cam.grab(timeout_s=0)
        clock.advance(0.05)
        assert cam.grab().meta.timestamp_ms == 10_150  # one waiting: read as is


def test_virtual_clock_jumps_so_grab_never_waits() -> None:
    clock = VirtualClock()
    sim = SimulatedCamera(clock=clock, noise=False)
    with _open(sim) as cam:
        cam.set_exposure_ms(100_000.0)  # 100 s exposures, still instant
        t0 = clock.now()
        frame = cam.grab()
        assert frame.meta.exposure_ms == 100_000.0
        assert clock.now() - t0 == pytest.approx(100.0)


def test_real_time_clock_follows_monotonic_time() -> None:
    clock = RealTimeClock()
    a = clock.now()
    assert clock.now() >= a >= 0.0
    assert clock.wait_until(a + 10.0) is False


def test_frames_reflect_bench_state_and_scene_at_grab_time() -> None:
    bench = {"led_ma": 100.0}

    def led_scene(state: AcquisitionState) -> np.ndarray:
        # 1 code (8-bit) per mA at 10 ms exposure, gain 1
        return np.full((state.height, state.width), rate_for_dn8(state.bench["led_ma"], 10.0))

    sim = SimulatedCamera(scene=led_scene, bench_state=lambda: dict(bench), noise=False)
    with _open(sim) as cam:
        cam.configure(width=32, height=8)
        assert np.all(cam.grab().pixels == 100)
        bench["led_ma"] = 40.0
        assert np.all(cam.grab().pixels == 40)
        assert np.all(cam.grab().pixels == 40)
        calls = sim.sensor.scene_calls
        cam.grab()
        assert sim.sensor.scene_calls == calls  # unchanged state: cached, not recomputed
        sim.scene = flat_field_scene(rate_for_dn8(7, 10.0))
        assert np.all(cam.grab().pixels == 7)


def test_time_dependent_scene_is_evaluated_every_frame() -> None:
    class Flicker:
        time_dependent = True

        def __call__(self, state: AcquisitionState) -> np.ndarray:
            dn8 = 10 + state.frame_index % 2 * 10
            return np.full((state.height, state.width), rate_for_dn8(dn8, 10.0))

    sim = SimulatedCamera(scene=Flicker(), noise=False)
    with _open(sim) as cam:
        cam.configure(width=16, height=8)
        values = {int(cam.grab().pixels[0, 0]) for _ in range(4)}
    assert values == {10, 20}


def test_bar_target_scene() -> None:
    scene = bar_target_scene(8, bright_e_per_ms=50, dark_e_per_ms=8)
    state = AcquisitionState(300.0, 1.0, 8, 32, 4, 0.0, 0)
    rate = scene(state)
    assert rate.shape == (4, 32)
    assert rate[0, :8].tolist() == [50] * 4 + [8] * 4
    assert np.all(rate == rate[0])
    horizontal = bar_target_scene(4, orientation="horizontal")(state)
    assert horizontal[:, 0].tolist() == [50, 50, 8, 8]
    with pytest.raises(ValueError, match="at least 2 pixels"):
        bar_target_scene(1)


def test_scene_with_wrong_shape_is_reported() -> None:
    sim = SimulatedCamera(scene=lambda state: np.zeros((2, 2)), noise=False)
    with _open(sim) as cam, pytest.raises(ValueError, match=r"scene returned shape \(2, 2\)"):
        cam.grab()


def test_invalid_commands_are_ignored_and_listed() -> None:
    sim = SimulatedCamera(noise=False)
    for raw in ("62 03 00 00 00", "63 02 00 01", "60 07 05 01 04 00 00 04 00", "30 02 00 0a",
                "99 00", "33 05 00"):
        sim.write_command(bytes.fromhex(raw))
    assert len(sim.rejected_commands) == 6
    assert sim.settings.gain_raw == 8 and sim.settings.width == 1280


def test_reset_restores_power_on_settings() -> None:
    sim = SimulatedCamera(noise=False)
    sim.write_command(p.encode_gain(40))
    sim.write_command(p.encode_work_mode("trigger", 12))
    sim.write_command(p.encode_reset())
    assert (sim.settings.gain_raw, sim.settings.mode, sim.settings.bits) == (8, 0, 8)


def test_grab_clears_older_frames_once_and_does_not_chase_new_ones() -> None:
    clock = ManualClock()
    sim = SimulatedCamera(clock=clock, noise=False)
    with _open(sim) as cam:
        cam.configure(width=64, height=16, buffer_count=4)
        cam.set_exposure_ms(50.0)
        clock.advance(0.175)  # frames at 50, 100, 150 ms
        send = cam._send

        def send_then_a_frame(data: bytes) -> None:  # a frame arrives after every clear
            send(data)
            if data[0] == 0x35:
                clock.advance(0.05)

        cam._send = send_then_a_frame  # type: ignore[method-assign]
        sim.command_log.clear()
        assert cam.grab().meta.timestamp_ms == 150  # the newest when asked; 200 not chased
        assert [c[0] for c in sim.command_log] == [0x33, 0x35, 0x33, 0x34]
        assert cam.skipped_frames == 2 and sim.buffered_frames == 1
