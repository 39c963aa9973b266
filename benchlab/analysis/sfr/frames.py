"""Several frames of one slanted edge, averaged for the SFR after checking they show the same edge.

Averaging N frames divides the noise sigma by sqrt(N) and costs nothing in resolution - if the
edge did not move. A shift of the edge between frames blurs the mean (random shifts of rms
``s`` px multiply the MTF by ``exp(-2 pi^2 s^2 f^2)``; 0.1 px costs 5 % of the MTF at Nyquist),
so the frames are compared with their mean first:

each frame minus the mean is regressed, pixel by pixel, on the mean's gradient along the edge
normal ``g`` and on ``g`` times the position along the edge (a shift and a rotation of the
edge), and on a constant and the mean itself (an offset and a gain: an LED or exposure change,
harmless to the normalised MTF). The fitted gain is each frame's edge step against the mean's;
a frame whose step is outside :data:`GAIN_RANGE` times the other frames' (their median) has not
got the edge - a dark frame (the lens cap on), a blank or a noise frame, which the offset and a
gain near 0 would otherwise fit perfectly - or is another exposure altogether, and is refused
first. The fitted shift at the edge's two ends, scaled to the mean of
the *other* frames, is each frame's movement; the frame that moved most is named; it is refused
above :data:`MAX_SHIFT_PX` when that is also more than :data:`SHIFT_SIGMAS` of its own noise (so
noisy frames of a still edge are not refused). This is linear and works at any SNR, where
fitting the edge in each frame alone would fail. A frame whose residual after all four is more
than :data:`RESIDUAL_RATIO` times the variance its own noise (row differences along the edge)
explains shows something else and is refused too. Two frames that differ cannot say which of
them is off; both are named.

The edge normal is the mean's dominant gradient direction (its structure tensor) unless given,
so the check needs no SFR of the mean: it runs first, and frames of two different edges are
reported as such, not as "other structure" in their mean.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.sfr.measure import difference_noise_sigma

#: A frame whose edge moved more than this (px, at either end of the edge) is refused ...
MAX_SHIFT_PX = 0.1
#: ... provided that movement is also this many of its standard errors.
SHIFT_SIGMAS = 5.0


#: A frame whose residual (after the shift, turn, offset and gain) exceeds this many times the
#: variance its own noise explains is not the same scene.
RESIDUAL_RATIO = 4.0

#: A frame's edge step (its fitted gain against the mean) must be within this range of the
#: other frames' median step: an exposure change is allowed, a frame without the edge is not.
GAIN_RANGE = (0.5, 2.0)


def _row_noise_var(frame: FloatArray, cos_n: float, sin_n: float) -> float:
    """Pixel noise variance of one frame from differences between neighbours along the edge
    (rows for a near-vertical edge, columns for a near-horizontal one): robust (MAD)."""
    axis = 0 if abs(cos_n) >= abs(sin_n) else 1
    return difference_noise_sigma(np.diff(frame, axis=axis)) ** 2


class FramesDiffer(ValueError):
    """The frames do not show the same edge; ``frame`` is the offending index, ``frames`` every
    index the message blames (both of two frames that differ: which one is off cannot be
    told)."""

    def __init__(self, frame: int, message: str, frames: tuple[int, ...] | None = None) -> None:
        self.frame = frame
        self.frames = frames if frames is not None else (frame,)
        super().__init__(message)


def edge_normal_of(image: npt.ArrayLike) -> float:
    """Direction (rad, from the column axis towards the row axis) of the dominant gradient of
    ``image``: the principal axis of its structure tensor (the edge normal, up to its sign)."""
    g_row, g_col = np.gradient(np.asarray(image, dtype=np.float64))
    jcc, jrr, jcr = float(np.sum(g_col**2)), float(np.sum(g_row**2)), float(np.sum(g_col * g_row))
    return 0.5 * math.atan2(2.0 * jcr, jcc - jrr)


def _blame(k: int, n: int) -> tuple[str, tuple[int, ...]]:
    """``frame k of n`` - or, of two frames, both (neither can be told from the other)."""
    if n == 2:
        return "frames 1 and 2 of 2", (0, 1)
    return f"frame {k + 1} of {n}", (k,)


def _check_gains(gains: FloatArray) -> None:
    """Refuse a frame whose edge step is outside :data:`GAIN_RANGE` of the others' median
    (a missing edge first: with two frames the one that has the step is not the odd one)."""
    n = gains.size
    lo, hi = GAIN_RANGE
    low, high = [], []
    for k in range(n):
        ref = float(np.median(np.delete(gains, k)))
        rel = gains[k] / ref if ref > 0 else math.inf
        if ref > 0 and rel < lo:
            low.append((rel, k))
        elif rel > hi:
            high.append((rel, k))
    if low:
        rel, k = min(low)
        what = ("the edge is inverted" if rel < 0 else
                "the edge is not there (a dark or blank frame, the lens cap on?)")
        raise FramesDiffer(k, f"frame {k + 1} of {n}: its edge step is {rel:.2f}x the other "
                              f"frames' (allowed {lo:g}-{hi:g}x, an exposure change): {what}")
    if high:
        rel, k = max(high)
        how = f"{rel:.2f}x" if math.isfinite(rel) else "far above"
        raise FramesDiffer(k, f"frame {k + 1} of {n}: its edge step is {how} the other "
                              f"frames' (allowed {lo:g}-{hi:g}x, an exposure change): not the "
                              "same scene")


@dataclass(frozen=True)
class FramesCheck:
    """The mean of the frames and what the check measured.

    Attributes
    ----------
    mean : ndarray
        The frames' mean (float64).
    frames : int
    max_shift_px : float
        Largest movement of the edge (either end) of any frame from the other frames' mean, px.
    gain_spread : float
        Max minus min of the frames' fitted gains (0 = the same exposure).
    """

    mean: FloatArray
    frames: int
    max_shift_px: float
    gain_spread: float


def duplicate_frames(stack: npt.NDArray[np.generic]) -> tuple[int, int] | None:
    """The first two frames of ``stack`` (frames, rows, cols) that are identical pixel for
    pixel, or ``None``. Two exposures of a camera never are (the noise differs): identical
    pixels are one frame saved twice (two file names, a copied page), and averaging them would
    claim the noise of two frames. (Noise-free synthetic frames are identical by design:
    :func:`average_frames` takes them; ``benchlab sfr`` refuses such files.)"""
    seen: dict[bytes, int] = {}
    for k in range(stack.shape[0]):
        frame = np.ascontiguousarray(stack[k])
        key = hashlib.blake2b(frame.tobytes(), digest_size=16).digest()
        first = seen.get(key)
        if first is not None and np.array_equal(stack[first], frame):
            return first, k
        seen.setdefault(key, k)
    return None


def average_frames(stack: npt.ArrayLike, normal_theta_rad: float | None = None) -> FramesCheck:
    """Mean of ``stack`` (frames, rows, cols) after checking the edge did not move.

    Parameters
    ----------
    stack : array_like, shape (frames, rows, cols)
        Frames of the same ROI, linear gray levels.
    normal_theta_rad : float, optional
        Direction of the edge normal (from the column axis towards the row axis), e.g.
        :attr:`benchlab.analysis.sfr.measure.SfrResult.normal_theta_rad` of the mean; by default the
        mean's dominant gradient direction (:func:`edge_normal_of`).

    Returns
    -------
    FramesCheck

    Raises
    ------
    FramesDiffer
        A frame has no edge step (or one outside :data:`GAIN_RANGE` of the others'), differs
        from the others beyond its noise, or its edge moved (its index and why in the
        message).
    ValueError
        Not a 3-D stack of at least one frame.
    """
    s = np.asarray(stack, dtype=np.float64)
    if s.ndim != 3 or s.shape[0] < 1:
        raise ValueError(f"frames must be a (frames, rows, cols) stack, got shape {s.shape}")
    mean = s.mean(axis=0)
    n = s.shape[0]
    if n == 1:
        return FramesCheck(mean, 1, 0.0, 0.0)
    if normal_theta_rad is None:
        normal_theta_rad = edge_normal_of(mean)
    c, si = math.cos(normal_theta_rad), math.sin(normal_theta_rad)
    g_row, g_col = np.gradient(mean)
    g = c * g_col + si * g_row  # d(mean)/du along the normal
    rows, cols = mean.shape
    rr, cc = np.mgrid[0:rows, 0:cols].astype(np.float64)
    along = -si * (cc - (cols - 1) / 2.0) + c * (rr - (rows - 1) / 2.0)
    half = float(np.max(np.abs(along)))
    t = along / half if half > 0 else along  # -1..1 from one end of the edge to the other
    design = np.stack([g.ravel(), (g * t).ravel(), np.ones(mean.size),
                       (mean - mean.mean()).ravel()], axis=1)
    resid = (s - mean).reshape(n, -1).T  # (pixels, frames)
    coef, *_ = np.linalg.lstsq(design, resid, rcond=None)
    fitted = design @ coef
    dof = max(1, mean.size - design.shape[1])
    noise_var = np.sum((resid - fitted) ** 2, axis=0) / dof  # per frame
    cov_unit = np.linalg.pinv(design.T @ design)
    shift, tilt = coef[0], coef[1]  # edge moves by -(shift + tilt t) along the normal
    gains = 1.0 + coef[3]  # each frame's edge step over the mean's
    _check_gains(gains)
    # A frame that differs from the others by more than its own noise is another scene.
    floor_var = (1e-3 * float(np.ptp(mean))) ** 2
    if np.all(s == np.round(s)):
        floor_var += 1.0 / 12.0  # integer codes: the rounding noise
    own = np.array([max(_row_noise_var(s[k], c, si), floor_var) for k in range(n)])
    ratio = noise_var / (own * (1.0 - 1.0 / n))
    k = int(np.argmax(ratio))  # the odd one out differs most from the mean
    if ratio[k] > RESIDUAL_RATIO:
        who, blamed = _blame(k, n)
        how = ("differs from the others", "its") if n > 2 else ("differ from each other",
                                                                 "their")
        raise FramesDiffer(k, f"{who} {how[0]} by {math.sqrt(noise_var[k]):.3g} RMS, "
                              f"{math.sqrt(ratio[k]):.1f}x {how[1]} own noise, after allowing "
                              "for a shift, a turn and an exposure change: not the same scene",
                           blamed)
    # From the mean of the *other* frames: n / (n - 1) times the move from the mean of all.
    loo = n / (n - 1)
    worst, flagged, flagged_k, flagged_se = 0.0, 0.0, -1, 0.0
    for k in range(n):
        for end in (-1.0, 1.0):
            move = loo * abs(float(shift[k] + end * tilt[k]))
            var = noise_var[k] * (cov_unit[0, 0] + 2 * end * cov_unit[0, 1] + cov_unit[1, 1])
            se = loo * math.sqrt(max(float(var), 0.0))
            if move > MAX_SHIFT_PX and move > SHIFT_SIGMAS * se and move > flagged:
                flagged, flagged_k, flagged_se = move, k, se
            worst = max(worst, move)
    if flagged_k >= 0:
        who, blamed = _blame(flagged_k, n)
        where = "from the other frames" if n > 2 else "between them"
        raise FramesDiffer(flagged_k, f"{who}: the edge moved {flagged:.2f} px {where} (> "
                                      f"{MAX_SHIFT_PX:g} px, "
                                      f"{flagged / max(flagged_se, 1e-12):.0f} standard "
                                      "errors): not the same scene, averaging would blur the "
                                      "edge", blamed)
    return FramesCheck(mean, n, worst, float(np.max(gains) - np.min(gains)))
