"""The forward view's figures from a fit and the disc, each with a 95 % interval.

- full field of view: ``2 theta_edge`` where the fitted mapping reaches the disc's radius;
- direction of view: the angle between the optical and the mechanical axis, ``|w|``;
- entrance pupil: ``e``;
- image height ``h(theta)`` at given field angles;
- local distortion (ISO 17850 style, % of image height) against ``f tan theta`` and against
  ``f theta``, ``f = a1`` the paraxial focal length: ``100 (h - h_model) / h_model``.

Intervals: the delta method on the fit's covariance (plus the disc radius's variance for the
field of view): ``value +- 1.96 sigma``, ``sigma`` from the figure's numerical gradient. The
direction of view is a length, which the delta method gets wrong near 0, so its interval is
the set of angles ``r`` whose circle ``|w| = r`` comes within the 95 % profile distance of the
fitted ``w`` (chi-square, 1 dof), widened to 0 when the fitted ``w`` is within the 2-dof 95 %
region of no tilt - 95 % coverage both at no tilt and far from it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.fov.disc import Disc
from benchlab.analysis.fov.fit import A1, Fit
from benchlab.analysis.fov.model import PIXEL_MM, poly_height_mm

Z95 = 1.959963984540054
CHI2_1_95 = 3.841458820694124
CHI2_2_95 = 5.991464547107979


@dataclass(frozen=True)
class Figure:
    """A value with its 95 % interval."""

    value: float
    low: float
    high: float

    @property
    def sigma(self) -> float:
        return (self.high - self.low) / (2.0 * Z95)

    def rounded(self, digits: int) -> tuple[float, list[float]]:
        """The value and interval rounded to ``digits`` decimals, or to more where the
        interval is narrow: the step is kept at most a tenth of its half-width, or rounding
        the ends moves them by a good part of it and the stored interval no longer covers what
        the computed one does (the radial view's are nanometres wide)."""
        half = (self.high - self.low) / 2.0
        if half > 0 and math.isfinite(half):
            digits = max(digits, min(math.ceil(-math.log10(half / 10.0)), 12))
        return round(self.value, digits), [round(self.low, digits), round(self.high, digits)]


def delta(fn: Callable[[FloatArray], float], x: FloatArray, cov: FloatArray) -> Figure:
    """``fn(x)`` with the delta-method 95 % interval (central differences)."""
    v = fn(x)
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0))
    grad = np.zeros(len(x))
    for k in range(len(x)):
        h = 1e-4 * sig[k] if sig[k] > 0 else 1e-9
        up, dn = x.copy(), x.copy()
        up[k] += h
        dn[k] -= h
        grad[k] = (fn(up) - fn(dn)) / (2.0 * h)
    s = math.sqrt(max(float(grad @ cov @ grad), 0.0))
    return Figure(v, v - Z95 * s, v + Z95 * s)


def edge_angle_rad(coeffs: FloatArray, height_mm: float, limit_rad: float = 1.5) -> float:
    """The field angle at which the mapping reaches ``height_mm`` (the first crossing)."""
    h = poly_height_mm(coeffs)
    grid = np.linspace(0.0, limit_rad, 601)
    vals = h(grid) - height_mm
    above = np.nonzero(vals >= 0)[0]
    if len(above) == 0:
        return math.nan
    k = int(above[0])
    if k == 0:
        return 0.0
    return float(brentq(lambda t: float(h(np.array([t]))[0]) - height_mm, grid[k - 1], grid[k],
                        xtol=1e-12))


def field_of_view(fit: Fit, disc: Disc) -> Figure:
    """Full field of view, degrees (module docstring)."""
    x = np.concatenate([fit.params[A1:], [disc.radius_px]])
    n = len(x)
    cov = np.zeros((n, n))
    cov[:-1, :-1] = fit.covariance[A1:, A1:]
    cov[-1, -1] = disc.covariance[2, 2]

    def fov(v: FloatArray) -> float:
        return 2.0 * math.degrees(edge_angle_rad(v[:-1], v[-1] * PIXEL_MM))
    return delta(fov, x, cov)


def direction_of_view(fit: Fit) -> tuple[Figure, float]:
    """Direction of view (degrees, module docstring) and the tilt's azimuth (degrees, from
    +col towards +row)."""
    w = fit.params[3:5]
    c = fit.covariance[3:5, 3:5]
    ci = np.linalg.inv(c)
    r_hat = float(np.hypot(*w))
    sig = math.sqrt(float(np.max(np.linalg.eigvalsh(c))))
    radii = np.linspace(max(r_hat - 8.0 * sig, 0.0), r_hat + 8.0 * sig, 801)
    # the circles near the fitted w only: around its azimuth when it is far from 0
    az0 = math.atan2(float(w[1]), float(w[0]))
    half = math.pi if r_hat < 10.0 * sig else 10.0 * sig / r_hat
    ang = az0 + np.linspace(-half, half, 361)
    d = np.stack([np.cos(ang), np.sin(ang)], axis=1)  # (a, 2)
    diff = radii[:, None, None] * d[None, :, :] - w[None, None, :]
    m2 = np.einsum("rai,ij,raj->ra", diff, ci, diff).min(axis=1)
    inside = radii[m2 <= CHI2_1_95]
    lo = float(inside.min()) if len(inside) else r_hat
    hi = float(inside.max()) if len(inside) else r_hat
    if float(w @ ci @ w) <= CHI2_2_95:
        lo = 0.0
    az = math.degrees(math.atan2(float(w[1]), float(w[0]))) if r_hat > 0 else 0.0
    return Figure(math.degrees(r_hat), math.degrees(lo), math.degrees(hi)), az


def entrance_pupil(fit: Fit) -> Figure:
    """Entrance pupil behind the front reference, mm."""
    return delta(lambda v: float(v[0]), fit.params[2:3], fit.covariance[2:3, 2:3])


def image_height(fit: Fit, angle_deg: float) -> Figure:
    """``h`` at a field angle, mm."""
    t = math.radians(angle_deg)
    return delta(lambda v: float(poly_height_mm(v)(np.array([t]))[0]), fit.params[A1:],
                 fit.covariance[A1:, A1:])


def local_distortion(fit: Fit, angle_deg: float, model: str) -> Figure:
    """Local distortion at a field angle, % of image height, against ``"rectilinear"``
    (``f tan theta``) or ``"equidistant"`` (``f theta``); ``angle_deg`` > 0."""
    t = math.radians(angle_deg)
    ideal = math.tan(t) if model == "rectilinear" else t

    def dist(v: FloatArray) -> float:
        h = float(poly_height_mm(v)(np.array([t]))[0])
        return 100.0 * (h - v[0] * ideal) / (v[0] * ideal)
    return delta(dist, fit.params[A1:], fit.covariance[A1:, A1:])


def paraxial_focal_length(fit: Fit) -> Figure:
    """The mapping's slope at 0 (``a1``), mm."""
    return delta(lambda v: float(v[0]), fit.params[A1:A1 + 1], fit.covariance[A1:A1 + 1, A1:A1 + 1])
