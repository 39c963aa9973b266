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


def _advance_on_clear(cam: MightexCamera, clock: ManualClock, dt_s: float) -> None:
    """Let ``dt_s`` pass after every 0x35 or 0x34 the driver sends (a frame arrives)."""
    send = cam._send

    def send_then_wait(data: bytes) -> None:
        send(data)
        if data[0] in (p.CMD_CLEAR_BUFFER, p.CMD_GET_IMAGE):
            clock.advance(dt_s)

    cam._send = send_then_wait  # type: ignore[method-assign]


def test_a_full_buffer_drops_new_frames_and_grab_still_returns_a_fresh_one() -> None:
    """Difference 5 (the buffer keeps its oldest frames) and the issue-29 defect (a grab
    after idling returned a frame exposed long before it)."""
    clock = ManualClock()
    sim = SimulatedCamera(clock=clock, noise=False)
    with _open(sim) as cam:
        cam.configure(width=64, height=16, buffer_count=4)
        cam.set_exposure_ms(50.0)  # period = exposure (longer than frame time and readout)
        t_ms = round((clock.now() - sim._t0) * 1000)
        assert sim.period_s == pytest.approx(0.05)
        assert cam.buffer_status().frames == 0
        with pytest.raises(DeviceTimeoutError):
            cam.grab(timeout_s=0)  # a manual clock never jumps
        clock.advance(0.125)
        assert cam.buffer_status().frames == 2  # ready at 50 and 100 ms
        clock.advance(10.0)  # 202 periods in all: the first 4 kept, the 198 after dropped
        assert cam.buffer_status().frames == 4 and sim.dropped_frames == 198
        stale = cam.grab(fresh=False)  # the newest the camera holds: 10 s old
        assert stale.meta.timestamp_ms == pytest.approx(t_ms + 200, abs=1)
        _advance_on_clear(cam, clock, 0.05)
        clock.advance(0.05)  # a frame was exposed since
        sim.command_log.clear()
        now_ms = round((clock.now() - sim._t0) * 1000)
        fresh = cam.grab()
        # Cleared: what was buffered; read and dropped: the frame under way; read: the next.
        assert [c[0] for c in sim.command_log] == [0x33, 0x35, 0x33, 0x34, 0x33, 0x34]
        assert fresh.meta.timestamp_ms - fresh.meta.exposure_ms >= now_ms - 1
        assert fresh.meta.timestamp_ms > stale.meta.timestamp_ms + 10_000


def test_virtual_clock_jumps_so_grab_never_waits() -> None:
    clock = VirtualClock()
    sim = SimulatedCamera(clock=clock, noise=False, model="MCE-B013-U/v1.0.6")
    with MightexCamera.open(backend=SimCameraBackend([sim]), model=sim.model) as cam:
        cam.set_exposure_ms(100_000.0)  # 100 s exposures (4-byte field), still instant
        t0 = clock.now()
        frame = cam.grab()
        assert frame.meta.exposure_ms == 100_000.0
        assert clock.now() - t0 == pytest.approx(300.0)  # cleared, under way, read


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
    for raw in ("62 03 00 00 00", "63 04 00 00 00 01", "60 07 05 01 04 00 00 04 00",
                "30 02 00 10",
                "99 00", "33 05 00"):
        sim.write_command(bytes.fromhex(raw))
    assert len(sim.rejected_commands) == 6
    assert sim.settings.gain_raw == 8 and sim.settings.width == 1280


def test_reset_restores_power_on_settings() -> None:
    clock = VirtualClock()
    sim = SimulatedCamera(noise=False, clock=clock)
    sim.write_command(p.encode_gain(40))
    sim.write_command(p.encode_work_mode("trigger", 12))
    clock.advance(0.1)  # the camera takes nothing for 100 ms after the work-mode command
    sim.write_command(p.encode_reset())
    assert (sim.settings.gain_raw, sim.settings.mode, sim.settings.bits) == (8, 0, 8)


def test_grab_clears_older_frames_and_does_not_chase_new_ones() -> None:
    clock = ManualClock()
    sim = SimulatedCamera(clock=clock, noise=False)
    with _open(sim) as cam:
        cam.configure(width=64, height=16, buffer_count=4)
        cam.set_exposure_ms(50.0)
        t_ms = round((clock.now() - sim._t0) * 1000)
        clock.advance(0.175)  # frames at 50, 100, 150 ms
        _advance_on_clear(cam, clock, 0.05)  # a frame arrives after every clear
        sim.command_log.clear()
        # 50..150 cleared, then 200 (under way at the call) read and dropped, 250 returned.
        assert cam.grab().meta.timestamp_ms == pytest.approx(t_ms + 250, abs=1)
        assert [c[0] for c in sim.command_log] == [0x33, 0x35, 0x33, 0x34, 0x33, 0x34]
        assert cam.skipped_frames == 4 and sim.buffered_frames == 1  # 300: not chased
