"""The array types every layer above the drivers annotates with (one definition each)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

#: A float64 array of any shape: pixels, profiles, curves.
FloatArray = npt.NDArray[np.float64]


def mean_of_frames(frames: Sequence[npt.ArrayLike]) -> FloatArray:
    """``np.mean(np.stack(frames).astype(np.float64), axis=0)``, bit for bit, without the
    float64 stack (``n`` x 10 MB for 1.3 Mpixel frames).

    Integer frames (8/16-bit codes) are summed as 32-bit integers: every partial sum of the
    float64 reduction is an integer below 2**53, so exact, and the same integer; the sum is then
    divided by ``n`` as :func:`numpy.mean` divides it. Anything else (floats, wider integers,
    more than 32767 frames) goes the plain way.

    Raises
    ------
    ValueError
        No frames, or frames of different shapes (as :func:`numpy.stack`).
    """
    arrays = [np.asarray(f) for f in frames]
    if not arrays:
        raise ValueError("need at least one frame to average")
    small_ints = all(a.dtype.kind in "ui" and a.dtype.itemsize <= 2 for a in arrays)
    if not small_ints or len(arrays) > 32767:
        return np.asarray(np.mean(np.stack(arrays).astype(np.float64), axis=0))
    shape = arrays[0].shape
    if any(a.shape != shape for a in arrays):
        raise ValueError(f"all frames must have the same shape, got "
                         f"{sorted({a.shape for a in arrays})}")
    total = arrays[0].astype(np.int32)
    for a in arrays[1:]:
        np.add(total, a, out=total)
    out = total.astype(np.float64)
    return np.asarray(np.true_divide(out, len(arrays), out=out))
