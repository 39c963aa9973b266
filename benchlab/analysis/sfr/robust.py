"""What a slanted edge may carry and still be read: the robust edge acceptance.

A real edge is not the clean step of a synthetic one. JPEG compression rings along it in
8 x 8 blocks and quantises its plateaus; a sensor adds column and row patterns, hot and dead
pixels; a printed chart adds paper grain. Against the pixel noise measured on the plateaus
(row differences, which compression smooths) such structure puts a few per cent of the pixels
more than :data:`~benchlab.analysis.sfr.measure.OUTLIER_SIGMAS` noise sigmas off the edge
profile. Those pixels are clipped to that limit before the MTF, as hot pixels are, and the
edge is read. Only two causes of stray pixels make an ROI unreadable, and they are refused
by name:

- a **bent edge** (lens distortion, a curved print): the per-row edge positions bow from a
  straight line by at least :data:`BENT_MIN_PX` and :data:`BENT_SIGMAS` times the bow's own
  standard error. A straight-line projection smears a bow into the ESF, so the edge is
  refused with a straight fit and read with ``fit_order`` 2 or 3, which follows it
  (:func:`edge_bow`);
- a **second edge** in the ROI: a bar or a line, bars, a corner
  (:func:`~benchlab.analysis.sfr.structure.find_two_edges`), or a second step of the same sign
  beside the edge (:func:`~benchlab.analysis.sfr.structure.find_second_edge`).

Pure numpy, no state.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from benchlab.analysis.noise import MAD_TO_SIGMA

#: A bow (sagitta of the per-row edge positions over the ROI) from this many px ...
BENT_MIN_PX = 0.5
#: ... and this many of its standard errors is a bent edge.
BENT_SIGMAS = 5.0
#: Rows whose centroid is more than this many robust sigmas off the quadratic are left out.
_ROW_OUTLIER_SIGMAS = 4.0


def edge_bow(rows: npt.ArrayLike, centroids: npt.ArrayLike) -> tuple[float, float]:
    """The bow of the per-row edge positions and its standard error, px.

    A quadratic ``a + b t + c (t^2 - <t^2>)`` in ``t``, the row scaled to [-1, 1] over the rows
    with a centroid, is fitted by least squares (rows more than 4 robust sigmas off dropped,
    twice); ``|c|`` is the sagitta - how far the middle of the edge sits from the chord through
    its ends. Its standard error comes from the robust (MAD) scatter of the rows about the
    fit.

    Parameters
    ----------
    rows : array_like
        Row coordinate of each centroid (px).
    centroids : array_like
        Edge position in each row (px; NaN where the row has none).

    Returns
    -------
    (float, float)
        Bow and its standard error, px; (0, inf) with fewer than 6 rows.
    """
    x = np.asarray(rows, dtype=np.float64)
    y = np.asarray(centroids, dtype=np.float64)
    keep = np.isfinite(y) & np.isfinite(x)
    if int(keep.sum()) < 6 or float(np.ptp(x[keep])) <= 0:
        return 0.0, math.inf
    half = 0.5 * float(np.ptp(x[keep]))
    t = (x - 0.5 * (float(np.max(x[keep])) + float(np.min(x[keep])))) / half
    coef = np.zeros(3)
    a_mat = np.zeros((0, 3))
    scale = 0.0
    for _ in range(3):
        tk = t[keep]
        a_mat = np.stack([np.ones_like(tk), tk, tk * tk - float(np.mean(tk * tk))], axis=1)
        coef = np.asarray(np.linalg.lstsq(a_mat, y[keep], rcond=None)[0], dtype=np.float64)
        res_all = np.asarray(
            y - (coef[0] + coef[1] * t + coef[2] * (t * t - float(np.mean(tk * tk)))),
            dtype=np.float64)
        res = res_all[keep]
        scale = MAD_TO_SIGMA * float(np.median(np.abs(res - np.median(res))))
        new_keep = keep & (np.abs(res_all) <= max(_ROW_OUTLIER_SIGMAS * scale, 1e-9))
        if int(new_keep.sum()) < 6 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    try:
        cov = np.linalg.inv(a_mat.T @ a_mat)
    except np.linalg.LinAlgError:
        return 0.0, math.inf
    return abs(float(coef[2])), scale * math.sqrt(max(float(cov[2, 2]), 0.0))


def is_bent(bow_px: float, bow_sigma_px: float) -> bool:
    """Whether a bow (:func:`edge_bow`) is a bent edge: at least :data:`BENT_MIN_PX` and
    :data:`BENT_SIGMAS` standard errors."""
    return bow_px >= BENT_MIN_PX and bow_px >= BENT_SIGMAS * bow_sigma_px


def bent_reason(bow_px: float, n_rows: int) -> str:
    """The refusal of a bent edge read with a straight fit."""
    return (f"bent edge: the edge bows {bow_px:.2f} px from a straight line over its {n_rows} "
            "rows (>= {:g} px); a straight fit smears the bow into the edge profile: read it "
            "with fit_order 2 (--fit-order 2), or a shorter ROI".format(BENT_MIN_PX))
