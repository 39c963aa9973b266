"""Photon transfer (EMVA 1288 "linear" model): system gain, noise, saturation, linearity, DSNU/PRNU.

Pure numpy. Inputs are frames (or per-step statistics) of a uniform field swept in exposure, each
step a pair of bright frames and a pair of dark frames at the same exposure, plus stacks of L
bright and L dark frames for the spatial non-uniformity. The definitions follow EMVA 1288 (3.1 /
4.0 "Linear"), as summarised in ``docs/measurement-notes.md`` section 3.6:

* mean ``mu_y`` = mean of both frames; temporal variance ``s2_y = var(A - B) / 2``;
* system gain K = slope of ``s2_y - s2_y.dark`` against ``mu_y - mu_y.dark``, fitted through
  the origin up to 70 % of saturation;
* saturation = the signal ``mu_y.sat - mu_y.dark`` where the temporal variance peaks (the peak
  step, refined by a parabola through its neighbours: :func:`saturation_vertex`);
* temporal dark noise ``s_y.dark`` = intercept of the dark variance against exposure (dark
  current shot noise removed), not below 0.24 DN^2 (quantisation-limited); read noise in
  electrons ``sqrt(s2_y.dark - 1/12) / K``;
* linearity error = min/max relative deviation (%) from a 1/Y-weighted line of ``mu_y -
  mu_y.dark`` against exposure quantity between 5 % and 95 % of saturation;
* dark current = slope of ``mu_y.dark`` against exposure, in electrons per second;
* DSNU / PRNU from averaged stacks, corrected for the residual temporal variance
  (``s^2 = s^2_measured - s^2_stack / L``).

Figures the frames cannot resolve are flagged, never reported as numbers (EMVA 1288 practice):
a dark level clipped at code 0 (more than 0.5 % of the dark pixels at 0) biases read noise, dark
current and DSNU low; a dark noise below 1 DN biases read noise and DSNU (quantisation); a dark
signal moving less than 1 DN over the sweep (or quantised, as above) biases the dark current; a
bright stack with more than 0.5 % of its pixels at the top code gives no PRNU.

Pixels flagged as defects (hot or dead, far outside the fixed-pattern distribution) are left out
of every statistic and counted; EMVA 1288 keeps them in its DSNU, so ``dsnu_all_pixels_dn`` is
reported too.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.noise import robust_sigma

#: Quantisation noise variance, DN^2.
QUANTISATION_VAR_DN2 = 1.0 / 12.0
#: EMVA reference implementation floor of the temporal dark variance, DN^2.
DARK_VAR_FLOOR_DN2 = 0.24
#: EMVA set-up rule: the temporal dark noise should be at least 1 DN; below it quantisation
#: biases the dark statistics (read noise, DSNU) and they are flagged as not resolved.
MIN_DARK_NOISE_DN = 1.0
#: K is fitted up to this fraction of saturation; linearity between these fractions.
K_FIT_MAX_FRACTION = 0.7
LINEARITY_RANGE = (0.05, 0.95)
#: A pixel whose mean dark or bright level is this many robust sigmas off is a defect.
DEFECT_SIGMAS = 8.0
#: EMVA 1288 practice: at most this fraction of pixels at code 0 in a dark frame (else the
#: black level is clipped) or at the top code in the PRNU stack (else it is saturated).
MAX_CLIPPED_FRACTION = 0.005
#: Below this rise of the dark mean over the sweep (DN) the dark current is not resolved.
MIN_DARK_SPAN_DN = 1.0
#: The quantities that can be flagged as not resolved, and their result keys.
UNRESOLVED_KEYS: dict[str, tuple[str, ...]] = {
    "read_noise": ("read_noise_dn", "read_noise_e"),
    "dark_current": ("dark_current_e_per_s", "dark_current_uncertainty_e_per_s"),
    "dsnu": ("dsnu_dn", "dsnu_all_pixels_dn"),
    "prnu": ("prnu_pct",),
}


def msb_aligned(frames: Sequence[npt.ArrayLike], bits: int) -> bool:
    """Whether a set of frames holds ``bits``-bit codes MSB-aligned in 16-bit words: some code
    exceeds the bit depth and every code is a multiple of ``2**(16 - bits)``.

    Decide on the whole set (a sweep always has bright frames): a dark MSB-aligned frame alone
    can look like plain codes.
    """
    step = 1 << (16 - bits)
    over = False
    for f in frames:
        arr = np.asarray(f)
        if arr.dtype.kind not in "ui" or np.any(arr.astype(np.int64) % step):
            return False
        over |= bool(arr.size and int(arr.max()) > (1 << bits) - 1)
    return over


def native_codes(pixels: npt.ArrayLike, bits: int, aligned: bool | None = None) -> FloatArray:
    """Frame as float DN of its native bit depth.

    ``aligned``: the codes are MSB-aligned in 16-bit words (see :func:`msb_aligned`) and are
    shifted down; ``None`` decides from this frame alone.

    Raises
    ------
    ValueError
        If codes exceed the bit depth and are not MSB-aligned.
    """
    arr = np.asarray(pixels)
    if aligned is None:
        aligned = msb_aligned([arr], bits)
    if aligned:
        return arr.astype(np.float64) / float(1 << (16 - bits))
    peak = int(arr.max()) if arr.size else 0
    if peak > (1 << bits) - 1:
        raise ValueError(f"codes up to {peak} do not fit {bits} bits and are not MSB-aligned "
                         "16-bit")
    return arr.astype(np.float64)


def pair_statistics(
    frame_a: npt.ArrayLike, frame_b: npt.ArrayLike, valid: npt.NDArray[np.bool_] | None = None
) -> tuple[float, float]:
    """Mean and temporal variance of a pair of frames of the same exposure.

    Returns
    -------
    mean_dn, variance_dn2 : float
        ``(mean(A) + mean(B)) / 2`` and ``var(A - B) / 2`` over the valid pixels.
    """
    a = np.asarray(frame_a, dtype=np.float64)
    b = np.asarray(frame_b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"frame pair shapes differ: {a.shape} vs {b.shape}")
    if valid is not None:
        a, b = a[valid], b[valid]
    if a.size < 2:
        raise ValueError("a frame pair needs at least 2 valid pixels")
    return float(0.5 * (a.mean() + b.mean())), float(np.var(a - b) / 2.0)


def fraction_at_code(frames: npt.ArrayLike, code: float,
                     valid: npt.NDArray[np.bool_] | None = None) -> float:
    """Fraction of the (valid) pixels of a frame or stack of frames reading exactly ``code``
    (0: a clipped black level; the top code: saturation).

    Parameters
    ----------
    frames : array_like, shape (rows, cols) or (n, rows, cols)
        Native DN.
    valid : bool array of shape (rows, cols), optional
        Pixels to count (defects left out).
    """
    arr = np.asarray(frames)
    if arr.ndim == 2:
        arr = arr[None]
    if valid is not None:
        arr = arr[:, valid]
    return float(np.count_nonzero(arr == code)) / arr.size if arr.size else 0.0


@dataclass(frozen=True)
class SweepPoint:
    """Statistics of one exposure step (bright pair and dark pair)."""

    exposure_ms: float
    mean_dn: float
    variance_dn2: float
    dark_mean_dn: float
    dark_variance_dn2: float
    #: Relative irradiance of the step (1 for an exposure sweep; the LED current ratio for a
    #: current sweep); the exposure quantity is ``exposure_ms * irradiance``.
    irradiance: float = 1.0
    #: Fraction of the dark pair's pixels at code 0 (a clipped black level).
    dark_zero_fraction: float = 0.0

    @property
    def exposure_quantity(self) -> float:
        return self.exposure_ms * self.irradiance

    @property
    def signal_dn(self) -> float:
        return self.mean_dn - self.dark_mean_dn

    @property
    def signal_variance_dn2(self) -> float:
        return self.variance_dn2 - self.dark_variance_dn2


@dataclass(frozen=True)
class SpatialResult:
    """DSNU / PRNU from averaged stacks."""

    dsnu_dn: float
    dsnu_all_pixels_dn: float
    prnu_pct: float
    defect_pixels: int
    stack_frames: int
    bright_signal_dn: float
    #: Fraction of the dark stack's (non-defect) pixels at code 0.
    dark_zero_fraction: float = 0.0
    #: Fraction of the bright stack's (non-defect) pixels at the top code (0 when not given).
    bright_top_fraction: float = 0.0


@dataclass(frozen=True)
class PhotonTransferResult:
    """Everything measured for one gain and bit depth (keys of the results table)."""

    system_gain_dn_per_e: float
    system_gain_uncertainty_dn_per_e: float
    read_noise_dn: float
    read_noise_e: float
    read_noise_resolved: bool
    saturation_dn: float | None
    saturation_e: float | None
    saturation_reached: bool
    linearity_error_pct: tuple[float, float]
    dark_current_e_per_s: float | None
    dark_current_uncertainty_e_per_s: float | None
    black_level_dn: float
    linear_slope_dn_per_unit: float
    linear_offset_dn: float
    k_fit_indices: tuple[int, ...]
    linearity_indices: tuple[int, ...]
    deviation_pct: tuple[float, ...]
    saturation_index: int | None
    warnings: tuple[str, ...] = ()
    spatial: SpatialResult | None = None
    #: Highest fraction of dark pixels at code 0 over the sweep's dark pairs and dark stack.
    dark_zero_fraction: float = 0.0
    #: Quantities the frames do not resolve (keys of :data:`UNRESOLVED_KEYS`) and why; their
    #: figures above are biased estimates and :meth:`measured` gives None for them.
    unresolved: tuple[tuple[str, str], ...] = ()

    def resolved(self, quantity: str) -> bool:
        """Whether ``quantity`` (``read_noise``, ``dark_current``, ``dsnu``, ``prnu``) is."""
        return quantity not in dict(self.unresolved)

    def measured(self) -> dict[str, Any]:
        """The issue's result keys (plus uncertainties and flags); a figure that is not
        resolved is None, with ``<quantity>_resolved`` False and ``<quantity>_unresolved`` the
        reason."""
        out: dict[str, Any] = {
            "system_gain_dn_per_e": self.system_gain_dn_per_e,
            "system_gain_uncertainty_dn_per_e": self.system_gain_uncertainty_dn_per_e,
            "read_noise_dn": self.read_noise_dn,
            "read_noise_e": self.read_noise_e,
            "saturation_dn": self.saturation_dn,
            "saturation_e": self.saturation_e,
            "linearity_error_pct": list(self.linearity_error_pct),
            "dark_current_e_per_s": self.dark_current_e_per_s,
            "dsnu_dn": self.spatial.dsnu_dn if self.spatial else None,
            "prnu_pct": self.spatial.prnu_pct if self.spatial else None,
        }
        out.update({
            "dark_current_uncertainty_e_per_s": self.dark_current_uncertainty_e_per_s,
            "dsnu_all_pixels_dn": self.spatial.dsnu_all_pixels_dn if self.spatial else None,
            "defect_pixels": self.spatial.defect_pixels if self.spatial else None,
            "read_noise_resolved": self.read_noise_resolved,
            "saturation_reached": self.saturation_reached,
            "black_level_dn": self.black_level_dn,
            "dark_level_clipped": self.dark_zero_fraction > MAX_CLIPPED_FRACTION,
            "dark_zero_pct": 100.0 * self.dark_zero_fraction,
        })
        reasons = dict(self.unresolved)
        for quantity, keys in UNRESOLVED_KEYS.items():
            if quantity != "read_noise":  # read_noise_resolved: above, from the start
                out[f"{quantity}_resolved"] = quantity not in reasons
            out[f"{quantity}_unresolved"] = reasons.get(quantity)
            if quantity in reasons:
                out.update(dict.fromkeys(keys))
        return out


def _fit_through_origin(x: FloatArray, y: FloatArray) -> tuple[float, float]:
    """Least-squares slope of ``y = k x`` and its standard error."""
    sxx = float(np.sum(x * x))
    k = float(np.sum(x * y)) / sxx
    if x.size < 2:
        return k, math.nan
    resid = y - k * x
    return k, math.sqrt(float(np.sum(resid**2)) / (x.size - 1) / sxx)


def _fit_line(x: FloatArray, y: FloatArray) -> tuple[float, float, float]:
    """Least-squares ``y = a x + b``: (a, b, standard error of a)."""
    if np.unique(x).size < 2:
        return 0.0, float(np.mean(y)), math.nan
    a, b = np.polyfit(x, y, 1)
    if x.size < 3:
        return float(a), float(b), math.nan
    resid = y - (a * x + b)
    se = math.sqrt(float(np.sum(resid**2)) / (x.size - 2) / float(np.sum((x - x.mean()) ** 2)))
    return float(a), float(b), se


def saturation_index(variance_dn2: Sequence[float]) -> tuple[int, bool]:
    """Step where the temporal variance peaks, and whether the sweep went past it.

    The sweep reached saturation when a later step's variance fell clearly (below 70 %) under
    the peak; a variance still rising at the last step means it did not, and no saturation
    value is given.
    """
    v = np.asarray(variance_dn2, dtype=np.float64)
    i = int(np.argmax(v))
    after = v[i + 1:]
    return i, bool(after.size and after.min() < 0.7 * v[i])


def saturation_vertex(signal_dn: FloatArray, variance_dn2: FloatArray, i_peak: int) -> float:
    """Signal at the variance peak, refined: the vertex of a parabola through the contiguous
    steps around the peak step - below it those within 10 % of the peak variance, above it
    those within 3 % (the clipping side falls steeply) - clamped to their signal range.

    EMVA 1288 takes the peak step itself; when the peak is flat (a compressive response) the
    temporal noise of each variance estimate can move that step by several steps, and the
    parabola through its neighbours is less sensitive to it (and to the step spacing). With
    fewer than 3 such steps, the peak step.
    """
    peak = variance_dn2[i_peak]
    lo = hi = i_peak
    while lo > 0 and variance_dn2[lo - 1] >= 0.9 * peak:
        lo -= 1
    while hi < signal_dn.size - 1 and variance_dn2[hi + 1] >= 0.97 * peak:
        hi += 1
    if hi - lo < 2:
        return float(signal_dn[i_peak])
    x, yv = signal_dn[lo:hi + 1], variance_dn2[lo:hi + 1]
    a, b, _ = np.polyfit(x, yv, 2)
    vertex = -b / (2 * a) if a < 0 else float(x[-1])
    return float(np.clip(vertex, x.min(), x.max()))


def linearity_deviation(
    exposure_quantity: FloatArray, signal_dn: FloatArray, fit_idx: npt.NDArray[np.intp]
) -> tuple[float, float, FloatArray]:
    """EMVA linearity: 1/Y-weighted line of signal against exposure quantity over ``fit_idx``.

    Returns
    -------
    slope, offset, deviation_pct
        The line and the relative deviation (%) of every step from it.
    """
    x, y = exposure_quantity[fit_idx], signal_dn[fit_idx]
    if fit_idx.size < 2:
        raise ValueError("linearity needs at least 2 steps in the 5-95 % range")
    a, b = np.polynomial.polynomial.polyfit(x, y, 1, w=1.0 / np.abs(y))[::-1]
    fit = a * exposure_quantity + b
    with np.errstate(divide="ignore", invalid="ignore"):
        dev = 100.0 * (signal_dn - fit) / fit
    return float(a), float(b), dev


def photon_transfer(
    points: Sequence[SweepPoint], *, spatial: SpatialResult | None = None
) -> PhotonTransferResult:
    """The EMVA 1288 linear-model figures from one gain's sweep.

    Parameters
    ----------
    points : sequence of SweepPoint
        One per exposure step, any order (sorted by exposure quantity here); at least 3.
    spatial : SpatialResult, optional
        From :func:`spatial_nonuniformity`, carried into the result.

    Returns
    -------
    PhotonTransferResult
        ``saturation_dn`` / ``saturation_e`` are None when the sweep never reached saturation
        (a warning says so); K and linearity then use every step.

    Raises
    ------
    ValueError
        Too few steps, or no step with signal above the dark level.
    """
    pts = sorted(points, key=lambda p: p.exposure_quantity)
    if len(pts) < 3:
        raise ValueError(f"photon transfer needs at least 3 exposure steps, got {len(pts)}")
    t = np.array([p.exposure_ms for p in pts])
    h = np.array([p.exposure_quantity for p in pts])
    y = np.array([p.signal_dn for p in pts])
    v = np.array([p.signal_variance_dn2 for p in pts])
    dark_mu = np.array([p.dark_mean_dn for p in pts])
    dark_var = np.array([p.dark_variance_dn2 for p in pts])
    warnings: list[str] = []

    i_sat, reached = saturation_index([p.variance_dn2 for p in pts])
    if reached:
        top = saturation_vertex(y, v, i_sat)
        y_sat: float | None = top
    else:
        y_sat = None
        top = float(np.max(y))
        warnings.append(f"the sweep never reached saturation (temporal variance still rising at "
                        f"the last step, {top:.4g} DN above dark): no saturation value")
    if top <= 0:
        raise ValueError("no step has signal above the dark level")

    k_idx = np.flatnonzero((y > 0) & (y <= K_FIT_MAX_FRACTION * top)
                           & (np.arange(y.size) <= i_sat))
    if k_idx.size < 2:
        k_idx = np.flatnonzero((y > 0) & (np.arange(y.size) <= i_sat))
        warnings.append("fewer than 2 steps below 70 % of saturation: K fitted on every step "
                        "below saturation")
    k, k_se = _fit_through_origin(y[k_idx], v[k_idx])
    if not k > 0:
        raise ValueError(f"photon transfer slope K = {k:.4g} DN/e- is not positive")

    # Temporal dark noise: intercept at zero exposure (dark current shot noise removed).
    if np.unique(t).size > 2:
        _, s2_dark, _ = _fit_line(t, dark_var)
    else:
        s2_dark = float(np.mean(dark_var))
    resolved = s2_dark >= MIN_DARK_NOISE_DN**2
    unresolved: dict[str, str] = {}
    zero = max([p.dark_zero_fraction for p in pts]
               + [spatial.dark_zero_fraction if spatial is not None else 0.0])
    if zero > MAX_CLIPPED_FRACTION:
        warnings.append(f"black level clipped: {100 * zero:.3g} % of the dark pixels read 0 "
                        f"(EMVA 1288: at most {100 * MAX_CLIPPED_FRACTION:g} %): read noise, "
                        "dark current and DSNU are biased low and not given; raise the black "
                        "level/offset")
        unresolved.update(dict.fromkeys(("read_noise", "dark_current", "dsnu"),
                                        "black level clipped"))
    if s2_dark < DARK_VAR_FLOOR_DN2:
        warnings.append(f"temporal dark variance {max(s2_dark, 0.0):.3g} DN^2 is below the "
                        f"quantisation limit ({DARK_VAR_FLOOR_DN2} DN^2): read noise, DSNU and "
                        "dark current are not given (raise the gain or use more bits)")
    elif not resolved:
        warnings.append(f"temporal dark noise {math.sqrt(s2_dark):.3g} DN is below "
                        f"{MIN_DARK_NOISE_DN:g} DN (EMVA set-up rule): read noise, DSNU and dark "
                        "current are biased by quantisation and not given")
    if not resolved:
        for quantity in ("read_noise", "dsnu", "dark_current"):
            unresolved.setdefault(quantity, "dark noise < 1 DN")
    s2_dark = max(s2_dark, DARK_VAR_FLOOR_DN2)
    read_dn = math.sqrt(s2_dark)
    read_e = math.sqrt(s2_dark - QUANTISATION_VAR_DN2) / k

    dc_slope, black, dc_se = _fit_line(t, dark_mu)
    dark_current: float | None = dc_slope * 1e3 / k
    dark_current_se: float | None = dc_se * 1e3 / k
    if np.unique(t).size < 2:
        dark_current = dark_current_se = None
        unresolved.pop("dark_current", None)  # not measured at all, not "unresolved"
        warnings.append("one exposure time only (irradiance sweep): no dark current, and the "
                        "read noise includes the dark current's shot noise at that exposure")
    elif dc_slope * float(t.max() - t.min()) < MIN_DARK_SPAN_DN:
        warnings.append(f"the dark signal rises {dc_slope * float(t.max() - t.min()):.3g} DN "
                        f"over the sweep (under {MIN_DARK_SPAN_DN:g} DN): dark current not "
                        "resolved and not given (longer exposures or a higher gain)")
        unresolved.setdefault("dark_current", "dark signal < 1 DN over the sweep")
    if spatial is not None and spatial.bright_top_fraction > MAX_CLIPPED_FRACTION:
        warnings.append(f"PRNU stack saturated: {100 * spatial.bright_top_fraction:.3g} % of "
                        f"its pixels at the top code (at most {100 * MAX_CLIPPED_FRACTION:g} %): "
                        "no PRNU (lower the stack exposure or the light)")
        unresolved["prnu"] = "stack saturated"

    lo, hi = LINEARITY_RANGE
    lin_idx = np.flatnonzero((y >= lo * top) & (y <= hi * top) & (np.arange(y.size) <= i_sat))
    if lin_idx.size < 2:
        lin_idx = np.flatnonzero((y > 0) & (np.arange(y.size) <= i_sat))
        warnings.append("fewer than 2 steps between 5 % and 95 % of saturation: linearity "
                        "over every step with signal")
    a, b, dev = linearity_deviation(h, y, lin_idx)
    le = (float(np.min(dev[lin_idx])), float(np.max(dev[lin_idx])))

    return PhotonTransferResult(
        system_gain_dn_per_e=k,
        system_gain_uncertainty_dn_per_e=k_se,
        read_noise_dn=read_dn,
        read_noise_e=read_e,
        read_noise_resolved="read_noise" not in unresolved,
        saturation_dn=y_sat,
        saturation_e=(y_sat / k) if y_sat is not None else None,
        saturation_reached=reached,
        linearity_error_pct=le,
        dark_current_e_per_s=dark_current,
        dark_current_uncertainty_e_per_s=dark_current_se,
        black_level_dn=black,
        linear_slope_dn_per_unit=a,
        linear_offset_dn=b,
        k_fit_indices=tuple(int(i) for i in k_idx),
        linearity_indices=tuple(int(i) for i in lin_idx),
        deviation_pct=tuple(float(d) for d in dev),
        saturation_index=i_sat if reached else None,
        warnings=tuple(warnings),
        spatial=spatial,
        dark_zero_fraction=zero,
        unresolved=tuple(sorted(unresolved.items())),
    )


def defect_mask(dark_mean: FloatArray, bright_mean: FloatArray, temporal_sd_dn: float
                ) -> npt.NDArray[np.bool_]:
    """Pixels far (``DEFECT_SIGMAS`` robust sigmas, at least 2 DN and 5 temporal sd of the mean)
    outside the dark or the dark-subtracted bright fixed pattern: hot, dead or stuck pixels."""
    bad = np.zeros(dark_mean.shape, dtype=bool)
    for img in (dark_mean, bright_mean - dark_mean):
        dev = np.abs(img - np.median(img))
        bad |= dev > max(DEFECT_SIGMAS * robust_sigma(img), 2.0, 5.0 * temporal_sd_dn)
    return bad


def spatial_nonuniformity(
    bright_stack: npt.ArrayLike, dark_stack: npt.ArrayLike, top_code_dn: float | None = None,
) -> tuple[SpatialResult, npt.NDArray[np.bool_]]:
    """DSNU (DN) and PRNU (%) from L bright and L dark frames of one exposure.

    Parameters
    ----------
    bright_stack, dark_stack : array_like, shape (L, rows, cols)
        Native DN (see :func:`native_codes`); L >= 2.
    top_code_dn : float, optional
        The bit depth's top code: the fraction of bright pixels at it is counted
        (``bright_top_fraction``; :func:`photon_transfer` flags the PRNU of a saturated stack).

    Returns
    -------
    SpatialResult, defect mask
        The mask (True = defect) is excluded from ``dsnu_dn``, ``prnu_pct`` and should be from
        the temporal statistics too.
    """
    bright = np.asarray(bright_stack, dtype=np.float64)
    dark = np.asarray(dark_stack, dtype=np.float64)
    if bright.ndim != 3 or dark.shape != bright.shape or bright.shape[0] < 2:
        raise ValueError(f"stacks must be (L >= 2, rows, cols) of one shape; got {bright.shape} "
                         f"and {dark.shape}")
    n = bright.shape[0]
    mb, md = bright.mean(axis=0), dark.mean(axis=0)
    vb_stack = float(bright.var(axis=0, ddof=1).mean())
    vd_stack = float(dark.var(axis=0, ddof=1).mean())
    bad = defect_mask(md, mb, math.sqrt(max(vd_stack, vb_stack) / n))
    good = ~bad

    def spatial_var(mean_img: FloatArray, stack_var: float, mask: npt.NDArray[np.bool_]) -> float:
        return float(np.var(mean_img[mask], ddof=1)) - stack_var / n

    s2_dark = spatial_var(md, vd_stack, good)
    s2_dark_all = spatial_var(md, vd_stack, np.ones_like(good))
    s2_bright = spatial_var(mb, vb_stack, good)
    signal = float(mb[good].mean() - md[good].mean())
    if not signal > 0:
        raise ValueError("the bright stack is not brighter than the dark stack")
    prnu = 100.0 * math.sqrt(max(s2_bright - s2_dark, 0.0)) / signal
    return SpatialResult(
        dsnu_dn=math.sqrt(max(s2_dark, 0.0)), dsnu_all_pixels_dn=math.sqrt(max(s2_dark_all, 0.0)),
        prnu_pct=prnu, defect_pixels=int(bad.sum()), stack_frames=n, bright_signal_dn=signal,
        dark_zero_fraction=fraction_at_code(dark, 0.0, good),
        bright_top_fraction=(fraction_at_code(bright, top_code_dn, good)
                             if top_code_dn is not None else 0.0),
    ), bad


# ------------------------------------------------------------------------------ linearisation


@dataclass(frozen=True)
class ResponseCurve:
    """Measured response of one gain and bit depth: dark-subtracted codes -> linear codes.

    ``measured_dn`` is increasing; ``linear_dn`` is what a perfectly linear camera (the line
    fitted in the low, linear part of the sweep) would read at the same exposure.
    """

    gain: float
    bits: int
    black_level_dn: float
    measured_dn: tuple[float, ...]
    linear_dn: tuple[float, ...]

    def __post_init__(self) -> None:
        m = np.asarray(self.measured_dn)
        if m.size < 2 or m.size != len(self.linear_dn) or np.any(np.diff(m) <= 0):
            raise ValueError("a response curve needs >= 2 points with increasing measured_dn")


def response_curve(
    points: Sequence[SweepPoint], result: PhotonTransferResult, *, gain: float, bits: int,
    reference_range: tuple[float, float] = (0.05, 0.4),
) -> ResponseCurve:
    """The calibration curve of one sweep: the linear reference is a line through the origin
    fitted to the steps between ``reference_range`` fractions of saturation (or of the highest
    signal when saturation was not reached); steps above saturation are dropped.

    Raises
    ------
    ValueError
        Fewer than 2 steps in the reference range.
    """
    pts = sorted(points, key=lambda p: p.exposure_quantity)
    h = np.array([p.exposure_quantity for p in pts])
    y = np.array([p.signal_dn for p in pts])
    last = result.saturation_index if result.saturation_index is not None else y.size - 1
    top = float(y[last])
    ref = np.flatnonzero((y >= reference_range[0] * top) & (y <= reference_range[1] * top))
    if ref.size < 2:
        raise ValueError(f"response curve: {ref.size} step(s) between {reference_range[0]:.0%} "
                         f"and {reference_range[1]:.0%} of saturation; need 2")
    slope, _ = _fit_through_origin(h[ref], y[ref])
    keep = [i for i in range(last + 1) if y[i] > 0]
    # Keep a strictly increasing curve (noise can make two dark-level steps swap).
    measured: list[float] = [0.0]
    linear: list[float] = [0.0]
    for i in keep:
        if y[i] > measured[-1]:
            measured.append(float(y[i]))
            linear.append(float(slope * h[i]))
    return ResponseCurve(gain=gain, bits=bits, black_level_dn=result.black_level_dn,
                         measured_dn=tuple(measured), linear_dn=tuple(linear))


def linearise(pixels: npt.ArrayLike, curve: ResponseCurve) -> FloatArray:
    """Frame codes corrected to the linear response: ``black + linear(codes - black)``.

    Between curve points the correction is interpolated; above the last point (the highest
    unsaturated step) the last point's ratio is applied.
    """
    arr = np.asarray(pixels, dtype=np.float64)
    m = np.asarray(curve.measured_dn)
    lin = np.asarray(curve.linear_dn)
    signal = arr - curve.black_level_dn
    out = np.interp(signal, m, lin)
    above = signal > m[-1]
    if np.any(above):
        out[above] = signal[above] * (lin[-1] / m[-1])
    below = signal < 0
    out[below] = signal[below]
    return np.asarray(out + curve.black_level_dn, dtype=np.float64)
