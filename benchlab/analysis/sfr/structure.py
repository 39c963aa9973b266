"""Bars, lines and corners in a slanted-edge ROI: found, so that its refusal can name them.

The SFR needs one straight edge. An ROI over a bar (dark-bright-dark or bright-dark-bright:
one bar of a USAF element, a thin line) has no net step, and one over a square's corner reads
as an edge near the pixel axis (the two sides' gradients average out); the generic refusals
("ESF step lost in the noise", "tilt the edge") then send the user the wrong way.
:func:`find_two_edges` reads the gradient directions instead:

1. Sobel gradients of the ROI. The *strong* pixels have a gradient of at least
   :data:`STRONG_OF_PEAK` of the peak (the :data:`PEAK_RANK`-th largest, so that a few hot
   pixels do not set it) and :data:`STRONG_SIGMAS` times its noise.
2. Their directions (weighted by the gradient) are grouped: the strongest direction, within
   +-:data:`SECTOR_DEG`, is one group, the strongest among the rest the other. Fewer than
   :data:`MIN_EDGE_PX` strong pixels outside the first: one edge, nothing to name.
3. Each group is split, across its direction, into parallel straight edges: runs of strong
   pixels at least :data:`MIN_EDGE_PX` long, with at least :data:`MIN_PIXELS_PER_PX` strong
   pixels per px of length and an RMS of at most :data:`MAX_LINE_RMS_PX` about a line.
4. Normals at least :data:`BAR_MIN_DEG` apart: one edge in each group is a bar or a line, two
   or more in each (as many, or one more), alternating in sign across the ROI, are bars - with
   at most :data:`MAX_OTHER_FRACTION_BARS` of the strong gradient outside those edges (their
   ends). Normals :data:`CORNER_MIN_DEG` to :data:`BAR_MIN_DEG` apart, one edge in each group,
   at most :data:`MAX_OTHER_FRACTION` elsewhere: a corner. Anything else (a third edge, an
   edge crossed by a bar, an edge with a bar beside it, hot pixels) is not named: the caller's
   own reasons stand. An edge with one opposite-signed edge on each side is not bars either:
   a sharpened edge's overshoot looks like that.

A second step of the same sign (its gradient in the first's direction group) is
:func:`find_second_edge`: the strongest direction's strong pixels split across it into two
parallel edges, the shorter at least half the longer, at least 4 px apart, with the gradient
falling between them; it names none of 3,000 clean synthetic edges (0-45 deg, 20-300 rows, 8 and
12 bit, SNR 10 to noise-free, a third sharpened up to 3x), and costs about what
:func:`find_two_edges` does.

No clean edge is named (3000 clean synthetic edges, 0-45 deg, 20-300 rows, 8 and 12 bit, SNR
10 to noise-free; 7500 more sharpened up to 3x, haloed, vignetted, bent, with up to 100 hot
or dead pixels). :func:`~benchlab.analysis.sfr.measure.measure_sfr` looks only where it refuses an
ROI, or where the ESF shows a second edge's marks (pixels clipped off it, a truncated ESF, an
ESF spanning more than :data:`ESF_SPAN_OF_STEP` times its step): a clean edge pays ~3 us for
that test. A look at a 100 x 100 ROI costs ~0.09 ms where it holds one edge (on clean edges
only at SNR 10, where ~1 in 4 ESFs reads as truncated), ~0.4 ms where it names something.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray

BoolArray = npt.NDArray[np.bool_]

#: A strong pixel's gradient is at least this fraction of the peak ...
STRONG_OF_PEAK = 0.3
#: ... the peak read as the gradient of this rank from the largest (an edge across a 10-row
#: ROI has >= 10 pixels near its peak; one hot pixel makes 8 large Sobel gradients) ...
PEAK_RANK = 10
#: ... and at least this many noise sigmas of the gradient (pure noise: exp(-5^2 / 2) = 4e-6).
STRONG_SIGMAS = 5.0
#: The Sobel gradient's noise sigma per pixel noise sigma (its kernel's norm, sqrt 12).
SOBEL_NOISE_GAIN = math.sqrt(12.0)
#: Half-width of a direction group, deg.
SECTOR_DEG = 30.0
#: Two strong pixels of one group further apart than this (px) across the group's direction
#: belong to two parallel edges.
EDGE_GAP_PX = 1.0
#: An edge is at least this long (px) ...
MIN_EDGE_PX = 8.0
#: ... has at least this many strong pixels per px of its length ...
MIN_PIXELS_PER_PX = 0.8
#: ... and its strong pixels lie within this RMS (px) of a straight line.
MAX_LINE_RMS_PX = 3.0
#: At most this fraction of the strong gradient (by weight) outside the edges found: for a
#: corner (an edge crossed by a bar would pass for one above ~20 %: the bar's second side) ...
MAX_OTHER_FRACTION = 0.15
#: ... and for bars, whose ends are in the ROI where the bars are short (a USAF element's
#: are 5 widths long: its ends hold ~17 % of the bars' outline).
MAX_OTHER_FRACTION_BARS = 0.25
#: Normals at least this far apart (deg) are edges of opposite sign (a bar, a line) ...
BAR_MIN_DEG = 150.0
#: ... and at least this far apart (up to BAR_MIN_DEG) two sides of a corner.
CORNER_MIN_DEG = 45.0
#: A measured ROI is checked where its ESF spans more than this many times its step (the
#: far side of a bar), as well as where pixels were clipped off the ESF or it is truncated.
ESF_SPAN_OF_STEP = 1.5


@dataclass(frozen=True)
class TwoEdges:
    """Edges of more than one direction found in an ROI: a bar or a line, bars, a corner.

    Attributes
    ----------
    kind : str
        ``"bar"`` (two parallel edges of opposite sign: a bar or a line), ``"bars"`` (more
        parallel edges, alternating in sign), ``"corner"``, ``"second edge"`` (two parallel
        edges of the same sign: a step beside the edge; :func:`find_second_edge`) or
        ``"other edge"`` (any edge in another direction: :func:`find_other_edge`).
    angle_deg : float
        Angle between the two groups' normals (~180 for bars, ~90 at a square's corner).
    lengths_px : tuple of float
        Length of each edge in the ROI, px, longest first.
    """

    kind: str
    angle_deg: float
    lengths_px: tuple[float, ...]

    def reason(self) -> str:
        """The refusal, in words the user can act on."""
        lengths = " and ".join(f"{v:.0f}" for v in self.lengths_px[:2])
        if self.kind == "bar":
            return (f"the ROI holds a bar or a line (two parallel edges of opposite sign, "
                    f"{lengths} px long), not one edge: put the ROI over one edge only, "
                    "with a plain plateau on each side of it")
        if self.kind == "bars":
            return (f"the ROI holds bars ({len(self.lengths_px)} parallel edges alternating "
                    "in sign), not one edge: put the ROI over one edge only, with a plain "
                    "plateau on each side of it")
        if self.kind == "other edge":
            return (f"the ROI holds a second edge (at {self.angle_deg:.0f} deg to the edge; "
                    f"edges {lengths} px long), not one edge: put the ROI over one edge only, "
                    "clear of other shapes")
        if self.kind == "second edge":
            return (f"the ROI holds a second edge (two parallel edges of the same sign, "
                    f"{lengths} px long), not one edge: put the ROI over one edge only, "
                    "with a plain plateau on each side of it")
        return (f"the ROI holds a corner (two edges at {self.angle_deg:.0f} deg to each other, "
                f"{lengths} px long), not one edge: put the ROI along one side only, clear "
                "of the corner")


@dataclass(frozen=True)
class _Edge:
    row: float  # centroid of its strong pixels
    col: float
    length_px: float


def _sobel(img: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Sobel gradients (along the columns, along the rows) at the inner pixels."""
    dx = img[:, 2:] - img[:, :-2]
    dy = img[2:, :] - img[:-2, :]
    return dx[:-2] + 2.0 * dx[1:-1] + dx[2:], dy[:, :-2] + 2.0 * dy[:, 1:-1] + dy[:, 2:]


