"""Edge points of a lit circle (the forward disc, the radial annulus) read on each frame where
nothing of the target is near it.

The dots and rings move between the procedure's positions and the field stops do not. A dot or
ring next to the edge pulls the half-level crossing inwards, and reading the edge on the
pixelwise maximum of the frames instead (which hides them) biases it the other way: the
maximum of noisy frames is brightest where the light is, which moves the crossing by ~0.01 px,
far beyond its statistical error over hundreds of rays. So once the target's geometry is
fitted, every dot or ring is predicted in every frame, and the edge is read on each frame's
rays that pass no predicted feature (``blockers``), each with its own lit level (the mean of
the lit side 6-12 px from the edge) and the frame's dark level (the median of the dark side's
pixels 6-12 px from the edge on every ray: the dark side is clipped at 0). Those points are
unbiased, and independent from frame to frame. The level windows are 6-12 px from the edge:
at 4 px a soft edge (sigma 1.5 px) has not reached its levels, which moves the crossing by
~0.004 px.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from benchlab.analysis.arrays import FloatArray

STEP_PX = 0.25
#: Half the length of the profile read across the edge, px.
REACH_PX = 14.0


def clean_edge_points(frame: FloatArray, centre_cr: tuple[float, float], radius_px: float,
                      rays: int, lit_inside: bool, blockers: FloatArray, block_px: float
                      ) -> FloatArray:
    """``(n, 2)`` edge points ``(col, row)`` of one frame near ``radius_px`` about
    ``centre_cr`` (col, row) (module docstring). ``lit_inside``: light inside the edge (a disc,
    an annulus's outer edge). ``blockers`` ``(m, 2)`` (col, row) are the centres of the
    target's features in this frame; a ray passing within ``block_px`` of one across the
    profile is skipped, as is a ray that leaves the frame."""
    c0, r0 = centre_cr
    az = np.linspace(0.0, 2.0 * np.pi, rays, endpoint=False)
    u = np.stack([np.cos(az), np.sin(az)], axis=1)
    offs = np.arange(-REACH_PX, REACH_PX + 1e-9, STEP_PX)
    sign = 1.0 if lit_inside else -1.0
    radii = radius_px + sign * offs  # from the lit side across into the dark side
    cols = c0 + u[:, :1] * radii[None, :]
    rows = r0 + u[:, 1:] * radii[None, :]
    h, w = frame.shape
    ok = ((rows >= 0) & (rows <= h - 1) & (cols >= 0) & (cols <= w - 1)).all(axis=1)
    if len(blockers):
        rel = np.asarray(blockers, dtype=np.float64) - (c0, r0)
        along = rel @ u.T  # (m, rays)
        perp = np.abs(rel[:, :1] * u[:, 1] - rel[:, 1:] * u[:, 0])
        near = (perp < block_px) & (np.abs(along - radius_px) < 12.0 + block_px)
        ok &= ~near.any(axis=0)
    idx = np.nonzero(ok)[0]
    prof = ndimage.map_coordinates(np.asarray(frame, dtype=np.float64),
                                   [rows[idx].ravel(), cols[idx].ravel()], order=1,
                                   mode="nearest").reshape(len(idx), len(offs))
    lit = prof[:, (offs >= -12.0) & (offs <= -6.0)].mean(axis=1)
    # the dark side is often clipped at 0, where a mean sits above the level, and so does the
    # median of interpolated samples (each mixes clipped pixels) or of a ray's few pixels: on
    # the ring tube's frames that raised the half level by ~0.3 code and moved the annulus's
    # edges by 0.0004 px towards the light. So the dark level is the median of the pixels
    # themselves (nearest, not interpolated) on every ray of the frame at once.
    band = (offs >= 6.0) & (offs <= 12.0)
    raw = ndimage.map_coordinates(np.asarray(frame, dtype=np.float64),
                                  [rows[idx][:, band].ravel(), cols[idx][:, band].ravel()],
                                  order=0, mode="nearest")
    dark = np.full(len(idx), float(np.median(raw)) if raw.size else 0.0)
    pts = []
    for n, k in enumerate(idx):
        p, half = prof[n], (lit[n] + dark[n]) / 2.0
        if lit[n] - dark[n] <= 0:
            continue
        above = np.nonzero(p >= half)[0]
        if len(above) == 0 or above[-1] >= len(offs) - 1:
            continue
        j = int(above[-1])
        t = offs[j] + STEP_PX * (p[j] - half) / (p[j] - p[j + 1])
        rr = radius_px + sign * t
        pts.append((c0 + u[k, 0] * rr, r0 + u[k, 1] * rr))
    return np.asarray(pts, dtype=np.float64).reshape(-1, 2)
