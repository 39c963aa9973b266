"""The spectrum of a uniform disc's line spread, ``jinc(x) = 2 J1(x) / x``, in numpy alone.

The defocus family of :mod:`benchlab.analysis.bars.knownbars` multiplies a pattern's spectrum by
``jinc(2 pi R f)`` on every frequency of its tabulation grid (a few million values for a whole
chart). ``scipy.special.j1`` did that, but importing ``scipy.special`` costs ~0.2 s of CPU, most
of what ``benchlab analyze SESSION`` spent beyond its start-up target (issue 11).

Two evaluations:

* :func:`bessel_j0_j1`, close to double precision (within 3e-14 of ``scipy.special.j0``/``j1``,
  tested), per region: the power series below :data:`SERIES_MAX_X`; between it and
  :data:`HANKEL_MIN_X` the integral ``J_n(x) = (1/pi) int_0^pi cos(n t - x sin t) dt`` by the
  trapezoid rule on :data:`TRAPEZOID_POINTS` points (a smooth periodic integrand: the error is
  ``~J_{2N-n}(x)``, below 1e-20 there); above it Hankel's asymptotic expansion to
  :data:`HANKEL_TERMS` terms (its smallest term there ~1e-17).
* :func:`jinc`, fast: a cubic Hermite interpolation of ``jinc`` and its derivative
  ``-2 J2(x) / x`` tabulated once (per process, on first use, ~3 ms) by
  :func:`bessel_j0_j1` every :data:`TABLE_STEP` up to :data:`TABLE_MAX_X`; beyond, Hankel's
  expansion. Its error is at most ~3e-10 (tested against ``scipy.special.j1`` on a dense grid:
  :data:`JINC_MAX_ERROR`), far below what moves a reading (a disc gain changed by 1e-9 moves a
  tabulated pattern by less than that).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray

#: Below this the power series (its largest term at 8 is ~23: ~1e-14 lost to cancellation).
SERIES_MAX_X = 8.0
SERIES_TERMS = 26
#: From here Hankel's expansion; between, the trapezoid rule on this many intervals.
HANKEL_MIN_X = 40.0
TRAPEZOID_POINTS = 64
HANKEL_TERMS = 12
#: :func:`jinc`'s table: step (a power of 2: the index is exact) and extent; beyond it
#: Hankel's expansion (at most 1300 is asked by the chart reading: a disc of 8 px at 25
#: cycles/px).
TABLE_STEP = 1.0 / 16.0
TABLE_MAX_X = 1400.0
#: What the tests hold :func:`jinc` to (absolute).
JINC_MAX_ERROR = 1e-8

_table: tuple[FloatArray, FloatArray] | None = None
_cubic: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None = None


def _series(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """J0 and J1 by their power series in ``w = x^2 / 4`` (Horner)."""
    w = 0.25 * x * x
    c0 = [1.0 / math.factorial(k) ** 2 for k in range(SERIES_TERMS)]
    c1 = [1.0 / (math.factorial(k) * math.factorial(k + 1)) for k in range(SERIES_TERMS)]
    a, b = np.full_like(x, c0[-1]), np.full_like(x, c1[-1])
    for k in range(SERIES_TERMS - 2, -1, -1):
        a = c0[k] - w * a
        b = c1[k] - w * b
    return a, 0.5 * x * b


def _trapezoid(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """J0 and J1 by Bessel's integral, trapezoid rule (exact to rounding for x < ~50)."""
    tau = np.arange(TRAPEZOID_POINTS + 1) * (math.pi / TRAPEZOID_POINTS)
    weights = np.ones(TRAPEZOID_POINTS + 1)
    weights[0] = weights[-1] = 0.5
    phase = np.outer(x, np.sin(tau))
    j0 = (np.cos(phase) @ weights) / TRAPEZOID_POINTS
    j1 = (np.cos(tau[None, :] - phase) @ weights) / TRAPEZOID_POINTS
    return np.asarray(j0, dtype=np.float64), np.asarray(j1, dtype=np.float64)


def _hankel(x: FloatArray, order: int, terms: int = HANKEL_TERMS) -> FloatArray:
    """J_order(x) for large x: ``sqrt(2 / (pi x)) (P cos chi - Q sin chi)``,
    ``chi = x - (order / 2 + 1 / 4) pi``, P and Q Hankel's series in ``1 / x``."""
    mu = 4.0 * order * order
    a = [1.0]
    for k in range(1, 2 * terms + 2):
        a.append(a[-1] * (mu - (2 * k - 1) ** 2) / (8.0 * k))
    y = 1.0 / x
    y2 = y * y
    p, q = np.zeros_like(x), np.zeros_like(x)
    for k in range(terms, -1, -1):
        sign = -1.0 if k % 2 else 1.0
        p = p * y2 + sign * a[2 * k]
        q = q * y2 + sign * a[2 * k + 1]
    chi = x - (0.5 * order + 0.25) * math.pi
    return np.sqrt(2.0 / math.pi * y) * (p * np.cos(chi) - q * y * np.sin(chi))


