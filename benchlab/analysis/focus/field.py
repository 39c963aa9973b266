"""Astigmatic focal difference and field curvature from per-edge best-focus draws.

Each field point's best focus comes with Monte Carlo draws
(:func:`benchlab.analysis.focus.through_focus.best_focus_draws`); quantities combining field
points are computed draw by draw, so their 95 % intervals carry every point's uncertainty
without a linearisation:

* astigmatic focal difference of a field point: mean best focus of its sagittal edges minus that
  of its tangential edges (mm; the thesis's S and T);
* field curvature of an orientation: the straight line best focus = ``b0 + k h^2`` through the
  field points (``h`` image height, mm) fitted by least squares; ``k`` (mm per mm^2) is the
  curvature, ``b0`` the best focus on axis.

Pure numpy; no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from benchlab.analysis.arrays import FloatArray


def _interval(values: FloatArray) -> tuple[float, float] | None:
    good = values[np.isfinite(values)]
    if good.size < 0.975 * values.size or good.size == 0:
        return None
    lo, hi = np.percentile(good, [2.5, 97.5])
    return float(lo), float(hi)


def astigmatic_difference(
    sagittal: Sequence[FloatArray], tangential: Sequence[FloatArray]
) -> tuple[float, tuple[float, float] | None]:
    """S minus T best focus (mm) and its 95 % interval, from each edge's draws (equal
    lengths); the value is the median of the differences."""
    s = np.mean(np.stack([np.asarray(d) for d in sagittal]), axis=0)
    t = np.mean(np.stack([np.asarray(d) for d in tangential]), axis=0)
    diff = s - t
    return float(np.nanmedian(diff)), _interval(diff)


def field_curvature(
    heights_mm: Sequence[float], draws: Sequence[FloatArray]
) -> tuple[float, float, tuple[float, float] | None, tuple[float, float] | None]:
    """``(k, b0, k_ci95, b0_ci95)`` of best focus = ``b0 + k h^2`` fitted draw by draw.

    Raises
    ------
    ValueError
        Fewer than two distinct image heights.
    """
    h2 = np.asarray(heights_mm, dtype=np.float64) ** 2
    if np.unique(np.round(h2, 9)).size < 2:
        raise ValueError("field curvature needs field points at two image heights at least")
    y = np.stack([np.asarray(d, dtype=np.float64) for d in draws])  # points x draws
    design = np.stack([np.ones_like(h2), h2], axis=1)
    pinv = np.linalg.pinv(design)  # 2 x points
    coef = pinv @ y  # 2 x draws (NaN where a point's draw is)
    b0, k = coef[0], coef[1]
    return (float(np.nanmedian(k)), float(np.nanmedian(b0)), _interval(k), _interval(b0))
