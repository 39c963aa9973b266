"""How good a synthesized view is against a flat truth: straightness, scale and bar period.

Used by ``benchlab benchmark viewsynth`` and the tests: a grid of straight printed lines must be
straight and evenly spaced in the unwrapped view, and a bar pattern of known object period must
repeat at that period times the output scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray

BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class LineFit:
    """One printed line found in a view.

    ``along`` are the row (or column) indices where it was found, ``across`` its sub-pixel
    position there; ``rms_px`` the RMS distance from its own fitted straight line, ``mean_px``
    its mean position, ``expected_px`` where the flat truth puts it.
    """

    expected_px: float
    along: FloatArray
    across: FloatArray
    rms_px: float
    mean_px: float


def find_line(
    view: npt.NDArray[np.generic],
    valid: BoolArray,
    expected_px: float,
    *,
    axis: int,
    half_window_px: float,
    skip: BoolArray | None = None,
    min_samples: int = 20,
) -> LineFit | None:
    """Sub-pixel centre of a dark line near ``expected_px`` in every row (``axis=1``: a line of
    constant column) or column (``axis=0``), then its straightness.

    A sample is the ink-weighted centroid of the window ``expected +- half_window_px``; windows
    not wholly valid, listed in ``skip`` (e.g. where a crossing line darkens the window), or
    with less than 30 % contrast are left out. None when fewer than ``min_samples`` remain.
    """
    img = np.asarray(view, dtype=np.float64)
    if axis == 0:
        img, valid = img.T, valid.T
    lo = int(np.floor(expected_px - half_window_px))
    hi = int(np.ceil(expected_px + half_window_px)) + 1
    if lo < 0 or hi > img.shape[1]:
        return None
    win = img[:, lo:hi]
    ok = valid[:, lo:hi].all(axis=1)
    if skip is not None:
        ok &= ~skip
    top = win.max(axis=1)
    ink = np.clip(top[:, None] - win, 0.0, None)
    contrast = ink.max(axis=1) / np.maximum(top, 1e-9)
    ok &= contrast > 0.3
    # Keep the core of the line profile: ink above half its peak.
    core = np.clip(ink - 0.5 * ink.max(axis=1, keepdims=True), 0.0, None)
    weight = core.sum(axis=1)
    ok &= weight > 0
    if int(ok.sum()) < min_samples:
        return None
    pos = lo + (core[ok] * np.arange(hi - lo)[None, :]).sum(axis=1) / weight[ok]
    along = np.flatnonzero(ok).astype(np.float64)
    coeffs = np.polyfit(along, pos, 1)
    rms = float(np.sqrt(np.mean((np.polyval(coeffs, along) - pos) ** 2)))
    return LineFit(float(expected_px), along, pos, rms, float(pos.mean()))


def scale_error(lines: list[LineFit]) -> float:
    """Relative scale error (found spacing / true spacing - 1) from a straight-line fit of the
    lines' mean positions against their expected positions. NaN with fewer than two lines."""
    if len(lines) < 2:
        return float("nan")
    expected = np.array([ln.expected_px for ln in lines])
    found = np.array([ln.mean_px for ln in lines])
    slope = np.polyfit(expected, found, 1)[0]
    return float(slope - 1.0)


def dominant_period_px(profile: npt.ArrayLike) -> float:
    """Period (px) of the strongest non-DC component of a profile (Hann window, 16x zero
    padding, parabolic interpolation of the log spectrum peak).

    Raises
    ------
    ValueError
        For fewer than 8 samples or a flat profile.
    """
    sig = np.asarray(profile, dtype=np.float64)
    if sig.size < 8 or not np.ptp(sig) > 0:
        raise ValueError("profile needs >= 8 samples and some variation")
    sig = (sig - sig.mean()) * np.hanning(sig.size)
    n = 16 * sig.size
    spec = np.abs(np.fft.rfft(sig, n))
    k = int(np.argmax(spec[2:])) + 2
    a, b, c = np.log(spec[k - 1 : k + 2] + 1e-300)
    denom = a - 2 * b + c
    k_fine = k + (0.5 * (a - c) / denom if denom != 0 else 0.0)
    return float(n / k_fine)
