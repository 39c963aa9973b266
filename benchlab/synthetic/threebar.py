"""A finite USAF three-bar set imaged through a chosen PSF, with its Eq. 2.9 truth.

The simulated bench blurs with a Gaussian, the same family :mod:`.knownbars` fits; a real lens
does not. This module renders one set independently of the reader's model: the sharp set (three
bars ``w`` wide, ``5 w`` long, on a ground) supersampled :data:`SUPERSAMPLE` times per px, a 2-D
PSF applied by FFT (Gaussian, uniform disc = defocus, Gaussian with a 10 % wide halo, disc and
Gaussian together), integrated over each pixel's square footprint (block mean), then optional
Poisson + read noise and an ADC of ``bits`` bits. The ROI is the one the chart reading uses
(three whole periods across, bar ends trimmed:
:func:`~benchlab.analysis.chart.pose.posed_bar_set_roi`). The
truth is defined as the simulated bench defines it (Eq. 2.9): the blurred image averaged over a
pixel-sized box centred on the middle bar and on the spaces either side of it (``u = 0, +-w``,
``v = 0``), read from the same supersampled image (bilinear between subsamples). A disc PSF wide
against the bars reverses the contrast (spurious resolution): that truth is negative.

Pure numpy, no I/O; seeded through the caller's ``numpy.random.Generator``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars.result import eq29_modulation
from benchlab.analysis.chart.pose import WHOLE_PERIODS_HALF_WIDTHS, posed_bar_set_roi

#: Subsamples per px of the rendering.
SUPERSAMPLE = 12
#: PSF kinds :func:`psf_kernel` knows.
PSF_KINDS = ("gauss", "disc", "gauss+halo", "disc+gauss")
#: The halo of ``gauss+halo``: its share of the light and its Gaussian sigma (px).
HALO_SHARE = 0.1
HALO_SIGMA_PX = 4.0
#: Ground and bar reflectance of the rendered target (target contrast 0.6).
GROUND_LEVEL = 0.8
BAR_LEVEL = 0.2


@dataclass(frozen=True)
class PsfSpec:
    """A radially symmetric PSF: ``kind`` (:data:`PSF_KINDS`), Gaussian ``sigma_px`` and disc
    ``radius_px`` (each used by the kinds that name it)."""

    kind: str
    sigma_px: float = 0.0
    radius_px: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in PSF_KINDS:
            raise ValueError(f"PSF kind must be one of {PSF_KINDS}, got {self.kind!r}")
        if not (self.sigma_px >= 0 and self.radius_px >= 0):
            raise ValueError("sigma_px and radius_px must be >= 0")

    @property
    def reach_px(self) -> float:
        """Radius (px) beyond which the PSF holds no light that matters."""
        halo = 4.0 * HALO_SIGMA_PX if self.kind == "gauss+halo" else 0.0
        return max(4.0 * self.sigma_px + self.radius_px, halo, 1.0)


@dataclass(frozen=True)
class SyntheticSet:
    """:func:`render_three_bars`'s answer: the ROI (codes, or float levels when ``bits`` is
    None), the set's centre in it (row, col), the geometry, and the Eq. 2.9 truth (negative
    when the contrast is reversed)."""

    roi: npt.NDArray[np.float64] | npt.NDArray[np.uint16]
    centre_rc: tuple[float, float]
    bar_width_px: float
    theta_deg: float
    truth_modulation: float
    max_code: float | None


def psf_kernel(psf: PsfSpec, supersample: int = SUPERSAMPLE) -> FloatArray:
    """The PSF on a grid of ``supersample`` points per px, normalised to sum 1.

    Parameters
    ----------
    psf : PsfSpec
        The PSF.
    supersample : int
        Grid points per px.

    Returns
    -------
    ndarray
        Square kernel (odd side), centred.
    """
    half = math.ceil(psf.reach_px * supersample)
    yy, xx = (np.mgrid[-half:half + 1, -half:half + 1] / supersample)
    rr = np.hypot(xx, yy)

    def gauss(sigma: float) -> FloatArray:
        if sigma <= 0:
            k = np.zeros_like(rr)
            k[half, half] = 1.0
            return k
        k = np.exp(-0.5 * (rr / sigma) ** 2)
        return k / k.sum()

    def disc(radius: float) -> FloatArray:
        # area coverage of each subsample, linear across the rim (an anti-aliased disc)
        k = np.clip((radius - rr) * supersample + 0.5, 0.0, 1.0)
        if k.sum() == 0:
            k[half, half] = 1.0
        return k / k.sum()

    if psf.kind == "gauss":
        return gauss(psf.sigma_px)
    if psf.kind == "disc":
        return disc(psf.radius_px)
    if psf.kind == "gauss+halo":
        return (1.0 - HALO_SHARE) * gauss(psf.sigma_px) + HALO_SHARE * gauss(HALO_SIGMA_PX)
    return _convolve(disc(psf.radius_px), gauss(psf.sigma_px))


def _convolve(image: FloatArray, kernel: FloatArray) -> FloatArray:
    """``image`` convolved with ``kernel`` (odd, centred), same shape, zero outside."""
    shape = (image.shape[0] + kernel.shape[0] - 1, image.shape[1] + kernel.shape[1] - 1)
    out = np.fft.irfft2(np.fft.rfft2(image, shape) * np.fft.rfft2(kernel, shape), shape)
    r0, c0 = kernel.shape[0] // 2, kernel.shape[1] // 2
    return np.asarray(out[r0:r0 + image.shape[0], c0:c0 + image.shape[1]], dtype=np.float64)


def render_three_bars(
    bar_width_px: float,
    theta_deg: float,
    psf: PsfSpec,
    *,
    rng: np.random.Generator | None = None,
    full_well_e: float | None = None,
    read_noise_e: float = 0.0,
    bits: int | None = 12,
    centre_offset_px: tuple[float, float] = (0.23, 0.37),
) -> SyntheticSet:
    """Render one three-bar set through ``psf`` (see the module docstring).

    Parameters
    ----------
    bar_width_px : float
        Bar width (px, 0.5-8).
    theta_deg : float
        Direction in which the intensity varies (across the bars), degrees from the column axis
        towards the row axis.
    psf : PsfSpec
        The PSF.
    rng : numpy.random.Generator, optional
        For the noise; required when ``full_well_e`` is given.
    full_well_e : float, optional
        Electrons at the top code (the ground sits at 0.8 of it); None = no shot or read noise.
    read_noise_e : float
        Read noise (electrons rms), with ``full_well_e``.
    bits : int or None
        ADC depth (8-16); None returns float levels (0-1) without quantisation.
    centre_offset_px : (float, float)
        Sub-pixel offset (row, col) of the set's centre from a pixel corner.

    Returns
    -------
    SyntheticSet
    """
    w = float(bar_width_px)
    if not (0.5 <= w <= 8.0):
        raise ValueError(f"bar_width_px must be 0.5-8, got {bar_width_px}")
    if bits is not None and not (8 <= bits <= 16):
        raise ValueError(f"bits must be 8-16 or None, got {bits}")
    if full_well_e is not None and (rng is None or not full_well_e > 0 or read_noise_e < 0):
        raise ValueError("noise needs rng, full_well_e > 0 and read_noise_e >= 0")
    s = SUPERSAMPLE
    half_roi = math.ceil(3.0 * w + 1.0)
    pad = math.ceil(psf.reach_px) + 1
    n = 2 * (half_roi + pad)
    cy, cx = n / 2 + centre_offset_px[0], n / 2 + centre_offset_px[1]
    th = math.radians(theta_deg)
    yy, xx = (np.mgrid[0:n * s, 0:n * s] + 0.5) / s
    u = (xx - cx) * math.cos(th) + (yy - cy) * math.sin(th)
    v = -(xx - cx) * math.sin(th) + (yy - cy) * math.cos(th)
    bars = np.zeros_like(u)
    for c in (-2.0 * w, 0.0, 2.0 * w):
        # anti-aliased edges: each subsample's covered fraction, linear across an edge
        across = np.clip((0.5 * w - np.abs(u - c)) * s + 0.5, 0.0, 1.0)
        along = np.clip((2.5 * w - np.abs(v)) * s + 0.5, 0.0, 1.0)
        bars += across * along
    # blurred deficit below the ground (the ground is uniform: zero padding is exact for it)
    deficit = _convolve((GROUND_LEVEL - BAR_LEVEL) * bars, psf_kernel(psf, s))
    pix = GROUND_LEVEL - deficit.reshape(n, s, n, s).mean(axis=(1, 3))
    # truth: a pixel-sized box centred at u = 0 and u = +-w (v = 0)
    box = np.ones((s, s)) / (s * s)
    boxed = GROUND_LEVEL - _convolve(deficit, box)

    def at(uu: float) -> float:
        fy = (cy + uu * math.sin(th)) * s - 0.5
        fx = (cx + uu * math.cos(th)) * s - 0.5
        i, j = math.floor(fy), math.floor(fx)
        a, b = fy - i, fx - j
        q = boxed[i:i + 2, j:j + 2]
        return float((1 - a) * (1 - b) * q[0, 0] + (1 - a) * b * q[0, 1]
                     + a * (1 - b) * q[1, 0] + a * b * q[1, 1])

    dark, bright = at(0.0), 0.5 * (at(w) + at(-w))
    truth = eq29_modulation(dark, bright)
    # the chart reading's ROI: three whole periods across, bar ends trimmed
    r0, c0, r1, c1 = (int(b) for b in posed_bar_set_roi(
        (cy - 0.5, cx - 0.5), w, theta_deg, half_across_widths=WHOLE_PERIODS_HALF_WIDTHS))
    levels = pix[r0:r1, c0:c1]
    centre = (cy - 0.5 - r0, cx - 0.5 - c0)
    if full_well_e is not None:
        assert rng is not None
        e = rng.poisson(levels * full_well_e).astype(np.float64)
        e += rng.normal(0.0, read_noise_e, e.shape)
        levels = e / full_well_e
    if bits is None:
        return SyntheticSet(np.asarray(levels, dtype=np.float64), centre, w, theta_deg,
                            truth, None)
    top = (1 << bits) - 1
    codes = np.clip(np.round(levels * top), 0, top).astype(np.uint16)
    return SyntheticSet(codes, centre, w, theta_deg, truth, float(top))


def element_with_ground(
    bar_width_px: float, theta_deg: float, ground: float, bar: float, size_px: int,
    noise_sigma: float, rng: np.random.Generator, supersample: int = 8,
    centre_offset_px: tuple[float, float] = (0.3, 0.1),
) -> npt.NDArray[np.uint8]:
    """A whole three-bar element with its ground: an 8-bit ``size_px`` square ROI, the set
    (three bars ``w`` wide and ``5 w`` long, level ``bar``, on ``ground``) centred in it, the
    intensity varying at ``theta_deg`` from the column axis; sharp, pixel-integrated
    (``supersample`` x ``supersample`` subsamples per px), Gaussian noise of
    ``noise_sigma`` gray levels. With ``w >= 2`` px some pixels lie wholly on a bar and on
    a space: the truth is ``eq29_modulation(bar, ground)``. The uncropped ROI of issue 37
    (point 6), unlike :func:`render_three_bars`' cropped one."""
    s, w = supersample, float(bar_width_px)
    yy, xx = (np.mgrid[0:size_px * s, 0:size_px * s] + 0.5) / s
    cy, cx = size_px / 2 + centre_offset_px[0], size_px / 2 + centre_offset_px[1]
    th = math.radians(theta_deg)
    u = (xx - cx) * math.cos(th) + (yy - cy) * math.sin(th)
    v = -(xx - cx) * math.sin(th) + (yy - cy) * math.cos(th)
    bars = np.zeros_like(u)
    for c in (-2.0 * w, 0.0, 2.0 * w):
        bars += (np.clip((0.5 * w - np.abs(u - c)) * s + 0.5, 0.0, 1.0)
                 * np.clip((2.5 * w - np.abs(v)) * s + 0.5, 0.0, 1.0))
    pix = (ground - (ground - bar) * bars).reshape(size_px, s, size_px, s).mean(axis=(1, 3))
    noisy = pix + rng.normal(0.0, noise_sigma, pix.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
