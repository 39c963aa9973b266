"""One estimate from several independent ones (the disc or annulus of each position's frames),
its covariance from their spread.

The field stops do not move between the procedure's positions, so each position's frames give
an estimate of the same circles; what sets them apart is the camera's noise and where the
moving dots or rings happen to fall near the edge - a shift no single frame's fit can see. So
the estimates are averaged and the covariance is their sample covariance over ``n``, scaled by
``(t_{0.975, n-1} / z_{0.975})^2`` so that a 95 % interval built with ``z`` is Student's
interval for ``n`` estimates. (Reading the edge once on the pixelwise maximum of the frames
instead biases it: the maximum of noisy frames is brightest where the light is, which moves
the half-level crossing by ~0.01 px, far beyond its statistical error.)
"""

from __future__ import annotations

import numpy as np
from scipy.stats import norm
from scipy.stats import t as student_t

from benchlab.analysis.arrays import FloatArray


def pooled(estimates: FloatArray, covariances: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Mean of ``estimates`` ``(n, k)`` and its covariance (module docstring); with one
    estimate, that estimate and its own ``covariances[0]``."""
    x = np.asarray(estimates, dtype=np.float64)
    n = len(x)
    if n < 2:
        return x[0], np.asarray(covariances[0], dtype=np.float64)
    spread = np.atleast_2d(np.cov(x.T, ddof=1))
    scale = (float(student_t.ppf(0.975, n - 1)) / float(norm.ppf(0.975))) ** 2
    return x.mean(axis=0), scale * spread / n
