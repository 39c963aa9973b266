"""Percentiles and medians exactly as :func:`numpy.percentile` (its default "linear"
method) and :func:`numpy.median` compute them, bit for bit, without the import of ``numpy.ma``
that numpy's first interpolated percentile (through :func:`numpy.unique`) or median of floats
(its NaN check) triggers: 7-12 ms of a re-analysis's start-up (issue 11).
``tests/test_analysis_quantiles.py`` pins the identity with numpy.

Same steps as numpy: positions ``(n - 1) q``, the order statistics either side (a partition),
and numpy's two-sided linear interpolation (from the lower value below a fraction of 0.5, from
the upper one from 0.5 up). A scalar ``q`` keeps the array's float type, as numpy's weak
promotion of a Python float does; a sequence gives float64. NaN anywhere gives NaN.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt


def median(a: npt.ArrayLike) -> Any:
    """``numpy.median(a)`` of the whole array (a numpy scalar): the mean of the middle one or
    two order statistics; NaN anywhere gives NaN."""
    arr = np.asanyarray(a)
    size = arr.size
    if size == 0:
        return np.median(arr)  # numpy's NaN and warning
    kth = [(size - 1) // 2] if size % 2 else [size // 2 - 1, size // 2]
    nans = np.issubdtype(arr.dtype, np.inexact) or arr.dtype.kind in "Mm"
    if nans:
        kth.append(-1)
    ordered = np.partition(arr, kth, axis=None)
    mid = size // 2
    middle = np.mean(ordered[mid:mid + 1] if size % 2 else ordered[mid - 1:mid + 1], axis=0)
    if nans and np.isnan(ordered[-1]):
        return ordered[-1]
    return middle


def percentile(a: npt.ArrayLike, q: float) -> Any:
    """``numpy.percentile(a, q)`` for a Python float ``q`` in [0, 100] (a numpy scalar)."""
    out = _percentiles(a, np.true_divide(q, 100, out=...), weak=True)
    return out[()]


def percentiles(a: npt.ArrayLike, qs: Sequence[float]) -> npt.NDArray[Any]:
    """``numpy.percentile(a, qs)`` for a sequence of percentiles in [0, 100] (an array)."""
    return _percentiles(a, np.true_divide(qs, 100, out=...), weak=False)


def _percentiles(a: npt.ArrayLike, q: npt.NDArray[Any], *, weak: bool) -> npt.NDArray[Any]:
    q = np.asanyarray(q)
    if q.ndim > 1 or not bool(np.all((q >= 0.0) & (q <= 1.0))):
        raise ValueError("Percentiles must be in the range [0, 100]")
    arr = np.asanyarray(a).ravel()
    if arr.dtype.kind == "c":
        raise TypeError("a must be an array of real numbers")
    n = arr.size
    if n == 0:
        raise IndexError("percentile of an empty array")
    position = np.asanyarray((n - 1) * q)
    below = np.floor(position, out=...)
    above = np.add(below, 1, out=...)
    at_end = position >= n - 1
    below[at_end] = -1
    above[at_end] = -1
    lo_i, hi_i = below.astype(np.intp), above.astype(np.intp)
    ordered = np.partition(arr, np.concatenate(([0, -1], lo_i.ravel(), hi_i.ravel())))
    lo, hi = ordered[lo_i], ordered[hi_i]
    t = np.asanyarray(position - lo_i, dtype=position.dtype)
    gamma: Any = float(t) if weak else t
    diff = hi - lo
    out = np.add(lo, diff * gamma, out=...)
    np.subtract(hi, diff * (1 - gamma), out=out, where=t >= 0.5, casting="unsafe",
                dtype=type(out.dtype))
    if arr.dtype.kind in "fc" and np.isnan(ordered[-1]):
        out[...] = np.nan
    return np.asanyarray(out)