def _wrap(a: FloatArray) -> FloatArray:
    """Angles wrapped to [-pi, pi)."""
    return np.asarray((a + math.pi) % (2.0 * math.pi) - math.pi, dtype=np.float64)


def _direction(theta: FloatArray, w: FloatArray, free: BoolArray) -> tuple[float, BoolArray]:
    """The strongest gradient direction among the ``free`` pixels (the weighted mean over
    +-:data:`SECTOR_DEG` around the fullest 30-deg span of a 10-deg histogram) and its
    members."""
    nbin = 36
    idx = np.minimum(((theta + math.pi) * (nbin / (2.0 * math.pi))).astype(np.intp), nbin - 1)
    hist = np.bincount(idx[free], weights=w[free], minlength=nbin)
    centre = (int(np.argmax(hist + np.roll(hist, 1) + np.roll(hist, -1))) + 0.5) * (
        2.0 * math.pi / nbin) - math.pi
    half = math.radians(SECTOR_DEG)
    member = free & (np.abs(_wrap(theta - centre)) <= half)
    mean = float(np.angle(np.sum(w[member] * np.exp(1j * theta[member]))))
    return mean, free & (np.abs(_wrap(theta - mean)) <= half)


def _edges(theta: float, rows: FloatArray, cols: FloatArray, w: FloatArray
           ) -> tuple[list[_Edge], float]:
    """The parallel straight edges among one group's pixels, and the weight of its pixels
    that belong to none."""
    c, s = math.cos(theta), math.sin(theta)
    across = cols * c + rows * s
    along = rows * c - cols * s
    q = along - along.mean()
    qq = float(np.dot(q, q))
    if qq > 0:  # the common tilt left by the mean direction
        across = across - q * (float(np.dot(q, across)) / qq)
    order = np.argsort(across)
    breaks = np.flatnonzero(np.diff(across[order]) > EDGE_GAP_PX) + 1
    edges, stray = [], 0.0
    for run in np.split(order, breaks):
        p, a = across[run], along[run]
        length = float(np.ptp(a)) + 1.0
        if (length >= MIN_EDGE_PX and run.size >= MIN_PIXELS_PER_PX * length
                and float(np.std(p)) <= MAX_LINE_RMS_PX):
            edges.append(_Edge(float(np.mean(rows[run])), float(np.mean(cols[run])), length))
        else:
            stray += float(np.sum(w[run]))
    return edges, stray


