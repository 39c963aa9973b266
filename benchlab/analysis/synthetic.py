"""Bar ROIs with known truth, for tests and the benchmark.

The scene is a square wave (50 % duty unless set) of object modulation ``M`` around ``mean``
gray, blurred by a Gaussian PSF (sigma in px) and integrated over the pixel aperture, sampled at
pixel centres; then Gaussian noise, optional exposure scaling with clipping (saturation) and
quantisation to 8- or 12-bit codes (12-bit optionally MSB-aligned in 16 bits).

Truth is the Eq. 2.9 bar contrast of the noise-free, unclipped image (max and min of the
continuous blurred waveform) - what an ideal estimator should report.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

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
    """Parameters of one synthetic bar ROI (gray levels in 8-bit units)."""

    shape: tuple[int, int] = (40, 50)
    px_per_period: float = 16.0
    modulation: float = 0.6
    mean: float = 100.0
    psf_sigma_px: float = 1.0
    noise_sigma: float = 2.0
    phase: float = 0.0
    orientation: str = "horizontal"
    exposure_scale: float = 1.0
    bits: int = 8
    msb_aligned: bool = False
    n_frames: int = 1
    duty: float = 0.5  # bright fraction of a period (printed lines may come out thicker)
    shading: float = 0.0  # multiplicative illumination ramp across the ROI: 1 -+ shading / 2

    @property
    def freq_cycles_per_px(self) -> float:
        return 1.0 / self.px_per_period if math.isfinite(self.px_per_period) else 0.0

    @property
    def truth(self) -> float:
        """True Eq. 2.9 bar contrast of the image (0 for a flat field)."""
        if self.modulation == 0 or not math.isfinite(self.px_per_period):
            return 0.0
        return true_modulation(self.px_per_period, self.modulation, self.psf_sigma_px, self.duty)

    @property
    def snr(self) -> float:
        """Half peak-to-valley signal over the per-frame noise sigma (inf without noise)."""
        amp = self.mean * self.truth
        return math.inf if self.noise_sigma == 0 else amp / self.noise_sigma


def render(case: BarCase, rng: np.random.Generator) -> npt.NDArray[np.generic]:
    """The ROI (rows, cols), or a (frames, rows, cols) stack when ``n_frames > 1``."""
    h, w = case.shape
    horizontal = case.orientation in ("horizontal", "sagittal")
    along = w if horizontal else h
    x = np.arange(along, dtype=np.float64)
    if math.isfinite(case.px_per_period) and case.modulation != 0:
        profile = waveform(
            x,
            case.px_per_period,
            case.modulation,
            case.mean,
            case.psf_sigma_px,
            case.phase,
            case.duty,
        )
    else:
        profile = np.full(along, case.mean)
    scale = 16.0 if case.bits == 12 else 1.0
    top = 255.0 if case.bits == 8 else 4095.0
    img = profile[None, :] if horizontal else profile[:, None]
    img = np.broadcast_to(img, (h, w)) * case.exposure_scale * scale
    if case.shading:
        # Illumination falls off along the rows and columns alike (a diagonal ramp).
        ramp = (np.arange(h)[:, None] / max(h - 1, 1) + np.arange(w)[None, :] / max(w - 1, 1)) / 2
        img = img * (1.0 + case.shading * (0.5 - ramp))
    frames = []
    for _ in range(case.n_frames):
        noisy = img + rng.normal(0.0, case.noise_sigma * scale, size=(h, w))
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
