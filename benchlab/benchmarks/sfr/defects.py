"""Real-looking defects under a slanted edge, scored against the edge's own truth.

The accuracy buckets of :mod:`benchlab.benchmarks.sfr.edges` are clean edges; a bench edge
is not. Each row here is one defect on 12-bit 100 x 100 Gaussian edges (sigma uniform in
0.5-2.5 px, angle 2-40 deg, levels 0.2 / 0.8 of full scale) at one SNR, read by each method;
the truth is the blur's, since no defect belongs to the lens:

- vignetting: the light falls off linearly across the ROI in a random direction (+-5 %,
  +-10 % about the centre): multiplies dark and bright alike;
- stray light: a linear background in a random direction (+-5 % of full scale) added;
- hot pixels: 0.2 % of the pixels at 95 % of full scale; dead pixels: 0.2 % at 0 (counted as
  clipped, so warned about).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from benchlab.analysis.sfr.measure import SfrMethod
from benchlab.benchmarks.sfr.edges import (
    _F_CHECK,
    ANGLE_RANGE_DEG,
    BRIGHT,
    DARK,
    ROI_SHAPE,
    NonGaussianBucket,
    score_cases,
)
from benchlab.synthetic.edges import edge_truth_mtf, edge_truth_mtf50, synthetic_edge

#: SNRs scored (edge step over noise sigma).
DEFECT_SNRS = (20.0, 50.0, 100.0)
SIGMA_RANGE_PX = (0.5, 2.5)
TOP = 4095.0

Defect = Callable[[np.ndarray, np.random.Generator], np.ndarray]


def _ramp(rng: np.random.Generator) -> np.ndarray:
    """A unit linear ramp across the ROI in a random direction, -0.5 .. +0.5 corner to corner
    along it (so +-a about the centre for an amplitude 2a)."""
    phi = rng.uniform(0.0, 2.0 * math.pi)
    r = np.arange(ROI_SHAPE[0], dtype=np.float64)[:, None] - (ROI_SHAPE[0] - 1) / 2.0
    c = np.arange(ROI_SHAPE[1], dtype=np.float64)[None, :] - (ROI_SHAPE[1] - 1) / 2.0
    along = c * math.cos(phi) + r * math.sin(phi)
    return np.asarray(along / (2.0 * np.abs(along).max()), dtype=np.float64)


def _vignetting(amplitude: float) -> Defect:
    return lambda clean, rng: clean * (1.0 + 2.0 * amplitude * _ramp(rng))


def _stray(amplitude: float) -> Defect:
    return lambda clean, rng: clean + 2.0 * amplitude * _ramp(rng)


#: Defects applied to the clean (noise-free) edge, before the noise and quantisation.
DEFECTS: dict[str, Defect] = {
    "vignetting +-5 %": _vignetting(0.05),
    "vignetting +-10 %": _vignetting(0.10),
    "stray light +-5 % of full scale": _stray(0.05),
}
#: Defects applied to the quantised codes (a pixel's own fault, not the light's): the
#: fraction of pixels and the code they sit at.
PIXEL_DEFECTS: dict[str, tuple[float, float]] = {
    "hot pixels 0.2 % (95 % of full scale)": (0.002, 0.95 * TOP),
    "dead pixels 0.2 % (code 0)": (0.002, 0.0),
}


def _case(name: str, rng: np.random.Generator, snr: float) -> tuple[np.ndarray, float, float]:
    """One ROI with the defect ``name``: the codes, its blur and angle."""
    angle = float(rng.uniform(*ANGLE_RANGE_DEG))
    sigma = float(rng.uniform(*SIGMA_RANGE_PX))
    clean = synthetic_edge(ROI_SHAPE, angle, sigma, dark=DARK, bright=BRIGHT,
                           offset_px=float(rng.uniform(-2, 2)))
    if name in DEFECTS:
        clean = DEFECTS[name](clean, rng)
    noisy = clean + rng.normal(0.0, (BRIGHT - DARK) / snr, clean.shape)
    codes = np.clip(np.floor(noisy * TOP + 0.5), 0.0, TOP)
    if name in PIXEL_DEFECTS:
        fraction, code = PIXEL_DEFECTS[name]
        hit = rng.choice(codes.size, int(round(fraction * codes.size)), replace=False)
        codes.ravel()[hit] = code
    return codes.astype(np.uint16), sigma, angle


def run_defects(
    cases: int = 20, seed: int = 6, methods: tuple[SfrMethod, ...] = ("free", "auto"),
    snrs: tuple[float, ...] = DEFECT_SNRS,
) -> list[NonGaussianBucket]:
    """Per defect, SNR and method (each method reads the same ROIs): the shares within the
    tolerances, the 95th percentile of the max MTF error to Nyquist (a refusal counts as a
    miss), the coverage of the +-1.96 sigma intervals and the share read by the LSF model."""
    rng = np.random.default_rng(seed)
    out = []
    for name in (*DEFECTS, *PIXEL_DEFECTS):
        for snr in snrs:
            drawn = []
            for _ in range(cases):
                img, sigma, angle = _case(name, rng, snr)
                theta = math.radians(angle)
                drawn.append((img, edge_truth_mtf(_F_CHECK, sigma, theta),
                              edge_truth_mtf50(sigma, theta)))
            out += score_cases(name, snr, drawn, methods)
    return out


DEFECTS_TITLE = ("real-looking defects on Gaussian edges (12-bit 100 x 100, sigma 0.5-2.5 px, "
                 "angle 2-40 deg; scored against the blur's own truth, a refusal is a miss):")
