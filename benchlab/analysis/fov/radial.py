"""The radial view's mapping and field from the rings' image radii (issue 41).

Ring ``k`` at stage position ``s`` sits at axial position ``z = z0 + s + k pitch`` on a wall of
radius ``R`` (``z0`` the mount's datum, the thesis's coordinates); its image radius is
``rho``. One mapping ``rho(z)`` is fitted to every (ring, position): a polynomial of degree
:data:`DEGREE` in ``u = (z - z_mid) / z_half``, by linear least squares with the points'
noise estimated from the residuals, so its covariance is ``s^2 (A^T A)^-1``.

Figures, each with a 95 % interval by the delta method on that covariance (and the annulus
radii's covariance where they enter):

- the radial field's **start** and **end** on the wall: where the mapping reaches the
  annulus's outer and inner radius (the thesis's "FOV range", section 3.1);
- the **field angle** of a wall point from the effective viewpoint on the axis at
  ``viewpoint_z_mm`` (chapter 5): ``-atan((z - z_vp) / R)``, negative like Table 4.14's
  radial field points, and the **radial field of view** ``|angle(start) - angle(end)|``;
- the **image height** at a field angle: ``rho`` at ``z = z_vp + R tan(-angle)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.fov.annulus import Annulus
from benchlab.analysis.fov.figures import Z95, Figure, delta
from benchlab.analysis.fov.model import PIXEL_MM

#: Degree of the mapping's polynomial in axial position.
DEGREE = 4


class RadialFitError(ValueError):
    """Too few rings or positions for the mapping (says how many)."""


@dataclass(frozen=True)
class RadialFit:
    """The fitted mapping ``rho(z)`` (mm): coefficients, their covariance, the normalisation,
    the points' noise (mm), the axial range of the rings and how many entered."""

    coeffs: FloatArray
    covariance: FloatArray
    z_mid_mm: float
    z_half_mm: float
    noise_mm: float
    z_range_mm: tuple[float, float]
    points: int
    radius_mm: float
    viewpoint_z_mm: float

    def height_mm(self, z_mm: float, c: FloatArray | None = None) -> float:
        u = (z_mm - self.z_mid_mm) / self.z_half_mm
        return float(np.polynomial.polynomial.polyval(u, self.coeffs if c is None else c))

    def z_of_angle(self, angle_deg: float) -> float:
        return self.viewpoint_z_mm + self.radius_mm * math.tan(math.radians(-angle_deg))

    def angle_of_z(self, z_mm: float) -> float:
        return -math.degrees(math.atan((z_mm - self.viewpoint_z_mm) / self.radius_mm))


def fit_mapping(z_mm: Sequence[float] | FloatArray, rho_mm: Sequence[float] | FloatArray,
                radius_mm: float, viewpoint_z_mm: float, ring_mm: float = 0.0,
                systematic_mm: float = 0.0) -> RadialFit:
    """Fit ``rho(z)`` (module docstring). A ring's measured radius is the midpoint of its
    edges' images, ``(rho(z - w/2) + rho(z + w/2)) / 2`` for a ring ``ring_mm`` wide - not
    ``rho(z)``, by ``rho'' w^2 / 8`` (~0.0007 px with the default tube, more than the
    rings' noise) - so each point is fitted as that midpoint.

    ``systematic_mm`` is a bound (95 %) on an error of the rings' radii that is smooth along
    the field, which the residuals cannot show (the polynomial follows it): it is added to the
    constant term's variance as ``(systematic_mm / 1.96)^2``, so every height's 95 % interval
    carries it in quadrature, and every figure read from the mapping its share.

    Raises
    ------
    RadialFitError
        Fewer than ``3 (DEGREE + 1)`` points.
    """
    z = np.asarray(z_mm, dtype=np.float64)
    rho = np.asarray(rho_mm, dtype=np.float64)
    if len(z) < 3 * (DEGREE + 1):
        raise RadialFitError(f"only {len(z)} ring images; the radial mapping needs "
                             f"{3 * (DEGREE + 1)} at least")
    lo, hi = float(z.min()), float(z.max())
    mid, half = (lo + hi) / 2.0, max((hi - lo) / 2.0, 1e-6)
    a = 0.5 * (np.polynomial.polynomial.polyvander((z - ring_mm / 2.0 - mid) / half, DEGREE)
               + np.polynomial.polynomial.polyvander((z + ring_mm / 2.0 - mid) / half, DEGREE))
    coeffs, *_ = np.linalg.lstsq(a, rho, rcond=None)
    r = rho - a @ coeffs
    s2 = float(r @ r) / (len(z) - DEGREE - 1)
    cov = s2 * np.linalg.inv(a.T @ a)
    cov[0, 0] += (systematic_mm / Z95) ** 2
    return RadialFit(np.asarray(coeffs, dtype=np.float64), np.asarray(cov, dtype=np.float64),
                     mid, half, math.sqrt(s2), (lo, hi), len(z), radius_mm,
                     viewpoint_z_mm)


