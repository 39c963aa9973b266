"""Bar ROIs with known truth, for tests and the benchmark.

Image formation, each step exact: a square wave (bright fraction ``duty``) of object modulation
``M`` around ``mean`` gray, with the intensity varying at ``angle_deg`` from the column axis ->
Gaussian PSF (sigma in px) -> exact integration over the unit pixel (trapezoid footprint on the
across-bar coordinate, closed form: :mod:`benchlab.analysis.bars.model`) -> linear illumination
shading -> exposure scaling -> pedestal -> Poisson photo-electrons (``electrons_per_dn``) and
Gaussian read noise (``noise_sigma``) -> clipping at the top code -> 8- or 12-bit quantisation
(12-bit optionally stored MSB-aligned in 16 bits).

Truth is the Eq. 2.9 contrast of the noiseless, blurred, pixel-integrated continuous profile
(max and min over every sampling phase, unclipped, pedestal included) - what an ideal estimator
should report.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars import model as barmodel
from benchlab.analysis.bars.projection import across_coordinate

N_HARMONICS = 401


def _harmonic_amplitudes(
    px_per_period: float, psf_sigma_px: float, duty: float
) -> tuple[np.ndarray, np.ndarray]:
    """Harmonic numbers and cosine amplitudes of a 0..1 bar pattern of bright fraction ``duty``,
    blurred by the Gaussian PSF and the pixel aperture."""
    k = np.arange(1, N_HARMONICS + 1, dtype=np.float64)
    f = k / px_per_period  # cycles/px
    gain = np.exp(-2 * (math.pi * psf_sigma_px * f) ** 2) * np.sinc(f)
    return k, 2.0 / (math.pi * k) * np.sin(math.pi * k * duty) * gain


def waveform(
    x: npt.ArrayLike,
    px_per_period: float,
    modulation: float,
    mean: float,
    psf_sigma_px: float,
    phase: float = 0.0,
    duty: float = 0.5,
) -> npt.NDArray[np.float64]:
    """Noise-free blurred bar waveform at positions ``x`` (px): levels ``mean (1 -+ M)`` before
    blur, bright fraction ``duty`` of each period; ``phase`` in periods."""
    xs = np.asarray(x, dtype=np.float64)
    k, amp = _harmonic_amplitudes(px_per_period, psf_sigma_px, duty)
    arg = 2 * math.pi * np.outer(xs / px_per_period + phase, k)
    s01 = duty + np.cos(arg) @ amp
    return mean * (1.0 + modulation * (2.0 * s01 - 1.0))


@lru_cache(maxsize=4096)
def true_modulation(
    px_per_period: float, modulation: float, psf_sigma_px: float, duty: float = 0.5
) -> float:
    """Eq. 2.9 contrast of the continuous blurred waveform (before sampling and noise)."""
    x = np.linspace(0.0, px_per_period, 2048, endpoint=False)
    w = waveform(x, px_per_period, modulation, 1.0, psf_sigma_px, duty=duty)
    hi, lo = float(w.max()), float(w.min())
    return (hi - lo) / (hi + lo)


@dataclass(frozen=True)
class BarCase:
    """Parameters of one synthetic bar ROI (gray levels in 8-bit units; x16 for 12-bit)."""

    shape: tuple[int, int] = (40, 50)
    px_per_period: float = 16.0
    modulation: float = 0.6
    mean: float = 100.0
    psf_sigma_px: float = 1.0
    noise_sigma: float = 2.0  # Gaussian read noise, gray units (8-bit scale)
    phase: float = 0.0  # cycles
    orientation: str = "horizontal"
    exposure_scale: float = 1.0
    bits: int = 8
    msb_aligned: bool = False
    n_frames: int = 1
    duty: float = 0.5  # bright fraction of a period (printed lines may come out thicker)
    shading: float = 0.0  # multiplicative illumination ramp across the ROI: 1 -+ shading / 2
    angle_deg: float | None = None  # direction of intensity variation; None: from orientation
    electrons_per_dn: float = 0.0  # > 0: Poisson shot noise with this many e- per gray unit
    pedestal: float = 0.0  # black level added before the noise, gray units

    @property
    def theta_rad(self) -> float:
        """Angle of the direction in which the intensity varies, from the column axis."""
        if self.angle_deg is not None:
            return math.radians(self.angle_deg)
        return 0.0 if self.orientation in ("horizontal", "sagittal") else math.pi / 2

    @property
    def freq_cycles_per_px(self) -> float:
        return 1.0 / self.px_per_period if math.isfinite(self.px_per_period) else 0.0

    @property
    def truth(self) -> float:
        """True Eq. 2.9 bar contrast of the image (0 for a flat field)."""
        if self.modulation == 0 or not math.isfinite(self.px_per_period):
            return 0.0
        scale = self.exposure_scale
        dark = self.mean * (1.0 - self.modulation) * scale + self.pedestal
        bright = self.mean * (1.0 + self.modulation) * scale + self.pedestal
        return barmodel.truth_modulation(
            dark, bright, self.px_per_period, self.duty, self.psf_sigma_px, self.theta_rad
        )

    @property
    def noise_at_mean(self) -> float:
        """Total per-frame noise sigma (gray units) at the mean level."""
        epd = self.electrons_per_dn
        shot2 = self.mean * self.exposure_scale / epd if epd else 0.0
        return math.sqrt(self.noise_sigma**2 + shot2)

    @property
    def snr(self) -> float:
        """Half peak-to-valley signal over the per-frame noise sigma at the mean (inf without
        noise)."""
        amp = (self.mean * self.exposure_scale + self.pedestal) * self.truth
        noise = self.noise_at_mean
        return math.inf if noise == 0 else amp / noise

    @property
    def top_code(self) -> float:
        """Saturation level in gray units (before MSB alignment)."""
        return 255.0 if self.bits == 8 else 4095.0

    @property
    def clipped(self) -> bool:
        """Whether the noiseless bright level reaches the top code."""
        return self.mean * (1 + self.modulation) * self.exposure_scale * (
            1 + self.shading / 2
        ) + self.pedestal >= self.top_code / (16.0 if self.bits == 12 else 1.0)


def noiseless(case: BarCase) -> npt.NDArray[np.float64]:
    """The noiseless ROI in gray units of the 8-bit scale (before bit depth and clipping)."""
    h, w = case.shape
    if math.isfinite(case.px_per_period) and case.modulation != 0:
        u = across_coordinate((h, w), case.theta_rad)
        s01 = barmodel.imaged_bars(
            u, case.px_per_period, case.duty, case.psf_sigma_px, case.theta_rad, case.phase
        )
        img = case.mean * (1.0 + case.modulation * (2.0 * s01 - 1.0))
    else:
        img = np.full((h, w), float(case.mean))
    img = img * case.exposure_scale
    if case.shading:
        # Illumination falls off along the rows and columns alike (a diagonal ramp).
        ramp = (np.arange(h)[:, None] / max(h - 1, 1) + np.arange(w)[None, :] / max(w - 1, 1)) / 2
        img = img * (1.0 + case.shading * (0.5 - ramp))
    return img + case.pedestal


def render(case: BarCase, rng: np.random.Generator) -> npt.NDArray[np.generic]:
    """The ROI (rows, cols), or a (frames, rows, cols) stack when ``n_frames > 1``."""
    h, w = case.shape
    scale = 16.0 if case.bits == 12 else 1.0
    top = case.top_code
    img = noiseless(case) * scale
    frames = []
    for _ in range(case.n_frames):
        if case.electrons_per_dn > 0:
            k = case.electrons_per_dn / scale  # electrons per code
            signal = rng.poisson(np.maximum(img - case.pedestal * scale, 0.0) * k) / k
            noisy = signal + case.pedestal * scale
        else:
            noisy = img
        noisy = noisy + rng.normal(0.0, case.noise_sigma * scale, size=(h, w))
        codes = np.clip(np.rint(noisy), 0, top)
        if case.bits == 8:
            frames.append(codes.astype(np.uint8))
        else:
            frames.append((codes * (16 if case.msb_aligned else 1)).astype(np.uint16))
    return frames[0] if case.n_frames == 1 else np.stack(frames)


def bar_roi(
    rng: np.random.Generator | int | None = 0, **params: object
) -> tuple[npt.NDArray[np.generic], BarCase]:
    """Render one :class:`BarCase` built from keyword parameters; returns (roi, case)."""
    case = BarCase(**params)  # type: ignore[arg-type]
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    return render(case, gen), case
