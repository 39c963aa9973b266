"""The bench camera's limits for parameter files: the driver's ``CameraSpec``, not a copy.

Every parameter module checks exposure and gain against these, so a file is refused before
the camera is touched for exactly what the camera itself would refuse, and a session records
the values the camera applies (its 0.05 ms exposure and 1/8 gain steps).
"""

from __future__ import annotations

from benchlab.drivers.mightex import protocol as camera

#: The bench camera (``bench.py`` opens this model unless the bench file says otherwise).
CAMERA_SPEC = camera.SPECS["MCE-B013-U"]
EXPOSURE_RANGE_MS = (camera.EXPOSURE_STEP_MS, CAMERA_SPEC.exposure_max_ms)
GAIN_RANGE = (CAMERA_SPEC.gain_raw_min / camera.GAIN_RAW_PER_UNITY,
              CAMERA_SPEC.gain_raw_max / camera.GAIN_RAW_PER_UNITY)
FRAME_SHAPE_PX = (CAMERA_SPEC.max_height, CAMERA_SPEC.max_width)


def camera_exposure_ms(exposure_ms: float) -> float:
    """The exposure the camera applies for a requested one (its 0.05 ms step): what a session
    records, e.g. 300.03 -> 300.05."""
    return round(camera.exposure_counts(exposure_ms, CAMERA_SPEC) * camera.EXPOSURE_STEP_MS, 6)


def camera_gain(gain: float) -> float:
    """The gain the camera applies for a requested one (its 1/8 step)."""
    return camera.gain_raw(gain, CAMERA_SPEC) / camera.GAIN_RAW_PER_UNITY
