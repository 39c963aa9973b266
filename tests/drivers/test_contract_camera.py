"""Camera contract: every Camera implementation behaves the same (simulator always, hardware
on opt-in; see tests/device_implementations.py)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from device_implementations import CAMERAS, Implementation

from benchlab.drivers.errors import SettingOutOfRangeError
from benchlab.drivers.interfaces import Camera

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(params=CAMERAS, ids=str)
def camera(request: pytest.FixtureRequest) -> Iterator[Camera]:
    impl: Implementation[Camera] = request.param
    with impl.opener() as cam:
        yield cam


def test_is_a_camera_with_an_identity(camera: Camera) -> None:
    assert isinstance(camera, Camera)
    ident = camera.identity
    assert ident.model and ident.serial and ident.firmware
    assert ident.port is None
    assert set(ident.to_dict()) == {"model", "serial", "firmware"}


@pytest.mark.parametrize(("bits", "dtype", "top"), [(8, np.uint8, 255), (12, np.uint16, 4095)])
def test_grab_delivers_the_configured_frame(camera: Camera, bits: int, dtype: type,
                                            top: int) -> None:
    camera.configure(width=640, height=480, bits=bits)
    camera.set_exposure_ms(5.0)
    camera.set_gain(2.0)
    frame = camera.grab()
    assert frame.pixels.shape == (480, 640)
    assert frame.pixels.dtype == dtype
    assert int(frame.pixels.max()) <= top
    assert frame.meta.bits == bits
    assert frame.meta.exposure_ms == pytest.approx(5.0)
    assert frame.meta.gain == pytest.approx(2.0)
    assert {"exposure_ms", "gain", "bits"} <= set(frame.meta.to_dict())


def test_settings_read_back(camera: Camera) -> None:
    camera.set_exposure_ms(12.5)
    camera.set_gain(1.5)
    assert camera.exposure_ms == pytest.approx(12.5)
    assert camera.gain == pytest.approx(1.5)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -1.0, 0.0, True, "10"])
def test_bad_exposure_or_gain_is_refused_and_changes_nothing(camera: Camera, bad: object) -> None:
    camera.set_exposure_ms(10.0)
    camera.set_gain(1.0)
    with pytest.raises(SettingOutOfRangeError):
        camera.set_exposure_ms(bad)  # type: ignore[arg-type]
    with pytest.raises(SettingOutOfRangeError):
        camera.set_gain(bad)  # type: ignore[arg-type]
    assert camera.exposure_ms == pytest.approx(10.0)
    assert camera.gain == pytest.approx(1.0)


@pytest.mark.parametrize("kwargs", [{"width": -8}, {"height": 0}, {"width": 640.0},
                                    {"bits": True}, {"width": 100_000}])
def test_bad_geometry_is_refused(camera: Camera, kwargs: dict[str, object]) -> None:
    with pytest.raises(SettingOutOfRangeError):
        camera.configure(**kwargs)  # type: ignore[arg-type]
    frame = camera.grab()  # still configured as before: full frame
    assert frame.pixels.shape == (1024, 1280)


@pytest.mark.parametrize("timeout_s", [-1.0, float("nan")])
def test_bad_timeout_is_refused(camera: Camera, timeout_s: float) -> None:
    with pytest.raises(SettingOutOfRangeError, match="timeout_s"):
        camera.grab(timeout_s=timeout_s)


def test_clear_buffer_then_grab(camera: Camera) -> None:
    camera.set_exposure_ms(1.0)
    assert camera.clear_buffer() >= 0
    assert camera.grab().pixels.shape == (1024, 1280)


def test_reopen_keeps_settings(camera: Camera) -> None:
    camera.configure(width=320, height=240, bits=12)
    camera.set_exposure_ms(7.5)
    camera.reopen()
    assert camera.exposure_ms == pytest.approx(7.5)
    frame = camera.grab()
    assert frame.pixels.shape == (240, 320) and frame.meta.bits == 12
