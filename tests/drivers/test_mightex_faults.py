"""Injected faults map to the right exception, and the driver recovers from each."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.drivers.errors import (
    DeviceLostError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    ProtocolError,
)
from benchlab.drivers.mightex.camera import MightexCamera, find_cameras
from benchlab.drivers.mightex.sim import (
    FirmwareSettings,
    SimCameraBackend,
    SimulatedCamera,
    flat_field_scene,
)
from benchlab.drivers.sensor import rate_for_dn8

H = bytes.fromhex


def open_sim(**kwargs) -> tuple[SimulatedCamera, MightexCamera, SimCameraBackend]:
    kwargs.setdefault("noise", False)
    kwargs.setdefault("scene", flat_field_scene(rate_for_dn8(100, 10.0)))
    sim = SimulatedCamera(**kwargs)
    backend = SimCameraBackend([sim])
    cam = MightexCamera.open(backend=backend)
    cam.configure(width=64, height=16)
    return sim, cam, backend


def test_reply_timeout_then_recovery() -> None:
    sim, cam, _ = open_sim()
    with cam:
        sim.faults.drop_replies = 1
        with pytest.raises(DeviceTimeoutError, match="buffer query"):
            cam.buffer_status()
        assert np.all(cam.grab().pixels == 100)
        sim.faults.drop_replies = 1
        with pytest.raises(DeviceTimeoutError):
            cam.grab()
        assert cam.grab().meta.width == 64


def test_late_reply_is_not_taken_for_the_next_querys() -> None:
    sim, cam, _ = open_sim()
    with cam:
        sim.faults.late_replies = 1
        with pytest.raises(DeviceTimeoutError, match="firmware version"):
            cam.firmware_version()
        # The firmware reply is now waiting: drained first, not read as the buffer status.
        status = cam.buffer_status()
        assert (status.width, status.height) == (64, 16)
        assert cam.firmware_version() == "1.0.6"
        assert np.all(cam.grab().pixels == 100)


def test_garbage_reply_is_a_protocol_error_then_recovery() -> None:
    sim, cam, _ = open_sim()
    with cam:
        sim.faults.garbage_replies = 1
        with pytest.raises(ProtocolError, match="length byte says 19 but 4 data bytes"):
            cam.firmware_version()
        assert cam.firmware_version() == "1.0.6"
        assert np.all(cam.grab().pixels == 100)


def test_non_one_status_byte_is_accepted() -> None:
    sim, cam, _ = open_sim()
    with cam:
        sim.faults.reply_status = 0x08
        assert cam.buffer_status().width == 64
        assert np.all(cam.grab().pixels == 100)


def test_short_frame_then_recovery() -> None:
    sim, cam, _ = open_sim()
    with cam:
        cam.configure(width=1280, height=1024)
        sim.faults.short_frames = 1
        with pytest.raises(ProtocolError, match="1307136 bytes, expected 1311232"):
            cam.grab()
        assert np.all(cam.grab().pixels == 100)


def test_unplug_mid_frame_then_reopen_restores_settings() -> None:
    sim, cam, backend = open_sim()
    with cam:
        cam.set_exposure_ms(20.0)
        sim.faults.unplug_mid_frame = True
        with pytest.raises(DeviceLostError, match="frame read"):
            cam.grab()
        with pytest.raises(DeviceLostError):
            cam.buffer_status()
        assert find_cameras(backend=backend) == []
        with pytest.raises(DeviceNotFoundError):
            cam.reopen()
        sim.replug()  # freshly powered: firmware back to its defaults
        assert sim.settings == FirmwareSettings()
        cam.reopen()
        frame = cam.grab()
        assert (frame.meta.width, frame.meta.height, frame.meta.exposure_ms) == (64, 16, 20.0)
        assert np.all(frame.pixels == 200)  # twice the exposure, twice the signal
    # A new driver object opens it too.
    with MightexCamera.open(backend=backend) as again:
        assert again.info.serial == "SIM-130001"


def test_unplugged_handle_stays_dead_after_replug() -> None:
    sim, cam, backend = open_sim()
    sim.unplug()
    sim.replug()
    with pytest.raises(DeviceLostError):
        cam.grab()
    cam.close()
    cam.close()  # idempotent


def test_stale_frames_after_exposure_change_are_discarded() -> None:
    sim, cam, _ = open_sim()
    with cam:
        cam.grab()
        sim.faults.stale_frames = 3
        cam.set_exposure_ms(5.0)
        assert sim.buffered_frames == 3  # exposed with 10 ms, still in the camera
        sent = sim.frames_sent
        skipped = cam.skipped_frames
        frame = cam.grab()
        assert frame.meta.exposure_ms == 5.0 and np.all(frame.pixels == 50)
        # A fresh grab clears the three unread; the one under way is read and dropped.
        assert cam.skipped_frames - skipped == 4 and cam.discarded_frames == 0
        assert sim.frames_sent == sent + 2


def test_stale_frames_of_other_geometry_are_cleared_unread() -> None:
    sim, cam, _ = open_sim()
    with cam:
        sim.inject_stale_frames(2, FirmwareSettings(width=640, height=480))
        sim.command_log.clear()
        frame = cam.grab()
        assert frame.pixels.shape == (16, 64)
        log = list(sim.command_log)
        assert log[:2] == [H("33 01 00"), H("35 01 02")]
        assert H("34 01 01") in log
        assert cam.discarded_frames == 0  # cleared by the fresh grab's first clear


def test_stale_frames_from_a_reconfiguration_are_flushed() -> None:
    sim, cam, _ = open_sim()
    with cam:
        sim.faults.stale_frames = 2
        sim.command_log.clear()
        # Same geometry, new bit depth: the camera's own 0x60 flush does not run (nothing
        # changed for it), so only the driver's clear can remove the two 8-bit frames - which
        # buffer status cannot tell from 12-bit ones (it reports geometry only).
        cam.configure(width=64, height=16, bits=12)
        log = list(sim.command_log)
        assert log[0][:1] == H("30") and log[1][:1] == H("60")
        # The driver's clear, for both and for the two exposed in the 100 ms after 0x30.
        assert log[2:] == [H("33 01 00"), H("35 01 04")]
        assert sim.buffered_frames == 0
        frame = cam.grab()
        assert frame.pixels.shape == (16, 64) and frame.pixels.dtype == np.uint16
        assert cam.discarded_frames == 0


def test_open_unplugged_camera_is_not_found() -> None:
    sim = SimulatedCamera()
    sim.unplug()
    with pytest.raises(DeviceNotFoundError, match="no Mightex camera found"):
        MightexCamera.open(backend=SimCameraBackend([sim]))


@pytest.mark.slow
def test_wake_up_retries_a_silent_camera_and_lists_a_dead_one() -> None:
    sim = SimulatedCamera(noise=False)
    backend = SimCameraBackend([sim])
    sim.faults.drop_replies = 1  # first firmware query after power-up goes unanswered
    with MightexCamera.open(backend=backend) as cam:
        assert cam.info.firmware == "1.0.6"
    sim.faults.drop_replies = 8  # silent for longer than the 3 s a camera takes to power up
    [info] = find_cameras(backend=backend)
    assert (info.serial, info.pid, info.address) == ("?", 0x0428, 2)
    assert "did not answer the firmware query for 4 s (8 tries)" in (info.error or "")
