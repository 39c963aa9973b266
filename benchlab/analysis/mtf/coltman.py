"""Bar (square-wave) contrast to sine-wave MTF: Coltman's series (JOSA 44:468, 1954).

- Forward: ``CTF(f) = 4/pi * sum_{k odd} (-1)^((k-1)/2) MTF(k f) / k``.
- Inverse: ``MTF(f) = pi/4 * sum_{k odd} B_k CTF(k f) / k`` with ``B_k = 0`` when k has a
  repeated prime factor, else ``(-1)^m (-1)^((k-1)/2)`` (m = number of prime factors):
  +1, +1/3, -1/5, +1/7, 0, +1/11, -1/13, -1/15, -1/17, +1/19, +1/21 for k = 1..21.

Valid for a linear, shift-invariant system, linear (radiometric) gray levels and a long 50 %-duty
square wave. The series needs CTF at 3f, 5f, ...: where ``k f`` is above a true cutoff
``f_c`` (MTF = 0 there) the term is zero, so for f > f_c / 3 MTF = (pi/4) CTF - exact only
when the MTF really vanishes above ``f_c``. A pixelated system has no such cutoff at Nyquist:
the optics x pixel-aperture MTF at 3f is ~0.2 on the simulated bench, and taking Nyquist as
the cutoff misconverts by up to 0.05-0.08 there. Harmonics below the cutoff but beyond the
measured range (or above Nyquist, where bars alias) are truncated - an assumption that MTF
there is small, reported per point. :func:`ctf_to_mtf_with_harmonics` instead takes the
harmonics from a measured sine-wave MTF (e.g. a slanted edge's, which extends past Nyquist).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


def _prime_factors(k: int) -> list[int]:
    out, d = [], 2
    while d * d <= k:
        while k % d == 0:
            out.append(d)
            k //= d
        d += 1
    if k > 1:
        out.append(k)
    return out


def coltman_coefficient(k: int) -> int:
    """Coltman's ``B_k`` for odd ``k >= 1`` (0, +1 or -1)."""
    if k < 1 or k % 2 == 0:
        raise ValueError(f"Coltman coefficients exist for odd k >= 1, got {k}")
    factors = _prime_factors(k)
    if len(set(factors)) != len(factors):
        return 0
    return (-1) ** len(factors) * (-1) ** ((k - 1) // 2)


@dataclass(frozen=True)
class CtfToMtf:
    """MTF from bar contrast, point by point.

    Attributes
    ----------
    freqs_lp_per_mm, ctf, mtf : ndarray
        Input frequencies and CTF, and the sine-wave MTF.
    method : tuple of str
        ``"pi/4"`` (f above a *given* cutoff's third: exact only if the MTF is zero above
        that cutoff, not for Nyquist on a pixelated system), ``"coltman"`` (every needed
        harmonic measured or above cutoff), or ``"truncated"`` (some harmonic below the cutoff
        - or, with no cutoff given, above the highest measured frequency - was not measured
        and was taken as 0).
    """

    freqs_lp_per_mm: npt.NDArray[np.float64]
    ctf: npt.NDArray[np.float64]
    mtf: npt.NDArray[np.float64]
    method: tuple[str, ...]


def ctf_to_mtf(
    freqs_lp_per_mm: npt.ArrayLike,
    ctf: npt.ArrayLike,
    *,
    cutoff_lp_per_mm: float | None = None,
    max_harmonic: int = 99,
) -> CtfToMtf:
    """Sine-wave MTF from bar contrast measured at several frequencies (Coltman's inverse).

    Parameters
    ----------
    freqs_lp_per_mm : array_like
        Frequencies where the CTF was measured (any order; duplicates not allowed), lp/mm.
    ctf : array_like
        Bar contrast (Eq. 2.9 modulation divided by the target's own modulation) at those
        frequencies.
    cutoff_lp_per_mm : float, optional
        Frequency above which the MTF is zero (optics cutoff, or Nyquist if you accept that
        assumption); ``CTF(k f)`` there is 0 exactly. ``None``: the highest measured frequency
        is taken as the cutoff (the usual truncation assumption).
    max_harmonic : int
        Highest odd harmonic of the series.

    Returns
    -------
    CtfToMtf
        MTF at each input frequency with the method used.
    """
    f = np.asarray(freqs_lp_per_mm, dtype=np.float64).ravel()
    c = np.asarray(ctf, dtype=np.float64).ravel()
    if f.size != c.size or f.size == 0:
        raise ValueError("need equally many frequencies and CTF values (at least one)")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(c))) or np.any(f <= 0):
        raise ValueError("frequencies must be positive and all values finite")
    order = np.argsort(f)
    fs, cs = f[order], c[order]
    if np.any(np.diff(fs) == 0):
        raise ValueError("duplicate frequencies")
    f_max = float(fs[-1])
    # Above ``limit`` the MTF is taken as zero: the cutoff when given, else the measured range.
    limit = f_max if cutoff_lp_per_mm is None else float(cutoff_lp_per_mm)
    mtf = np.empty_like(f)
    methods: list[str] = []
    for i, fi in enumerate(f):
        total = 0.0
        if 3 * fi > limit:
            # Only a known cutoff makes the one-term series exact; without one, CTF(3f) and up
            # were never measured and are merely assumed to be 0.
            method = "pi/4" if cutoff_lp_per_mm is not None else "truncated"
        else:
            method = "coltman"
        for k in range(1, max_harmonic + 1, 2):
            b = coltman_coefficient(k)
            fk = k * fi
            if b == 0 or fk > limit * (1 + 1e-12):
                continue
            if fk <= f_max * (1 + 1e-9):
                total += b * float(np.interp(fk, fs, cs)) / k
            else:
                method = "truncated"  # needed below the cutoff but not measured
        if method == "coltman" and (max_harmonic + 2 - max_harmonic % 2) * fi <= limit:
            method = "truncated"  # the series stopped at max_harmonic inside the range
        mtf[i] = math.pi / 4 * total
        methods.append(method)
    return CtfToMtf(f, c, mtf, tuple(methods))


