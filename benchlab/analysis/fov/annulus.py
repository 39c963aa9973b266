"""The radial annulus's edges: its centre and its inner and outer radii.

In the radial set-up (the ring tube, the forward disc dark) the lit annulus is bounded by two
circles about the optical axis; their radii are the image heights of the radial field's two
ends on the wall (issue 41). Each position's frame gives one annulus (:func:`find_annulus`; a
ring next to an edge shifts that position's edge); their median is the first estimate, and
:func:`refine_annulus` reads each edge again on the positions where no ring is near it.

First guess: the dark hole inside the lit annulus (its centroid and equivalent radius); then
on 360 rays the innermost rising crossing of the half level (the inner edge) and, where the
ray stays inside the frame, the outermost falling one (the outer edge), read at 0.25 px steps
(bilinear). One centre and two radii are fitted to both sets of points, points further than 4
robust standard deviations dropped; the covariance is the Gauss-Newton one scaled by the
residual variance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.optimize import least_squares

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.fov.edges import clean_edge_points
from benchlab.analysis.fov.figures import Z95

#: The edge reading's modelling error on each radius (px, a 95 % bound): on noise-free renders
#: of the default tube the refined inner and outer radii are 0.00040 and 0.00028 px inside
#: the scene's (the half-level crossing read by bilinear interpolation along rays across a
#: curved soft edge), as large as the radii's statistical sigma (~0.0005 px), which the
#: points' scatter cannot show; refined radii carry this bound, rounded up, in quadrature.
ANNULUS_EDGE_SYSTEMATIC_PX = 0.0005


class AnnulusNotFoundError(ValueError):
    """No lit annulus around a dark centre (wrong set-up, lamp off, the tube missing)."""


@dataclass(frozen=True)
class Annulus:
    """Centre ``(col, row)``, inner and outer radius (px), their covariance, the lit level."""

    centre_col: float
    centre_row: float
    inner_px: float
    outer_px: float
    covariance: FloatArray
    bright: float
    edge_points: int

    @property
    def sigma(self) -> FloatArray:
        return np.sqrt(np.diag(self.covariance))


def _first_guess(img: FloatArray) -> tuple[float, float, float, float, float]:
    bright = float(np.percentile(img, 99.5))
    dark = float(np.percentile(img, 1.0))
    if bright - dark < 10.0:
        raise AnnulusNotFoundError(f"no lit annulus: the frame's bright level {bright:.1f} is "
                                   f"barely above its dark level {dark:.1f}")
    lit = img > (bright + dark) / 2.0
    hole = ndimage.binary_fill_holes(lit) & ~lit
    labels, n = ndimage.label(hole)
    if n == 0:
        raise AnnulusNotFoundError("no dark centre inside a lit ring: is the radial view (the "
                                   "ring tube, the forward view capped) on the camera?")
    sizes = ndimage.sum_labels(hole, labels, index=np.arange(1, n + 1))
    biggest = labels == int(np.argmax(sizes)) + 1
    rows, cols = np.nonzero(biggest)
    c0, r0 = float(cols.mean()), float(rows.mean())
    lr, lc = np.nonzero(lit)
    outer = float(np.percentile(np.hypot(lc - c0, lr - r0), 99.9))
    return c0, r0, float(np.sqrt(biggest.sum() / np.pi)), outer, dark


def find_annulus(frame: npt.ArrayLike, rays: int = 360) -> Annulus:
    """The radial annulus of one frame (module docstring; a ring next to an edge pulls it).

    Raises
    ------
    AnnulusNotFoundError
        No lit annulus, or too few edge points.
    """
    img = np.asarray(frame, dtype=np.float64)
    c0, r0, rin0, rout0, dark = _first_guess(img)
    h, w = img.shape
    az = np.linspace(0.0, 2.0 * np.pi, rays, endpoint=False)
    inner: list[tuple[float, float]] = []
    outer: list[tuple[float, float]] = []
    for guess, is_inner, store in ((rin0, True, inner), (rout0, False, outer)):
        radii = guess + np.arange(-25.0, 25.0 + 1e-9, 0.25)
        cols = c0 + np.cos(az)[:, None] * radii[None, :]
        rows = r0 + np.sin(az)[:, None] * radii[None, :]
        inside = (rows >= 0) & (rows <= h - 1) & (cols >= 0) & (cols <= w - 1)
        prof = ndimage.map_coordinates(img, [rows.ravel(), cols.ravel()], order=1,
                                       mode="nearest").reshape(rows.shape)
        for k in range(rays):
            if not inside[k].all():
                continue  # the annulus runs off the frame on this ray
            lit_level = float(np.percentile(prof[k], 90.0))
            half = (lit_level + dark) / 2.0
            above = np.nonzero(prof[k] >= half)[0]
            if len(above) == 0:
                continue
            j = int(above[0]) - 1 if is_inner else int(above[-1])
            if j < 0 or j + 1 >= len(radii):
                continue
            a, b = prof[k, j], prof[k, j + 1]
            t = (a - half) / (a - b) if a != b else 0.5
            store.append((az[k], radii[j] + t * (radii[j + 1] - radii[j])))
    if len(inner) < 20 or len(outer) < 20:
        raise AnnulusNotFoundError(f"only {len(inner)} inner and {len(outer)} outer edge points "
                                   "of the annulus found (20 each needed)")
    pts_in = np.array([(c0 + r * np.cos(a), r0 + r * np.sin(a)) for a, r in inner])
    pts_out = np.array([(c0 + r * np.cos(a), r0 + r * np.sin(a)) for a, r in outer])
    p, cov, n = _robust_fit(pts_in, pts_out, np.array([c0, r0, rin0, rout0]))
    bright = float(np.median(img[_ring_mask(img.shape, p)]))
    return Annulus(float(p[0]), float(p[1]), float(p[2]), float(p[3]), cov, bright, n)


def _robust_fit(pts_in: FloatArray, pts_out: FloatArray, start: FloatArray
                ) -> tuple[FloatArray, FloatArray, int]:
    """One centre and two radii fitted to both edges' points, points beyond 4 robust standard
    deviations dropped: ``(col, row, inner, outer)``, its covariance, the points kept."""
    keep_in = np.ones(len(pts_in), dtype=bool)
    keep_out = np.ones(len(pts_out), dtype=bool)
    p = start
    for _ in range(3):
        p, cov, res_in, res_out = _fit(pts_in[keep_in], pts_out[keep_out], p)
        r_in = np.hypot(pts_in[:, 0] - p[0], pts_in[:, 1] - p[1]) - p[2]
        r_out = np.hypot(pts_out[:, 0] - p[0], pts_out[:, 1] - p[1]) - p[3]
        mad = 1.4826 * float(np.median(np.abs(np.concatenate([res_in, res_out])))) + 1e-6
        keep_in, keep_out = np.abs(r_in) <= 4.0 * mad, np.abs(r_out) <= 4.0 * mad
    return p, cov, int(keep_in.sum() + keep_out.sum())


def _ring_mask(shape: tuple[int, ...], p: FloatArray) -> npt.NDArray[np.bool_]:
    rows = np.arange(shape[0], dtype=np.float64)[:, None] - p[1]
    cols = np.arange(shape[1], dtype=np.float64)[None, :] - p[0]
    r = np.hypot(rows, cols)
    return (r > p[2] + 5.0) & (r < p[3] - 5.0)


def _fit(pin: FloatArray, pout: FloatArray, start: FloatArray
         ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    def res(p: FloatArray) -> FloatArray:
        return np.concatenate([np.hypot(pin[:, 0] - p[0], pin[:, 1] - p[1]) - p[2],
                               np.hypot(pout[:, 0] - p[0], pout[:, 1] - p[1]) - p[3]])

    sol = least_squares(res, start, method="lm")
    r = res(sol.x)
    s2 = float(r @ r) / max(len(r) - 4, 1)
    cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2
    return sol.x, cov, r[:len(pin)], r[len(pin):]


def refine_annulus(inner_frames: Sequence[FloatArray], outer_frames: Sequence[FloatArray],
                   annulus: Annulus, rays: int = 360) -> Annulus:
    """The annulus again from the inner edge of ``inner_frames`` and the outer edge of
    ``outer_frames`` (the positions where no ring is near that edge), one centre for both
    (:func:`benchlab.analysis.fov.edges.clean_edge_points`); the covariance is the fit's,
    from the points' scatter, with :data:`ANNULUS_EDGE_SYSTEMATIC_PX` on each radius.

    Raises
    ------
    AnnulusNotFoundError
        Fewer than 20 edge points on either edge.
    """
    centre = (annulus.centre_col, annulus.centre_row)
    none = np.empty((0, 2))
    pin = [clean_edge_points(np.asarray(f, dtype=np.float64), centre, annulus.inner_px, rays,
                             False, none, 0.0) for f in inner_frames]
    pout = [clean_edge_points(np.asarray(f, dtype=np.float64), centre, annulus.outer_px, rays,
                              True, none, 0.0) for f in outer_frames]
    pts_in = np.concatenate(pin) if pin else none
    pts_out = np.concatenate(pout) if pout else none
    if len(pts_in) < 20 or len(pts_out) < 20:
        raise AnnulusNotFoundError(f"only {len(pts_in)} inner and {len(pts_out)} outer edge "
                                   "points clear of the rings (20 each needed)")
    p, cov, n = _robust_fit(pts_in, pts_out,
                            np.array([*centre, annulus.inner_px, annulus.outer_px]))
    cov = cov.copy()
    cov[2, 2] += (ANNULUS_EDGE_SYSTEMATIC_PX / Z95) ** 2
    cov[3, 3] += (ANNULUS_EDGE_SYSTEMATIC_PX / Z95) ** 2
    return Annulus(float(p[0]), float(p[1]), float(p[2]), float(p[3]), cov, annulus.bright, n)


def median_annulus(annuli: Sequence[Annulus]) -> Annulus:
    """The positions' annuli's median (a first estimate a ring next to an edge cannot move;
    its covariance is the median one)."""
    x = np.median(np.array([[a.centre_col, a.centre_row, a.inner_px, a.outer_px]
                            for a in annuli]), axis=0)
    cov = np.median(np.array([a.covariance for a in annuli]), axis=0)
    return Annulus(float(x[0]), float(x[1]), float(x[2]), float(x[3]), cov,
                   float(np.median([a.bright for a in annuli])), annuli[0].edge_points)
