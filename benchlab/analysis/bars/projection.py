"""Projection of ROI pixels onto the across-feature coordinate, binned finely.

One projection, two uses: the bar estimators at any angle and the slanted-edge SFR both reduce a
2-D ROI to a 1-D profile along the direction in which the intensity varies. With that direction
at angle ``theta`` from the column axis (x, numpy axis 1) towards the row axis (y, numpy axis 0,
downwards), each pixel centre lands at

    u = x cos(theta) + y sin(theta)

(pixels, measured from the ROI centre). When the direction is oblique to the pixel grid the
pixel centres fall at many different sub-pixel offsets in ``u``, so a bin narrower than one
pixel still collects samples: the profile is sampled below the pixel pitch (ISO 12233's 4x
oversampled edge spread function is the same construction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True, slots=True)
class BinnedProfile:
    """Mean pixel value per bin of the across-feature coordinate ``u`` (pixels).

    Attributes
    ----------
    u_px : ndarray of float64, shape (n_bins,)
        Bin centres (pixels from the ROI centre along the normal).
    mean : ndarray of float64, shape (n_bins,)
        Mean pixel value in each bin; NaN where ``count`` is 0.
    count : ndarray of int64, shape (n_bins,)
        Number of pixels in each bin.
    bin_width_px : float
        Width of every bin (pixels).
    """

    u_px: npt.NDArray[np.float64]
    mean: npt.NDArray[np.float64]
    count: npt.NDArray[np.int64]
    bin_width_px: float

    @property
    def filled(self) -> npt.NDArray[np.bool_]:
        """Bins holding at least one pixel."""
        return self.count > 0


def across_coordinate(
    shape: tuple[int, int],
    theta_rad: float,
    origin_rc: tuple[float, float] | None = None,
) -> npt.NDArray[np.float64]:
    """Across-feature coordinate ``u`` of every pixel centre of an ROI.

    Parameters
    ----------
    shape : (int, int)
        ROI shape (rows, columns); both at least 1.
    theta_rad : float
        Angle (radians) of the direction in which the intensity varies, from the column axis
        towards the row axis. 0 = intensity varies along the columns (vertical bars).
    origin_rc : (float, float), optional
        (row, col) where ``u = 0``; default the ROI centre ``((rows-1)/2, (cols-1)/2)``.

    Returns
    -------
    ndarray of float64, shape ``shape``
        ``u = (col - c0) cos(theta) + (row - r0) sin(theta)`` in pixels.
    """
    rows, cols = int(shape[0]), int(shape[1])
    if rows < 1 or cols < 1:
        raise ValueError(f"ROI shape must be at least 1 x 1, got {rows} x {cols}")
    if not math.isfinite(theta_rad):
        raise ValueError(f"theta_rad must be finite, got {theta_rad}")
    if origin_rc is None:
        yc, xc = _centred_coordinates(rows, cols)
    else:
        yc = np.arange(rows, dtype=np.float64) - origin_rc[0]
        xc = np.arange(cols, dtype=np.float64) - origin_rc[1]
    y = yc * math.sin(theta_rad)
    x = xc * math.cos(theta_rad)
    return y[:, None] + x[None, :]


@lru_cache(maxsize=64)
def _centred_coordinates(
    rows: int, cols: int
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Row and column offsets from the ROI centre (cached per shape, read-only)."""
    y = np.arange(rows, dtype=np.float64) - (rows - 1) / 2.0
    x = np.arange(cols, dtype=np.float64) - (cols - 1) / 2.0
    y.setflags(write=False)
    x.setflags(write=False)
    return y, x


def bin_profile(
    u_px: npt.ArrayLike,
    values: npt.ArrayLike,
    bin_width_px: float = 0.25,
) -> BinnedProfile:
    """Average ``values`` in bins of width ``bin_width_px`` along ``u_px``.

    Bins are aligned so that ``min(u)`` is a bin centre (axis-aligned ROIs binned at 1 px then
    give one bin per pixel column, centred on it) and span ``[min(u), max(u)]``. Cost is
    linear in the pixel count (one ``np.bincount`` pass for sums and one for counts; no BLAS).

    Parameters
    ----------
    u_px : array_like of float
        Across-feature coordinate of each sample (pixels), any shape.
    values : array_like of float
        Pixel values, same shape as ``u_px``.
    bin_width_px : float, default 0.25
        Bin width in pixels (> 0). 0.25 is ISO 12233's 4x oversampling.

    Returns
    -------
    BinnedProfile
        Bin centres, means (NaN in empty bins) and counts.

    Raises
    ------
    ValueError
        On mismatched shapes, no samples, non-finite ``u`` or a non-positive bin width.
    """
    return bin_profiles(u_px, [values], bin_width_px)[0]


