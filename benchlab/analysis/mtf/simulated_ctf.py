"""The simulated lens's square-wave response: a sine-wave MTF curve (a Zemax export or the
simulated bench's own) converted to bar contrast (CTF) with Coltman's series, never above 1.

Used where measured bar contrast meets the design: the report's plot, and the MTF procedure's
check that a target's contrast is read where the lens passes (nearly) all of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from benchlab.analysis.mtf.coltman import mtf_to_ctf, signed_mtf
from benchlab.analysis.mtf.compare import SimulatedCurve

#: A curve whose last value is below this has ended where the response has vanished.
TAIL_VANISHED = 0.01
#: Coltman's series is summed until its harmonics reach a frequency where the MTF is below
#: this (the terms alternate in sign: stopping while they are large overshoots 1).
SERIES_MTF_FLOOR = 1e-6
#: ... but with no more than this many odd harmonics (a tail that never vanishes).
MAX_HARMONIC = 20001


def extended_mtf(curve: SimulatedCurve) -> tuple[Callable[[Any], Any], bool]:
    """The real OTF of a simulated curve for any f >= 0, and whether its tail was
    extrapolated.

    The exported modulus is given the sign of each lobe (:func:`~benchlab.analysis.mtf.
    coltman.signed_mtf`: past a zero the contrast is reversed). Coltman's series at f needs
    the MTF at 3f, 5f, ...; a curve that ends while the response is still clearly above 0 (a
    Zemax export cut at Nyquist) is continued with a Gaussian, ``ln MTF = c - a f^2``,
    fitted to the last third of its last lobe."""
    mtf_at, extrapolated, _ = _extended(curve)
    return mtf_at, extrapolated


def _extended(curve: SimulatedCurve) -> tuple[Callable[[Any], Any], bool, float]:
    """:func:`extended_mtf` and the frequency past which its response is below
    :data:`SERIES_MTF_FLOOR` (the curve's end when not extrapolated)."""
    f = np.asarray(curve.freqs_lp_per_mm, dtype=np.float64)
    m = signed_mtf(f, np.asarray(curve.mtf, dtype=np.float64))
    plain = (lambda x: np.interp(x, f, m, right=0.0)), False, float(f[-1])
    if abs(m[-1]) <= TAIL_VANISHED or f.size < 3:
        return plain
    zeros = np.flatnonzero(m == 0.0)
    lobe = slice(int(zeros[-1]) + 1 if zeros.size else 0, None)
    fl, ml = f[lobe], np.abs(m[lobe])
    tail = slice(2 * fl.size // 3, None)
    ok = ml[tail] > 0
    if fl.size < 3 or ok.sum() < 2:
        return plain
    slope, _ = np.polyfit(fl[tail][ok] ** 2, np.log(ml[tail][ok]), 1)
    a = max(-float(slope), 1e-12)
    c = math.log(abs(float(m[-1]))) + a * float(f[-1]) ** 2  # continuous at the last point
    sign = math.copysign(1.0, float(m[-1]))

    def mtf_at(x: Any) -> Any:
        xa = np.asarray(x, dtype=np.float64)
        return np.where(xa <= f[-1], np.interp(xa, f, m), sign * np.exp(c - a * xa**2))

    support = math.sqrt(max(c - math.log(SERIES_MTF_FLOOR), 0.0) / a)
    return mtf_at, True, max(support, float(f[-1]))


def _harmonics_needed(support_lp_per_mm: float, freqs_lp_per_mm: np.ndarray) -> int:
    """The odd harmonic past which every term of the series at the lowest frequency lies
    beyond the response (at most :data:`MAX_HARMONIC`)."""
    positive = freqs_lp_per_mm[freqs_lp_per_mm > 0]
    if positive.size == 0:
        return 1
    k = min(MAX_HARMONIC, math.ceil(support_lp_per_mm / float(positive.min())) + 2)
    return k if k % 2 else k + 1


def simulated_ctf(curve: SimulatedCurve, freqs_lp_per_mm: np.ndarray) -> np.ndarray:
    """Square-wave response (CTF) of a simulated sine-wave MTF curve, by Coltman's forward
    series, summed until the harmonics reach the end of the response (see
    :func:`extended_mtf` for the sign of each lobe and for curves that end early).

    A blurred square wave stays between its levels, so no CTF exceeds 1; the shipped curves,
    sampled every 2 lp/mm, come to at most 1.002 (the export's own rounding), held at 1. A
    contrast reversal (negative CTF) is drawn as 0."""
    grid = np.asarray(freqs_lp_per_mm, dtype=np.float64)
    mtf_at, _, support = _extended(curve)
    k = _harmonics_needed(support, grid)
    return np.clip(mtf_to_ctf(mtf_at, grid, max_harmonic=k), 0.0, 1.0)
