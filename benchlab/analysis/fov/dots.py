"""Dots of the grid chart: their centroids in a frame, and their indices on the grid.

The chart (docs/procedures/fov.md) is a square grid of dark dots of pitch ``p`` on clear glass,
back-lit; the dot at grid index ``(0, 0)`` is larger (the fiducial), so every distance names
its dots the same way. Detection: pixels darker than half the disc's level, inside the disc
less a margin (a dot cut by the disc's edge has a biased centroid), labelled 8-connected;
each dot's centroid is weighted by its darkening below the disc level over the dot grown by
two pixels (the blur's tails), an unbiased window for a symmetric dot.

Identification grows the grid from the fiducial: from a dot with index ``(i, j)`` and its
local lattice vectors ``u`` (``i + 1``) and ``v`` (``j + 1``), the neighbours are looked for at
``+-u``, ``+-v`` (within 0.3 of the pitch in pixels), and each found neighbour carries the
vector that reached it - so a barrel-distorted grid is followed to its edge. A dot reached
twice with different indices is dropped (both claims).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.spatial import cKDTree

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.fov.disc import Disc

IntArray = npt.NDArray[np.int64]


class DotsError(ValueError):
    """The dots cannot be found or identified in a frame (says why)."""


@dataclass(frozen=True)
class Dots:
    """Identified dots of one frame: ``ij`` grid indices ``(n, 2)``, ``xy`` centroids
    ``(col, row)`` px ``(n, 2)``; ``found`` counts the dots detected before identification."""

    ij: IntArray
    xy: FloatArray
    found: int


def detect(frame: npt.ArrayLike, disc: Disc, margin_px: float
           ) -> tuple[FloatArray, FloatArray]:
    """Centroids ``(n, 2)`` as ``(col, row)`` and areas (px) of the dark dots in the disc."""
    img = np.asarray(frame, dtype=np.float64)
    rows, cols = np.indices(img.shape)
    rho = np.hypot(cols - disc.centre_col, rows - disc.centre_row)
    usable = rho <= disc.radius_px - margin_px
    half = (disc.bright + disc.dark) / 2.0
    lit = img[usable & (img > half)]
    # this frame's own glass level: a level off by d adds d x the window to every dot's
    # weights, pulling its centroid towards the window's centre
    bright = float(np.median(lit)) if lit.size else disc.bright
    dark = (img < half) & (rho <= disc.radius_px)
    labels, n = ndimage.label(dark, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return np.zeros((0, 2)), np.zeros(0)
    slices = ndimage.find_objects(labels)
    out, areas = [], []
    h, w = img.shape
    for k, sl in enumerate(slices, start=1):
        if sl is None:
            continue
        r0, r1 = max(sl[0].start - 3, 0), min(sl[0].stop + 3, h)
        c0, c1 = max(sl[1].start - 3, 0), min(sl[1].stop + 3, w)
        own = labels[r0:r1, c0:c1] == k
        if not usable[r0:r1, c0:c1][own].all():
            continue  # touches the margin: cut by the disc's edge
        area = int(own.sum())
        if area < 2:
            continue  # noise
        window = ndimage.binary_dilation(own, iterations=2)
        wgt = (bright - img[r0:r1, c0:c1]) * window
        total = float(wgt.sum())
        if total <= 0:
            continue
        rr, cc = np.indices(own.shape)
        out.append(((float((wgt * cc).sum()) / total) + c0,
                    (float((wgt * rr).sum()) / total) + r0))
        areas.append(area)
    return np.asarray(out, dtype=np.float64).reshape(-1, 2), np.asarray(areas, dtype=np.float64)


def identify(xy: FloatArray, areas: FloatArray) -> Dots:
    """Grid indices of detected dots (module docstring).

    Raises
    ------
    DotsError
        No fiducial (no dot clearly larger than the rest), or it has no neighbours.
    """
    n = len(xy)
    if n < 5:
        raise DotsError(f"only {n} dots found in the disc")
    typical = float(np.median(areas))
    fid = int(np.argmax(areas))
    if not areas[fid] > 2.0 * typical:
        raise DotsError(f"no fiducial: the largest dot ({areas[fid]:.0f} px) is not clearly "
                        f"larger than a typical one ({typical:.0f} px)")
    tree = cKDTree(xy)
    dist, idx = tree.query(xy[fid], k=5)
    nb = [int(i) for i in idx[1:] if np.isfinite(dist[1])]
    vecs = xy[nb] - xy[fid]
    u = vecs[int(np.argmax(vecs[:, 0]))]  # towards +col: i + 1
    v = vecs[int(np.argmax(vecs[:, 1]))]  # towards +row: j + 1
    if np.linalg.norm(u - v) < 1e-6 or abs(u[0] * v[1] - u[1] * v[0]) < 0.5 * np.dot(u, u):
        raise DotsError("the fiducial's neighbours do not form a grid")
    index: dict[int, tuple[int, int]] = {fid: (0, 0)}
    bad: set[int] = set()
    queue = deque([(fid, u, v)])
    while queue:
        k, uk, vk = queue.popleft()
        i, j = index[k]
        for step, (di, dj) in ((uk, (1, 0)), (-uk, (-1, 0)), (vk, (0, 1)), (-vk, (0, -1))):
            tol = 0.3 * float(np.linalg.norm(step))
            d, m = tree.query(xy[k] + step, k=1, distance_upper_bound=tol)
            if not np.isfinite(d):
                continue
            m = int(m)
            want = (i + di, j + dj)
            if m in index:
                if index[m] != want:
                    bad.update((m, k))
                continue
            index[m] = want
            reach = xy[m] - xy[k]
            nu = reach * di if di else uk
            nv = reach * dj if dj else vk
            queue.append((m, nu, nv))
    keep = [k for k in index if k not in bad]
    keep.sort(key=lambda k: index[k])
    return Dots(np.asarray([index[k] for k in keep], dtype=np.int64).reshape(-1, 2),
                xy[keep].reshape(-1, 2), n)
