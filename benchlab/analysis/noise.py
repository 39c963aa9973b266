"""Robust noise scale: the median absolute deviation, made consistent with a normal sigma."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

#: Normal-consistency factor of the median absolute deviation (1 / Phi^-1(3/4)).
MAD_TO_SIGMA = 1.4826


def robust_sigma(values: npt.ArrayLike) -> float:
    """Sigma of ``values`` from their median absolute deviation (outliers barely move it)."""
    x = np.asarray(values, dtype=np.float64)
    return float(MAD_TO_SIGMA * np.median(np.abs(x - np.median(x))))
