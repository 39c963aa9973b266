"""Relative radiometry (thesis section 4.4, Table 4.16): LED mask from the high-gain frame,
mean gray of the measurement frame inside it, normalisation to the maximum, comparison with
simulated irradiance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


def led_mask(
    high_gain_frame: npt.ArrayLike,
    *,
    threshold: float | None = None,
    largest_only: bool = True,
    min_pixels: int = 4,
) -> npt.NDArray[np.bool_]:
    """Where the LED is: pixels of the high-gain (gain 5) frame above a threshold.

    Parameters
    ----------
    high_gain_frame : array_like
        2-D frame.
    threshold : float, optional
        Gray level; default Otsu's threshold of the frame.
    largest_only : bool
        Keep only the largest connected blob (drops hot pixels and stray light).
    min_pixels : int
        Fewer mask pixels than this is an error.

    Raises
    ------
    ValueError
        Non-2-D frame, uniform frame (nothing to find) or a mask smaller than ``min_pixels``.
    """
    from scipy import ndimage  # imported here: most analyses never need them
    from skimage.filters import threshold_otsu

    img = np.asarray(high_gain_frame, dtype=np.float64)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"mask frame must be a non-empty 2-D array, got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("mask frame contains NaN or infinite pixels")
    if threshold is None:
        if float(img.max()) == float(img.min()):
            raise ValueError("mask frame is uniform: no LED visible")
        threshold = float(threshold_otsu(img))
    mask = img > threshold
    if largest_only and mask.any():
        labels, n = ndimage.label(mask)
        if n > 1:
            sizes = np.bincount(labels.ravel())[1:]
            mask = labels == (1 + int(np.argmax(sizes)))
    if int(mask.sum()) < min_pixels:
        raise ValueError(f"LED mask has {int(mask.sum())} pixels (< {min_pixels}): no LED found")
    return mask


def reading_mask(
    locator_frame: npt.ArrayLike,
    measurement_frame: npt.ArrayLike,
    threshold_fraction: float,
    *,
    plateau_percentile: float = 90.0,
) -> npt.NDArray[np.bool_]:
    """The pixels a radiometry reading averages: the LED found in the high-gain frame, its
    level taken from the measurement frame.

    The high-gain frame only locates the LED (the largest blob above ``threshold_fraction`` of
    the way from its median to its peak): at gain 5 it is usually clipped, so a threshold at a
    fraction of *its* peak is a fixed code whose place on the spot's edge moves with the LED's
    brightness (the mask grows on bright positions). The reading's mask is then the
    measurement frame's pixels above ``threshold_fraction`` of the way from its median (the
    dark room) to its plateau (``plateau_percentile`` of the measurement inside the located
    blob): the same fraction of every spot's own level, so the mean inside it is proportional
    to that level.

    Parameters
    ----------
    locator_frame, measurement_frame : array_like
        2-D frames of the same shape (high gain, unity gain).
    threshold_fraction : float
        In (0, 1).
    plateau_percentile : float
        Percentile of the measurement inside the located blob taken as the plateau.

    Raises
    ------
    ValueError
        Frames of different shapes, a fraction outside (0, 1), no LED in either frame, or a
        measurement no brighter inside the LED than around it.
    """
    loc = np.asarray(locator_frame, dtype=np.float64)
    meas = np.asarray(measurement_frame, dtype=np.float64)
    if loc.shape != meas.shape:
        raise ValueError(f"mask frame {loc.shape} and measurement frame {meas.shape} differ "
                         "in shape")
    if not 0.0 < threshold_fraction < 1.0:
        raise ValueError(f"threshold fraction must be in (0, 1), got {threshold_fraction:g}")
    background, peak = float(np.median(loc)), float(loc.max())
    located = led_mask(loc, threshold=background + threshold_fraction * (peak - background))
    dark = float(np.median(meas))
    plateau = float(np.percentile(meas[located], plateau_percentile))
    if not plateau > dark:
        raise ValueError(f"measurement frame is no brighter inside the LED ({plateau:g}) than "
                         f"its background ({dark:g})")
    return led_mask(meas, threshold=dark + threshold_fraction * (plateau - dark))


def clipped_in_mask(frame: npt.ArrayLike, mask: npt.ArrayLike, saturation_code: float) -> int:
    """How many pixels of ``frame`` inside ``mask`` are at (or above) ``saturation_code``:
    a reading with any is a lower bound, not a measurement.

    Raises
    ------
    ValueError
        Shape mismatch.
    """
    img = np.asarray(frame)
    m = np.asarray(mask).astype(bool)
    if img.shape != m.shape:
        raise ValueError(f"frame {img.shape} and mask {m.shape} differ in shape")
    return int(np.count_nonzero(img[m] >= saturation_code))


def mean_in_mask(
    frame: npt.ArrayLike, mask: npt.ArrayLike, dark: npt.ArrayLike | None = None
) -> float:
    """Mean gray level of ``frame`` (minus ``dark`` if given) inside ``mask``.

    Raises
    ------
    ValueError
        Shape mismatch or an empty mask.
    """
    img = np.asarray(frame, dtype=np.float64)
    m = np.asarray(mask).astype(bool)
    if img.shape != m.shape:
        raise ValueError(f"frame {img.shape} and mask {m.shape} differ in shape")
    if not m.any():
        raise ValueError("mask is empty: no pixels to average")
    if dark is not None:
        d = np.asarray(dark, dtype=np.float64)
        if d.shape != img.shape and d.ndim != 0:
            raise ValueError(f"dark frame {d.shape} and frame {img.shape} differ in shape")
        img = img - d
    value = float(img[m].mean())
    if not math.isfinite(value):
        raise ValueError("mean inside the mask is not finite")
    return value


def normalise_to_max(values: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Values divided by their maximum (fig. 4.21).

    Raises
    ------
    ValueError
        Empty input, non-finite values or a maximum <= 0.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        raise ValueError("nothing to normalise")
    if not np.all(np.isfinite(v)):
        raise ValueError("values must be finite")
    top = float(v.max())
    if top <= 0:
        raise ValueError(f"maximum must be positive to normalise, got {top}")
    return v / top


@dataclass(frozen=True)
class RadiometryRow:
    """One field position of Table 4.16."""

    field_position_mm: float
    simulated: float
    measured: float
    simulated_normalised: float
    measured_normalised: float
    difference: float  # measured_normalised - simulated_normalised


def radiometry_table(
    field_positions_mm: npt.ArrayLike, simulated: npt.ArrayLike, measured: npt.ArrayLike
) -> list[RadiometryRow]:
    """Table 4.16: simulated irradiance and measured mean gray, each normalised to its maximum.

    Raises
    ------
    ValueError
        Lengths differ, or a column cannot be normalised.
    """
    pos = np.asarray(field_positions_mm, dtype=np.float64).ravel()
    sim = np.asarray(simulated, dtype=np.float64).ravel()
    mea = np.asarray(measured, dtype=np.float64).ravel()
    if not pos.size == sim.size == mea.size:
        raise ValueError("field positions, simulated and measured must have the same length")
    sn, mn = normalise_to_max(sim), normalise_to_max(mea)
    return [
        RadiometryRow(float(p), float(s), float(m), float(a), float(b), float(b - a))
        for p, s, m, a, b in zip(pos, sim, mea, sn, mn, strict=True)
    ]
