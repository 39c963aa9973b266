"""The joint fit of the forward view's geometry to the dots seen at several distances.

Parameters (:data:`NAMES`, then the mapping's terms): the image centre ``(cx, cy)`` px, the
entrance pupil ``e`` (mm behind the lens's front reference), the axis tilt ``(wx, wy)`` (rad),
the chart's roll ``psi`` (rad) and lateral offset ``(x0, y0)`` (mm), then the mapping's odd
polynomial ``a1, a3, a5, ...`` (:data:`MAPPING_TERMS` of them; mm per radian^k, ``a1`` the
paraxial focal length). The model is :func:`.model.project`. Five terms: ``tan theta`` and a
strong barrel differ from their 9th-order polynomial by under 2e-5 mm at 30 deg, below the
centroids' noise; three terms would leave 2e-3 mm there.

Why several distances: at one distance the focal length and the pupil position trade against
each other (only their ratio to ``D + e`` is seen), and a tilt of the axis looks like a chart
offset. A stage step of known length separates both: the chart's image scales as
``1 / (D + e)`` and an offset's angle shrinks with distance while a tilt's does not.

The image centre is tied to the disc's centre (its fitted value and covariance enter as a
prior): a tilt and a shifted centre move every dot alike, and the disc's centre is where the
thesis puts the optical axis (section 4.3.3).

Uncertainty: the centroid noise ``s`` is estimated from the residuals, per distance (both
coordinates alike); the covariance is ``(J^T J)^-1`` of the weighted problem (dots by
``1 / s``, the prior by its own covariance). Figures derived from the parameters get their
intervals by the delta method (:mod:`.figures`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.fov.disc import Disc, DiscNotFoundError, refine_disc
from benchlab.analysis.fov.dots import Dots
from benchlab.analysis.fov.model import PIXEL_MM, Pose, chart_points_mm, poly_height_mm, project

NAMES = ("cx", "cy", "e", "wx", "wy", "psi", "x0", "y0")
#: Terms of the mapping's odd polynomial (a1 ... a9).
MAPPING_TERMS = 5
#: Index of ``a1`` in the parameter vector.
A1 = len(NAMES)


class FitError(ValueError):
    """The geometry cannot be fitted (too few dots or distances; says which)."""


@dataclass(frozen=True)
class Fit:
    """The fitted parameters (:data:`NAMES`), their covariance, the centroid noise (px, RMS
    over the distances), the
    residual RMS per distance (px) and how many dots entered."""

    params: FloatArray
    covariance: FloatArray
    noise_px: float
    rms_px: tuple[float, ...]
    dots: int

    def pose(self, p: FloatArray | None = None) -> Pose:
        return pose_of(self.params if p is None else p)


def pose_of(p: FloatArray) -> Pose:
    return Pose(centre_col=float(p[0]), centre_row=float(p[1]), entrance_pupil_mm=float(p[2]),
                tilt_x_rad=float(p[3]), tilt_y_rad=float(p[4]), roll_rad=float(p[5]),
                offset_x_mm=float(p[6]), offset_y_mm=float(p[7]))


def predict(p: FloatArray, ij: FloatArray, distance_mm: FloatArray, pitch_mm: float
            ) -> FloatArray:
    """Image positions ``(n, 2)`` of dots under parameters ``p``."""
    pts = chart_points_mm(ij, pitch_mm, distance_mm, pose_of(p))
    return project(pts, pose_of(p), poly_height_mm(p[A1:]))


def _start(views: Sequence[tuple[float, Dots]], disc: Disc, pitch_mm: float) -> FloatArray:
    """A first guess: focal length from the spacing next to the fiducial at the nearest
    distance, the offset from where the fiducial is, no tilt, no distortion."""
    d0, near = min(views, key=lambda v: v[0])
    ij, xy = near.ij.astype(np.float64), near.xy
    fid = np.nonzero((near.ij == 0).all(axis=1))[0]
    right = np.nonzero((near.ij == (1, 0)).all(axis=1))[0]
    if len(fid) == 0 or len(right) == 0:
        raise FitError(f"the fiducial or its neighbour is missing at {d0:g} mm")
    vec = xy[right[0]] - xy[fid[0]]
    spacing = float(np.hypot(*vec))
    a1 = spacing * PIXEL_MM * d0 / pitch_mm
    psi = float(np.arctan2(vec[1], vec[0]))
    scale = PIXEL_MM * d0 / a1
    x0 = (xy[fid[0], 0] - disc.centre_col) * scale
    y0 = (xy[fid[0], 1] - disc.centre_row) * scale
    del ij
    return np.array([disc.centre_col, disc.centre_row, 0.0, 0.0, 0.0, psi, x0, y0, a1]
                    + [0.0] * (MAPPING_TERMS - 1))


def fit_views(views: Sequence[tuple[float, Dots]], disc: Disc, pitch_mm: float,
              min_dots: int = 20) -> Fit:
    """Fit :data:`NAMES` to the dots of each ``(object distance mm, dots)`` view.

    Raises
    ------
    FitError
        Fewer than two distinct distances, or a view with fewer than ``min_dots`` dots.
    """
    if len({round(d, 6) for d, _ in views}) < 2:
        raise FitError("the pupil and the tilt need the chart at two distances at least")
    for d, v in views:
        if len(v.ij) < min_dots:
            raise FitError(f"only {len(v.ij)} dots identified at {d:g} mm (at least "
                           f"{min_dots} needed)")
    ij = np.concatenate([v.ij for _, v in views]).astype(np.float64)
    xy = np.concatenate([v.xy for _, v in views])
    dist = np.concatenate([np.full(len(v.ij), d, dtype=np.float64) for d, v in views])
    prior_c = np.array([disc.centre_col, disc.centre_row])
    prior_w = np.linalg.cholesky(np.linalg.inv(disc.covariance[:2, :2])).T

    def residuals(p: FloatArray, s: FloatArray) -> FloatArray:
        dots = ((predict(p, ij, dist, pitch_mm) - xy) / s[:, None]).ravel()
        return np.concatenate([dots, prior_w @ (p[:2] - prior_c)])

    p = _start(views, disc, pitch_mm)
    # the centroid noise per distance (dots differ in size and number between distances):
    # one pooled value would under-weight the quieter distance's dots
    s = np.ones(len(ij))
    share = len(p) / len(ij)
    for _ in range(2):  # the noise from the residuals, then the weighted fit again
        sol = least_squares(residuals, p, args=(s,), method="lm", x_scale="jac")
        p = sol.x
        r = (predict(p, ij, dist, pitch_mm) - xy)
        for d, _v in views:
            sel = dist == d
            dof = max(2 * int(sel.sum()) - share * int(sel.sum()), 1.0)
            s[sel] = max(float(np.sqrt((r[sel] ** 2).sum() / dof)), 1e-4)
    sol = least_squares(residuals, p, args=(s,), method="lm", x_scale="jac")
    p = sol.x
    jac = sol.jac
    cov = np.linalg.inv(jac.T @ jac)
    r = predict(p, ij, dist, pitch_mm) - xy
    rms = []
    for d, _ in views:
        sel = dist == d
        rms.append(float(np.sqrt((r[sel] ** 2).sum(axis=1).mean())))
    noise = float(np.sqrt(np.mean(s ** 2)))
    return Fit(p, cov, noise, tuple(rms), len(ij))


def fit_with_clean_disc(frames: Mapping[float, FloatArray], views: Sequence[tuple[float, Dots]],
                        disc: Disc, pitch_mm: float, dot_mm: float, half_count: int,
                        min_dots: int = 20) -> tuple[Disc, Fit, str]:
    """Fit, read the disc's edge again on every distance's frame clear of the dots the fit
    predicts there (:func:`benchlab.analysis.fov.disc.refine_disc`; a ray is skipped within a
    dot's half size at that distance, paraxial scale, plus 3 px of blur), and fit again
    with that disc: ``(disc, fit, "")``. Where the dots crowd the edge so that too few rays
    are clear (a strong barrel squeezes them radially), the first disc and fit are kept and
    the third value says so.

    Raises
    ------
    FitError
        As :func:`fit_views`.
    """
    fit = fit_views(views, disc, pitch_mm, min_dots)
    k = np.arange(-half_count, half_count + 1, dtype=np.float64)
    i, j = np.meshgrid(k, k)
    ij = np.stack([i.ravel(), j.ravel()], axis=1)
    dots = [predict(fit.params, ij, np.full(len(ij), d), pitch_mm) for d in frames]
    block_px = [0.5 * dot_mm * float(fit.params[A1]) / d / PIXEL_MM + 3.0 for d in frames]
    try:
        clean = refine_disc(list(frames.values()), disc, dots, block_px)
    except DiscNotFoundError as exc:
        return disc, fit, (f"disc edge read on the maximum of the frames ({exc}): it may be "
                           "biased by ~0.01 px, beyond its interval")
    return clean, fit_views(views, clean, pitch_mm, min_dots), ""
