"""The forward disc's edge: a circle fitted to where the lit disc falls to half its level.

The forward view images the back-lit chart into a disc bounded by the field stop; the field of
view is the field angle at which the image reaches that edge (issue 41). The thesis took the
disc's centre as the optical axis in the image (section 4.3.3); so does this module.

Profiles along 360 rays from a first centre are read at 0.25 px steps (bilinear); on each the
outermost crossing of the half level between the disc's bright level and the dark surround is
the edge point. A dark dot sitting on the edge pulls its crossing inwards, so points more than
4 robust standard deviations from the circle are dropped and the circle fitted again. The
covariance of ``(col, row, radius)`` is the Gauss-Newton one scaled by the residual variance.
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


class DiscNotFoundError(ValueError):
    """No lit disc in the frame (wrong set-up, lamp off, or the disc runs off the frame)."""


@dataclass(frozen=True)
class Disc:
    """The forward disc: centre ``(col, row)`` and radius (px), their covariance, the levels."""

    centre_col: float
    centre_row: float
    radius_px: float
    covariance: FloatArray
    bright: float
    dark: float
    edge_points: int

    @property
    def sigma(self) -> FloatArray:
        return np.sqrt(np.diag(self.covariance))


def _first_guess(img: FloatArray) -> tuple[float, float, float, float, float]:
    dark = float(np.median(img))
    bright = float(np.percentile(img, 99.5))
    low = img[img <= dark]
    noise = 1.4826 * float(np.median(np.abs(low - np.median(low)))) if low.size else 0.0
    if bright - dark < 10.0 * max(noise, 1.0):
        raise DiscNotFoundError(f"no lit disc: the frame's bright level {bright:.1f} is barely "
                                f"above its dark level {dark:.1f}")
    mask = ndimage.binary_fill_holes(img > (bright + dark) / 2.0)
    labels, n = ndimage.label(mask)
    if n == 0:
        raise DiscNotFoundError("no lit disc in the frame")
    sizes = ndimage.sum_labels(mask, labels, index=np.arange(1, n + 1))
    biggest = labels == int(np.argmax(sizes)) + 1
    rows, cols = np.nonzero(biggest)
    if rows.min() == 0 or cols.min() == 0 or rows.max() == img.shape[0] - 1 \
            or cols.max() == img.shape[1] - 1:
        raise DiscNotFoundError("the lit disc runs off the frame: its edge cannot be traced "
                                "all round")
    inside = img[biggest]
    bright = float(np.median(inside[inside > (bright + dark) / 2.0]))  # the glass, not the dots
    return float(cols.mean()), float(rows.mean()), float(np.sqrt(biggest.sum() / np.pi)), \
        bright, dark


def _circle_fit(pts: FloatArray, start: tuple[float, float, float]
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    def res(p: FloatArray) -> FloatArray:
        return np.asarray(np.hypot(pts[:, 0] - p[0], pts[:, 1] - p[1]) - p[2])

    sol = least_squares(res, np.asarray(start, dtype=np.float64), method="lm")
    r = res(sol.x)
    dof = max(len(pts) - 3, 1)
    s2 = float(r @ r) / dof
    cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2
    return sol.x, cov, r


def find_disc(frame: npt.ArrayLike, rays: int = 720) -> Disc:
    """The forward disc of a frame (module docstring).

    Raises
    ------
    DiscNotFoundError
        No lit disc, or one that runs off the frame.
    """
    img = np.asarray(frame, dtype=np.float64)
    c0, r0, rad0, bright, dark = _first_guess(img)
    half = (bright + dark) / 2.0
    az = np.linspace(0.0, 2.0 * np.pi, rays, endpoint=False)
    steps = np.arange(-20.0, 20.0 + 1e-9, 0.25)
    radii = rad0 + steps
    cols = c0 + np.cos(az)[:, None] * radii[None, :]
    rows = r0 + np.sin(az)[:, None] * radii[None, :]
    prof = ndimage.map_coordinates(img, [rows.ravel(), cols.ravel()], order=1,
                                   mode="nearest").reshape(rows.shape)
    pts = []
    for k in range(rays):
        above = np.nonzero(prof[k] >= half)[0]
        if len(above) == 0 or above[-1] == len(steps) - 1:
            continue
        j = int(above[-1])  # outermost sample still lit; the crossing is between j and j + 1
        a, b = prof[k, j], prof[k, j + 1]
        t = (a - half) / (a - b) if a != b else 0.5
        rr = radii[j] + t * (radii[j + 1] - radii[j])
        # a clean edge only: lit 3-10 px inside, dark 3-10 px outside (a dot near the edge
        # would pull the crossing inwards)
        inner = prof[k, (radii >= rr - 10.0) & (radii <= rr - 3.0)]
        outer = prof[k, (radii >= rr + 3.0) & (radii <= rr + 10.0)]
        if inner.size == 0 or outer.size == 0 or inner.min() < bright - 0.25 * (bright - dark) \
                or outer.max() > dark + 0.25 * (bright - dark):
            continue
        pts.append((c0 + np.cos(az[k]) * rr, r0 + np.sin(az[k]) * rr))
    if len(pts) < 20:
        raise DiscNotFoundError(f"the disc's edge was traced on only {len(pts)} of {rays} rays")
    p = np.asarray(pts)
    x, cov, n = robust_circle(p, (c0, r0, rad0))
    return Disc(float(x[0]), float(x[1]), float(x[2]), cov, bright, dark, n)


def robust_circle(p: FloatArray, start: tuple[float, float, float]
                  ) -> tuple[FloatArray, FloatArray, int]:
    """A circle fitted to edge points, outliers (4 robust standard deviations) dropped:
    ``(col, row, radius)``, its covariance, the points kept."""
    x, cov, r = _circle_fit(p, start)
    for _ in range(5):  # dots on the edge: drop the outliers and fit again
        med = float(np.median(r))
        mad = 1.4826 * float(np.median(np.abs(r - med)))
        keep = np.abs(r - med) <= max(4.0 * mad, 0.05)
        if keep.all():
            break
        p = p[keep]
        x, cov, r = _circle_fit(p, (float(x[0]), float(x[1]), float(x[2])))
    return x, cov, len(p)


def refine_disc(frames: Sequence[FloatArray], disc: Disc, blockers: Sequence[FloatArray],
                block_px: Sequence[float], rays: int = 720) -> Disc:
    """The disc again from every frame's edge where no dot is near it (``blockers[k]``: the
    dots' image positions in ``frames[k]``; :func:`benchlab.analysis.fov.edges.
    clean_edge_points`; ``block_px[k]`` how near a ray may pass one in that frame); the
    covariance is the fit's, from the points' scatter.

    Raises
    ------
    DiscNotFoundError
        Fewer than 20 clean edge points.
    """
    pts = np.concatenate([
        clean_edge_points(np.asarray(f, dtype=np.float64), (disc.centre_col, disc.centre_row),
                          disc.radius_px, rays, True, b, px)
        for f, b, px in zip(frames, blockers, block_px, strict=True)])
    if len(pts) < 20:
        raise DiscNotFoundError(f"only {len(pts)} edge points of the disc clear of the dots")
    x, cov, n = robust_circle(pts, (disc.centre_col, disc.centre_row, disc.radius_px))
    return Disc(float(x[0]), float(x[1]), float(x[2]), cov, disc.bright, disc.dark, n)