def _crossing(fit: RadialFit, c: FloatArray, rho_mm: float) -> float:
    """The axial position where the mapping ``c`` reaches ``rho_mm`` (nearest the rings)."""
    lo, hi = fit.z_range_mm
    span = hi - lo
    grid = np.linspace(lo - 0.5 * span, hi + 0.5 * span, 801)
    u = (grid - fit.z_mid_mm) / fit.z_half_mm
    vals = np.polynomial.polynomial.polyval(u, c) - rho_mm
    sign = np.nonzero(np.diff(np.sign(vals)) != 0)[0]
    if len(sign) == 0:
        return math.nan
    mid = (lo + hi) / 2.0
    k = int(sign[np.argmin(np.abs(grid[sign] - mid))])
    return float(brentq(lambda t: fit.height_mm(t, c) - rho_mm, grid[k], grid[k + 1],
                        xtol=1e-12))


def _with_radius(fit: RadialFit, annulus: Annulus, which: int) -> tuple[FloatArray, FloatArray]:
    """The coefficients plus one annulus radius (``which`` 2 inner, 3 outer; px) and their
    covariance."""
    n = len(fit.coeffs)
    x = np.concatenate([fit.coeffs, [annulus.inner_px if which == 2 else annulus.outer_px]])
    cov = np.zeros((n + 1, n + 1))
    cov[:n, :n] = fit.covariance
    cov[n, n] = annulus.covariance[which, which]
    return x, cov


def field_end(fit: RadialFit, annulus: Annulus, outer: bool) -> Figure:
    """Axial position (mm) imaged on the annulus's outer (the field's start) or inner edge."""
    x, cov = _with_radius(fit, annulus, 3 if outer else 2)
    return delta(lambda v: _crossing(fit, v[:-1], v[-1] * PIXEL_MM), x, cov)


def field_of_view_deg(fit: RadialFit, annulus: Annulus) -> Figure:
    """The radial field of view from the viewpoint, degrees (both ends' angles' difference)."""
    n = len(fit.coeffs)
    x = np.concatenate([fit.coeffs, [annulus.inner_px, annulus.outer_px]])
    cov = np.zeros((n + 2, n + 2))
    cov[:n, :n] = fit.covariance
    cov[n:, n:] = annulus.covariance[2:4, 2:4]

    def fov(v: FloatArray) -> float:
        start = _crossing(fit, v[:n], v[n + 1] * PIXEL_MM)
        end = _crossing(fit, v[:n], v[n] * PIXEL_MM)
        return abs(fit.angle_of_z(start) - fit.angle_of_z(end))
    return delta(fov, x, cov)


def end_angle_deg(fit: RadialFit, end: Figure) -> Figure:
    """The field angle of a field end (the angle is monotonic in z: the interval maps over)."""
    a, b = fit.angle_of_z(end.low), fit.angle_of_z(end.high)
    return Figure(fit.angle_of_z(end.value), min(a, b), max(a, b))


def height_at_z(fit: RadialFit, z_mm: float) -> Figure:
    """The image height (mm) of a wall position."""
    return delta(lambda c: fit.height_mm(z_mm, c), fit.coeffs, fit.covariance)
