"""The pyusb driver against the simulated firmware: exact bytes on the wire, frames, limits."""

from __future__ import annotations

import numpy as np
import pytest
import usb.core
from hypothesis import given, settings
from hypothesis import strategies as st

from benchlab.drivers.errors import DeviceNotFoundError, DeviceTimeoutError, SettingOutOfRangeError
from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.camera import MightexCamera, find_cameras
from benchlab.drivers.mightex.sim import (
    SimCameraBackend,
    SimulatedCamera,
    flat_field_scene,
)
from benchlab.drivers.sensor import rate_for_dn8

H = bytes.fromhex


def open_sim(**kwargs) -> tuple[SimulatedCamera, MightexCamera]:
    kwargs.setdefault("noise", False)
    sim = SimulatedCamera(**kwargs)
    return sim, MightexCamera.open(backend=SimCameraBackend([sim]), pid=sim.pid)


def test_open_sends_wake_up_identity_and_full_configuration() -> None:
    sim, cam = open_sim()
    with cam:
        assert cam.info.model == "MCE-B013-U"
        assert (cam.info.serial, cam.info.firmware, cam.info.pid) == ("SIM-130001", "1.0.6", 0x428)
        log = list(sim.command_log)
    # The 0x60 changed nothing (power-on geometry), so the frames of the 100 ms the driver
    # waited after 0x30 are still there: the 0x33 poll finds 3 and the driver flushes them.
    assert log == [H("01 01 01"), H("21 01 00"), H("30 02 00 08"), H("60 07 05 00 04 00 00 04 00"),
                   H("33 01 00"), H("35 01 03"), H("63 02 00 c8"), H("64 02 00 01"),
                   H("62 03 08 08 08")]
    assert not sim.rejected_commands  # the 0x60 came after the 100 ms the camera needs


def test_every_command_is_sent_byte_exact() -> None:
    sim, cam = open_sim()
    with cam:
        sim.command_log.clear()
        cam.set_exposure_ms(300)
        cam.set_gain(2.5)
        cam.set_frame_time_ms(100)
        cam.configure(width=640, height=480, bits=12, mode="trigger", buffer_count=24)
        cam.software_trigger()
        # The virtual clock jumps to the end of the triggered exposure: one frame waits.
        assert cam.buffer_status() == p.BufferStatus(1, 640, 480, 0)
        assert cam.firmware_version() == "1.0.6"
        assert cam.device_info().serial == "SIM-130001"
        cam.reset()
        assert list(sim.command_log) == [
            H("63 02 17 70"), H("62 03 14 14 14"), H("64 02 07 d0"),
            H("30 02 01 0c"), H("60 07 02 80 01 e0 00 18 00"), H("33 01 00"),
            H("36 01 00"), H("33 01 00"), H("01 01 01"), H("21 01 00"),
            H("50 01 01"),  # the camera powers up for 3 s: asked every 0.5 s until it answers
            *[H("01 01 01")] * 7,
            H("30 02 01 0c"), H("60 07 02 80 01 e0 00 18 00"), H("33 01 00"),
            H("63 02 17 70"), H("64 02 07 d0"), H("62 03 14 14 14"),
        ]
        assert sim.settings.gain_raw == 20 and sim.settings.exposure_counts == 6000
        assert list(sim.rejected_commands) == [H("01 01 01")] * 6  # while powering up


def test_grab_8bit_exact_noise_free_values_and_zero_copy() -> None:
    sim, cam = open_sim(scene=flat_field_scene(rate_for_dn8(100, 300.0)))
    with cam:
        cam.set_exposure_ms(300)
        sim.command_log.clear()
        frame = cam.grab()
        # Fresh: what the camera holds is cleared unread (here the frame that completed as
        # the virtual clock jumped), the first frame after that (it may have been under way
        # at the call) is read and dropped, the next one returned.
        assert list(sim.command_log) == [H("33 01 00"), H("35 01 01"), H("33 01 00"),
                                         H("34 01 01"), H("33 01 00"), H("34 01 01")]
    assert frame.pixels.dtype == np.uint8 and frame.pixels.shape == (1024, 1280)
    assert np.all(frame.pixels == 100)
    assert not frame.pixels.flags.owndata  # a view of the USB receive buffer
    m = frame.meta
    assert (m.width, m.height, m.bits, m.gain, m.gain_raw) == (1280, 1024, 8, 1.0, 8)
    assert (m.exposure_ms, m.exposure_counts, m.trigger_occurred) == (300.0, 6000, False)
    d = m.to_dict()
    assert d["exposure_ms"] == 300.0 and isinstance(d["received_utc"], str)


