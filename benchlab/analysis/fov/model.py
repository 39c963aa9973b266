"""The imaging geometry of the forward view: chart point -> field angle -> image position.

Frame: ``z`` along the stage's travel (the mechanical axis), origin at the entrance pupil. A
chart point ``(X, Y)`` (mm, in the chart's plane, ``Y`` along image rows) mounted with a roll
``psi`` and a lateral offset ``(x0, y0)`` at object distance ``D`` (from the lens's front
reference) sits at ``(x0 + X cos psi - Y sin psi, y0 + X sin psi + Y cos psi, D + e)`` where
``e`` is the entrance pupil's distance behind that reference. The optical axis is the
mechanical axis turned by the rotation vector ``(wx, wy, 0)``: the direction of view (the
angle between the two axes) is ``|w|``. In the camera frame a ray at field angle ``theta``
and azimuth ``phi`` lands at ``centre + h(theta) / pitch * (cos phi, sin phi)`` in
``(col, row)``, ``h`` the image-height mapping (mm).

The simulator (:mod:`benchlab.scenes.dots`) and the fit (:mod:`.fit`) both call
:func:`project`; they differ only in ``h``: the simulator's exact blend of ``f tan theta`` and
``f theta``, the fit's odd polynomial :func:`poly_height_mm`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from benchlab.analysis.arrays import FloatArray
from benchlab.drivers.mightex.profile import PIXEL_PITCH_UM

#: Pixel pitch, mm.
PIXEL_MM = PIXEL_PITCH_UM / 1000.0
HeightFn = Callable[[FloatArray], FloatArray]


@dataclass(frozen=True)
class Pose:
    """Where the chart and the optical axis are (module docstring); angles in radians."""

    centre_col: float
    centre_row: float
    entrance_pupil_mm: float
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    roll_rad: float = 0.0
    offset_x_mm: float = 0.0
    offset_y_mm: float = 0.0


def chart_points_mm(ij: FloatArray, pitch_mm: float, distance_mm: float | FloatArray,
                    pose: Pose) -> FloatArray:
    """World coordinates ``(n, 3)`` of grid dots ``ij`` (column index, row index) at object
    distances ``distance_mm`` (one per dot, or one for all)."""
    x = ij[:, 0] * pitch_mm
    y = ij[:, 1] * pitch_mm
    c, s = np.cos(pose.roll_rad), np.sin(pose.roll_rad)
    z = np.broadcast_to(np.asarray(distance_mm, dtype=np.float64), x.shape)
    return np.stack([pose.offset_x_mm + c * x - s * y, pose.offset_y_mm + s * x + c * y,
                     z + pose.entrance_pupil_mm], axis=1)


def to_camera(points: FloatArray, tilt_x_rad: float, tilt_y_rad: float) -> FloatArray:
    """Points in the camera frame: the inverse of the axis's rotation (Rodrigues)."""
    w = np.array([tilt_x_rad, tilt_y_rad, 0.0])
    angle = float(np.linalg.norm(w))
    if angle == 0.0:
        return np.asarray(points, dtype=np.float64)
    k = -w / angle  # the inverse rotation
    cos, sin = np.cos(angle), np.sin(angle)
    kxp = np.cross(k, points)
    kdp = points @ k
    return np.asarray(points * cos + kxp * sin + np.outer(kdp, k) * (1.0 - cos))


def field_angles(points: FloatArray, pose: Pose) -> tuple[FloatArray, FloatArray]:
    """``(theta, phi)`` (radians) of world points seen through the pose's optical axis."""
    cam = to_camera(points, pose.tilt_x_rad, pose.tilt_y_rad)
    theta = np.arctan2(np.hypot(cam[:, 0], cam[:, 1]), cam[:, 2])
    phi = np.arctan2(cam[:, 1], cam[:, 0])
    return theta, phi


def project(points: FloatArray, pose: Pose, height_mm: HeightFn) -> FloatArray:
    """Image positions ``(n, 2)`` as ``(col, row)`` px of world points."""
    theta, phi = field_angles(points, pose)
    rho = height_mm(theta) / PIXEL_MM
    return np.stack([pose.centre_col + rho * np.cos(phi),
                     pose.centre_row + rho * np.sin(phi)], axis=1)


def blend_height_mm(focal_length_mm: float, barrel: float) -> HeightFn:
    """The simulator's mapping: ``f ((1 - b) tan theta + b theta)``; ``b = 0`` rectilinear,
    ``1`` equidistant, above 1 stronger barrel."""
    def h(theta: FloatArray) -> FloatArray:
        t = np.asarray(theta, dtype=np.float64)
        return focal_length_mm * ((1.0 - barrel) * np.tan(t) + barrel * t)
    return h


def poly_height_mm(coeffs: FloatArray) -> HeightFn:
    """The fit's mapping: ``a1 theta + a3 theta^3 + a5 theta^5 + ...`` (``coeffs`` =
    ``a1, a3, a5, ...``); ``a1`` is the paraxial focal length."""
    c = np.asarray(coeffs, dtype=np.float64)

    def h(theta: FloatArray) -> FloatArray:
        t = np.asarray(theta, dtype=np.float64)
        return np.asarray(sum(ck * t ** (2 * k + 1) for k, ck in enumerate(c)) + 0.0 * t)
    return h
