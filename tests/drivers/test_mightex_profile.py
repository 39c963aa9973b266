"""Issue 31, differences 1-4: the camera's per-model facts, and a driver that notices when the
camera (a simulator built from another profile) does not follow them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from benchlab.drivers.errors import ProtocolError
from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.camera import CameraProfileMismatchError, MightexCamera
from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera, flat_field_scene
from benchlab.drivers.sensor import rate_for_dn8

H = bytes.fromhex
MCE = p.SPECS["MCE-B013-U"]


def _open(sim: SimulatedCamera, **kwargs: object) -> MightexCamera:
    return MightexCamera.open(backend=SimCameraBackend([sim]), **kwargs)  # type: ignore[arg-type]


def test_mce_defaults_follow_the_cmos_sources() -> None:
    assert (MCE.exposure_bytes, MCE.exposure_unit_ms, MCE.exposure_max_ms) == (2, 0.05, 750.0)
    assert MCE.bit_depths == (8, 10, 12) and MCE.frame_time_unit_ms == 0.05
    assert (MCE.work_mode_wait_s, MCE.power_up_wait_s, MCE.buffer_full) == (0.1, 3.0, "drop_new")


def test_difference_1_exposure_is_a_two_byte_field_of_0_05_ms() -> None:
    sim = SimulatedCamera(noise=False)
    with _open(sim) as cam:
        cam.set_exposure_ms(750)
        assert sim.command_log[-1] == H("63 02 3a 98")
        assert cam.grab().meta.exposure_ms == 750.0


def test_difference_1_a_camera_with_a_four_byte_field_is_detected_not_decoded() -> None:
    """The camera ignores the 2-byte command (wrong length): its frames keep 10 ms."""
    sim = SimulatedCamera(noise=False, profile=p.SPECS["MCE-B013-U/v1.0.6"])
    with _open(sim, model="MCE-B013-U") as cam:
        cam.configure(width=64, height=16)
        cam.set_exposure_ms(50)
        assert sim.rejected_commands[-1] == H("63 02 03 e8")
        with pytest.raises(CameraProfileMismatchError,
                           match=r"exposure 200 counts.*set 1000 counts \(50 ms as a 2-byte"):
            cam.grab()


def test_difference_2_ten_bit_frames_decode_to_0_1023() -> None:
    sim = SimulatedCamera(noise=False, scene=flat_field_scene(1e6))  # saturated
    with _open(sim) as cam:
        sim.command_log.clear()
        cam.configure(width=64, height=16, bits=10)
        assert sim.command_log[0] == H("30 02 00 0a")
        frame = cam.grab()
    assert frame.meta.bits == 10 and int(frame.pixels.max()) == 1023
    assert np.all(frame.pixels == 1023)  # a 12-bit decode would read 4083


def test_difference_2_a_camera_without_the_10_bit_mode_is_named() -> None:
    sim = SimulatedCamera(noise=False, profile=p.SPECS["MCE-B013-U/v1.0.6"])
    with _open(sim, model="MCE-B013-U") as cam:
        cam.configure(width=64, height=16, bits=10)
        assert H("30 02 00 0a") in sim.rejected_commands
        with pytest.raises(ProtocolError, match="is an 8-bit frame.*profile differs"):
            cam.grab()


def test_difference_3_the_trailer_is_the_frames_truth_within_tolerance() -> None:
    """The camera raises 0.05 ms to its own minimum (0.1 ms): the frame is kept, and says so."""
    sim = SimulatedCamera(noise=False, min_exposure_counts=2,
                          scene=flat_field_scene(rate_for_dn8(100, 10.0)))
    with _open(sim) as cam:
        cam.configure(width=64, height=16)
        cam.set_exposure_ms(0.05)
        frame = cam.grab()
    assert (frame.meta.exposure_ms, frame.meta.set_exposure_ms) == (0.1, 0.05)
    assert frame.meta.exposure_counts == 2 and cam.discarded_frames == 0


def test_difference_3_a_gain_clamped_by_one_step_is_kept() -> None:
    profile = replace(MCE, gain_raw_max=63)
    sim = SimulatedCamera(noise=False, profile=profile)
    with _open(sim) as cam:
        cam.configure(width=64, height=16)
        cam.set_gain(8.0)  # raw 64: this camera refuses it and keeps raw 8 - far off
        with pytest.raises(CameraProfileMismatchError, match="gain raw 8"):
            cam.grab()


def test_difference_4_the_driver_waits_after_the_work_mode_command() -> None:
    """The camera ignores commands for 100 ms after 0x30; back to back, the 0x60 was lost."""
    sim = SimulatedCamera(noise=False)
    with _open(sim) as cam:
        cam.configure(width=64, height=16, bits=12)
        assert not sim.rejected_commands
        assert (sim.settings.width, sim.settings.height, sim.settings.bits) == (64, 16, 12)


def test_difference_4_a_replugged_camera_is_waited_for_while_it_powers_up() -> None:
    sim = SimulatedCamera(noise=False)
    with _open(sim) as cam:
        cam.configure(width=64, height=16)
        sim.unplug()
        sim.replug()  # silent for 3 s (simulated time: the driver's waits move the clock)
        t0 = sim.clock.now()
        cam.reopen()
        assert sim.clock.now() - t0 >= 3.0
        assert cam.grab().pixels.shape == (16, 64)
        assert sim.rejected_commands  # the queries made while it powered up


def test_the_tolerance_does_not_let_a_frame_of_the_previous_settings_through() -> None:
    """10 ms -> 10.05 ms is within the trailer tolerance, but frames still carrying 10 ms are
    stale (left from before the change), not the camera's own adjustment."""
    sim = SimulatedCamera(noise=False)
    with _open(sim) as cam:
        cam.configure(width=64, height=16)
        sim.faults.stale_frames = 3
        cam.set_exposure_ms(10.05)
        frame = cam.grab(fresh=False)  # the newest buffered frame is one of the stale ones
    assert frame.meta.exposure_counts == 201 and cam.discarded_frames == 1