def bessel_j0_j1(x: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Bessel functions ``J0(x)`` and ``J1(x)`` of ``x >= 0`` to near double precision.

    Parameters
    ----------
    x : array_like
        Non-negative values.

    Returns
    -------
    (ndarray, ndarray)
        ``J0(x)`` and ``J1(x)``, same shape as ``x``.

    Raises
    ------
    ValueError
        For a negative or non-finite value.
    """
    xa = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(xa)) or np.any(xa < 0):
        raise ValueError("bessel_j0_j1 needs finite x >= 0")
    flat = xa.ravel()
    j0, j1 = np.empty_like(flat), np.empty_like(flat)
    series = flat < SERIES_MAX_X
    hankel = flat >= HANKEL_MIN_X
    middle = ~series & ~hankel
    if series.any():
        j0[series], j1[series] = _series(flat[series])
    if middle.any():
        j0[middle], j1[middle] = _trapezoid(flat[middle])
    if hankel.any():
        j0[hankel], j1[hankel] = _hankel(flat[hankel], 0), _hankel(flat[hankel], 1)
    return j0.reshape(xa.shape), j1.reshape(xa.shape)


def _jinc_table() -> tuple[FloatArray, FloatArray]:
    """``jinc`` and ``TABLE_STEP * jinc'`` at every table node (built on first use)."""
    global _table
    if _table is None:
        nodes = np.arange(int(TABLE_MAX_X / TABLE_STEP) + 2) * TABLE_STEP
        j0, j1 = bessel_j0_j1(nodes)
        value, slope = np.ones_like(nodes), np.zeros_like(nodes)
        x = nodes[1:]
        value[1:] = 2.0 * j1[1:] / x
        slope[1:] = 2.0 * j0[1:] / x - 4.0 * j1[1:] / (x * x)  # -2 J2(x) / x
        # near 0 the difference above cancels: the derivative of the series instead,
        # x/2 sum_{k>=1} (-1)^k k w^(k-1) / (k! (k+1)!), w = x^2 / 4
        near = nodes < 1.0
        w = 0.25 * nodes[near] ** 2
        series = np.zeros_like(w)
        for k in range(SERIES_TERMS - 1, 0, -1):
            series = series * w + (-1.0) ** k * k / (math.factorial(k) * math.factorial(k + 1))
        slope[near] = 0.5 * nodes[near] * series
        _table = (value, slope * TABLE_STEP)
    return _table


def jinc(x: npt.ArrayLike) -> FloatArray:
    """``2 J1(x) / x`` (1 at 0), elementwise; even in ``x``. Within :data:`JINC_MAX_ERROR`.

    Parameters
    ----------
    x : array_like
        Finite values.

    Returns
    -------
    ndarray of float64
        Same shape as ``x``: 1 at 0, first zero at 3.8317, negative up to 7.0156.

    Raises
    ------
    ValueError
        For a non-finite value.
    """
    xa = np.abs(np.asarray(x, dtype=np.float64))
    if not np.isfinite(xa.sum()):
        raise ValueError("jinc needs finite x")
    flat = xa.ravel()
    # every value through the table (elementwise: a value's result does not depend on the
    # others; the indices beyond it clipped), then those beyond it replaced
    out = _hermite_fast(flat)
    far_at = np.flatnonzero(flat >= TABLE_MAX_X)
    if far_at.size:
        far = flat[far_at]
        out[far_at] = 2.0 * _hankel(far, 1, terms=4) / far
    return out.reshape(xa.shape)


def _cubic_table() -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The cubic Hermite polynomial's coefficients per table interval, ``f0, d0`` and the
    ``t^2`` and ``t^3`` ones, computed by the per-value interpolation's own expressions on the
    table (elementwise, so the same bits as computing them per value)."""
    global _cubic
    if _cubic is None:
        value, slope = _jinc_table()
        f0, f1, d0, d1 = value[:-1], value[1:], slope[:-1], slope[1:]
        df = f1 - f0
        _cubic = (f0.copy(), d0.copy(), 3.0 * df - 2.0 * d0 - d1, d0 + d1 - 2.0 * df)
    return _cubic


def _hermite_fast(x: FloatArray) -> FloatArray:
    """The per-value cubic Hermite interpolation bit for bit (the same products and sums in
    the same order), its per-interval coefficients gathered from :func:`_cubic_table` instead
    of formed per value; indices beyond the table are clipped (the caller overwrites those)."""
    f0, d0, c2, c3 = _cubic_table()
    s = x * (1.0 / TABLE_STEP)
    i = s.astype(np.intp)
    t = s - i
    out = c3.take(i, mode="clip")
    out *= t
    out += c2.take(i, mode="clip")
    out *= t
    out += d0.take(i, mode="clip")
    out *= t
    out += f0.take(i, mode="clip")
    return out
