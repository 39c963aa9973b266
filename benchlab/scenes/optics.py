"""The optics of the simulated prototype: a Gaussian blur whose widths depend on image height.

Only what the bar measurements need: a separable Gaussian point spread with one width across
the sagittal direction and one across the tangential direction, both interpolated from a
table over image height (astigmatism and field curvature grow off axis, section 2.4). Which
image direction is "sagittal" follows :mod:`benchlab.analysis.chart.layout`: in the forward view the
sagittal width blurs along columns (x) and the tangential width along rows (y); in the radial
view the sagittal width blurs around the circle (across spokes) and the tangential width along
the radius (across rings).

The pixel aperture (a 1 x 1 px box) is a further blur. The forward view integrates it exactly
(:func:`box_blurred_rect`); in the annulus, whose bars run at every angle, it is a Gaussian of
the same variance, 1/12 px^2 (:data:`PIXEL_APERTURE_VAR_PX2`), which the truth values use too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from benchlab.analysis.arrays import FloatArray

#: Variance of a 1-px box, px^2: the Gaussian stand-in for the pixel aperture in the annulus.
PIXEL_APERTURE_VAR_PX2 = 1.0 / 12.0
#: Widths below this are treated as this (avoids 0/0 in the closed forms).
_MIN_SIGMA_PX = 1e-6
#: ``ndtr`` is exactly 1.0 in float64 from z = 8.3 up and exactly 0.0 from z = -38.5 down
#: (margins kept): :func:`saturated_ndtr` evaluates it only between.
NDTR_ONE_Z = 9.0
NDTR_ZERO_Z = -40.0


def saturated_ndtr(z: FloatArray) -> FloatArray:
    """``scipy.special.ndtr(z)`` bit for bit, evaluated only where it is neither exactly 1 nor
    exactly 0: a field stop's blurred rim is a thin annulus of a frame, and the full-frame
    ``ndtr`` was a quarter of rendering a simulated chart."""
    z = np.asarray(z, dtype=np.float64)
    out = np.where(z >= NDTR_ONE_Z, 1.0, 0.0)
    band = (z > NDTR_ZERO_Z) & (z < NDTR_ONE_Z)
    band |= np.isnan(z)
    out[band] = ndtr(z[band])
    return np.asarray(out, dtype=np.float64)


@dataclass(frozen=True)
class BlurProfile:
    """Gaussian blur widths (standard deviation, px) tabulated over image height (mm).

    Linear interpolation between the table rows, constant beyond the ends.
    """

    image_height_mm: tuple[float, ...]
    sigma_sagittal_px: tuple[float, ...]
    sigma_tangential_px: tuple[float, ...]

    def __post_init__(self) -> None:
        n = len(self.image_height_mm)
        if n == 0 or len(self.sigma_sagittal_px) != n or len(self.sigma_tangential_px) != n:
            raise ValueError("BlurProfile needs equally long, non-empty tables")
        if any(
            b <= a for a, b in zip(self.image_height_mm, self.image_height_mm[1:], strict=False)
        ):
            raise ValueError("BlurProfile image heights must increase")
        if min(self.sigma_sagittal_px + self.sigma_tangential_px) < 0:
            raise ValueError("blur widths must be >= 0")

    def sagittal_px(self, image_height_mm: float | FloatArray) -> FloatArray:
        """Sagittal blur width(s), px, at the given image height(s)."""
        return np.asarray(
            np.interp(image_height_mm, self.image_height_mm, self.sigma_sagittal_px), np.float64
        )

    def tangential_px(self, image_height_mm: float | FloatArray) -> FloatArray:
        """Tangential blur width(s), px, at the given image height(s)."""
        return np.asarray(
            np.interp(image_height_mm, self.image_height_mm, self.sigma_tangential_px), np.float64
        )

    @classmethod
    def uniform(cls, sigma_sagittal_px: float, sigma_tangential_px: float) -> BlurProfile:
        """The same widths everywhere (handy for tests)."""
        return cls((0.0,), (sigma_sagittal_px,), (sigma_tangential_px,))


#: Forward view: nearly isotropic, slightly worse tangentially and off axis, so the simulated
#: Table 4.11 falls from ~0.78 at G1E5 to ~0.5 at G2E4 like the thesis's.
FORWARD_BLUR = BlurProfile(
    image_height_mm=(0.0, 0.6, 1.3),
    sigma_sagittal_px=(0.12, 0.18, 0.45),
    sigma_tangential_px=(0.15, 0.28, 0.70),
)
#: Radial view: sharp across spokes, badly blurred along the radius, so the tangential target
#: is unresolved from ~50 lp/mm (image) while the sagittal stays near 0.5 (Table 4.12).
RADIAL_BLUR = BlurProfile(
    image_height_mm=(1.5, 2.48, 3.0),
    sigma_sagittal_px=(0.18, 0.22, 0.35),
    sigma_tangential_px=(1.20, 1.60, 2.00),
)


def _box_gauss_antiderivative(t: FloatArray, sigma: float) -> FloatArray:
    """Antiderivative of the Gaussian CDF ``Phi(t / sigma)``: ``sigma (z Phi(z) + phi(z))``."""
    z = t / sigma
    return sigma * (z * ndtr(z) + np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi))


def box_blurred_rect(x: FloatArray, a: float | FloatArray, b: float | FloatArray,
                     sigma: float) -> FloatArray:
    """Value at pixel centres ``x`` of the indicator of ``[a, b]`` blurred by a Gaussian of width
    ``sigma`` and integrated over a 1-px pixel aperture (exact closed form). Arrays ``a``, ``b``
    broadcast against ``x`` (several intervals at once, each value as for scalar ends).
    """
    s = max(float(sigma), _MIN_SIGMA_PX)
    x = np.asarray(x, dtype=np.float64)
    antideriv = _box_gauss_antiderivative
    return (antideriv(x + 0.5 - a, s) - antideriv(x - 0.5 - a, s)) - (
        antideriv(x + 0.5 - b, s) - antideriv(x - 0.5 - b, s)
    )


def blurred_square_wave(
    u: FloatArray | float, period: float, sigma: FloatArray | float
) -> FloatArray:
    """A 50 % duty square wave (1 on ``[0, period/2)`` mod period, else 0) blurred by a Gaussian.

    ``sigma`` may vary per sample. Exact to ~1e-7: either a sum of Gaussian CDFs over the
    neighbouring bars or the Gaussian-damped Fourier series, whichever needs fewer terms.
    """
    u_arr = np.asarray(u, dtype=np.float64)
    s = np.maximum(np.asarray(sigma, dtype=np.float64), _MIN_SIGMA_PX)
    s_max, s_min = float(np.max(s)), float(np.min(s))
    # Bright intervals [n p, n p + p/2] within 6 sigma of [0, p) matter (t = u mod p).
    reach = 6.0 * s_max / period
    n_lo, n_hi = -math.floor(reach + 0.5), math.floor(reach + 1.0)
    erf_terms = 2 * (n_hi - n_lo + 1)
    # Highest odd harmonic whose damping exp(-2 pi^2 s^2 k^2 / p^2) is above 1e-8.
    k_max = math.sqrt(math.log(1e8) / (2.0 * math.pi**2)) * period / s_min
    fourier_terms = int(k_max // 2) + 1
    if erf_terms <= fourier_terms:
        t = np.mod(u_arr, period)
        out = np.zeros(np.broadcast(t, s).shape)
        for n in range(n_lo, n_hi + 1):
            start = n * period
            out += ndtr((t - start) / s) - ndtr((t - start - period / 2.0) / s)
        return out
    out = np.full(np.broadcast(u_arr, s).shape, 0.5)
    phase = 2.0 * math.pi * u_arr / period
    for k in range(1, 2 * fourier_terms, 2):
        damping = np.exp(-2.0 * (math.pi * k * s / period) ** 2)
        out += (2.0 / (math.pi * k)) * damping * np.sin(k * phase)
    return out
