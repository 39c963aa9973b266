"""The imaged bar pattern in closed form: a square wave of bright fraction ``duty`` blurred by a
Gaussian PSF and integrated over the pixel aperture, at any bar angle.

A unit pixel integrates a 1-D pattern that varies along ``u = x cos(t) + y sin(t)`` through its
footprint on ``u``: the projection of the unit square, a trapezoid ``box(|cos t|) * box(|sin t|)``
(a 1 px box on axis-aligned bars, a triangle of half-width 1/sqrt(2) px at 45 deg). A step edge
seen through that footprint and a Gaussian PSF of ``sigma`` px is a second finite difference of
the twice-integrated Gaussian CDF, ``Phi2(x) = ((x^2 + s^2) Phi(x/s) + x s phi(x/s)) / 2``:

    E(x) = [Phi2(x + (a+b)/2) - Phi2(x + (a-b)/2) - Phi2(x - (a-b)/2) + Phi2(x - (a+b)/2)] / (a b)

with ``a = |cos t|`` and ``b = |sin t|`` (one finite difference and ``Phi1`` when ``b -> 0``).
:func:`imaged_bars` sums those edges (spatial form, for rendering and truth);
:func:`fourier_gains` gives the same pattern's harmonic gains (``exp(-2 pi^2 s^2 f^2)
sinc(f a) sinc(f b)``) for the fitting model, which needs it on few points and many times.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray

#: Below this footprint side (px) a box is treated as a delta (first-order exact).
_THIN_BOX_PX = 1e-3
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


def _phi1(x: FloatArray, s: float) -> FloatArray:
    """Integral of the Gaussian CDF ``Phi(x / s)`` (``max(x, 0)`` at ``s = 0``)."""
    if s <= 0:
        return np.maximum(x, 0.0)
    from scipy.special import ndtr  # here: a re-analysis never blurs an edge (start-up)

    z = x / s
    return x * ndtr(z) + s * _INV_SQRT_2PI * np.exp(-0.5 * z * z)


def _phi2(x: FloatArray, s: float) -> FloatArray:
    """Second integral of ``Phi(x / s)`` (``max(x, 0)^2 / 2`` at ``s = 0``)."""
    if s <= 0:
        xp = np.maximum(x, 0.0)
        return 0.5 * xp * xp
    from scipy.special import ndtr  # here, as in _phi1

    z = x / s
    return 0.5 * ((x * x + s * s) * ndtr(z) + x * s * _INV_SQRT_2PI * np.exp(-0.5 * z * z))


def footprint_sides(theta_rad: float) -> tuple[float, float]:
    """Sides ``(a, b)`` of the pixel footprint's trapezoid on ``u``, ``a >= b``."""
    c, s = abs(math.cos(theta_rad)), abs(math.sin(theta_rad))
    return (c, s) if c >= s else (s, c)


def edge_response(x: npt.ArrayLike, sigma_px: float, theta_rad: float) -> FloatArray:
    """Rising step at ``u = 0`` seen through the PSF and the pixel footprint, at ``u = x``.

    Parameters
    ----------
    x : array_like
        Across-bar positions (px) of the pixel centres relative to the edge.
    sigma_px : float
        Gaussian PSF sigma (px, >= 0).
    theta_rad : float
        Angle of the direction of intensity variation from the column axis.

    Returns
    -------
    ndarray
        Values in [0, 1].
    """
    xs = np.asarray(x, dtype=np.float64)
    a, b = footprint_sides(theta_rad)
    s = max(float(sigma_px), 0.0)
    if b < _THIN_BOX_PX:
        return (_phi1(xs + a / 2, s) - _phi1(xs - a / 2, s)) / a
    h1, h2 = (a + b) / 2, (a - b) / 2
    return (_phi2(xs + h1, s) - _phi2(xs + h2, s) - _phi2(xs - h2, s) + _phi2(xs - h1, s)) / (
        a * b
    )


def imaged_bars(
    u_px: npt.ArrayLike,
    period_px: float,
    duty: float,
    sigma_px: float,
    theta_rad: float,
    phase_cycles: float = 0.0,
) -> FloatArray:
    """Bright fraction (0..1) of the imaged bar pattern at across-bar positions ``u_px``.

    The bright bars occupy ``[0, duty)`` of each period (in cycles, after adding
    ``phase_cycles``). Exact: a sum of :func:`edge_response` over every edge within reach of
    the footprint and 6 sigma.
    """
    if not (period_px > 0 and 0 < duty < 1):
        raise ValueError(f"need period > 0 and 0 < duty < 1, got {period_px}, {duty}")
    u = np.asarray(u_px, dtype=np.float64)
    w = np.mod(u / period_px + phase_cycles, 1.0) * period_px  # position within the period
    reach = (6.0 * max(sigma_px, 0.0) + 1.0) / period_px
    lo, hi = -math.floor(reach + 1.0), math.floor(reach + 1.0)
    out = np.zeros_like(w)
    for n in range(lo, hi + 1):
        start = n * period_px
        out += edge_response(w - start, sigma_px, theta_rad)
        out -= edge_response(w - start - duty * period_px, sigma_px, theta_rad)
    return out


def truth_modulation(
    dark: float, bright: float, period_px: float, duty: float, sigma_px: float, theta_rad: float
) -> float:
    """Eq. 2.9 contrast of the noiseless, blurred, pixel-integrated continuous profile between
    object levels ``dark`` and ``bright`` (max and min over every sampling phase)."""
    w = np.linspace(0.0, period_px, 2048, endpoint=False)
    s = imaged_bars(w, period_px, duty, sigma_px, theta_rad)
    hi = dark + (bright - dark) * float(s.max())
    lo = dark + (bright - dark) * float(s.min())
    return (hi - lo) / (hi + lo) if hi + lo > 0 else 0.0


def fourier_gains(
    freq_cycles_per_px: float, n_harmonics: int, sigma_px: float, theta_rad: float
) -> FloatArray:
    """Gain of harmonics ``1..n`` of a pattern at ``freq`` through the PSF and footprint."""
    a, b = footprint_sides(theta_rad)
    fk = freq_cycles_per_px * np.arange(1, n_harmonics + 1, dtype=np.float64)
    return np.exp(-2.0 * (math.pi * sigma_px * fk) ** 2) * np.sinc(fk * a) * np.sinc(fk * b)
