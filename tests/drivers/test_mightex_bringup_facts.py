"""Issue 36, points 3-7: facts about the camera the bring-up settles on the bench - product id,
trailer order, timestamp unit, exposure-field width, region of interest - and a frame
endpoint drained after a frame of the wrong size. Simulators built from another profile (or
with a firmware behaviour) than the driver believes stand in for the unknown camera."""

from __future__ import annotations

from dataclasses import replace

import pytest

from benchlab.drivers.errors import ProtocolError
from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.camera import (
    CameraProfileMismatchError,
    CameraRoiRefusedError,
    FrameEndpointTimeoutError,
    MightexCamera,
    udev_rule_line,
    vendor_devices,
)
from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera

MCE = p.SPECS["MCE-B013-U"]


def _open(sim: SimulatedCamera, **kwargs: object) -> MightexCamera:
    return MightexCamera.open(backend=SimCameraBackend([sim]), **kwargs)  # type: ignore[arg-type]


def test_point_3_a_camera_of_another_product_id_is_listed_with_its_lines() -> None:
    backend = SimCameraBackend([SimulatedCamera(pid=0x0528)])
    with pytest.raises(ProtocolError.__mro__[1], match="PID 0x0428"):  # DeviceError family
        MightexCamera.open(backend=backend)
    [seen] = vendor_devices(backend)
    assert (seen.vid, seen.pid, seen.manufacturer, seen.product) == (
        0x04B4, 0x0528, "Mightex", "MCE-B013-U")
    assert seen.describe() == "04b4:0528 Mightex MCE-B013-U serial SIM-130001 (usb 1:2)"
    assert udev_rule_line(0x04B4, 0x0528) == (
        'SUBSYSTEM=="usb", ATTR{idVendor}=="04b4", ATTR{idProduct}=="0528", MODE="0660", '
        'GROUP="plugdev", TAG+="uaccess"')
    with MightexCamera.open(backend=backend, pid=0x0528) as cam:
        assert cam.info.pid == 0x0528


def test_point_4_the_trailer_order_shows_only_in_a_non_square_frame() -> None:
    sim = SimulatedCamera(noise=False, profile=replace(MCE, trailer_order="column_row"))
    with _open(sim) as cam:
        cam.configure(width=256, height=256, bits=8)
        assert cam.grab().meta.width == 256  # square: either order reads the same
        cam.configure(width=1280, height=1024, bits=8)
        with pytest.raises(p.TrailerGeometryError) as info:
            cam.grab()
        assert info.value.swapped and info.value.trailer == (1024, 1280)
        cam.use_profile(replace(cam.spec, trailer_order="column_row"))
        meta = cam.grab().meta
        assert (meta.width, meta.height) == (1280, 1024)


def test_point_5_the_timestamp_unit_is_a_profile_fact() -> None:
    sim = SimulatedCamera(noise=False, profile=replace(MCE, timestamp_unit_ms=0.1))
    with _open(sim) as cam:
        cam.configure(width=256, height=256, bits=8)
        cam.set_exposure_ms(100.0)
        a, b = cam.grab().meta.timestamp_ms, cam.grab(fresh=False).meta.timestamp_ms
        assert (b - a) % 65536 == 1000  # 1 ms assumed: the period reads 1000 ms
        cam.use_profile(replace(cam.spec, timestamp_unit_ms=0.1))
        a, b = cam.grab().meta.timestamp_ms, cam.grab(fresh=False).meta.timestamp_ms
        assert b - a == pytest.approx(100.0, abs=0.2)  # one 0.1 ms step of rounding
        t0 = cam.host_time_s()
        cam.grab()
        assert cam.host_time_s() - t0 >= 0.1  # the simulated host clock moves with frames


def test_point_6_a_firmware_that_reads_four_bytes_is_fitted_by_the_v106_profile() -> None:
    sim = SimulatedCamera(noise=False)
    sim.faults.exposure_reads_4_bytes = True
    with _open(sim) as cam:
        cam.configure(width=256, height=256, bits=8)
        cam.set_exposure_ms(100.0)
        with pytest.raises(CameraProfileMismatchError, match=r"exposure 131072\d{3} counts"):
            cam.grab()  # 07 d0 and two stale bytes of the command buffer: ~2000 x 65536
    with _open(sim, profile=p.SPECS["MCE-B013-U/v1.0.6"]) as cam:
        cam.configure(width=256, height=256, bits=8)
        cam.set_exposure_ms(100.0)
        assert cam.grab().meta.exposure_ms == 100.0


def test_point_7_after_a_wrong_size_frame_the_frame_endpoint_is_drained() -> None:
    sim = SimulatedCamera(noise=False)
    with _open(sim) as cam:
        cam.configure(width=256, height=256, bits=8)
        sim.write_command(p.encode_work_mode("normal", 12))  # the camera went to 12 bits...
        sim.clock.advance(0.2)  # type: ignore[attr-defined]
        with pytest.raises(ProtocolError):
            cam.grab()  # ...the driver reads an 8-bit frame's worth of a 12-bit one
        surplus = p.FrameLayout(256, 256, 12).total_bytes - p.FrameLayout(256, 256, 8).total_bytes
        assert cam.drained_bytes == surplus
        sim.write_command(p.encode_work_mode("normal", 8))
        sim.clock.advance(0.2)  # type: ignore[attr-defined]
        frame = cam.grab()  # not the rest of the 12-bit frame: a whole 8-bit one
        assert (frame.meta.width, frame.meta.height) == (256, 256)


def test_a_refused_region_of_interest_is_named_not_waited_for() -> None:
    sim = SimulatedCamera(noise=False)
    sim.faults.refuse_roi = True
    with _open(sim) as cam:
        cam.configure(width=256, height=256, bits=8)
        with pytest.raises(CameraRoiRefusedError, match="keeps sending 1280x1024 frames"):
            cam.grab(timeout_s=30.0)
        cam.configure(width=1280, height=1024, bits=8)
        assert cam.grab().meta.width == 1280


def test_frames_that_never_come_on_the_frame_endpoint_are_named() -> None:
    sim = SimulatedCamera(noise=False)
    sim.faults.frames_never_sent = True
    with _open(sim) as cam, pytest.raises(FrameEndpointTimeoutError, match="EP 0x82"):
        cam.grab()