def bin_profiles(
    u_px: npt.ArrayLike,
    values: list[npt.ArrayLike],
    bin_width_px: float = 0.25,
) -> list[BinnedProfile]:
    """:func:`bin_profile` of several quantities on the same coordinate, binned once.

    The bins are computed once (same alignment and counts as :func:`bin_profile`), then one
    ``np.bincount`` per quantity: what a model fit needs beside the pixel values (mean
    coordinate, its spread, positions along the feature) costs one pass each.

    Parameters
    ----------
    u_px : array_like of float
        Across-feature coordinate of each sample (pixels), any shape.
    values : list of array_like
        Quantities to average per bin, each the same size as ``u_px``.
    bin_width_px : float, default 0.25
        Bin width in pixels (> 0).

    Returns
    -------
    list of BinnedProfile
        One per quantity, in order; identical to ``bin_profile(u_px, v, bin_width_px)``.
    """
    u, idx, n_bins, u_min = _bin_index(u_px, bin_width_px)
    count = np.bincount(idx, minlength=n_bins).astype(np.int64)
    centres = u_min + np.arange(n_bins, dtype=np.float64) * bin_width_px
    inv = 1.0 / np.maximum(count, 1)
    filled = count > 0
    out = []
    for vals in values:
        v = np.asarray(vals, dtype=np.float64).ravel()
        if v.shape != u.shape:
            raise ValueError(f"u_px and values differ in size: {u.size} vs {v.size}")
        sums = np.bincount(idx, weights=v, minlength=n_bins)
        mean = np.where(filled, sums * inv, np.nan)
        out.append(BinnedProfile(u_px=centres, mean=mean, count=count,
                                 bin_width_px=float(bin_width_px)))
    return out


def _bin_index(
    u_px: npt.ArrayLike, bin_width_px: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], int, float]:
    """The samples ``u`` (flat), each one's bin, the number of bins and ``min(u)`` (the first
    bin's centre), as :func:`bin_profiles` bins them."""
    u = np.asarray(u_px, dtype=np.float64).ravel()
    if u.size == 0:
        raise ValueError("no samples to bin")
    if not (bin_width_px > 0 and math.isfinite(bin_width_px)):
        raise ValueError(f"bin_width_px must be a positive number, got {bin_width_px}")
    u_min, u_max = float(u.min()), float(u.max())
    if not (math.isfinite(u_min) and math.isfinite(u_max)):  # NaN or inf anywhere shows here
        raise ValueError("u_px holds a non-finite value")
    # floor(x + 0.5) with a tolerance: samples on a bin edge (half-pixel steps at 1 px bins)
    # go to one side consistently despite rounding noise in cos/sin. In place, same order of
    # operations; the last bin is that of u_max (every step is monotonic).
    scaled = u - u_min
    scaled /= bin_width_px
    scaled += 0.5
    scaled += 1e-9
    idx = np.floor(scaled, out=scaled).astype(np.int64)
    n_bins = math.floor((u_max - u_min) / bin_width_px + 0.5 + 1e-9) + 1
    return u, idx, n_bins, u_min


def filled_bin_means(
    u_px: npt.ArrayLike,
    values: list[npt.NDArray[np.float64]],
    bin_width_px: float,
) -> tuple[npt.NDArray[np.int64], list[npt.NDArray[np.float64]]]:
    """The counts and means of :func:`bin_profiles` in its filled bins only (in order): the
    same numbers, without the empty bins' NaNs and the per-quantity profile objects (a model
    fit on a 100 us scale feels them).

    Parameters
    ----------
    u_px : array_like of float
        Across-feature coordinate of each sample (pixels), any shape.
    values : list of ndarray of float64
        Quantities to average per bin, each the same size as ``u_px``.
    bin_width_px : float
        Bin width in pixels (> 0).

    Returns
    -------
    (ndarray of int64, list of ndarray of float64)
        Pixels per filled bin, and each quantity's mean per filled bin.
    """
    u, idx, n_bins, _ = _bin_index(u_px, bin_width_px)
    count = np.bincount(idx, minlength=n_bins)
    filled = count > 0
    count = count[filled].astype(np.int64)
    inv = 1.0 / count  # = 1 / max(count, 1) on the filled bins: the same means
    out = []
    for v in values:
        if v.size != u.size:
            raise ValueError(f"u_px and values differ in size: {u.size} vs {v.size}")
        sums = np.bincount(idx, weights=v.ravel(), minlength=n_bins)
        out.append(sums[filled] * inv)
    return count, out


def project_roi(
    pixels: npt.ArrayLike,
    theta_rad: float,
    bin_width_px: float = 0.25,
    origin_rc: tuple[float, float] | None = None,
) -> BinnedProfile:
    """Project a 2-D ROI onto the normal at ``theta_rad`` and bin it (see :func:`bin_profile`).

    Parameters
    ----------
    pixels : array_like, shape (rows, cols)
        The ROI (any numeric dtype).
    theta_rad : float
        Direction of intensity variation, as in :func:`across_coordinate`.
    bin_width_px : float, default 0.25
        Bin width in pixels.
    origin_rc : (float, float), optional
        Where ``u = 0``; default the ROI centre.

    Returns
    -------
    BinnedProfile
    """
    img = np.asarray(pixels)
    if img.ndim != 2:
        raise ValueError(f"pixels must be 2-D, got shape {img.shape}")
    u = across_coordinate((img.shape[0], img.shape[1]), theta_rad, origin_rc)
    return bin_profile(u, img, bin_width_px)
