"""Slanted edges with known truth, in closed form, for the SFR tests and benchmark.

An ideal straight edge (a half-plane) blurred by a Gaussian PSF of width ``sigma`` along its
normal is ``Phi(d / sigma)`` at signed distance ``d`` from the edge. A square pixel of side 1
whose sides make angle ``a`` with the normal sees ``d`` vary as ``d0 + x cos a + y sin a`` over
``x, y in [-1/2, 1/2]``, so its value is the double integral of ``Phi``, which has the closed form
:func:`pixel_integrated_step` (the second antiderivative of ``Phi`` evaluated at the four
corners). The same function draws the slanted-edge target of the simulated bench
(:mod:`benchlab.scenes.edge`).

The truth MTF along the normal (cycles/px measured along the normal) is the Gaussian's
``exp(-2 pi^2 sigma^2 f^2)`` times the pixel aperture projected onto the normal, a box of width
``|cos a|`` convolved with a box of width ``|sin a|``: ``sinc(f cos a) sinc(f sin a)``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy.optimize import brentq
from scipy.special import ndtr

from benchlab.analysis.arrays import FloatArray

#: Below this |sin a| (or |cos a|) the pixel is integrated as a 1-D box (error O(sin^2 a)).
_THIN_BOX = 1e-3
_MIN_SIGMA_PX = 1e-6
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


def _phi_antiderivative(t: FloatArray, sigma: float) -> FloatArray:
    """First antiderivative of ``Phi(t / sigma)``: ``t Phi + sigma phi``."""
    z = t / sigma
    return t * ndtr(z) + sigma * _INV_SQRT_2PI * np.exp(-0.5 * z * z)


def _phi_second_antiderivative(t: FloatArray, sigma: float) -> FloatArray:
    """Second antiderivative of ``Phi(t / sigma)``: ``(t^2 + sigma^2)/2 Phi + t sigma/2 phi``."""
    z = t / sigma
    return 0.5 * (t * t + sigma * sigma) * ndtr(z) + 0.5 * t * sigma * _INV_SQRT_2PI * np.exp(
        -0.5 * z * z
    )


def pixel_integrated_step(
    distance_px: npt.ArrayLike, sigma_px: float, cos_a: float, sin_a: float
) -> FloatArray:
    """Mean of ``Phi(d / sigma)`` over a unit pixel whose centre is at signed distance
    ``distance_px`` from the edge, the edge normal at angle ``a`` to the pixel's sides.

    Parameters
    ----------
    distance_px : array_like
        Signed distance of each pixel centre from the edge along the normal (px).
    sigma_px : float
        Gaussian PSF width along the normal (px); values below 1e-6 are taken as 1e-6.
    cos_a, sin_a : float
        Direction cosines of the normal in pixel axes (signs do not matter).

    Returns
    -------
    ndarray of float64
        Values in [0, 1] (0 far on the negative side, 1 far on the positive side).
    """
    d = np.asarray(distance_px, dtype=np.float64)
    s = max(float(sigma_px), _MIN_SIGMA_PX)
    a, b = abs(float(cos_a)), abs(float(sin_a))
    a, b = max(a, b), min(a, b)  # the integral is symmetric in the two pixel axes
    if b < _THIN_BOX:
        f1 = _phi_antiderivative
        return np.asarray((f1(d + a / 2, s) - f1(d - a / 2, s)) / a, dtype=np.float64)
    f2 = _phi_second_antiderivative
    total = (
        f2(d + (a + b) / 2, s)
        - f2(d + (a - b) / 2, s)
        - f2(d - (a - b) / 2, s)
        + f2(d - (a + b) / 2, s)
    )
    return np.asarray(np.clip(total / (a * b), 0.0, 1.0), dtype=np.float64)


def edge_truth_mtf(
    freqs_cycles_per_px: npt.ArrayLike, sigma_px: float, normal_theta_rad: float
) -> FloatArray:
    """MTF along the edge normal of a Gaussian PSF and the square pixel aperture.

    ``exp(-2 pi^2 sigma^2 f^2) |sinc(f cos t) sinc(f sin t)|`` with ``f`` in cycles per pixel
    along the normal (``np.sinc`` is the normalised sinc).
    """
    f = np.asarray(freqs_cycles_per_px, dtype=np.float64)
    c, s = math.cos(normal_theta_rad), math.sin(normal_theta_rad)
    gauss = np.exp(-2.0 * math.pi**2 * sigma_px**2 * f * f)
    return np.asarray(gauss * np.abs(np.sinc(f * c) * np.sinc(f * s)), dtype=np.float64)


def edge_truth_mtf50(sigma_px: float, normal_theta_rad: float) -> float:
    """Frequency (cycles/px along the normal) where :func:`edge_truth_mtf` falls to 0.5."""

    def g(f: float) -> float:
        return float(edge_truth_mtf(np.array([f]), sigma_px, normal_theta_rad)[0]) - 0.5

    return float(brentq(g, 1e-9, 1.2))


def synthetic_edge(
    shape: tuple[int, int],
    angle_deg: float,
    sigma_px: float,
    *,
    dark: float = 0.2,
    bright: float = 0.8,
    offset_px: float = 0.0,
    noise_sigma: float = 0.0,
    bits: int | None = None,
    rng: np.random.Generator | None = None,
) -> FloatArray:
    """A slanted-edge ROI: dark on the left, bright on the right, the edge running
    ``angle_deg`` away from vertical (ISO 12233 style), exactly pixel-integrated.

    Parameters
    ----------
    shape : (rows, cols)
    angle_deg : float
        Edge angle from vertical (deg); the normal is at ``angle_deg`` from the column axis
        towards the row axis. 90 gives a horizontal edge, dark on top.
    sigma_px : float
        Gaussian PSF width (px), isotropic.
    dark, bright : float
        Levels as fractions of full scale (0..1).
    offset_px : float
        Edge offset from the ROI centre along the normal (px).
    noise_sigma : float
        Gaussian noise, fraction of full scale, added before quantisation.
    bits : int, optional
        Quantise to integer codes of this bit depth (clipped to ``0..2**bits - 1``); None keeps
        floats in 0..1.
    rng : numpy Generator, optional
        Noise source.

    Returns
    -------
    ndarray of float64
        Codes (``bits`` given) or fractions of full scale.
    """
    rows, cols = int(shape[0]), int(shape[1])
    t = math.radians(angle_deg)
    c, s = math.cos(t), math.sin(t)
    y = np.arange(rows, dtype=np.float64)[:, None] - (rows - 1) / 2.0
    x = np.arange(cols, dtype=np.float64)[None, :] - (cols - 1) / 2.0
    d = x * c + y * s - offset_px
    img = dark + (bright - dark) * pixel_integrated_step(d, sigma_px, c, s)
    if noise_sigma > 0:
        gen = rng if rng is not None else np.random.default_rng()
        img = img + gen.normal(0.0, noise_sigma, img.shape)
    if bits is None:
        return np.asarray(img, dtype=np.float64)
    top = float(2**bits - 1)
    return np.asarray(np.clip(np.floor(img * top + 0.5), 0.0, top), dtype=np.float64)