def _alternate(first: list[_Edge], second: list[_Edge], theta: float) -> bool:
    """Whether the edges of the two groups alternate across the ROI (along ``theta``)."""
    c, s = math.cos(theta), math.sin(theta)
    marks = sorted([(e.col * c + e.row * s, k) for k, group in enumerate((first, second))
                    for e in group])
    return all(a[1] != b[1] for a, b in zip(marks, marks[1:], strict=False))


def _strong_pixels(pixels: npt.ArrayLike, noise_sigma: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray, npt.NDArray[np.intp]] | None:
    """The ROI's Sobel gradients ``(gx, gy, |g|^2 flattened)`` and the flat indices of its
    strong pixels (above :data:`STRONG_OF_PEAK` of the peak gradient and the noise floor), or
    None: too small an ROI, no gradient, or too few strong pixels for two edges."""
    img = np.asarray(pixels, dtype=np.float64)
    if img.ndim != 2 or min(img.shape) < MIN_EDGE_PX + 2:
        return None
    gx, gy = _sobel(img)
    mag2 = (gx * gx + gy * gy).ravel()
    rank = min(PEAK_RANK, mag2.size)
    peak2 = float(np.partition(mag2, mag2.size - rank)[mag2.size - rank])
    if not peak2 > 0.0:
        return None
    floor = STRONG_SIGMAS * SOBEL_NOISE_GAIN * max(noise_sigma, 0.0)
    sel = np.flatnonzero(mag2 >= max(STRONG_OF_PEAK**2 * peak2, floor * floor))
    if sel.size < 2 * MIN_EDGE_PX:
        return None
    return gx, gy, mag2, sel