def ctf_to_mtf_with_harmonics(
    freqs_lp_per_mm: npt.ArrayLike, ctf: npt.ArrayLike,
    harmonic_mtf: Callable[[npt.NDArray[np.float64]], npt.ArrayLike], max_harmonic: int = 99,
) -> npt.NDArray[np.float64]:
    """Sine-wave MTF from bar contrast with the harmonics taken from a measured MTF.

    Coltman's forward series solved for its first term:
    ``MTF(f) = pi/4 CTF(f) - sum_{k >= 3 odd} (-1)^((k-1)/2) MTF(k f) / k``, ``MTF(k f)`` from
    ``harmonic_mtf`` (a slanted edge's curve, which runs past Nyquist; it should return 0
    beyond its range). No cutoff is assumed: exact for a long square wave whenever the
    harmonics' MTF is right.

    Parameters
    ----------
    freqs_lp_per_mm, ctf : array_like
        Where the bar contrast was measured and its value (modulation over the target's own).
    harmonic_mtf : callable
        Sine-wave MTF at an array of frequencies (lp/mm).
    max_harmonic : int
        Highest odd harmonic.

    Returns
    -------
    ndarray
        The MTF at each frequency.
    """
    f = np.asarray(freqs_lp_per_mm, dtype=np.float64).ravel()
    c = np.asarray(ctf, dtype=np.float64).ravel()
    if f.size != c.size:
        raise ValueError("need equally many frequencies and CTF values")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(c))) or np.any(f <= 0):
        raise ValueError("frequencies must be positive and all values finite")
    out = math.pi / 4 * c
    for k in range(3, max_harmonic + 1, 2):
        out = out - (-1) ** ((k - 1) // 2) * np.asarray(harmonic_mtf(k * f), np.float64) / k
    return np.asarray(out, dtype=np.float64)


def mtf_to_ctf(
    mtf_at: object, freqs_lp_per_mm: npt.ArrayLike, max_harmonic: int = 101
) -> npt.NDArray[np.float64]:
    """Coltman's forward series: CTF from a callable MTF(f) (vectorised), for checks.

    ``mtf_at`` is called on blocks of harmonics at once (a call per harmonic cost most of a
    re-analysis's target contrast: up to 10,000 terms per frequency); the terms are still added
    one after another from 0 in the order of ``k`` (an accumulation, not a pairwise sum), so
    the result has the same bits as the plain loop's."""
    f = np.asarray(freqs_lp_per_mm, dtype=np.float64)
    flat = f.reshape(1, -1)
    ks = np.arange(1, max_harmonic + 1, 2)
    total = np.zeros((1, flat.shape[1]))
    rows = max(1, _SERIES_BLOCK // max(flat.shape[1], 1))
    for start in range(0, ks.size, rows):
        k = ks[start:start + rows, None]
        sign = np.where((k - 1) // 2 % 2 == 0, 1.0, -1.0)
        terms = sign * np.asarray(mtf_at(k * flat), dtype=np.float64) / k  # type: ignore[operator]
        total = np.cumsum(np.concatenate([total, terms]), axis=0)[-1:]
    return np.asarray(4 / math.pi * total.reshape(f.shape), dtype=np.float64)


#: Terms of :func:`mtf_to_ctf` evaluated per call of the MTF (bounds its memory).
_SERIES_BLOCK = 1 << 16


def mtf_from_fundamental(fundamental_modulation: float, object_modulation: float = 1.0) -> float:
    """Sine-wave MTF from the fundamental of a long square-wave target: the fundamental of a
    bar pattern of modulation M is (4/pi) M, so MTF = (pi/4) fundamental / M (Sitter 1995)."""
    if object_modulation <= 0:
        raise ValueError(f"object modulation must be positive, got {object_modulation}")
    return math.pi / 4 * fundamental_modulation / object_modulation


#: A local minimum of an MTF modulus curve at or below this is taken as a zero of the OTF.
ZERO_DIP = 0.05


def signed_mtf(freqs_lp_per_mm: npt.ArrayLike, modulus: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The real OTF that an MTF modulus curve (a lens design program's export) stands for.

    An exported MTF is ``|OTF|``: past a zero the contrast is *reversed* (spurious
    resolution), yet the modulus bounces back up. Coltman's series adds the harmonics with
    their sign, so the modulus would count a reversed harmonic as a positive one and the
    square-wave response could exceed 1, which no contrast can (a blurred square wave stays
    between its levels). Each local minimum at or below :data:`ZERO_DIP` that the curve
    rises from again is taken as a zero: the sign flips after it (the minimum itself is 0).

    Parameters
    ----------
    freqs_lp_per_mm, modulus : array_like
        The curve, frequencies increasing.

    Returns
    -------
    ndarray
        The modulus with the sign of each lobe.
    """
    f = np.asarray(freqs_lp_per_mm, dtype=np.float64)
    m = np.asarray(modulus, dtype=np.float64)
    if f.shape != m.shape:
        raise ValueError("need as many MTF values as frequencies")
    out = m.copy()
    sign = 1.0
    for i in range(m.size):
        dip = (0 < i < m.size - 1 and m[i] <= ZERO_DIP and m[i] <= m[i - 1]
               and m[i] < m[i + 1])
        if dip:
            out[i] = 0.0
            sign = -sign
        else:
            out[i] = sign * m[i]
    return out
