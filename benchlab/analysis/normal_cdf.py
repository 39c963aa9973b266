"""The standard normal cumulative distribution function in numpy alone.

``scipy.special`` costs 35-130 ms to import (its array-API layer pulls in ``numpy.testing``
and ``numpy.f2py``); the analysis layer's bar model needs only this one function, so it lives
here. :func:`ndtr` has ``scipy.special.ndtr``'s name and contract so callers swap the import.
On large arrays of ``|x| < 6`` it is up to 7x slower than scipy's C loop, so the scenes (which
render whole frames and import scipy anyway) keep scipy's.

The method is W. J. Cody's ``ANORM`` (ACM TOMS Algorithm 715, SPECFUN, 1993; the rational
Chebyshev approximations of Cody, Math. Comp. 23 (1969) 631-637), evaluated here per region
on whole arrays:

* ``|x| <= 0.66291``: ``0.5 + x A(x^2) / B(x^2)``;
* ``0.66291 < |x| <= sqrt(32)``: tail ``= exp(-x^2/2) C(|x|) / D(|x|)``;
* ``|x| > sqrt(32)``: tail ``= exp(-x^2/2) (1/sqrt(2 pi) - z P(z) / Q(z)) / |x|``, ``z = 1/x^2``;

where the tail is ``Phi(-|x|)`` and ``Phi(x) = 1 - tail`` for ``x > 0``. Beyond ``sqrt(32)``
``exp(-x^2/2)`` is computed as ``exp(-s^2/2) exp(-(x - s)(x + s)/2)`` with ``s`` = ``x``
truncated to 1/16, so the far tail keeps full relative precision (scipy's ``ndtr`` loses
``~x^2 eps`` there, 2.4e-13 at ``x = -37``); in the middle region the plain ``exp`` costs at
most ``x^2 eps / 2`` < 2e-15 relative. Below ``x = -37.519`` the result is
0 (scipy returns subnormals there, < 1e-307) and from ``x = 8.572`` it is 1.

Accuracy against ``scipy.special.ndtr`` (tested in ``tests/test_normal_cdf.py`` on a dense
grid over [-40, 10]): absolute difference <= 2.3e-16 everywhere; against a 50-digit reference
in the lower tail: relative error < 2e-15.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray

#: ``|x| <= THRESHOLD``: the central approximation (where Phi = 0.75).
THRESHOLD = 0.66291
#: Between THRESHOLD and ROOT32 the middle approximation, above it the asymptotic one.
ROOT32 = 5.656854248
#: Phi is 0 (below the smallest normal double) from here down ...
X_LOW = -37.519
#: ... and 1 (to double precision) from here up.
X_HIGH = 8.572
_INV_SQRT_2PI = 0.39894228040143267794

# Cody's coefficients, highest-order numerator term last in A, C, P (as published).
_A = (2.2352520354606839287, 161.02823106855587881, 1067.6894854603709582,
      18154.981253343561249, 0.065682337918207449113)
_B = (47.20258190468824187, 976.09855173777669322, 10260.932208618978205,
      45507.789335026729956)
_C = (0.39894151208813466764, 8.8831497943883759412, 93.506656132177855979,
      597.27027639480026226, 2494.5375852903726711, 6848.1904505362823326,
      11602.651437647350124, 9842.7148383839780218, 1.0765576773720192317e-8)
_D = (22.266688044328115691, 235.38790178262499861, 1519.377599407554805,
      6485.558298266760755, 18615.571640885098091, 34900.952721145977266,
      38912.003286093271411, 19685.429676859990727)
_P = (0.21589853405795699, 0.1274011611602473639, 0.022235277870649807,
      0.001421619193227893466, 2.9112874951168792e-5, 0.02307344176494017303)
_Q = (1.28426009614491121, 0.468238212480865118, 0.0659881378689285515,
      0.00378239633202758244, 7.29751555083966205e-5)


def _ratio(t: FloatArray, num: tuple[float, ...], den: tuple[float, ...]) -> FloatArray:
    """Cody's nested evaluation: ``num[-1] t^n + ...`` over the monic ``t^n + den ...``
    (``len(den) == len(num) - 1 == n``), numerator's last coefficient leading."""
    xnum = num[-1] * t
    xden = t.copy()
    for a, b in zip(num[:-2], den[:-1], strict=True):
        xnum += a
        xnum *= t
        xden += b
        xden *= t
    return (xnum + num[-2]) / (xden + den[-1])


def _split_gaussian(y: FloatArray) -> FloatArray:
    """``exp(-y^2 / 2)`` with the argument split so that rounding ``y^2`` costs no relative
    precision for large ``y`` (Cody's device; the middle region does without it)."""
    s = np.trunc(y * 16.0) * 0.0625
    out = np.exp(-0.5 * s * s)
    out *= np.exp(-0.5 * (y - s) * (y + s))
    return out


def ndtr(x: npt.ArrayLike) -> FloatArray:
    """Standard normal CDF ``Phi(x) = P(Z <= x)``, elementwise.

    Parameters
    ----------
    x : array_like
        Any real values (NaN gives NaN, -inf 0, +inf 1).

    Returns
    -------
    ndarray of float64
        ``Phi(x)``, same shape as ``x`` (0-d for a scalar).
    """
    xa = np.asarray(x, dtype=np.float64)
    flat_x = xa.ravel()
    # Saturated values first (0 below X_LOW, 1 from X_HIGH; NaN is fixed at the end): most
    # of a blurred scene is that, so only the rest is gathered and computed.
    flat = (flat_x > 0.0).astype(np.float64)
    work = np.flatnonzero((flat_x > X_LOW) & (flat_x < X_HIGH))
    if work.size:
        flat[work] = _unsaturated(flat_x[work])
    if np.isnan(flat_x.sum()):  # one reduction instead of a mask in the usual NaN-free case
        flat[np.isnan(flat_x)] = np.nan
    return flat.reshape(xa.shape)


def _unsaturated(x: FloatArray) -> FloatArray:
    """:func:`ndtr` of values in ``(X_LOW, X_HIGH)`` (1-d)."""
    y = np.abs(x)
    centre = y <= THRESHOLD
    middle = ~centre & (y <= ROOT32)
    far = y > ROOT32
    # tail = Phi(-|x|) in both tails; 1 - tail where x > 0.
    out = np.empty_like(x)
    if middle.any():
        ym = y[middle]
        tail = np.exp(-0.5 * ym * ym)
        tail *= _ratio(ym, _C, _D)
        out[middle] = tail
    if far.any():
        yf = y[far]
        z = 1.0 / (yf * yf)
        out[far] = _split_gaussian(yf) * (_INV_SQRT_2PI - z * _ratio(z, _P, _Q)) / yf
    # Not on the centre: its entries are still np.empty's garbage (a NaN there warned).
    np.subtract(1.0, out, out=out, where=(x > 0.0) & ~centre)
    if centre.any():
        xc = x[centre]
        out[centre] = 0.5 + xc * _ratio(xc * xc, _A, _B)
    return out
