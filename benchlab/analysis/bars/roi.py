"""Common preparation of a region of interest before any estimator runs.

Orientation convention (used by every estimator and by :mod:`benchlab.analysis.geometry`):
``orientation`` names the direction in which the **intensity varies** (the testing direction,
perpendicular to the bars).

- ``"horizontal"`` - intensity varies along the columns (x, numpy axis 1): the bars are
  vertical stripes; the bar profile is the mean over rows.
- ``"vertical"`` - intensity varies along the rows (y, numpy axis 0): horizontal stripes.
- ``"sagittal"`` / ``"tangential"`` - the thesis's forward-view convention (Table 4.11 note):
  sagittal = horizontal, tangential = vertical. For radial-view ROIs, resolve the direction with
  :func:`benchlab.analysis.geometry.roi_orientation_relative_to_centre` first.
- ``None`` - detected from the data (the axis whose mean profile varies most).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.result import (
    CLIPPED_FRACTION_LIMIT,
    NYQUIST_CYCLES_PER_PX,
    PHASE_SENSITIVE_CYCLES_PER_PX,
    Diagnostics,
)


def row_major(img: npt.NDArray[Any]) -> npt.NDArray[Any]:
    """``img`` itself when numpy traverses it row by row (C-contiguous, or a view such as a
    crop whose strides fall from the first axis to the last), else its C-contiguous copy
    (Fortran order, transposed or reversed views).

    numpy sums an array in its memory order: a Fortran-order ROI would round a few ulps
    differently (1e-15) from the same pixels in C order, so the same pixels in another layout
    would read differently. Every estimator reads this array instead.

    Parameters
    ----------
    img : ndarray
        Any array (any number of dimensions, any dtype).

    Returns
    -------
    ndarray
        ``img`` or its copy in C order (same dtype and values).
    """
    strides = [s for s, n in zip(img.strides, img.shape, strict=True) if n > 1]
    if all(s > 0 for s in strides) and strides == sorted(strides, reverse=True):
        return img
    return np.ascontiguousarray(img)


#: Largest pixel magnitude analysed: sums of squares of larger values overflow float64.
MAX_ABS_VALUE = 1e150
#: Smallest spread of pixel values analysed (``vmax - vmin``): the fits square such differences
#: and multiply them by derivatives far below 1 (sharp bars), which fall below float64's normal
#: range (2.2e-308), lose their precision and vanish - profilefit divided by zero up to a
#: spread of 1e-144, sinefit read 0.215 for 0.238 at 1e-170. Such a ROI reads as flat (see
#: :attr:`PreparedROI.contrast_underflows`); the margin costs nothing, no camera gives it.
MIN_CONTRAST = 1e-100
#: The warning of a ROI of one gray level (``vmax == vmin``).
FLAT_WARNING = "single-valued ROI: one gray level, no bars"
#: The warning of a ROI whose pixel values span less than :data:`MIN_CONTRAST`.
TINY_CONTRAST_WARNING = (f"pixel values span less than {MIN_CONTRAST:g}: their squares "
                         "underflow float64, no bar profile (rescale the data)")
#: The directions the intensity of bars may vary in, as the API and the command line take them
#: (sagittal = horizontal, tangential = vertical: the thesis's forward-view convention).
BarOrientation = Literal["horizontal", "vertical", "sagittal", "tangential"]
#: Orientation -> the array axis the intensity varies along.
ORIENTATION_AXIS: dict[BarOrientation, int] = {
    "horizontal": 1, "vertical": 0, "sagittal": 1, "tangential": 0}


@dataclass(slots=True)
class PreparedROI:
    """A validated ROI with the facts every estimator needs (internal; callers treat it as
    read-only: the axis and the noise are filled in on their first use)."""

    pixels: npt.NDArray[np.float64]  # 2-D, frames averaged
    #: Numpy axis along which the intensity varies; ``None`` until :attr:`axis` detects it.
    known_axis: int | None
    integer_valued: bool  # values lie on a grid of ``code_step`` (integer codes or their means)
    code_step: float
    #: Per-pixel noise; ``None`` until :attr:`noise_sigma` measures it (along the bars).
    known_noise: float | None
    noise_given: bool
    max_code: float | None
    clipped_fraction: float
    vmin: float  # of ``pixels``
    vmax: float
    freq_cycles_per_px: float | None
    n_frames: int
    warnings: tuple[str, ...]
    orientation_given: bool = False
    #: ``pixels.sum(axis=0)`` and ``pixels.sum(axis=1)`` once :attr:`axis` was detected
    #: (the bar geometry's plane fit reuses them); ``None`` otherwise. Read them through
    #: :meth:`sums_for`, which knows the array they were summed from.
    profile_sums: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None
    sums_source: npt.NDArray[np.float64] | None = None
    #: The ROI a selection (:meth:`selected`) was taken from: its axis is that ROI's.
    source: PreparedROI | None = None

    def line_phase_gap(self) -> float:
        """Largest gap (cycles) between the bar phases the lines across axis-aligned bars of
        given orientation and frequency sample (e.g. 0.36 on 5 lines at 2.2 px per period);
        0 when either is unknown (the bars are then found at any angle, every phase sampled)."""
        f = self.freq_cycles_per_px
        if not f or not self.orientation_given:
            return 0.0
        phases = np.sort(np.mod(f * np.arange(self.pixels.shape[self.axis]), 1.0))
        return float(np.diff(np.concatenate([phases, [phases[0] + 1.0]])).max())

    @property
    def axis(self) -> int:
        """Numpy axis along which the intensity varies: the orientation given, else detected
        (on first use: the histogram method with a frequency never needs it)."""
        if self.known_axis is None and self.source is not None:
            self.known_axis = self.source.axis  # a selection's pixels show no bar direction
        elif self.known_axis is None:
            self.known_axis, sums = _axis_and_sums(self.pixels)
            if sums is not None and self.profile_sums is None:
                self.profile_sums, self.sums_source = sums, self.pixels
        return self.known_axis

    @property
    def noise_sigma(self) -> float:
        """Per-pixel noise (gray units): given, from the frames' spread, or measured on first
        use from neighbour differences along the bars (:func:`robust_noise_sigma`), never
        below the code step's quantisation."""
        if self.known_noise is None:
            self.known_noise = max(robust_noise_sigma(self.pixels, self.axis),
                                   self.quantisation_sd)
        return self.known_noise

    @property
    def quantisation_sd(self) -> float:
        """:func:`quantisation_sd` of this ROI's code grid: the floor of any noise estimate."""
        return quantisation_sd(self.integer_valued, self.code_step)

    def measured(self) -> PreparedROI:
        """``self`` with the axis and noise measured (before copies with other pixels, e.g. a
        bootstrap's resamples, which must share the ROI's own)."""
        _ = self.axis, self.noise_sigma
        return self

    def sums_for(
        self, img: npt.NDArray[np.float64]
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
        """:attr:`profile_sums` if they are the sums of ``img`` (the very array), else None:
        a copy with other pixels (a selection, a bootstrap resample) cannot reuse them."""
        return self.profile_sums if img is self.sums_source else None

    @property
    def contrast_underflows(self) -> bool:
        """Whether the pixel values differ, but by less than :data:`MIN_CONTRAST`: no
        estimator can read them (a flat ROI, ``vmax == vmin``, is labelled apart)."""
        return 0.0 < self.vmax - self.vmin < MIN_CONTRAST

    @property
    def n_pixels(self) -> int:
        return int(self.pixels.size)

    @property
    def aliased(self) -> bool:
        f = self.freq_cycles_per_px
        return f is not None and f > NYQUIST_CYCLES_PER_PX + 1e-12

    @property
    def phase_sensitive(self) -> bool:
        f = self.freq_cycles_per_px
        return f is not None and PHASE_SENSITIVE_CYCLES_PER_PX <= f <= NYQUIST_CYCLES_PER_PX + 1e-12

    def selected(
        self, pixels: npt.NDArray[np.float64], noise_sigma: float, vmin: float, vmax: float
    ) -> PreparedROI:
        """A copy holding ``pixels`` (a subset of the ROI's, with their ``vmin`` and ``vmax``)
        and ``noise_sigma``; the other facts unchanged (cheaper than ``dataclasses.replace``,
        which estimators on a 100 us budget feel)."""
        return PreparedROI(
            pixels, self.known_axis, self.integer_valued, self.code_step, noise_sigma,
            self.noise_given, self.max_code, self.clipped_fraction, vmin, vmax,
            self.freq_cycles_per_px, self.n_frames, self.warnings, self.orientation_given,
            self.profile_sums, self.sums_source, self.source or self,
        )

    def diagnostics(self, n_pixels: int | None = None, **extra: object) -> Diagnostics:
        """The shared diagnostics plus ``extra`` fields; ``n_pixels`` defaults to the pixels
        held (pass the whole ROI's count when they are a selection)."""
        if n_pixels is not None:
            extra["n_pixels"] = n_pixels
        return self.diagnostics_with(**extra)

    def diagnostics_with(self, **fields: object) -> Diagnostics:
        """:meth:`diagnostics` with ``fields`` added or overriding the shared ones (e.g. a
        measured ``noise_sigma``): cheaper than ``dataclasses.replace`` afterwards."""
        f = self.freq_cycles_per_px
        aliased = f is not None and f > NYQUIST_CYCLES_PER_PX + 1e-12
        shared: dict[str, Any] = dict(
            n_pixels=self.pixels.size,
            px_per_period=(1.0 / f) if f else None,
            freq_cycles_per_px=f,
            clipped_fraction=self.clipped_fraction,
            # Not measured only to be overridden (the noise is measured on first use).
            noise_sigma=fields["noise_sigma"] if "noise_sigma" in fields else self.noise_sigma,
            aliased=aliased,
            phase_sensitive=f is not None and not aliased and PHASE_SENSITIVE_CYCLES_PER_PX <= f,
            code_step=self.code_step if self.integer_valued else None,
            n_frames=self.n_frames,
            saturation_code=self.max_code if self.clipped_fraction > 0 else None,
        )
        shared.update(fields)
        return Diagnostics(**shared)


def quantisation_sd(integer_valued: bool, code_step: float) -> float:
    """Standard deviation of rounding to a grid of ``code_step`` (``code_step / sqrt(12)``)
    for integer codes (or their means), 0 for continuous data: no noise estimate on such data
    goes below it (a flat ROI of one code has none it can measure)."""
    return (code_step or 1.0) / math.sqrt(12.0) if integer_valued else 0.0


def orientation_axis(orientation: str | None) -> int | None:
    """Numpy axis along which intensity varies for an orientation name (``None`` if auto)."""
    if orientation is None:
        return None
    key = orientation.strip().lower()
    if key not in ORIENTATION_AXIS:
        raise ValueError(
            f"orientation must be one of {sorted(ORIENTATION_AXIS)} or None, got {orientation!r}"
        )
    return ORIENTATION_AXIS[key]


def infer_max_code(
    roi: npt.NDArray[np.generic], code_step: float, roi_max: float | None = None
) -> float | None:
    """Saturation code for integer data: 255 (uint8), 4095 (12-bit in 16), 65520 (MSB-aligned
    12-bit) or 65535; ``None`` for float data."""
    if roi.dtype == np.uint8:
        return 255.0
    if roi.dtype.kind in "ui":
        top = float(roi.max()) if roi_max is None else roi_max
        if code_step == 16 and top > 4095:
            return 65520.0
        if top <= 4095:
            return 4095.0
        return 65535.0
    return None


def is_integer_valued(raw: npt.NDArray[Any]) -> bool:
    """Whether ``raw`` holds integer codes (an integer dtype, or floats that are all whole
    numbers within float64's exact range)."""
    return raw.dtype.kind in "ui" or bool(
        np.all(raw == np.round(raw)) and np.abs(raw).max() < 2**53
    )


def saturation_code(
    raw: npt.NDArray[np.generic], code_step: float, top: Any = None
) -> float | None:
    """The code ``raw`` saturates at: the integer dtype's top code (:func:`infer_max_code`) or,
    lower, a plateau at the maximum (:func:`detect_plateau`; 16-bit words and float data);
    ``None`` when neither. ``top``: ``raw.max()`` if already known.

    8-bit data clip at 255 only: the dtype pins the bit depth, whose full scale is the one
    code a camera's 8-bit output saturates at (issue 37: a noisy ground of 180 +- 3 with 5
    pixels on its top code 188 was called clipped, and the element read a bound 0.53 for
    0.8). A 16-bit word holds 10- to 16-bit codes and some sensors saturate below full scale
    (a plateau at 3000), so there the data's plateau is the evidence; a camera's own
    saturation code, where known, is passed as ``max_code`` to :func:`prepare_roi`."""
    values = raw.ravel()
    if top is None:
        top = values.max()
    code = infer_max_code(raw, code_step, float(top)) if raw.dtype.kind in "ui" else None
    if raw.dtype == np.uint8:
        return code
    plateau = detect_plateau(values, code_step, top)
    if plateau is not None and (code is None or plateau < code):
        code = plateau
    return code


#: A plateau at the top code: at least this share of the pixels (and 3) sit on the maximum ...
PLATEAU_MIN_FRACTION = 0.005
#: ... and at least this many times as many as in the code step just below it.
PLATEAU_RATIO = 2.0
#: ... and some pixel lies within this many code steps below it (for float data: this share of
#: the data's range), else the top is one level of noise-free sharp bars.
NEAR_TOP_STEPS = 8
NEAR_TOP_RANGE = 0.03
#: ... or the ROI holds at least this many levels below it (noise-free sharp bars at a whole
#: period of P px hold at most P).
FEW_LEVELS = 8


def detect_plateau(
    values: npt.NDArray[np.generic], code_step: float, top: Any = None
) -> float | None:
    """The maximum value when it is a saturation plateau, else ``None``.

    A clipped bright level piles pixels up exactly on the top code, whatever the bit depth or
    pedestal; an unclipped noise tail thins out towards the maximum. So the maximum counts as
    saturation when it holds at least ``PLATEAU_MIN_FRACTION`` of the pixels (and 3) and
    ``PLATEAU_RATIO`` times as many as either of the two code steps below it - and the data
    lead up to it: pixels within ``NEAR_TOP_STEPS`` code steps below, or ``FEW_LEVELS`` levels
    or more (blurred edges). Noise-free sharp bars (two codes, or a few levels none near the
    top) sit on a plateau at every level: their top is one of them, not saturation (issue 37).
    ``top``: ``values.max()`` if already known (the numpy scalar: comparisons keep the data's
    precision).
    """
    if top is None:
        top = values.max()
    n_top = int(np.count_nonzero(values == top))
    if n_top < max(3, PLATEAU_MIN_FRACTION * values.size):
        return None
    step = code_step if code_step > 0 else 0.0
    if step > 0:
        # The larger count of the two codes below: a noise tail's top code may hold a few
        # pixels more than the code below it by chance (a 14 x 16 ROI: 3 on 203, 1 on 202).
        n_below = max(int(np.count_nonzero((values >= top - step) & (values < top))),
                      int(np.count_nonzero((values >= top - 2 * step) & (values < top - step))))
    else:
        n_below = 0
    if n_top < PLATEAU_RATIO * max(n_below, 1):
        return None
    # Noise-free sharp bars sit on plateaus at every level, the top one included: the top is
    # saturation only when the data approach it (noise puts pixels just below it) or hold
    # more than a few levels (blurred edges ramping up into it). Issue 37: 8-bit bars of
    # codes 50 and 200 were called "52 % clipped at code 200".
    near = NEAR_TOP_STEPS * step if step > 0 else NEAR_TOP_RANGE * float(top - values.min())
    below = values[values < top]
    if below.size and np.all(below == below.min()):
        return None  # two codes only: a two-level pattern
    if not np.any(below >= top - near) and np.unique(below).size < FEW_LEVELS:
        return None  # a few levels, none near the top: sharp noise-free bars
    return float(top)


def detect_code_step(values: npt.NDArray[np.generic]) -> float:
    """Greatest common spacing of integer codes (1 for ordinary data, 16 for 12-bit data stored
    MSB-aligned in 16 bits); 1 when fewer than two distinct values.

    A stored code step comes from shifting a sensor's codes left by whole bits, so it is a power
    of two: the largest one dividing the spacing is kept. A noise-free two-level pattern (codes
    42 and 78) has a spacing of 36, which is the bars' contrast, not a step: taken as one, its
    rounding noise (10 codes) hid the bars."""
    ints = values if values.dtype.kind in "ui" else values.astype(np.int64)
    head = ints[:64]  # odd and even codes among the first few: spacing 1
    n_odd = np.count_nonzero(np.bitwise_and(head, 1))
    if 0 < n_odd < head.size:
        return 1.0
    n_odd = np.count_nonzero(np.bitwise_and(ints, 1))
    if 0 < n_odd < ints.size:
        return 1.0
    ints = ints.astype(np.int64)
    step = int(np.gcd.reduce(ints - ints.min()))
    return float(max(step & -step, 1))


def _diff_sigma(img: npt.NDArray[np.float64], ax: int) -> float:
    """Noise sigma from neighbour differences along ``ax``: RMS difference / sqrt(2), then once
    more over the differences within 4 sigma (drops bar ends, edges and hot pixels)."""
    d = (img[1:, :] - img[:-1, :]) if ax == 0 else (img[:, 1:] - img[:, :-1])
    d = d.ravel()
    # einsum, not ``d @ d``: a BLAS dot on a large ROI wakes OpenBLAS threads (ms under load).
    rms2 = float(np.einsum("i,i->", d, d)) / d.size
    if rms2 == 0.0:
        return 0.0
    # In place: |d| has the same squares, so the clipped sum below is unchanged.
    if float(np.abs(d, out=d).max()) ** 2 > 16.0 * rms2:
        kept = d[d * d <= 16.0 * rms2]
        rms2 = float(np.einsum("i,i->", kept, kept)) / kept.size if kept.size else rms2
    # A 4-sigma-clipped Gaussian keeps 99.99 % of its variance: no correction needed.
    return math.sqrt(rms2 / 2.0)


def robust_noise_sigma(img: npt.NDArray[np.float64], axis: int | None) -> float:
    """Per-pixel noise from differences of neighbours **along the bars** (where the scene is
    flat). With ``axis`` unknown, the smaller of both directions; a single line across the bars
    falls back to differences across them (edges are clipped out). 0.0 without any pair."""
    along = [1 - axis] if axis is not None else [0, 1]
    estimates = [_diff_sigma(img, ax) for ax in along if img.shape[ax] >= 2]
    if not estimates and axis is not None and img.shape[axis] >= 2:
        estimates.append(_diff_sigma(img, axis))
    return min(estimates) if estimates else 0.0


#: Side (px) of the centred crop :func:`quiet_noise_sigma` reads at most.
QUIET_CROP_PX = 64
#: Lower quartile of |N(0, 2 sigma^2)| over sigma.
_Q25_DIFF = 0.31863936 * math.sqrt(2.0)


def quiet_noise_sigma(img: npt.NDArray[np.float64]) -> float | None:
    """Per-pixel noise from the quietest quarter of the neighbour differences, in whichever of
    the four directions (rows, columns, both diagonals) is quietest: bars at any angle leave one
    direction that runs along them, and edges, bar ends and ground may spoil up to three in
    four of its differences. ``None`` with fewer than 16 differences in every direction."""
    rows, cols = img.shape
    if rows > QUIET_CROP_PX or cols > QUIET_CROP_PX:  # a centred crop: the cost stays flat
        r0, c0 = max(0, (rows - QUIET_CROP_PX) // 2), max(0, (cols - QUIET_CROP_PX) // 2)
        img = img[r0:r0 + QUIET_CROP_PX, c0:c0 + QUIET_CROP_PX]
        rows, cols = img.shape
    pairs = []
    if rows >= 2:
        pairs.append(img[1:, :] - img[:-1, :])
    if cols >= 2:
        pairs.append(img[:, 1:] - img[:, :-1])
    if rows >= 2 and cols >= 2:
        # Diagonal neighbours are sqrt(2) px apart: still neighbours for the noise.
        pairs += [img[1:, 1:] - img[:-1, :-1], img[1:, :-1] - img[:-1, 1:]]
    found = []
    for d in pairs:
        if d.size >= 16:
            flat = np.abs(d).ravel()
            k = (flat.size - 1) // 4  # the lower quartile (np.percentile costs ~20 us more)
            found.append(float(np.partition(flat, k)[k]) / _Q25_DIFF)
    return min(found) if found else None


def detect_axis(img: npt.NDArray[np.float64]) -> int:
    """Axis along which the mean profile varies most (the testing direction)."""
    return _axis_and_sums(img)[0]


def _profile_var(img: npt.NDArray[np.float64], ax: int) -> float:
    """``np.var(img.mean(axis=ax))`` by the same ufunc steps (bit-identical), without
    ``np.mean``/``np.var``'s Python wrappers: this runs on every ROI with no orientation."""
    return _sums_var(np.add.reduce(img, axis=ax), img.shape[ax])


def _sums_var(sums: npt.NDArray[np.float64], n: int) -> float:
    """:func:`_profile_var` from the sums along the axis (``n`` of them per entry)."""
    add = np.add.reduce
    profile = sums / n
    dev = profile - add(profile) / profile.size
    np.multiply(dev, dev, out=dev)
    return float(add(dev) / dev.size)


def _axis_and_sums(
    img: npt.NDArray[np.float64],
) -> tuple[int, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None]:
    """:func:`detect_axis` and the column and row sums it used (``None`` for a single line)."""
    if img.shape[0] < 2:
        return 1, None
    if img.shape[1] < 2:
        return 0, None
    col_sums = np.add.reduce(img, axis=0)
    row_sums = np.add.reduce(img, axis=1)
    v_cols = _sums_var(col_sums, img.shape[0])
    v_rows = _sums_var(row_sums, img.shape[1])
    return (1 if v_cols >= v_rows else 0), (col_sums, row_sums)


def prepare_roi(
    roi: npt.ArrayLike,
    *,
    freq_cycles_per_px: float | None = None,
    orientation: str | None = None,
    max_code: float | None = None,
    noise_sigma: float | None = None,
) -> PreparedROI:
    """Validate a ROI (2-D, or a 3-D stack of frames averaged along axis 0) and measure what all
    estimators share.

    Raises
    ------
    ValueError
        Empty ROI, wrong number of dimensions, non-finite pixels, negative or non-finite
        frequency / noise, unknown orientation.
    """
    # Row-major: numpy sums in memory order, so a Fortran-order (or transposed, reversed) ROI
    # would read a few ulps differently from the same pixels in C order.
    arr = row_major(np.asarray(roi))
    kind = arr.dtype.kind
    if kind == "b":
        arr = arr.astype(np.uint8)
        kind = "u"
    if kind not in "uif":
        raise ValueError(f"ROI must hold numbers, got dtype {arr.dtype}")
    if arr.ndim not in (2, 3):
        raise ValueError(
            f"ROI must be 2-D (rows, cols) or 3-D (frames, rows, cols), got {arr.shape}"
        )
    if arr.size == 0:
        raise ValueError(f"ROI is empty (shape {arr.shape})")
    if kind == "f" and not np.isfinite(arr).all():
        raise ValueError("ROI contains NaN or infinite pixels")
    if freq_cycles_per_px is not None:
        if not math.isfinite(freq_cycles_per_px) or freq_cycles_per_px < 0:
            raise ValueError(
                f"frequency must be finite and >= 0 cycles/px, got {freq_cycles_per_px}"
            )
    if noise_sigma is not None and (not math.isfinite(noise_sigma) or noise_sigma < 0):
        raise ValueError(f"noise_sigma must be finite and >= 0, got {noise_sigma}")
    if max_code is not None and (not math.isfinite(max_code) or max_code <= 0):
        raise ValueError(f"max_code must be positive, got {max_code}")
    axis = orientation_axis(orientation)
    warnings: list[str] = []

    raw = arr
    stack = arr.astype(np.float64, copy=False)
    n_frames = 1
    temporal_sigma: float | None = None
    if stack.ndim == 3:
        n_frames = stack.shape[0]
        if n_frames >= 2:
            temporal_sigma = float(np.sqrt(np.mean(np.var(stack, axis=0, ddof=1))))
        img = stack.mean(axis=0)
    else:
        img = stack

    values = raw.ravel()
    top = values.max()
    raw_max = float(top)
    raw_min = float(values.min())
    if kind == "f" and max(raw_max, -raw_min) > MAX_ABS_VALUE:
        raise ValueError(f"ROI holds values up to {max(raw_max, -raw_min):.3g}: beyond "
                         f"+-{MAX_ABS_VALUE:g} their squares overflow (rescale the data)")
    integer_valued = is_integer_valued(raw)
    code_step = detect_code_step(values) if integer_valued else 0.0
    max_code_f = saturation_code(raw, code_step, top) if max_code is None else float(max_code)
    clipped = 0.0
    if max_code_f is not None:
        clipped = (
            float(np.count_nonzero(raw >= max_code_f) / raw.size) if raw_max >= max_code_f else 0.0
        )
        if clipped > CLIPPED_FRACTION_LIMIT:
            warnings.append(
                f"{100 * clipped:.1f}% of pixels clipped at code {max_code_f:g}: "
                "the bright level (and the modulation) reads low"
            )
    if n_frames > 1 and integer_valued:
        # The mean of n frames on a grid of ``code_step`` lies on a grid of code_step / n.
        code_step = code_step / n_frames

    # The axis (when not given) and the noise (when neither given nor from frames) are
    # measured on first use: see PreparedROI.axis and .noise_sigma.
    sigma: float | None = None
    given = noise_sigma is not None
    if noise_sigma is not None:
        sigma = float(noise_sigma)
    elif temporal_sigma is not None:
        sigma = max(temporal_sigma / math.sqrt(n_frames),
                    quantisation_sd(integer_valued, code_step))

    f = freq_cycles_per_px
    if f is not None:
        if f > NYQUIST_CYCLES_PER_PX + 1e-12:
            warnings.append(
                f"{f:.3f} cycles/px is above Nyquist (0.5): aliased, exclude from comparisons"
            )
        elif f >= PHASE_SENSITIVE_CYCLES_PER_PX:
            warnings.append(
                f"{f:.3f} cycles/px is near Nyquist: the reading depends on sampling phase"
            )
        elif f == 0:
            warnings.append("zero frequency: no bar period to analyse")
    if img.size < 100:
        warnings.append(f"only {img.size} pixels: sparse histogram, noisy modulation")
    return PreparedROI(
        pixels=img,
        known_axis=axis,
        integer_valued=integer_valued,
        code_step=code_step,
        known_noise=sigma,
        noise_given=given,
        max_code=max_code_f,
        clipped_fraction=clipped,
        vmin=float(img.min()) if n_frames > 1 else raw_min,  # raw: less to read
        vmax=float(img.max()) if n_frames > 1 else raw_max,
        freq_cycles_per_px=f,
        n_frames=n_frames,
        warnings=tuple(warnings),
        orientation_given=orientation is not None,
    )
