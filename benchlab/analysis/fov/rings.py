"""The ring tube's rings in one radial frame: image radius and index of each.

The rings are circles about the optical axis, so each frame is reduced to its azimuthal
profile: the mean of the pixels in 0.25 px bins of radius about the annulus's centre (pixels
off the frame simply do not count). Each position's profile is divided by the brightest of
the positions' profiles at that radius (the annulus without its rings: the rings move, the
lighting does not), so ``darkening = 1 - profile / baseline`` is 0 on the clear tube and near
the ring's depth on a ring. A ring is a peak of the darkening; its image radius is the
darkening-weighted mean radius of the bins around the peak down to a tenth of its height.
Rings within ``margin_px`` of the annulus's edges are left out (an edge cuts them).

Identification: the fiducial ring (index 0) is wider, so its darkening's area is about
``fiducial_scale`` times its neighbours'; the others are counted from it, outwards in image
radius towards lower axial position (``direction`` -1, the radial view images the far end of
the field innermost) or the other way (+1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares
from scipy.signal import find_peaks
from scipy.special import ndtr

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.fov.annulus import Annulus

BIN_PX = 0.25
#: The ring-centre estimator's modelling error (px): the image of a ring is a box in wall
#: position blurred in wall units through the curved mapping, so its edges are skewed in image
#: radius, while the fit's model is a box in image radius with a blur linear across it. On
#: noise-free renders of the default tube through the design's ray-trace table every ring's
#: centre is within 0.00036 px (1.9 nm) of its edges' midpoint, the error smooth along the
#: field (so the mapping's fit does not see it in its residuals), and the fitted mapping
#: within 0.00039 px of the truth; this bound, 0.0004 px, enters the mapping's interval.
RING_CENTRE_SYSTEMATIC_PX = 0.0004
#: A ring whose darkening area is this much above its neighbours' median is the fiducial.
FIDUCIAL_RATIO = 1.8


@dataclass(frozen=True)
class Profile:
    """Azimuthal profile: the bins' mean radius (px), mean level and pixel count."""

    radius_px: FloatArray
    level: FloatArray
    count: FloatArray


@dataclass(frozen=True)
class Rings:
    """The rings found in one frame, in ascending image radius: radius (px), darkening area
    (px), and the fiducial's position in that order (None: not found)."""

    radius_px: FloatArray
    area_px: FloatArray
    fiducial: int | None

    def indices(self, direction: int) -> FloatArray:
        """Ring indices: counted from the fiducial, ``direction`` the sign of d(index) per
        step outwards in image radius."""
        if self.fiducial is None:
            raise ValueError("the fiducial ring was not found")
        return direction * (np.arange(len(self.radius_px)) - self.fiducial).astype(np.float64)


def profile(frame: npt.ArrayLike, annulus: Annulus, margin_px: float) -> Profile:
    """The azimuthal profile of a frame inside the annulus less ``margin_px`` each side."""
    img = np.asarray(frame, dtype=np.float64)
    rows = np.arange(img.shape[0], dtype=np.float64)[:, None] - annulus.centre_row
    cols = np.arange(img.shape[1], dtype=np.float64)[None, :] - annulus.centre_col
    r = np.hypot(rows, cols).ravel()
    lo, hi = annulus.inner_px + margin_px, annulus.outer_px - margin_px
    sel = (r >= lo) & (r < hi)
    b = ((r[sel] - lo) / BIN_PX).astype(np.intp)
    n = int(np.ceil((hi - lo) / BIN_PX))
    count = np.bincount(b, minlength=n)[:n]
    ok = count > 0
    rsum = np.bincount(b, weights=r[sel], minlength=n)[:n]
    vsum = np.bincount(b, weights=img.ravel()[sel], minlength=n)[:n]
    return Profile(rsum[ok] / count[ok], vsum[ok] / count[ok], count[ok].astype(np.float64))


def find_rings(prof: Profile, baseline: FloatArray, min_depth: float = 0.15) -> Rings:
    """The rings of one profile against the ring-free ``baseline`` (module docstring)."""
    dark = 1.0 - prof.level / np.maximum(baseline, 1e-9)
    peaks, _ = find_peaks(dark, height=min_depth, distance=int(2.0 / BIN_PX))
    radius, area = [], []
    for p in peaks:
        floor = 0.1 * dark[p]
        lo = p
        while lo > 0 and dark[lo - 1] > floor:
            lo -= 1
        hi = p
        while hi < len(dark) - 1 and dark[hi + 1] > floor:
            hi += 1
        if lo == 0 or hi == len(dark) - 1:
            continue  # cut by the profile's end: the centroid would be biased
        w = dark[lo:hi + 1]
        centroid = float(w @ prof.radius_px[lo:hi + 1] / w.sum())
        area.append(float(w.sum() * BIN_PX))
        radius.append(_fitted_centre(prof, dark, lo, hi, centroid, area[-1] / dark[p]))
    r = np.array(radius)
    a = np.array(area)
    fiducial = None
    if len(a) >= 3:
        ratio = np.array([a[i] / np.median(a[max(i - 2, 0):i].tolist() + a[i + 1:i + 3].tolist())
                          for i in range(len(a))])
        best = int(np.argmax(ratio))
        if ratio[best] >= FIDUCIAL_RATIO:
            fiducial = best
    return Rings(r, a, fiducial)


def _fitted_centre(prof: Profile, dark: FloatArray, lo: int, hi: int, centroid: float,
                   width_px: float) -> float:
    """The ring's centre from a fit of a blurred box (the ring's image; the blur may change
    linearly across it) to its bins, each weighted by its pixel count. A plain
    darkening-weighted centroid is biased by ~0.01 px: the number of pixel centres per bin
    of radius fluctuates around a circle, and a centroid
    that weights every bin alike follows the fluctuation; a fit weighted by the count does
    not."""
    pad = int(round(4.0 / BIN_PX))
    a, b = max(lo - pad, 0), min(hi + pad, len(dark) - 1)
    r = prof.radius_px[a:b + 1]
    y = dark[a:b + 1]
    wt = np.sqrt(prof.count[a:b + 1])

    def res(p: FloatArray) -> FloatArray:
        depth, c, half, s, base, slope = p
        # the blur may change across the ring (it does with image height)
        sig = np.abs(s + slope * (r - c)) + 1e-3
        model = base + depth * (ndtr((r - c + half) / sig) - ndtr((r - c - half) / sig))
        return np.asarray((model - y) * wt)

    start = np.array([float(dark[lo:hi + 1].max()), centroid, max(width_px / 2.0, 0.5), 1.0,
                      0.0, 0.0])
    sol = least_squares(res, start, method="lm")
    c = float(sol.x[1])
    return c if abs(c - centroid) < 2.0 else centroid


def spacing_gap(rings: Rings) -> float | None:
    """The largest ratio of a spacing between neighbouring rings to its neighbours' (a missed
    ring doubles one); None with fewer than 3 rings."""
    d = np.diff(rings.radius_px)
    if len(d) < 2:
        return None
    ratios = [d[i] / np.median(np.r_[d[max(i - 1, 0):i], d[i + 1:i + 2]]) for i in range(len(d))]
    return float(max(ratios))