def test_grab_12bit_and_8bit_is_12bit_shifted() -> None:
    rate = rate_for_dn8(100.3, 300.0)  # 12-bit code 1605 -> 8-bit 100
    sim, cam = open_sim(scene=flat_field_scene(rate))
    with cam:
        cam.set_exposure_ms(300)
        cam.configure(bits=12)
        f12 = cam.grab()
        cam.configure(bits=8)
        f8 = cam.grab()
    assert f12.pixels.dtype == np.uint16 and np.all(f12.pixels == 1605)
    assert np.all(f8.pixels == 1605 >> 4)


def test_saturation_at_adc_and_full_well() -> None:
    sim, cam = open_sim(scene=flat_field_scene(1e6))
    with cam:
        cam.configure(bits=12)
        assert np.all(cam.grab().pixels == 4095)
        cam.set_gain(0.5)  # full well reached before the ADC: 20000 e- * 0.5 * 4095/20000
        assert np.all(cam.grab().pixels == 2047)


def test_noise_model_statistics() -> None:
    rate = rate_for_dn8(100, 300.0)  # mean 1600 DN12 = 7814 e-
    sim, cam = open_sim(scene=flat_field_scene(rate), noise=True, seed=3)
    with cam:
        cam.configure(bits=12)
        cam.set_exposure_ms(300)
        a, b = cam.grab().pixels.astype(float), cam.grab().pixels.astype(float)
    electrons = 1600 / (4095 / 20000)
    expected_sigma = np.sqrt(electrons + 8.0**2) * 4095 / 20000
    assert abs(a.mean() - 1600) < 0.2
    assert abs(a.std() / expected_sigma - 1) < 0.02
    assert not np.array_equal(a, b)  # a new noise draw every frame
    assert abs((a - b).std() / (np.sqrt(2) * expected_sigma) - 1) < 0.05


def test_find_and_open_by_serial_among_several() -> None:
    sims = [SimulatedCamera(serial=f"SIM-00000{i}", noise=False) for i in (1, 2)]
    backend = SimCameraBackend(sims)
    infos = find_cameras(backend=backend)
    assert [(i.serial, i.address) for i in infos] == [("SIM-000001", 2), ("SIM-000002", 3)]
    with MightexCamera.open("SIM-000002", backend=backend) as cam:
        assert cam.info.serial == "SIM-000002"
    with pytest.raises(DeviceNotFoundError, match="found: SIM-000001, SIM-000002"):
        MightexCamera.open("NOPE", backend=backend)
    assert find_cameras(backend=backend, pid=0x0528) == []


def test_configurable_pid() -> None:
    sim = SimulatedCamera(pid=0x0529, noise=False)
    backend = SimCameraBackend([sim])
    with pytest.raises(DeviceNotFoundError, match="PID 0x0428"):
        MightexCamera.open(backend=backend)
    with MightexCamera.open(backend=backend, pid=0x0529) as cam:
        assert cam.info.pid == 0x0529


def test_v105_model_uses_two_byte_exposure() -> None:
    sim, cam = open_sim(model="BTN-B013U", firmware=(1, 0, 5))
    with cam:
        assert cam.spec.exposure_bytes == 2
        cam.set_exposure_ms(750)
        assert sim.command_log[-1] == H("63 02 3a 98")
        assert cam.grab().meta.exposure_ms == 750.0
        with pytest.raises(SettingOutOfRangeError, match="0.05 .. 750 ms"):
            cam.set_exposure_ms(751)
        with pytest.raises(SettingOutOfRangeError, match="accepts 8"):
            cam.configure(bits=12)


def test_trigger_mode_one_frame_per_software_trigger() -> None:
    sim, cam = open_sim()
    with cam:
        cam.configure(mode="trigger")
        with pytest.raises(DeviceTimeoutError, match="no frame within 0 s"):
            cam.grab(timeout_s=0)
        cam.software_trigger()
        cam.software_trigger()
        first, second = cam.grab(), cam.grab()
        assert (first.meta.trigger_occurred, first.meta.trigger_count) == (True, 1)
        assert second.meta.trigger_count == 2
        with pytest.raises(DeviceTimeoutError):
            cam.grab(timeout_s=0)