def find_two_edges(pixels: npt.ArrayLike, noise_sigma: float) -> TwoEdges | None:
    """A bar or line, bars, or a corner in the ROI (and little else), else None.

    Parameters
    ----------
    pixels : array_like, shape (rows, cols)
        The ROI (either orientation).
    noise_sigma : float
        The pixel noise (gray levels); 0 for noise-free data.
    """
    strong = _strong_pixels(pixels, noise_sigma)
    if strong is None:
        return None
    gx, gy, mag2, sel = strong
    sgx, sgy = gx.ravel()[sel], gy.ravel()[sel]
    w = np.sqrt(mag2[sel])
    # One edge (however noisy): its gradients all lie within SECTOR_DEG of their vector sum.
    # Said cheaply, no angles needed: nothing to name.
    vx, vy = float(np.sum(sgx)), float(np.sum(sgy))
    norm = math.hypot(vx, vy)
    if norm > 0.0:
        aligned = sgx * vx + sgy * vy >= math.cos(math.radians(SECTOR_DEG)) * norm * w
        if sel.size - int(np.count_nonzero(aligned)) < MIN_EDGE_PX:
            return None
    theta = np.arctan2(sgy, sgx)
    r_i, c_i = np.divmod(sel, gx.shape[1])
    rows, cols = r_i.astype(np.float64), c_i.astype(np.float64)
    free = np.ones(sel.size, dtype=bool)
    directions = []
    for _ in range(2):
        if np.count_nonzero(free) < MIN_EDGE_PX:
            return None  # one direction only: one edge (or nothing to name)
        mean, member = _direction(theta, w, free)
        directions.append((mean, member))
        free &= ~member
    stray = float(np.sum(w[free]))
    groups: list[tuple[float, list[_Edge]]] = []
    for mean, member in directions:
        edges, off = _edges(mean, rows[member], cols[member], w[member])
        if not edges:
            return None
        groups.append((mean, edges))
        stray += off
    other = stray / float(np.sum(w))
    (t1, e1), (t2, e2) = groups
    apart = abs(math.degrees(math.remainder(t1 - t2, 2.0 * math.pi)))
    lengths = tuple(sorted((e.length_px for e in e1 + e2), reverse=True))
    if apart >= BAR_MIN_DEG and other <= MAX_OTHER_FRACTION_BARS:
        if len(e1) == len(e2) == 1:
            return TwoEdges("bar", apart, lengths)
        if min(len(e1), len(e2)) >= 2 and abs(len(e1) - len(e2)) <= 1 and _alternate(
                e1, e2, t1):
            return TwoEdges("bars", apart, lengths)
        return None
    if CORNER_MIN_DEG <= apart < BAR_MIN_DEG and len(e1) == len(e2) == 1 and (
            other <= MAX_OTHER_FRACTION):
        return TwoEdges("corner", apart, lengths)
    return None


#: A second edge of the same sign is at least this fraction of the longest edge's length.
SECOND_EDGE_LENGTH_FRACTION = 0.5
#: ... and its centre at least this far (px) across from the first's (a noisy, blurred edge's
#: strong pixels can split into two runs a pixel or two apart).
SECOND_EDGE_MIN_APART_PX = 4.0
#: ... with the mean gradient midway between them below this fraction of theirs.
SECOND_EDGE_DIP = 0.3