def test_any_pyusb_client_and_bare_wake_up_byte() -> None:
    sim = SimulatedCamera(serial="13-000042", noise=False)
    dev = usb.core.find(idVendor=0x04B4, idProduct=0x0428, backend=SimCameraBackend([sim]))
    assert (dev.manufacturer, dev.product, dev.serial_number) == ("Mightex", "MCE-B013-U",
                                                                 "13-000042")
    dev.set_configuration()
    dev.write(0x01, b"\x21")  # bare wake-up byte: answered with the device info
    reply = bytes(dev.read(0x81, 255))
    assert reply[:2] == H("01 2b") and len(reply) == 45 and reply[17:26] == b"13-000042"
    dev.write(0x01, H("01 01 01"))
    assert bytes(dev.read(0x81, 255)) == H("01 03 01 00 06")
    dev.write(0x01, H("60 07 00 10 00 08 00 04 00"))  # 16x8
    dev.write(0x01, H("33 01 00"))
    assert bytes(dev.read(0x81, 255)) == H("01 06 01 00 10 00 08 00")
    dev.write(0x01, H("34 01 01"))
    data = bytes(dev.read(0x82, 4096))
    assert len(data) == 1024 and p.decode_trailer(data[512:]).row == 16
    with pytest.raises(usb.core.USBTimeoutError):
        dev.read(0x82, 4096)


@settings(max_examples=25, deadline=None)
@given(
    exposure_counts=st.one_of(st.sampled_from([1, 2, 15_000, 14_999]), st.integers(1, 15_000)),
    gain_raw=st.one_of(st.sampled_from([1, 8, 64]), st.integers(1, 64)),
)
def test_exposure_and_gain_limits_reach_the_frame(exposure_counts: int, gain_raw: int) -> None:
    sim, cam = open_sim()
    with cam:
        cam.configure(width=64, height=8)
        cam.set_exposure_ms(exposure_counts * 0.05)
        cam.set_gain(gain_raw / 8)
        assert sim.command_log[-2] == H("63 02") + exposure_counts.to_bytes(2, "big")
        assert sim.command_log[-1] == bytes((0x62, 3, gain_raw, gain_raw, gain_raw))
        meta = cam.grab().meta
    assert (meta.exposure_counts, meta.gain_raw) == (exposure_counts, gain_raw)
    assert meta.exposure_ms == pytest.approx(exposure_counts * 0.05)
    assert meta.gain == gain_raw / 8


@settings(max_examples=25, deadline=None)
@given(value=st.one_of(st.floats(-1e6, 0.0499), st.floats(750.01, 1e9)))
def test_exposure_out_of_range_sends_nothing(value: float) -> None:
    sim, cam = open_sim()
    with cam:
        before = list(sim.command_log)
        with pytest.raises(SettingOutOfRangeError, match=r"0\.05 \.\. 750 ms"):
            cam.set_exposure_ms(value)
        with pytest.raises(SettingOutOfRangeError, match=r"0\.125 \.\. 8x"):
            cam.set_gain(value if value < 0.1 else 8.5)
        assert list(sim.command_log) == before
        assert cam.exposure_ms == 10.0


sizes = st.integers(2, 320).map(lambda k: 4 * k)


@settings(max_examples=25, deadline=None)
@given(
    width=st.one_of(st.sampled_from([8, 12, 1276, 1280]), sizes.filter(lambda w: w <= 1280)),
    height=st.one_of(st.sampled_from([8, 12, 1020, 1024]), sizes.filter(lambda h: h <= 1024)),
    bits=st.sampled_from([8, 12]),
)
def test_geometry_limits_and_padding(width: int, height: int, bits: int) -> None:
    rate = rate_for_dn8(50, 10.0)  # 12-bit code 800
    sim, cam = open_sim(scene=flat_field_scene(rate))
    with cam:
        cam.configure(width=width, height=height, bits=bits, buffer_count=1)
        frame = cam.grab()
    assert frame.pixels.shape == (height, width)
    assert cam.layout.total_bytes % 512 == 0
    assert np.all(frame.pixels == (800 if bits == 12 else 50))


@pytest.mark.parametrize("kwargs", [{"width": 1282}, {"height": 6}, {"width": 642},
                                    {"bits": 16}, {"buffer_count": 0}])
def test_bad_geometry_sends_nothing(kwargs: dict) -> None:
    sim, cam = open_sim()
    with cam:
        before = list(sim.command_log)
        with pytest.raises(SettingOutOfRangeError, match="accepts"):
            cam.configure(**kwargs)
        assert list(sim.command_log) == before