def find_second_edge(pixels: npt.ArrayLike, noise_sigma: float) -> TwoEdges | None:
    """Two parallel edges of the same sign (a second step beside the edge), else None.

    :func:`find_two_edges` sees only edges of different directions; a second step of the same
    sign puts its strong gradient in the same direction group. Here the strong pixels of the
    strongest direction are split across it into parallel straight edges (as
    :func:`find_two_edges` does); two or more, the shorter at least
    :data:`SECOND_EDGE_LENGTH_FRACTION` of the longest, are a second edge. Compression ringing
    and sensor structure beside one edge stay below the strong pixels' threshold (30 % of the
    peak gradient), so they are not named. Parameters as :func:`find_two_edges`.
    """
    strong = _strong_pixels(pixels, noise_sigma)
    if strong is None:
        return None
    gx, gy, mag2, sel = strong
    theta = np.arctan2(gy.ravel()[sel], gx.ravel()[sel])
    w = np.sqrt(mag2[sel])
    r_i, c_i = np.divmod(sel, gx.shape[1])
    mean, member = _direction(theta, w, np.ones(sel.size, dtype=bool))
    edges, _ = _edges(mean, r_i[member].astype(np.float64), c_i[member].astype(np.float64),
                      w[member])
    if len(edges) < 2:
        return None
    edges.sort(key=lambda e: e.length_px, reverse=True)
    first, second = edges[0], edges[1]
    c, s = math.cos(mean), math.sin(mean)
    a1, a2 = (e.col * c + e.row * s for e in (first, second))
    if second.length_px < SECOND_EDGE_LENGTH_FRACTION * first.length_px or (
            abs(a1 - a2) < SECOND_EDGE_MIN_APART_PX):
        return None
    # Two edges, not one wide edge split by noise: the gradient across them falls between.
    rr, cc = np.mgrid[0:gx.shape[0], 0:gx.shape[1]]
    across = cc * c + rr * s
    along_grad = gx * c + gy * s

    def strip(a: float) -> float:
        near = np.abs(across - a) <= 0.75
        return float(np.mean(along_grad[near])) if near.any() else 0.0

    if strip(0.5 * (a1 + a2)) < SECOND_EDGE_DIP * min(strip(a1), strip(a2)):
        return TwoEdges("second edge", 0.0, tuple(e.length_px for e in edges))
    return None


def find_other_edge(pixels: npt.ArrayLike, noise_sigma: float) -> TwoEdges | None:
    """Any straight edge beside the strongest one, in another direction, else None.

    The strong pixels (as :func:`find_two_edges` selects them) outside the strongest
    direction's group, split into straight edges; one at least :data:`MIN_EDGE_PX` long is a
    second edge (a corner of another shape reaching into the ROI, a bar crossing it). Broader
    than :func:`find_two_edges`, which names only bars and corners and leaves the rest to the
    caller: :func:`benchlab.analysis.sfr.measure.measure_sfr` asks it only where many pixels
    lie off the edge profile, to tell a second edge from compression or sensor structure
    (whose gradients stay below the strong pixels' threshold, 30 % of the peak).
    """
    strong = _strong_pixels(pixels, noise_sigma)
    if strong is None:
        return None
    gx, gy, mag2, sel = strong
    theta = np.arctan2(gy.ravel()[sel], gx.ravel()[sel])
    w = np.sqrt(mag2[sel])
    r_i, c_i = np.divmod(sel, gx.shape[1])
    rows, cols = r_i.astype(np.float64), c_i.astype(np.float64)
    main, member = _direction(theta, w, np.ones(sel.size, dtype=bool))
    free = ~member
    if np.count_nonzero(free) < MIN_EDGE_PX:
        return None
    other, second = _direction(theta, w, free)
    edges, _ = _edges(other, rows[second], cols[second], w[second])
    if not edges:
        return None
    first, _ = _edges(main, rows[member], cols[member], w[member])
    apart = abs(math.degrees(math.remainder(main - other, 2.0 * math.pi)))
    lengths = tuple(sorted((e.length_px for e in first + edges), reverse=True))
    return TwoEdges("other edge", apart, lengths)
