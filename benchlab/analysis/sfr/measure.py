"""Slanted-edge spatial frequency response (ISO 12233 e-SFR): the sine-wave MTF from one edge.

Steps (ISO 12233 / sfrmat in outline; the implementation is benchlab's own):

1. Work frame: the ROI as given when the intensity varies along the columns (a near-vertical
   edge), else transposed, so the edge crosses every row of the work frame.
2. Edge location: per row, the centroid of the 2-tap derivative under a window centred on the
   edge; a line (or a low-order polynomial) is fitted to the centroids against the row. Three
   passes: a wide window around the mean profile's edge, then a window of a few ESF widths
   around the fitted edge; centroids more than 4 robust standard deviations off the fit are
   dropped.
3. ESF: every pixel is projected onto the edge normal with the shared projection
   (:mod:`~benchlab.analysis.bars.projection`, the one the oblique bar estimators use) and
   averaged in
   1/4-px bins (4x oversampling), each bin's mean placed at the mean position of its pixels.
   A curved fit shifts each row by its bend before binning. Angles near 45 deg or atan(1/2)
   put the pixel centres on a lattice coarser than the bins: empty bins are skipped (the
   samples keep their true spacing) and a warning is given.
4. LSF: the difference of neighbouring ESF samples at their midpoints, multiplied by a Tukey
   window centred on the LSF near the fitted edge, whose flat top covers the LSF core (1.2
   10-90 % rise distances + 1.5 px, and at least the LSF's support as the data show it: where
   the ESF still departs from its plateaus beyond the noise, e.g. a halo) so the window barely
   touches the signal while it cuts the plateaus' noise. Above ~1.25 x MTF50 narrower windows
   on the core take over, in two steps (a frequency-dependent window: the smooth tails shape
   only the low frequencies).
5. MTF: ``|DFT|`` at the midpoints (a regular grid when the phases are dense; the lattice's
   own spacing otherwise), normalised at zero frequency, with the noise power (known from
   the pixel noise) subtracted from ``|DFT|^2`` so noise does not read as MTF where the
   true MTF is ~0 (where even that is within the noise, averaged over +-0.1 cycles/px:
   :data:`NOISE_BAND_CYCLES_PER_PX`), and divided by the transfer function of the
   difference (``sinc(f h)`` for gap ``h``) and of the in-bin averaging (``sinc(f b)``,
   ``b`` from the spread of the pixel positions in the bins, 1/4 px when dense); the
   correction is capped at 10, as ISO 12233 caps its derivative correction. Frequencies are
   cycles per pixel *along the edge normal*, so no cos(angle) rescaling is needed.
6. MTF50 (the first crossing of 0.5, refined by a local quadratic fit), MTF at chosen
   frequencies and at Nyquist (0.5 cycles/px). Uncertainty: the pixel noise (per level,
   from row differences on the plateaus, at least the codes' rounding: both reported in
   :class:`SfrResult`) propagated to first order through the MTF, with
   a scale and floor calibrated for ~95 % coverage of +-1.96 sigma (the benchmark prints
   it); a bootstrap over rows on request.

Refused (:class:`SfrRefused`, every reason listed): noise only / no edge, fewer than
:data:`MIN_EDGE_ROWS` rows, an edge within :data:`MIN_ANGLE_DEG` of a pixel axis or too short
for its angle to span one phase cycle, more than :data:`CLIP_REFUSE_FRACTION` of the pixels
clipped; an ROI holding a bar or a line, bars, a corner or a second step of the same sign is
refused as such, in place of the reasons its structure caused
(:mod:`benchlab.analysis.sfr.structure`), and a bent edge read with a straight fit as bent
(:mod:`benchlab.analysis.sfr.robust`). Warned (in :attr:`SfrResult.warnings`): low contrast,
short edge, near-axis angle, uneven sample phases, a truncated ESF, any clipping, a poor edge
fit, pixels more than :data:`OUTLIER_SIGMAS` noise sigmas off the ESF (clipped to that limit
before the MTF; more than :data:`OUTLIER_REFUSE_FRACTION` of them, with no second edge and no
bend, and an edge fit within :data:`FIT_RMS_WARN_PX`, are taken for compression or sensor
structure).

Code layout: :func:`measure_sfr` reads as the pipeline, one named function per step
(:func:`_prepare_roi`, :func:`_find_edge`, :func:`_read_esf`, :func:`_correct_shading`,
:func:`_clip_outliers_and_check`, :func:`_refuse_second_edge`, :func:`_choose_estimator`,
:func:`_read_mtf50`, :func:`_warnings`, :func:`_result`), handing small frozen dataclasses
(:class:`_Roi`, :class:`_Edge`, :class:`_Esf`) from one to the next; the numerics they call
follow. The refusals once the ESF is read (:mod:`benchlab.analysis.sfr.refusals`), the LSF
model, shading, structure refusals and multi-frame averaging live in their own modules.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars.projection import across_coordinate, bin_profile, bin_profiles
from benchlab.analysis.bars.result import NYQUIST_CYCLES_PER_PX
from benchlab.analysis.bars.roi import detect_code_step, infer_max_code
from benchlab.analysis.noise import MAD_TO_SIGMA
from benchlab.analysis.sfr.refusals import (
    FIT_RMS_WARN_PX,
    OUTLIER_REFUSE_FRACTION,
    OUTLIER_SIGMAS,
    SfrRefused,
    quality_gate,
    stray_pixels,
    structure_refusal,
)
from benchlab.analysis.sfr.shading import (
    PLATEAU_MARGIN_PX,
    SHADING_PASSES,
    Shading,
    fit_shading,
    flatten,
)
from benchlab.analysis.sfr.structure import (
    ESF_SPAN_OF_STEP,
    find_second_edge,
    find_two_edges,
)

#: ESF bin width, px: ISO 12233's 4x oversampling.
BIN_WIDTH_PX = 0.25
#: Edges closer than this to a pixel axis are refused (too few sample phases per row shift).
MIN_ANGLE_DEG = 1.5
#: ... and warned about below this angle.
WARN_ANGLE_DEG = 2.0
#: Fewer rows along the edge than this are refused; fewer than WARN_EDGE_ROWS are warned about
#: (MTF Mapper marks edges under ~25 px and recommends >= 35 px).
MIN_EDGE_ROWS = 10
WARN_EDGE_ROWS = 35
#: Centroid passes after the first, wide one: each narrows the window to a few ESF widths
#: around the last fit. A third lets a long, steep edge (500 rows at 28 deg drift 260 px
#: across the ROI) recover from a first fit that the wide window's noise bent by several px.
EDGE_PASSES = 2
#: Bins with fewer pixels than this fraction of the median bin are left out of the rise the
#: edge-fit window is set from (and of the ESF: :func:`_esf_samples`).
SPARSE_BIN_FRACTION = 0.2
#: Eq. 2.9 contrast between the ESF plateaus below which a warning is given (sfrmat: 20 %).
LOW_CONTRAST = 0.2
#: "No edge" (noise only): the ROI's 2-98 % gray-level spread must exceed this many noise
#: sigmas (an edge at SNR 10 spreads ~13 sigma, pure noise ~4) ...
NOISE_SPREAD_RATIO = 8.0
#: ... and the ESF step this many standard errors of a plateau mean (noise / sqrt(rows)).
MIN_STEP_NOISE_RATIO = 6.0
#: Clipped pixels: any is warned about; above this fraction the edge is refused (sfrmat flags
#: more than 0.5 %: clipping steepens the ESF and lifts the MTF).
CLIP_REFUSE_FRACTION = 0.005
#: Empty ESF bins in the LSF core (a coarse pixel lattice) above this fraction: a warning.
EMPTY_BIN_WARN_FRACTION = 0.05
#: Derivative-filter correction cap (ISO 12233 / sfrmat limit the correction to 10).
MAX_DERIVATIVE_CORRECTION = 10.0
#: Reported frequency range, cycles/px (twice Nyquist, as sfrmat reports with 4x bins).
MAX_FREQ_CYCLES_PER_PX = 1.0
#: Wide LSF window: flat over +-(FLAT_RISES x the 10-90 % rise + FLAT_EXTRA_PX, at least
#: FLAT_MIN_PX), cosine taper to
#: TAPER_FACTOR times that. A Gaussian LSF (rise 2.56 sigma) has > 99.7 % of its area under the
#: flat top (+-3.1 sigma + 1.5 px); a wider window only adds plateau noise (tuned on the
#: benchmark: the MTF noise near Nyquist grows as the square root of the window width).
FLAT_RISES = 1.2
FLAT_EXTRA_PX = 1.5
FLAT_MIN_PX = 2.0
#: The taper ends at this multiple of the flat half-width.
TAPER_FACTOR = 1.5
#: Frequency-dependent LSF window. Up to WIDE_UP_TO_RISES / rise (cycles/px, ~1.25 x MTF50
#: for a Gaussian LSF; at most WIDE_UP_TO_MAX_CYCLES_PER_PX) the wide window above; then,
#: blended in up to twice that frequency, a narrow one on the LSF core: flat over
#: +-(NARROW_RISES x rise + NARROW_EXTRA_PX), at least NARROW_MIN_PX, tapered to NARROW_TAPER
#: times that; from CORE_FROM_F_WIDE x that frequency (blended over 1.5x) a still narrower
#: one (CORE_*). The LSF's smooth tails shape only the low frequencies; at high frequencies
#: a wide window adds plateau noise (sigma ~ sqrt(width)) and nothing else. Each step was
#: kept only if the +-1.96 sigma coverage on the benchmark stayed ~95 % (no truncation bias).
WIDE_UP_TO_RISES = 0.6
WIDE_UP_TO_MAX_CYCLES_PER_PX = 0.15
NARROW_RISES = 0.9
NARROW_EXTRA_PX = 0.5
NARROW_MIN_PX = 1.5
NARROW_TAPER = 1.3
CORE_FROM_F_WIDE = 2.5
CORE_RISES = 0.6
CORE_EXTRA_PX = 0.5
CORE_TAPER = 1.8
#: The propagated 1-sigma is scaled by this and a systematic floor (the method's own error
#: on noise-free edges, up to ~0.005 at the lattice angles) added in quadrature, so that the
#: +-1.96 sigma interval covers the truth in ~95 % of synthetic cases (``benchlab benchmark
#: sfr`` prints the coverage): the first-order propagation leaves out the data-dependent
#: choices (edge fit, window width and centre), worth ~15 % more scatter at SNR 20-100.
SIGMA_SCALE = 1.2
OUTLIER_FLOOR_OF_STEP = 0.01
SIGMA_FLOOR = 0.002
#: The LSF model's propagated 1-sigma (from the fit's covariance) is scaled by this (the edge
#: fit and the bin positions it leaves out); coverage per bucket in ``benchlab benchmark sfr``.
MODEL_SIGMA_SCALE = 1.0
#: The uncertainty is computed every this many frequency steps (0.02 cycles/px), then
#: interpolated.
SIGMA_GRID_STEP = 4
#: Noise-band pooling (stated prior: where the MTF is lost in the noise, its power varies
#: little over +-NOISE_BAND_CYCLES_PER_PX). The debiased power ``|X|^2 - P`` is replaced by
#: its average over that band where the average is below NOISE_BAND_LO x the noise power P,
#: blended back to the unpooled value by NOISE_BAND_HI x P; where the signal stands clear of
#: the noise nothing changes (so noise-free edges are untouched). A single frequency's
#: debiased power at a true MTF of 0 is ``P (E - 1)``, E exponential: its upper tail reads as
#: MTF ~1.9 sqrt(P) once in 100; the average over the ~3 independent cells in the band has
#: a far shorter tail (on the benchmark: sigma 2-3 px at SNR 50, 100 rows, 50-68 % -> 85 %
#: of the cases within 0.02). 0 disables it.
NOISE_BAND_CYCLES_PER_PX = 0.1
NOISE_BAND_LO = 1.0
NOISE_BAND_HI = 3.0
#: Data-driven support of the LSF (:func:`_esf_support_half`): the wide window's flat top
#: reaches at least as far as the ESF departs from its plateaus by SUPPORT_SIGMAS of the
#: noise of its SUPPORT_SPAN_PX average and SUPPORT_FLOOR_OF_STEP of the step; each plateau
#: a line through the outer SUPPORT_PLATEAU_FRACTION of the fully populated samples on its
#: side. A halo or flare around a sharp core (10 % of the light in a 4 px Gaussian) is wider
#: than the 10-90 % rise says: cut at the rise-based width it lifts the MTF by 0.04 at
#: 0.07 c/px; 0 disables it.
SUPPORT_SPAN_PX = 1.0
SUPPORT_SIGMAS = 3.0
SUPPORT_PLATEAU_FRACTION = 0.4
SUPPORT_FLOOR_OF_STEP = 0.005


@dataclass(frozen=True)
class LsfWindow:
    """One of the frequency-dependent LSF windows (Tukey, centred on the LSF near the edge).

    Attributes
    ----------
    flat_half_px, total_half_px : float
        Half-width of the flat top and of the whole window (taper included), px along the
        normal.
    from_cycles_per_px, full_from_cycles_per_px : float
        It is blended in from the first frequency and alone from the second (0, 0 for the
        widest, used from zero frequency); a narrower one takes over above.
    """

    flat_half_px: float
    total_half_px: float
    from_cycles_per_px: float
    full_from_cycles_per_px: float


@dataclass(frozen=True)
class EdgeFit:
    """The fitted edge, in the work frame (edge crossing the rows).

    Attributes
    ----------
    transposed : bool
        True when the ROI was transposed (a near-horizontal edge, intensity varying along rows).
    coeffs : ndarray
        Polynomial (highest power first, ``np.polyval`` order) of the edge column against the
        row, in work-frame pixel coordinates.
    slope : float
        d(column)/d(row) of the edge at the middle row: tan of the angle from the pixel axis.
    rms_px : float
        RMS residual of the per-row centroids about the fit (px).
    rows_used : int
        Rows whose centroid entered the final fit.
    """

    transposed: bool
    coeffs: FloatArray
    slope: float
    rms_px: float
    rows_used: int


@dataclass(frozen=True)
class SfrResult:
    """Slanted-edge SFR of one ROI.

    Attributes
    ----------
    freqs_cycles_per_px : ndarray
        Frequency grid, cycles/px along the edge normal, 0 to 1.
    mtf : ndarray
        MTF on that grid (1 at 0).
    mtf_sigma : ndarray or None
        1-sigma per frequency (0 at 0; None only if the spectrum is empty).
    uncertainty_method : str
        ``"analytic"`` (the pixel noise propagated through the MTF, see
        :func:`_mtf_from_samples`) or ``"bootstrap"`` (resampled rows, on request).
    mtf50_cycles_per_px, mtf50_sigma : float or None
        First frequency where the MTF falls to 0.5 (None if it never does below 1 cycle/px),
        and its 1-sigma.
    mtf_nyquist : float
        MTF at 0.5 cycles/px.
    edge_angle_deg : float
        Angle between the edge and the nearest pixel axis (0-45, deg).
    normal_theta_rad : float
        Direction of the edge normal (dark to bright) in the projection convention of
        :func:`benchlab.analysis.bars.projection.across_coordinate` (from the column axis towards
        the row axis), in the ROI's own frame.
    direction : str
        Direction the intensity varies: ``"horizontal"`` (a near-vertical edge; sagittal in the
        forward view) or ``"vertical"`` (tangential).
    dark, bright : float
        Plateau levels of the ESF (ROI units).
    contrast : float
        Eq. 2.9 contrast ``(bright - dark) / (bright + dark)`` of the plateaus.
    noise_sigma : float
        Pixel noise (robust, from differences along the edge over the whole ROI: the "no edge"
        test).
    noise_dark_sigma, noise_bright_sigma : float
        The pixel noise per level the analysis used (the analytic uncertainty, the noise power
        subtracted, the outlier limit): measured on each plateau, at least the codes' rounding.
    noise_dark_measured, noise_bright_measured : float
        The same as measured (row differences on the plateau), before that floor.
    noise_rounding_sigma : float
        The codes' rounding, ``code step / sqrt(12)`` (0.2887 for plain integer codes, 0 for
        float data).
    noise_rounding_floor : tuple of str
        The sides (``"dark"``, ``"bright"``) whose measured noise was below the rounding, which
        was used instead.
    clipped_fraction : float
        Fraction of pixels at 0 or at full scale.
    edge_rows : int
        Length of the edge in pixels along it (rows of the work frame).
    fit : EdgeFit
    esf_u_px, esf, lsf : ndarray
        The oversampled ESF (bin centres along the normal, px from the edge) and the windowed
        LSF used.
    warnings : tuple of str
    lsf_windows : tuple of LsfWindow
        The LSF windows chosen from the data (their widths from the measured 10-90 % rise),
        widest first, each with the frequencies where it takes over.
    estimator : str
        ``"model-free"`` (the windowed LSF's DFT) or ``"LSF model"`` (K pixel-integrated
        Gaussians fitted to the ESF, :mod:`benchlab.analysis.sfr.model`).
    estimator_reason : str
        Why that one (the method asked for, and for ``auto`` the model-free reading's own
        accuracy; the model's gates).
    lsf_model : dict or None
        The LSF model fitted (components, chi-square, gates), used or not; None when none was
        tried.
    """

    freqs_cycles_per_px: FloatArray
    mtf: FloatArray
    mtf_sigma: FloatArray | None
    uncertainty_method: str
    mtf50_cycles_per_px: float | None
    mtf50_sigma: float | None
    mtf_nyquist: float
    edge_angle_deg: float
    normal_theta_rad: float
    direction: str
    dark: float
    bright: float
    contrast: float
    noise_sigma: float
    noise_dark_sigma: float
    noise_bright_sigma: float
    noise_dark_measured: float
    noise_bright_measured: float
    noise_rounding_sigma: float
    noise_rounding_floor: tuple[str, ...]
    clipped_fraction: float
    edge_rows: int
    fit: EdgeFit
    esf_u_px: FloatArray
    esf: FloatArray
    lsf: FloatArray
    warnings: tuple[str, ...]
    lsf_windows: tuple[LsfWindow, ...] = ()
    estimator: str = "model-free"
    estimator_reason: str = ""
    lsf_model: dict[str, Any] | None = None

    def mtf_at(self, freqs_cycles_per_px: npt.ArrayLike) -> FloatArray:
        """MTF interpolated at the given frequencies (cycles/px, 0..1)."""
        f = np.asarray(freqs_cycles_per_px, dtype=np.float64)
        return np.asarray(np.interp(f, self.freqs_cycles_per_px, self.mtf), dtype=np.float64)

    def sigma_at(self, freqs_cycles_per_px: npt.ArrayLike) -> FloatArray | None:
        """1-sigma interpolated at the given frequencies (None if there is none)."""
        if self.mtf_sigma is None:
            return None
        f = np.asarray(freqs_cycles_per_px, dtype=np.float64)
        return np.asarray(np.interp(f, self.freqs_cycles_per_px, self.mtf_sigma))

    def to_dict(self, step_cycles_per_px: float = 0.01) -> dict[str, Any]:
        """JSON-ready summary with the curve resampled every ``step_cycles_per_px``."""
        grid = np.round(np.arange(0.0, MAX_FREQ_CYCLES_PER_PX + 1e-9, step_cycles_per_px), 6)
        sig = self.sigma_at(grid)
        return {
            "mtf50_cycles_per_px": self.mtf50_cycles_per_px,
            "mtf50_sigma": self.mtf50_sigma,
            "uncertainty_method": self.uncertainty_method,
            "estimator": self.estimator,
            "estimator_reason": self.estimator_reason,
            "lsf_model": self.lsf_model,
            "mtf_nyquist": self.mtf_nyquist,
            "edge_angle_deg": self.edge_angle_deg,
            "normal_theta_deg": math.degrees(self.normal_theta_rad),
            "direction": self.direction,
            "dark": self.dark,
            "bright": self.bright,
            "contrast": self.contrast,
            "noise_sigma": self.noise_sigma,
            "noise_dark_sigma": self.noise_dark_sigma,
            "noise_bright_sigma": self.noise_bright_sigma,
            "noise_dark_measured": self.noise_dark_measured,
            "noise_bright_measured": self.noise_bright_measured,
            "noise_rounding_sigma": self.noise_rounding_sigma,
            "noise_rounding_floor": list(self.noise_rounding_floor),
            "clipped_fraction": self.clipped_fraction,
            "edge_rows": self.edge_rows,
            "fit_rms_px": self.fit.rms_px,
            "warnings": list(self.warnings),
            "lsf_windows": [{"flat_half_px": round(w.flat_half_px, 4),
                             "total_half_px": round(w.total_half_px, 4),
                             "from_cycles_per_px": round(w.from_cycles_per_px, 4),
                             "full_from_cycles_per_px": round(w.full_from_cycles_per_px, 4)}
                            for w in self.lsf_windows],
            "freqs_cycles_per_px": grid.tolist(),
            "mtf": [round(float(v), 6) for v in self.mtf_at(grid)],
            "mtf_sigma": None if sig is None else [round(float(v), 6) for v in sig],
        }


def full_scale_of(pixels: npt.NDArray[Any]) -> float | None:
    """Full-scale code of integer image data by its dtype and code grid
    (:func:`benchlab.analysis.bars.roi.infer_max_code`: 255, 4095 for 12-bit data in uint16, 65520
    MSB-aligned, 65535); None for float data (no clipping check). Not the plateau test of the
    bar estimators (:func:`benchlab.analysis.bars.roi.saturation_code`): an edge's wide, nearly
    noise-free bright side is a plateau at its maximum without being clipped."""
    if pixels.dtype.kind not in "ui" or pixels.size == 0:
        return None
    return infer_max_code(pixels, detect_code_step(pixels.ravel()))


def full_scale_of_frame(frame: npt.NDArray[Any], metadata: Mapping[str, Any] | None
                        ) -> float | None:
    """Full-scale code of a whole frame from its camera's bit depth, the ``bits`` of its own
    metadata (:mod:`benchlab.storage`): ``2**bits - 1``, or, for codes MSB-aligned in 16-bit
    words (some code above that, every code a multiple of ``2**(16 - bits)``), the aligned top
    (65520 for 12 bits). None - the caller infers it from the data (:func:`full_scale_of`) -
    without ``bits`` (or one that is not an integer 1..16 the dtype holds), for float data, or
    when the codes rule that bit depth out. The whole frame, not an ROI: a dark ROI alone does
    not show the alignment."""
    bits = None if metadata is None else metadata.get("bits")
    if isinstance(bits, bool) or not isinstance(bits, int) or frame.dtype.kind not in "ui":
        return None
    if not 1 <= bits <= min(16, 8 * frame.dtype.itemsize):
        return None
    top = (1 << bits) - 1
    if frame.size == 0 or int(frame.max()) <= top:
        return float(top)
    shift = 16 - bits
    if frame.dtype == np.uint16 and shift > 0 and not np.any(
            np.bitwise_and(frame, np.uint16((1 << shift) - 1))):
        return float(top << shift)
    return None


def _code_step_of(top: float | None) -> float:
    """Code spacing of integer data with full scale ``top``: ``2**(16 - bits)`` for codes
    MSB-aligned in 16-bit words (65520: 16 for 12 bits, 65472: 64 for 10 bits), else 1."""
    if top is not None and 32768.0 <= top < 65535.0 and float(top).is_integer():
        gap = 65536 - int(top)
        if gap & (gap - 1) == 0:
            return float(gap)
    return 1.0


def _sinc(x: FloatArray) -> FloatArray:
    """``sin(pi x) / (pi x)`` (``np.sinc`` without its generic-input overhead)."""
    px = math.pi * np.where(x == 0.0, 1.0, x)
    return np.asarray(np.where(x == 0.0, 1.0, np.sin(px) / px), dtype=np.float64)


def _tukey(x: FloatArray, flat: float, total: float) -> FloatArray:
    """1 for ``|x| <= flat``, cosine taper to 0 at ``|x| = total``, 0 beyond."""
    ax = np.abs(x)
    if total <= flat:
        return np.where(ax > flat, 0.0, 1.0)
    # cos(0) = 1 and cos(pi) = -1 exactly: 1 on the flat top, 0 beyond the taper.
    t = (ax - flat) * (math.pi / (total - flat))
    np.maximum(t, 0.0, out=t)
    np.minimum(t, math.pi, out=t)
    return np.asarray(0.5 * (1.0 + np.cos(t)), dtype=np.float64)


def difference_noise_sigma(row_diff: FloatArray) -> float:
    """Robust (MAD) pixel noise from differences between neighbouring pixels along the edge."""
    if row_diff.size == 0:
        return 0.0
    d = row_diff.ravel()
    mad = float(np.median(np.abs(d - np.median(d))))
    return MAD_TO_SIGMA * mad / math.sqrt(2.0)


def _finite_median(a: npt.NDArray[Any]) -> float:
    """``float(np.median(a))`` of a non-empty array known to be finite (no NaN check): the
    same order statistics and the same mean of the middle two, without numpy's overhead (a
    few of these per edge on a few hundred values cost more than the arithmetic)."""
    flat = a.ravel()
    n = flat.size
    k = n // 2
    if n % 2:
        return float(np.partition(flat, k)[k])
    part = np.partition(flat, (k - 1, k))
    return (float(part[k - 1]) + float(part[k])) / 2.0


def _mean(a: npt.NDArray[Any]) -> float:
    """``float(np.mean(a))`` of a non-empty array (the same sum, the same division)."""
    return float(a.sum(dtype=np.float64)) / a.size


def _row_centroids(
    deriv: FloatArray, centres: FloatArray | float, half_width: float
) -> FloatArray:
    """Centroid per row of the derivative under a Hann window of ``half_width`` around
    ``centres`` (per row, or one for every row). Derivative samples sit at half-pixel
    positions ``j + 0.5``."""
    # Only the columns any row's window reaches (the weights are 0 elsewhere): after the
    # first pass the window spans a few ESF widths, not the ROI.
    per_row = isinstance(centres, np.ndarray)
    c_lo = float(np.min(centres)) if per_row else float(centres)
    c_hi = float(np.max(centres)) if per_row else float(centres)
    lo = max(0, math.floor(c_lo - half_width - 0.5))
    hi = min(deriv.shape[1], math.ceil(c_hi + half_width + 0.5))
    if hi <= lo:
        return np.full(deriv.shape[0], np.nan)
    deriv = deriv[:, lo:hi]
    x = np.arange(lo, hi, dtype=np.float64) + 0.5
    # One window for every row when they share the centre (the first, wide pass).
    dist = ((x[None, :] - np.asarray(centres)[:, None]) if per_row else (x - c_lo)[None, :]) \
        / half_width
    w = np.where(np.abs(dist) < 1.0, 0.5 * (1.0 + np.cos(math.pi * dist)), 0.0)
    wd = w * deriv
    total = wd.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = (wd * x[None, :]).sum(axis=1) / total
    c[~(total > 0)] = np.nan
    return np.asarray(c, dtype=np.float64)


def _polyval(coeffs: FloatArray, x: Any) -> Any:
    """``np.polyval`` (Horner, the same operations) without its generic-input overhead."""
    y = float(coeffs[0]) + 0.0 * x
    for c in coeffs[1:]:
        y = y * x + float(c)
    return y


def _polyfit(x: FloatArray, y: FloatArray, order: int) -> FloatArray:
    """``np.polyfit``; a straight line in closed form (the common case, 10x cheaper)."""
    if order != 1:
        return np.asarray(np.polyfit(x, y, order), dtype=np.float64)
    xm, ym = float(x.mean()), float(y.mean())
    dx = x - xm
    sxx = float(dx @ dx)
    slope = float(dx @ (y - ym)) / sxx if sxx > 0 else 0.0
    return np.array([slope, ym - slope * xm])


def _fit_edge(
    rows: FloatArray, cents: FloatArray, order: int
) -> tuple[FloatArray, FloatArray]:
    """Polynomial fit of the centroids against the row, dropping outliers (> 4 robust sigma);
    returns the coefficients and the mask of rows kept."""
    finite = np.isfinite(cents)
    keep = finite
    coeffs = np.zeros(order + 1)
    fitted = False  # whether coeffs were fitted to the rows in keep
    for _ in range(3):
        if int(keep.sum()) <= order + 1:
            break
        coeffs, fitted = _polyfit(rows[keep], cents[keep], order), True
        res = np.abs(cents - _polyval(coeffs, rows))
        limit = max(4.0 * MAD_TO_SIGMA * _finite_median(res[keep]), 0.25)
        new_keep = finite & (res <= limit)
        if np.array_equal(new_keep, keep):
            break
        keep, fitted = new_keep, False
    if not fitted and int(keep.sum()) > order + 1:
        coeffs = _polyfit(rows[keep], cents[keep], order)
    return coeffs, keep


def _rise_10_90(u: FloatArray, esf: FloatArray) -> float:
    """10-90 % rise distance (px) of a rising ESF (plateaus from its outer fifths)."""
    n = esf.size
    k = max(1, n // 5)
    lo, hi = _mean(esf[:k]), _mean(esf[-k:])
    if hi <= lo:
        return float("nan")
    frac = (esf - lo) / (hi - lo)
    # The first crossings from each side, so noise in the plateaus does not matter much.
    i10 = int(np.argmax(frac >= 0.1))
    i90 = n - 1 - int(np.argmax(frac[::-1] <= 0.9))
    # Interpolated between the samples either side of each crossing: where the pixel
    # lattice is coarse (0.71 px at 45 deg) the samples alone misread the rise by up to 2x.
    u10 = float(u[i10])
    if i10 > 0 and frac[i10] > frac[i10 - 1]:
        u10 -= (frac[i10] - 0.1) / (frac[i10] - frac[i10 - 1]) * float(u[i10] - u[i10 - 1])
    i90 = min(i90, n - 1)
    u90 = float(u[i90])
    if i90 < n - 1 and frac[i90 + 1] > frac[i90]:
        u90 += (0.9 - frac[i90]) / (frac[i90 + 1] - frac[i90]) * float(u[i90 + 1] - u[i90])
    return max(u90 - u10, 0.0)


@dataclass(frozen=True)
class _Samples:
    """The binned ESF as samples at their own mean positions (not the bin centres)."""

    u: FloatArray  # mean position of the pixels in each filled bin, px from the edge
    esf: FloatArray  # mean value in each filled bin
    spread_var: FloatArray  # variance of the pixel positions within each bin, px^2
    count: FloatArray  # pixels in each bin
    empty_core_fraction: float  # empty bins within the core (coarse pixel lattice)


def _esf_samples(
    u: FloatArray, values: FloatArray, bin_width: float, core_half_px: float
) -> _Samples:
    """Bin the projected pixels; keep the well-populated stretch around the edge.

    Each bin's value is placed at the mean position of its pixels: at angles where the pixel
    centres fall on a lattice a little coarser or finer than the bins (atan 1/4, atan 1/3,
    ...) the bin centre would misplace the samples by up to half a bin. Empty bins are not
    filled in: the samples keep their true spacing (the DFT below takes any spacing).
    """
    prof, pos_p, sq_p = bin_profiles(u, [values, u, u * u], bin_width)
    pos, sq = pos_p.mean, sq_p.mean
    counts = prof.count
    filled = counts > 0
    typical = _finite_median(counts[filled])
    good = counts >= max(1.0, SPARSE_BIN_FRACTION * typical)
    idx = np.flatnonzero(good)
    centre = int(np.argmin(np.abs(prof.u_px)))
    left, right = idx[idx <= centre], idx[idx >= centre]
    lo = int(left[-1]) if left.size else int(idx[0])
    hi = int(right[0]) if right.size else int(idx[-1])
    # Walk outwards while the gaps between well-populated bins stay short (sparse ROI corners
    # are dropped; a coarse lattice leaves regular gaps of up to 3 bins).
    if left.size:
        run = np.concatenate(([lo], left[::-1]))
        gap = np.flatnonzero(-np.diff(run) > 4)
        lo = int(run[gap[0]] if gap.size else run[-1])
    if right.size:
        run = np.concatenate(([hi], right))
        gap = np.flatnonzero(np.diff(run) > 4)
        hi = int(run[gap[0]] if gap.size else run[-1])
    sl = slice(lo, hi + 1)
    keep = good[sl]
    centres = prof.u_px[sl]
    core = np.abs(centres) <= core_half_px
    n_core = int(np.count_nonzero(core))
    empty = (n_core - int(np.count_nonzero(filled[sl][core]))) / n_core if n_core else 0.0
    p, e = pos[sl][keep], prof.mean[sl][keep]
    var = np.clip(sq[sl][keep] - p * p, 0.0, None)
    return _Samples(np.asarray(p, np.float64), np.asarray(e, np.float64),
                    np.asarray(var, np.float64), counts[sl][keep].astype(np.float64), empty)


#: Frequency grid of the MTF, cycles/px along the normal.
FREQ_STEP_CYCLES_PER_PX = 0.005
FREQS_CYCLES_PER_PX = np.round(
    np.arange(0.0, MAX_FREQ_CYCLES_PER_PX + 1e-9, FREQ_STEP_CYCLES_PER_PX), 6
)
#: Index of Nyquist on that grid.
_NYQUIST_INDEX = int(np.flatnonzero(FREQS_CYCLES_PER_PX <= NYQUIST_CYCLES_PER_PX + 1e-9)[-1])


@dataclass(frozen=True)
class _Spectrum:
    """The MTF of one set of ESF samples (see :func:`_mtf_from_samples`)."""

    mtf: FloatArray  # on FREQS_CYCLES_PER_PX, corrected
    lsf: FloatArray  # windowed LSF at the midpoints
    mid: FloatArray  # midpoints, px
    truncated: bool  # the window had to stop short of the LSF core
    sigma: FloatArray | None  # 1-sigma per frequency from the sample variances (if given)
    windows: tuple[LsfWindow, ...] = ()  # the LSF windows used, widest first


@dataclass(frozen=True)
class _NoiseModel:
    """Pixel noise variance linear in the level between the two plateaus (shot noise makes
    the bright side noisier)."""

    dark: float
    bright: float
    var_dark: float
    var_bright: float

    def pixel_var(self, level: FloatArray) -> FloatArray:
        """Noise variance of one pixel at each level."""
        span = self.bright - self.dark
        frac = np.clip((level - self.dark) / span, 0.0, 1.0) if span != 0 else 0.5
        return np.asarray(self.var_dark + (self.var_bright - self.var_dark) * frac,
                          dtype=np.float64)

    def sample_var(self, s: _Samples) -> FloatArray:
        """Variance of each ESF sample (a mean of ``count`` pixels)."""
        return np.asarray(self.pixel_var(s.esf) / s.count, dtype=np.float64)


def _clip_outliers(
    u: FloatArray, work: FloatArray, s: _Samples, noise: _NoiseModel,
    bin_width_px: float | None = None,
) -> tuple[FloatArray, int]:
    """The pixels with any more than :data:`OUTLIER_SIGMAS` noise sigmas off the ESF pulled
    back to that limit (a hot or dead pixel, dust: one such pixel in a bin of ~25 puts a
    spike in the ESF, a dipole in the LSF and a ripple over the whole MTF). Each pixel is
    compared with the ESF interpolated at its own position; the limit also allows for the
    interpolation's own error (a quarter of the local second difference) and 1 % of the
    step, so a sharp, noise-free edge is left alone. With ``bin_width_px``, once any pixel is
    found, they are all compared with the bins' medians instead: a hot pixel moves its own
    bin's mean, and against that mean its innocent neighbours read as outliers (20 hot pixels
    in a noise-free ROI clipped 79). Returns the pixels and how many were clipped."""
    found = _outliers(u, work, s, noise)
    if found is not None and bin_width_px is not None:
        found = _outliers(u, work, _median_samples(u, work, bin_width_px), noise)
    if found is None:
        return work, 0
    hit, pred_c, res_c, limit = found
    fixed = np.array(work, dtype=np.float64, order="C")  # a copy in u's (C) order
    fixed.reshape(-1)[hit] = pred_c + np.clip(res_c, -limit, limit)
    return fixed, int(hit.size)


def _median_samples(u: FloatArray, work: FloatArray, bin_width_px: float) -> _Samples:
    """The ESF as the median of each bin of at least 3 pixels, at the bin centre (an outlier
    does not move it)."""
    b = np.floor(u.ravel() / bin_width_px).astype(np.int64)
    v = np.asarray(work, dtype=np.float64).ravel()
    order = np.lexsort((v, b))
    bs, vs = b[order], v[order]
    starts = np.flatnonzero(np.concatenate(([True], bs[1:] != bs[:-1])))
    ends = np.concatenate((starts[1:], [bs.size]))
    count = ends - starts
    ok = count >= 3
    starts, count = starts[ok], count[ok]
    med = 0.5 * (vs[starts + (count - 1) // 2] + vs[starts + count // 2])
    centre = (bs[starts] + 0.5) * bin_width_px
    return _Samples(centre.astype(np.float64), med, np.zeros(med.size),
                    count.astype(np.float64), 0.0)


def _outliers(
    u: FloatArray, work: FloatArray, s: _Samples, noise: _NoiseModel
) -> tuple[npt.NDArray[np.intp], FloatArray, FloatArray, FloatArray] | None:
    """The flat indices of the pixels beyond the limit of :func:`_clip_outliers` against the
    ESF ``s``, their ESF values, residuals and limits; None when there is none."""
    pred = np.interp(u, s.u, s.esf)
    res = work - pred
    # Plus a floor of 1 % of the step: misregistration of a noise-free edge, and a deviation
    # that small moves a bin mean by < 0.1 % of the step.
    floor = OUTLIER_FLOOR_OF_STEP * abs(noise.bright - noise.dark)
    # The limit is at least this (the pixel variance lies between the plateaus', the
    # curvature term is >= 0): only the pixels beyond it need their own.
    least = OUTLIER_SIGMAS * math.sqrt(min(noise.var_dark, noise.var_bright)) + floor
    cand = np.flatnonzero(np.abs(res).ravel() > least)
    if cand.size == 0:
        return None
    curv = np.zeros_like(s.esf)
    if s.esf.size >= 3:
        curv[1:-1] = np.abs(np.diff(s.esf, 2))
    u_c, pred_c, res_c = u.ravel()[cand], pred.ravel()[cand], res.ravel()[cand]
    limit = (OUTLIER_SIGMAS * np.sqrt(noise.pixel_var(pred_c))
             + 0.25 * np.interp(u_c, s.u, curv) + floor)
    out = np.abs(res_c) > limit
    if not out.any():
        return None
    return cand[out], pred_c[out], res_c[out], limit[out]


def window_matrix(windows: Any, x: FloatArray, f: FloatArray) -> FloatArray:
    """The frequency-dependent LSF window (a sequence of :class:`LsfWindow`, widest first) at
    offsets ``x`` (px from its centre) for each frequency ``f``: shape (f, x)."""
    blends, shapes = window_terms(windows, x, f)
    return np.asarray(blends @ shapes, dtype=np.float64)


def window_terms(windows: Any, x: FloatArray, f: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`window_matrix` as a sum of products: ``win(f, x) = sum_j c_j(f) w_j(x)``.
    Returns ``c`` (f, J) and ``w`` (J, x), J the number of windows (each narrower one blends
    in over the last: the coefficients are products of the blends)."""
    coeffs = [np.ones(f.size)]
    shapes = [_tukey(x, windows[0].flat_half_px, windows[0].total_half_px)]
    for w in windows[1:]:
        blend = _tukey(f, w.from_cycles_per_px, w.full_from_cycles_per_px)
        coeffs = [c * blend for c in coeffs] + [1.0 - blend]
        shapes.append(_tukey(x, w.flat_half_px, w.total_half_px))
    return np.stack(coeffs, axis=1), np.stack(shapes)


#: The DFT's exponentials on a uniform frequency grid ``k df``, ``k = B a + b``, are products
#: ``exp(2 pi i B a df x) exp(2 pi i b df x)`` of two small tables (angle addition): ~29 rows
#: of sines and cosines instead of 201, and a sum over the samples becomes one small matrix
#: product. Rounding differs from direct evaluation by ~1e-14.
_DFT_BLOCK = 16
#: Samples per (coarse x fine) product: 13 x 16 x 256 multiply-adds stay single-threaded.
_BLAS_CHUNK = 256
_BLOCK_STEPS = np.arange(_DFT_BLOCK, dtype=np.float64)


def _expi(phase: FloatArray) -> npt.NDArray[np.complex128]:
    """``exp(i phase)`` from its cosine and sine (cheaper than the complex exponential)."""
    out = np.empty(phase.shape, dtype=np.complex128)
    out.real = np.cos(phase)
    out.imag = np.sin(phase)
    return out


@dataclass(frozen=True)
class _GridTables:
    """``exp(2 pi i k step x)`` for ``k = 0 .. count - 1`` as the coarse
    (``exp(2 pi i B a step x)``) and fine (``exp(2 pi i b step x)``) tables, ``k = B a + b``."""

    coarse: npt.NDArray[np.complex128]
    fine: npt.NDArray[np.complex128]
    count: int

    @classmethod
    def of(cls, x: FloatArray, step: float, count: int) -> _GridTables:
        n_a = -(-count // _DFT_BLOCK)
        base = (2.0 * math.pi * step) * x
        fine = _expi(_BLOCK_STEPS[:, None] * base[None, :])
        coarse = _expi((_DFT_BLOCK * np.arange(n_a, dtype=np.float64))[:, None] * base[None, :])
        return cls(coarse, fine, count)

    def dft(self, values: FloatArray) -> npt.NDArray[np.complex128]:
        """``sum_x exp(2 pi i k step x) values[j, x]``: shape (count, J) for ``values`` of
        shape (J, x)."""
        n_j, n_x = values.shape
        out = np.zeros((self.coarse.shape[0] * _DFT_BLOCK, n_j), dtype=np.complex128)
        # One window and at most _BLAS_CHUNK samples per product: OpenBLAS runs a complex
        # product of more than 65536 multiply-adds on several threads, whose wake-up costs
        # milliseconds on a busy machine (10x the product itself).
        for j in range(n_j):
            for lo in range(0, n_x, _BLAS_CHUNK):
                part = slice(lo, lo + _BLAS_CHUNK)
                mixed = self.fine[:, part] * values[j, part]
                out[:, j] += (self.coarse[:, part] @ mixed.T).reshape(-1)
        return np.asarray(out[:self.count])

    def rows(self, every: int) -> npt.NDArray[np.complex128]:
        """The exponentials themselves for ``k = 0, every, 2 every, ...``: (k, x)."""
        k = np.arange(0, self.count, every)
        return np.asarray(self.coarse[k // _DFT_BLOCK] * self.fine[k % _DFT_BLOCK])


def _mean_sinc(gaps: FloatArray, weight: FloatArray, f: FloatArray) -> FloatArray:
    """``sum_g sinc(f g) weight_g / sum_g weight_g`` on the frequency grid ``f`` (``k``
    FREQ_STEP_CYCLES_PER_PX, from 0): ``sin(pi f g) = Im exp(2 pi i f g / 2)``."""
    total = max(float(weight.sum()), 1e-300)
    nz = gaps != 0.0  # sinc(0) = 1 at every frequency
    g, w = gaps[nz], weight[nz]
    tables = _GridTables.of(0.5 * g, FREQ_STEP_CYCLES_PER_PX, f.size)
    sines = tables.dft((w / g)[None, :])[:, 0].imag
    out = np.empty(f.size)
    out[0] = float(np.sum(w))
    out[1:] = sines[1:] / (math.pi * f[1:])
    out += float(np.sum(weight[~nz]))
    return np.asarray(out / total, dtype=np.float64)


def _mtf_from_samples(
    s: _Samples,
    flat_half_px: float,
    noise: _NoiseModel | None = None,
    *,
    narrow_half_px: float = math.inf,
    rise_px: float = math.inf,
) -> _Spectrum:
    """MTF on :data:`FREQS_CYCLES_PER_PX` from the ESF samples, and its 1-sigma.

    LSF: the ESF increments between neighbouring samples, at their midpoints (a 2-point
    difference over each gap ``h``), windowed; its DFT at the midpoints, normalised at zero
    frequency. Corrections: the 2-point difference passes ``sinc(f h)`` (averaged over the
    gaps with the LSF as weight) and the in-bin averaging a box, ``sinc(f b)`` with
    ``b = sqrt(12 var)`` from the LSF-weighted spread of the pixel positions within the bins
    (1/4 px when the phases are dense, less where the pixel lattice leaves one position per
    bin); the total correction is capped at :data:`MAX_DERIVATIVE_CORRECTION`.

    With a noise model: (1) the noise bias of the modulus is removed. ``X(f)`` is linear in
    the samples, so its noise power ``P(f) = E|X - E X|^2 = sum_k |dX/de_k|^2 var_k`` is known
    and ``|X|^2 - P`` is unbiased for the signal's ``|X|^2``: the MTF is
    ``sqrt(max(|X|^2 - P, 0)) / X(0)``. Without it, where the true MTF is ~0 (beyond the
    cut-off of a blurred edge) the modulus of the noise reads as a Rayleigh-distributed
    "MTF" of about 1.25 sigma. (2) the 1-sigma per frequency, first-order propagation of the
    sample variances: ``sum_k (dM/de_k)^2 var_k``, the gradient taken along ``X`` (the
    window and the frequency correction held fixed). Where the signal is ~0 the debiased
    reading is within 1.96 of these sigmas of 0 in ~95 % of cases.
    """
    de = np.diff(s.esf)
    h = np.diff(s.u)
    mid = 0.5 * (s.u[1:] + s.u[:-1])
    # Window centre: the LSF centroid near the fitted edge (u = 0). A centroid over the whole
    # ROI would be pulled towards the ROI's middle by the plateaus' positive noise increments.
    near = np.abs(mid) <= flat_half_px
    pos = np.clip(de[near], 0.0, None)
    centre = float(np.sum(mid[near] * pos) / np.sum(pos)) if np.sum(pos) > 0 else 0.0
    half_data = min(centre - float(s.u[0]), float(s.u[-1]) - centre)
    total = min(half_data, TAPER_FACTOR * flat_half_px)
    truncated = half_data < flat_half_px
    # Frequency-dependent window: the wide one up to just above MTF50 (the LSF's tails set the
    # low frequencies), a narrow one on the core beyond (the tails hold no high frequencies,
    # only plateau noise, which grows as the square root of the window width). Each window is
    # recorded once and applied from its record (what the output reports is what was used).
    narrow_half = min(narrow_half_px, flat_half_px)
    f_wide = min(WIDE_UP_TO_RISES / max(rise_px, 1e-6), WIDE_UP_TO_MAX_CYCLES_PER_PX)
    narrow_total = min(total, NARROW_TAPER * narrow_half)
    windows = [LsfWindow(min(flat_half_px, 0.8 * total), total, 0.0, 0.0),
               LsfWindow(min(narrow_half, 0.8 * total), narrow_total, f_wide, 2.0 * f_wide)]
    core_half = max(CORE_RISES * rise_px + CORE_EXTRA_PX, NARROW_MIN_PX)
    if CORE_FROM_F_WIDE > 0 and core_half < narrow_half:
        windows.append(LsfWindow(min(core_half, 0.8 * narrow_total),
                                 min(narrow_total, CORE_TAPER * core_half),
                                 CORE_FROM_F_WIDE * f_wide, 1.5 * CORE_FROM_F_WIDE * f_wide))
    wide = windows[0]
    win = _tukey(mid - centre, wide.flat_half_px, wide.total_half_px)
    inside = np.flatnonzero(win > 0)
    x = mid[inside] - centre
    f = FREQS_CYCLES_PER_PX
    di = de[inside]
    # X(f) = sum_x exp(2 pi i f x) win(f, x) di(x), the frequency-dependent window a blend
    # sum_j c_j(f) w_j(x) of the fixed ones: one small DFT per window, no (freq, x) window.
    blends, shapes = window_terms(windows, x, f)
    tables = _GridTables.of(x, FREQ_STEP_CYCLES_PER_PX, f.size)
    x_f = np.sum(blends * tables.dft(shapes * di), axis=1)
    re, im = x_f.real, x_f.imag
    spectrum = np.hypot(re, im)
    lsf = de * win
    li = lsf[inside]
    x0 = float(spectrum[0])
    mtf_raw = spectrum / x0 if x0 > 0 else np.zeros_like(spectrum)
    # The 2-point difference over each gap: sinc(f h) averaged with the LSF as weight, the
    # sines from the same small DFT (sin(pi f h) = Im exp(2 pi i f h / 2)).
    gaps = np.round(h[inside], 4)
    weight = np.abs(li)
    gap_response = _mean_sinc(gaps, weight, f)
    # Each sample's weight: the LSF on the increments either side of it.
    w_inc = np.abs(lsf)
    w_sample = np.zeros(s.u.size)
    w_sample[:-1] += 0.5 * w_inc
    w_sample[1:] += 0.5 * w_inc
    var_eff = float(np.sum(w_sample * s.spread_var) / max(float(w_sample.sum()), 1e-300))
    response = gap_response * _sinc(f * math.sqrt(12.0 * var_eff))
    correction = np.minimum(1.0 / np.maximum(response, 1e-12), MAX_DERIVATIVE_CORRECTION)
    sigma = None
    if noise is not None and x0 > 0:
        sample_var = noise.sample_var(s)
        k0 = int(inside[0])  # the window's increments are contiguous (one bump)
        var_k = sample_var[k0:k0 + inside.size + 1]
        # Noise power and sigma vary slowly with f (scale 1 / window width): every
        # SIGMA_GRID_STEP-th frequency, interpolated in between.
        sub = slice(0, None, SIGMA_GRID_STEP)
        fs = f[sub]
        win_sub = (blends[sub] @ shapes) / x0  # the window at these frequencies
        grad = tables.rows(SIGMA_GRID_STEP) * win_sub
        gc, gs, wi = grad.real, grad.imag, win_sub  # d(re, im, x0) / d increment / x0

        def _on_samples(g: FloatArray) -> FloatArray:
            """Gradient per increment -> per sample (sample k enters increments k-1, k)."""
            out = np.zeros((g.shape[0], g.shape[1] + 1))
            out[:, 1:] += g
            out[:, :-1] -= g
            return out

        power = (_on_samples(gc) ** 2 + _on_samples(gs) ** 2) @ var_k  # noise power / x0^2
        sp = spectrum[sub]
        unit_re = np.where(sp > 0, re[sub] / np.maximum(sp, 1e-300), 1.0)
        unit_im = np.where(sp > 0, im[sub] / np.maximum(sp, 1e-300), 0.0)
        # Along X, with the normalisation by X(0) (d x0 / d increment = win at f = 0).
        g_par = (unit_re[:, None] * gc + unit_im[:, None] * gs
                 - mtf_raw[sub][:, None] * wi[0][None, :])
        sig = np.sqrt((_on_samples(g_par) ** 2) @ var_k)
        sigma = np.interp(f, fs, sig) * correction
        sigma = np.hypot(SIGMA_SCALE * sigma, SIGMA_FLOOR)
        sigma[0] = 0.0  # normalised there
        power = np.interp(f, fs, power)
        power[0] = 0.0
        excess = mtf_raw * mtf_raw - power
        if NOISE_BAND_CYCLES_PER_PX > 0:
            excess = _pool_noise_band(excess, power)
        mtf_raw = np.sqrt(np.clip(excess, 0.0, None))
    return _Spectrum(np.asarray(mtf_raw * correction, np.float64), lsf, mid, truncated, sigma,
                     tuple(windows))


def _esf_support_half(s: _Samples, noise: _NoiseModel) -> float:
    """Half-width (px) of the LSF's support as the data show it: how far from the edge the ESF
    still departs from its plateaus.

    Each plateau is a line (an illumination slope is not an edge) fitted to the outer
    SUPPORT_PLATEAU_FRACTION of the fully populated samples on its side (the ROI's corners,
    where fewer rows reach, are left out: there the bins' mean position along the edge
    drifts). Walking out from the edge, the ESF averaged over SUPPORT_SPAN_PX departs from
    that line by more than SUPPORT_SIGMAS of its noise (the average's and the line's own) and
    more than SUPPORT_FLOOR_OF_STEP of the step, until the support ends (the first stretch
    that does not): the LSF mass left outside is then below that floor on each side. 0 when
    a plateau is too short to fit.
    """
    n = s.esf.size
    step = _finite_median(np.diff(s.u)) if n > 1 else 1.0
    m = max(1, int(round(SUPPORT_SPAN_PX / max(step, 1e-6))))
    if n < 4 * m + 8:
        return 0.0
    var = noise.sample_var(s)
    kernel = np.ones(m) / m
    smooth = np.convolve(s.esf, kernel, mode="valid")
    sd = np.sqrt(np.convolve(var, kernel * kernel, mode="valid"))
    at = np.convolve(s.u, kernel, mode="valid")
    full = np.convolve(s.count >= 0.8 * _finite_median(s.count), kernel, mode="valid") > 0.99
    centre = int(np.argmin(np.abs(at)))
    floor = SUPPORT_FLOOR_OF_STEP * abs(noise.bright - noise.dark)
    reach = 0.0
    for side, sign in ((np.flatnonzero(full[:centre]), -1),
                       (centre + np.flatnonzero(full[centre:]), 1)):
        k_out = max(3, int(SUPPORT_PLATEAU_FRACTION * side.size))
        if side.size < 2 * k_out:
            continue
        outer = side[:k_out] if side[0] < centre else side[-k_out:]
        x, y = at[outer], smooth[outer]
        line = _polyfit(x, y, 1)
        sxx = float(np.sum((x - x.mean()) ** 2))
        # The smoothed values are m-fold correlated: outer.size / m independent ones.
        v_line = float(np.mean(sd[outer] ** 2)) * m * (
            1.0 / outer.size + (at - x.mean()) ** 2 / max(sxx, 1e-12))
        limit = np.maximum(SUPPORT_SIGMAS * np.sqrt(sd * sd + v_line), floor)
        dev = np.abs(smooth - _polyval(line, at)) > limit
        walk = dev[centre::-1] if sign < 0 else dev[centre:]  # outwards from the edge
        run = int(np.argmin(walk)) if not walk.all() else walk.size
        last = centre + sign * max(run - 1, 0)
        reach = max(reach, abs(float(at[last])) + 0.5 * m * step)
    return reach


@lru_cache(maxsize=8)
def _band_edges(n: int) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """First and one-past-last grid index of each frequency's noise band (n frequencies)."""
    half = int(round(NOISE_BAND_CYCLES_PER_PX / FREQ_STEP_CYCLES_PER_PX))
    lo = np.clip(np.arange(n) - half, 0, n)
    hi = np.clip(np.arange(n) + half + 1, 0, n)
    lo.setflags(write=False)
    hi.setflags(write=False)
    return lo, hi


def _pool_noise_band(excess: FloatArray, power: FloatArray) -> FloatArray:
    """The debiased power ``excess`` (``|X|^2 - P`` over ``X(0)^2``, on the MTF grid) pooled
    over +-NOISE_BAND_CYCLES_PER_PX where that average is within the noise power ``power``
    (see :data:`NOISE_BAND_CYCLES_PER_PX`); unchanged where the signal stands clear of it.
    The band is truncated at the grid's ends."""
    lo, hi = _band_edges(excess.size)
    c = np.concatenate(([0.0], np.cumsum(excess)))
    pooled = (c[hi] - c[lo]) / (hi - lo)
    scale = (NOISE_BAND_HI - NOISE_BAND_LO) * power
    t = np.divide(NOISE_BAND_HI * power - pooled, scale, out=np.zeros_like(power),
                  where=power > 0)
    s = np.clip(t, 0.0, 1.0)
    return np.asarray(s * pooled + (1.0 - s) * excess, dtype=np.float64)


@dataclass(frozen=True)
class _PlateauNoise:
    """Pixel noise on the two sides of the edge: measured (sigma) and the code rounding's
    variance, the floor of the variances used."""

    measured_dark: float
    measured_bright: float
    rounding_var: float

    @property
    def var_dark(self) -> float:
        return max(self.measured_dark * self.measured_dark, self.rounding_var)

    @property
    def var_bright(self) -> float:
        return max(self.measured_bright * self.measured_bright, self.rounding_var)

    def floored(self) -> tuple[str, ...]:
        """The sides whose variance is the rounding floor (measured below it)."""
        return tuple(side for side, sd in (("dark", self.measured_dark),
                                           ("bright", self.measured_bright))
                     if sd * sd < self.rounding_var)


def _plateau_noise(
    row_diff: FloatArray, u: FloatArray, core_half_px: float, fallback_sigma: float,
    code_step: float,
) -> _PlateauNoise:
    """Pixel noise on the dark and on the bright side of the edge, from differences
    between neighbouring rows (along the edge) of the pixels clear of the core; the overall
    robust noise where a side has too few pixels. The variances used are at least the rounding
    noise of the codes, ``code_step^2 / 12``: noise-free plateaus round to one code, but across
    the edge the rounding error varies from pixel to pixel like noise."""
    u_pair = 0.5 * (u[1:] + u[:-1])
    out = []
    for side in (u_pair < -core_half_px, u_pair > core_half_px):
        vals = row_diff[side]
        sig = fallback_sigma
        if vals.size >= 30:
            # Differences along a plateau are centred on 0. The median of |d| alone misreads
            # quantised noise (it is a whole number of codes: 1.5 codes of noise can read as
            # 1.05), so it only sets a 5-sigma cut for the RMS of what is left.
            mag = np.abs(vals)
            cut = 5.0 * max(MAD_TO_SIGMA * _finite_median(mag), code_step)
            kept = vals[mag <= cut]
            sig = math.sqrt(_mean(kept * kept) / 2.0) if kept.size else 0.0
        out.append(sig)
    return _PlateauNoise(out[0], out[1], code_step * code_step / 12.0)


def _mtf50_sigma(
    freqs: FloatArray, mtf: FloatArray, sigma: FloatArray | None, mtf50: float | None
) -> float | None:
    """1-sigma of MTF50: the MTF's 1-sigma there over the curve's slope (first order)."""
    if sigma is None or mtf50 is None:
        return None
    # Slope over +-2 grid steps (0.01 cycles/px): the chord, not two noisy neighbours.
    i = min(max(int(np.searchsorted(freqs, mtf50)), 2), freqs.size - 3)
    slope = float((mtf[i + 2] - mtf[i - 2]) / (freqs[i + 2] - freqs[i - 2]))
    if slope >= 0:
        return None
    return float(np.interp(mtf50, freqs, sigma) / -slope)


def _quadratic_fit(x: FloatArray, y: FloatArray) -> tuple[float, float, float]:
    """Least-squares ``a x^2 + b x + c`` (``np.polyfit(x, y, 2)`` by its normal equations:
    a handful of points near x = 0, well conditioned, 20x cheaper)."""
    x2 = x * x
    s4, s3, s2, s1 = float(x2 @ x2), float(x2 @ x), float(x2.sum()), float(x.sum())
    m = np.array([[s4, s3, s2], [s3, s2, s1], [s2, s1, float(x.size)]])
    a, b, c = np.linalg.solve(m, np.array([float(x2 @ y), float(x @ y), float(y.sum())]))
    return float(a), float(b), float(c)


#: MTF50: a quadratic fitted over +-this (cycles/px) around the first crossing of 0.5.
MTF50_FIT_HALF_CYCLES_PER_PX = 0.03


def _mtf50(freqs: FloatArray, mtf: FloatArray) -> float | None:
    """First frequency where the MTF falls to 0.5: located by the first crossing, then read
    off a quadratic fitted to the curve around it (the neighbouring frequencies' noise
    averages out; linear interpolation between two noisy points does not)."""
    below = np.flatnonzero(mtf < 0.5)
    if below.size == 0 or below[0] == 0:
        return None
    i = int(below[0])
    f0, f1, m0, m1 = freqs[i - 1], freqs[i], mtf[i - 1], mtf[i]
    linear = float(f0 + (m0 - 0.5) * (f1 - f0) / (m0 - m1))
    near = np.abs(freqs - linear) <= MTF50_FIT_HALF_CYCLES_PER_PX
    if int(near.sum()) < 5:
        return linear
    fc = freqs[near] - linear
    a, b, c = _quadratic_fit(fc, mtf[near] - 0.5)
    # The root of a x^2 + b x + c nearest 0 (the quadratic is nearly linear here).
    disc = b * b - 4.0 * a * c
    if disc < 0 or b == 0:
        return linear
    root = float(-2.0 * c / (b + math.copysign(math.sqrt(disc), b)))
    if abs(root) > MTF50_FIT_HALF_CYCLES_PER_PX:
        return linear
    return linear + root


#: ``method`` of :func:`measure_sfr` (and ``benchlab sfr --method``).
SfrMethod = Literal["auto", "free", "model"]
#: ``method`` values of :func:`measure_sfr`.
METHODS: tuple[SfrMethod, ...] = ("auto", "free", "model")
#: ``auto``: the model-free reading stands where its own +-1.96 sigma already meets the
#: issue's accuracy (MTF within AUTO_MTF_TOL at every f <= Nyquist, MTF50 within
#: AUTO_MTF50_REL_TOL); elsewhere (low SNR, short edges) the LSF model is tried.
AUTO_MTF_TOL = 0.02
AUTO_MTF50_REL_TOL = 0.02


@dataclass(frozen=True)
class _Choice:
    """The estimator chosen for one edge (see :func:`_choose_estimator`)."""

    spec: _Spectrum
    estimator: str  # "model-free" or "LSF model"
    reason: str
    warning: str
    decision: Any  # sfr_model.ModelDecision or None
    mtf50: tuple[float | None, float | None] | None = None  # (MTF50, 1-sigma) when known

    def model_summary(self) -> dict[str, Any] | None:
        """The LSF model fitted (used or not), JSON-ready; None when none was tried."""
        d = self.decision
        if d is None or d.fit is None:
            return None
        f = d.fit
        step = float(np.sum(f.weights))
        return {"used": self.estimator == "LSF model", "components": f.components,
                "weights": [round(float(w) / step, 5) for w in f.weights],
                "centres_px": [round(float(m), 4) for m in f.centres_px],
                "sigmas_px": [round(float(x), 4) for x in f.sigmas_px],
                "chi2": round(f.chi2, 2), "dof": f.n_samples - f.n_params,
                "esf_p_value": d.esf_p_value, "residual_peak_sigmas": round(d.residual_peak, 3),
                "rejected_because": d.reason or None}


def _free_meets_target(spec: _Spectrum) -> tuple[bool, str, tuple[float | None, float | None]]:
    """Whether the model-free reading's own +-1.96 sigma meets the accuracy target, why, and
    its MTF50 and 1-sigma (kept: the reading needs them when it stands)."""
    if spec.sigma is None:
        return False, "no uncertainty", (None, None)
    worst = 1.96 * float(np.max(spec.sigma[:_NYQUIST_INDEX + 1]))
    m50 = _mtf50(FREQS_CYCLES_PER_PX, spec.mtf)
    s50 = _mtf50_sigma(FREQS_CYCLES_PER_PX, spec.mtf, spec.sigma, m50)
    rel50 = 1.96 * s50 / m50 if (m50 and s50 is not None) else 0.0
    ok = worst <= AUTO_MTF_TOL and rel50 <= AUTO_MTF50_REL_TOL
    return ok, (f"model-free +-1.96 sigma {worst:.3f} of MTF to Nyquist, "
                f"{100 * rel50:.1f} % of MTF50"), (m50, s50)


def _model_fit(
    spec: _Spectrum, samples: _Samples, noise: _NoiseModel, cos_a: float, sin_a: float,
    rise_px: float,
) -> Any:
    """The BIC-chosen LSF model fit of these samples, no gates (the bootstrap's refit)."""
    from benchlab.analysis.sfr.model import FIT_MARGIN_PX, fit_lsf_model

    near = np.abs(samples.u) <= spec.windows[0].total_half_px + FIT_MARGIN_PX
    fits = fit_lsf_model(samples.u[near], samples.esf[near], noise.sample_var(samples)[near],
                         samples.spread_var[near], cos_a, sin_a, rise_px=rise_px)
    return fits[-1] if fits else None


#: An accepted model's interval also allows for its disagreement with the model-free reading
#: beyond this fraction of that reading's 1-sigma, pooled over +-NOISE_BAND_CYCLES_PER_PX:
#: ``sqrt(max(<(M - F)^2> - <(k s_F)^2>, 0))``. A model can pass its gates and still miss a
#: shape the data only hint at (a disc R 1.5 px blurred by 1 px read as one Gaussian: 79-88 %
#: coverage on the benchmark); the model-free reading is unbiased for any shape, so what it
#: keeps saying against the model, over a band, is evidence of that miss. The fraction is
#: below 1 (the full noise subtracted leaves that disc at 87 %): the allowance leans to cover.
AGREEMENT_NOISE_FRACTION = 0.4


def _agreement_allowance(model: FloatArray, free: FloatArray, free_sigma: FloatArray
                         ) -> FloatArray:
    """The model's extra 1-sigma from its disagreement with the model-free reading (see
    :data:`AGREEMENT_NOISE_FRACTION`), on the MTF grid."""
    lo, hi = _band_edges(model.size)
    width = hi - lo

    def pooled(x: FloatArray) -> FloatArray:
        c = np.concatenate(([0.0], np.cumsum(x)))
        return np.asarray((c[hi] - c[lo]) / width, dtype=np.float64)

    diff2 = (model - free) ** 2
    noise2 = (AGREEMENT_NOISE_FRACTION * free_sigma) ** 2
    return np.sqrt(np.clip(pooled(diff2) - pooled(noise2), 0.0, None))


def _choose_estimator(
    method: str, spec: _Spectrum, samples: _Samples, noise: _NoiseModel, cos_a: float,
    sin_a: float, rise_px: float,
) -> _Choice:
    """Step 7: the model-free spectrum ``spec`` or the LSF model's
    (:mod:`benchlab.analysis.sfr.model`) for ``method`` (see :func:`measure_sfr`)."""
    if method == "free":
        return _Choice(spec, "model-free", "requested (method free)", "", None)
    if method == "auto":
        ok, why, m50 = _free_meets_target(spec)
        if ok:
            return _Choice(spec, "model-free", f"auto: {why} meets the target", "", None, m50)
        reason = f"auto: {why} misses the target"
    else:
        reason = "requested (method model)"
    from benchlab.analysis.sfr.model import decide_model

    dec = decide_model(samples.u, samples.esf, noise.sample_var(samples), samples.spread_var,
                       cos_a, sin_a, rise_px=rise_px, centre_px=0.0,
                       half_px=spec.windows[0].total_half_px,
                       window=lambda x, f: window_matrix(spec.windows, x, f))
    if dec.fit is None or not dec.accepted:
        return _Choice(spec, "model-free", f"{reason}; LSF model rejected",
                       f"LSF model rejected ({dec.reason}): the model-free reading is given",
                       dec)
    model_mtf = dec.fit.mtf(FREQS_CYCLES_PER_PX)
    sigma = np.hypot(MODEL_SIGMA_SCALE * dec.fit.mtf_sigma(FREQS_CYCLES_PER_PX), SIGMA_FLOOR)
    sigma = np.hypot(sigma, dec.misfit_at(FREQS_CYCLES_PER_PX))
    if spec.sigma is not None:
        sigma = np.hypot(sigma, _agreement_allowance(model_mtf, spec.mtf, spec.sigma))
    sigma[0] = 0.0
    k = dec.fit.components
    model_spec = _Spectrum(model_mtf, spec.lsf, spec.mid, spec.truncated, sigma, spec.windows)
    return _Choice(model_spec, "LSF model",
                   f"{reason}; {k} Gaussian{'s' if k > 1 else ''} accepted by its gates",
                   "", dec)


def measure_sfr(
    pixels: npt.ArrayLike,
    *,
    full_scale: float | None = None,
    fit_order: int = 1,
    bootstrap: int = 0,
    seed: int = 0,
    bin_width_px: float = BIN_WIDTH_PX,
    method: SfrMethod = "auto",
) -> SfrResult:
    """Slanted-edge SFR (sine-wave MTF along the edge normal) of one ROI holding one edge.

    Parameters
    ----------
    pixels : array_like, shape (rows, cols)
        The ROI, linear gray levels (any numeric dtype). The edge should cross the ROI from one
        side to the opposite side, a few degrees off a pixel axis.
    full_scale : float, optional
        Saturation code for the clipping check; default from the dtype (:func:`full_scale_of`).
        The camera's own (:func:`full_scale_of_frame`) is better where known. An MSB-aligned
        top (65520, 65472, ...) also sets the code step, ``2**(16 - bits)``.
    fit_order : int, default 1
        Polynomial order of the edge fit (1 = straight; 2-3 follow a bent edge).
    bootstrap : int, default 0
        0: the analytic uncertainty (pixel noise per level, from row differences on the two
        plateaus, propagated through the MTF). N > 0: a bootstrap over rows with N resamples
        instead (kept for cross-checks; it overstates the noise at sharp edges, where
        resampled rows leave uneven sample phases, and costs N times the analysis).
    seed : int
        Random seed of the bootstrap.
    bin_width_px : float, default 0.25
        ESF bin width (0.25 = 4x oversampling).
    method : {"auto", "free", "model"}, default "auto"
        The MTF estimator: ``free`` the windowed LSF's DFT, ``model`` the LSF model where its
        gates accept it, ``auto`` the model-free reading where its own uncertainty meets the
        accuracy target (:data:`AUTO_MTF_TOL`, :data:`AUTO_MTF50_REL_TOL`), else the model.

    Returns
    -------
    SfrResult

    Raises
    ------
    SfrRefused
        No usable edge (reasons listed).
    ValueError
        Malformed input (not 2-D, non-finite values, bad options).
    """
    # The pipeline; each step's function says what it reads and why it refuses.
    # 1. The ROI in its work frame: full scale, clipping, pixel noise.
    roi = _prepare_roi(pixels, full_scale, fit_order, bootstrap, method)
    # 2. The edge line. 3. The ESF about it, its levels and noise.
    edge = _find_edge(roi, fit_order, bin_width_px)
    esf = _read_esf(roi, edge, roi.work, bin_width_px, check_usable=True)
    # 4. Shading flattened (edge and ESF read again). 5. Outliers clipped, structure refused.
    edge, esf, shading_warning = _correct_shading(roi, edge, esf, fit_order, bin_width_px)
    esf, outliers = _clip_outliers_and_check(roi, edge, esf, fit_order, bin_width_px)
    # 6. The model-free MTF; a second edge refused. 7. The LSF model where it is needed.
    free = _mtf_from_samples(esf.samples, esf.wide_half_px, esf.model,
                             narrow_half_px=esf.narrow_half_px, rise_px=esf.rise_px)
    _refuse_second_edge(roi, esf, free, outliers.count)
    choice = _choose_estimator(method, free, esf.samples, esf.model, *edge.direction_cosines,
                               esf.rise_px)
    # 8. MTF50 and the uncertainty (analytic, or a bootstrap on request). 9. Warnings.
    reading = _read_mtf50(choice)
    if bootstrap > 0:
        reading = _bootstrap(roi, edge, esf, choice, reading.mtf50, bootstrap, seed,
                             bin_width_px)
    warnings = ([] if shading_warning is None else [shading_warning]) + _warnings(
        roi, edge, esf, free.truncated, outliers, reading.mtf50, choice)
    return _result(roi, edge, esf, free, choice, reading, warnings)


@dataclass(frozen=True)
class _Roi:
    """The validated ROI, in its work frame (the edge crossing the rows), with what the
    whole-ROI checks read: full scale, clipping, pixel noise."""

    img: FloatArray  # the ROI as given, float64
    top: float | None  # full-scale code (None: no clipping check)
    code_step: float  # spacing of integer codes (16 for 12 bits MSB-aligned); 0: float data
    clipped: float  # fraction of the pixels at 0 or full scale
    transposed: bool  # True: a near-horizontal edge, the work frame is the ROI transposed
    work: FloatArray  # the work frame
    row_diff: FloatArray  # differences along the edge (between rows of the work frame)
    col_diff: FloatArray  # differences across it
    noise: float  # robust pixel noise from ``row_diff`` (the "no edge" test)

    @property
    def n_rows(self) -> int:
        """Rows of the work frame: the edge's length in pixels."""
        return int(self.work.shape[0])

    @property
    def r_mid(self) -> float:
        """The middle row of the work frame, the origin of the edge polynomial."""
        return (self.n_rows - 1) / 2.0

    def refusal(self, reasons: list[str], also: list[str] | None = None) -> SfrRefused:
        """:func:`structure_refusal` of this ROI."""
        return structure_refusal(reasons, self.img, self.noise, also)


def _prepare_roi(
    pixels: npt.ArrayLike, full_scale: float | None, fit_order: int, bootstrap: int, method: str
) -> _Roi:
    """Step 1: the options and the ROI checked, the work frame chosen and the whole-ROI
    refusals (no edge in the noise, too few rows, too much clipping).

    Raises
    ------
    ValueError
        Malformed input or options (see :func:`measure_sfr`).
    SfrRefused
        An ROI too small, noise only, too short an edge or clipped.
    """
    raw = np.asarray(pixels)
    _check_input(raw, fit_order, bootstrap, method)
    img = raw.astype(np.float64)
    if raw.dtype.kind == "f" and not np.all(np.isfinite(img)):
        raise ValueError("ROI holds a non-finite value")
    top = full_scale if full_scale is not None else full_scale_of(raw)
    clipped = 0.0
    if top is not None:
        clipped = int(np.count_nonzero((img <= 0.0) | (img >= top))) / img.size
    # Integer codes: a step of 1, or 16 for 12-bit data MSB-aligned in 16 bits.
    code_step = _code_step_of(top) if np.issubdtype(raw.dtype, np.integer) else 0.0

    # The work frame: the edge crosses the rows (intensity varies along the columns).
    d_cols, d_rows = np.diff(img, axis=1), np.diff(img, axis=0)
    transposed = _mean(np.abs(d_rows)) > _mean(np.abs(d_cols))
    work = img.T if transposed else img
    row_diff, col_diff = (d_cols.T, d_rows.T) if transposed else (d_rows, d_cols)
    d_flat = row_diff.ravel()  # finite: checked above
    mad = _finite_median(np.abs(d_flat - _finite_median(d_flat)))
    noise = MAD_TO_SIGMA * mad / math.sqrt(2.0)
    p02, p98 = np.percentile(work, [2.0, 98.0])
    spread = float(p98 - p02)
    if spread <= NOISE_SPREAD_RATIO * noise or spread == 0.0:
        raise SfrRefused([f"no edge: the gray-level spread {spread:.3g} is within "
                          f"{NOISE_SPREAD_RATIO:g} x the noise {noise:.3g} (noise only?)"])
    reasons = []
    if work.shape[0] < MIN_EDGE_ROWS:
        reasons.append(f"edge only {work.shape[0]} px long (< {MIN_EDGE_ROWS} px)")
    if clipped > CLIP_REFUSE_FRACTION:
        reasons.append(f"{100 * clipped:.1f} % of the pixels are clipped at 0 or full scale "
                       f"({top:g}) (> {100 * CLIP_REFUSE_FRACTION:g} %): the ESF is flattened")
    if reasons:
        raise SfrRefused(reasons)
    return _Roi(img, top, code_step, clipped, transposed, work, row_diff, col_diff, noise)


def _check_input(raw: npt.NDArray[Any], fit_order: int, bootstrap: int, method: str) -> None:
    """The ROI's dtype and shape and the options, in this order (see :func:`measure_sfr`).

    Raises
    ------
    ValueError
        Not real numbers, not 2-D, or an option out of range.
    SfrRefused
        An ROI under 3 px on a side.
    """
    if raw.dtype.kind not in "uifb":
        raise ValueError(f"ROI must hold real numbers, got dtype {raw.dtype}")
    if raw.ndim != 2:
        raise ValueError(f"ROI must be 2-D, got shape {raw.shape}")
    if min(raw.shape) < 3:
        raise SfrRefused([f"ROI {raw.shape[0]} x {raw.shape[1]} px is too small for an edge"])
    if not 1 <= fit_order <= 3:
        raise ValueError(f"fit_order must be 1..3, got {fit_order}")
    if bootstrap < 0:
        raise ValueError(f"bootstrap must be >= 0, got {bootstrap}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")


@dataclass(frozen=True)
class _Edge:
    """The edge located in a work frame (see :func:`_locate_edge`)."""

    polarity: float  # +1: the work frame brightens along the columns, -1: it darkens
    coeffs: FloatArray  # the edge polynomial (column against row - r_mid)
    u: FloatArray  # every pixel's signed distance from the edge, px, bright side positive
    rise_px: float  # 10-90 % rise on the coarse ESF (NaN where unread)
    half_window: float  # the centroid window of the last pass, px
    fit: EdgeFit  # the fit as reported

    @property
    def angle_deg(self) -> float:
        """Angle between the edge and the pixel axis, deg."""
        return math.degrees(math.atan(abs(self.fit.slope)))

    @property
    def direction_cosines(self) -> tuple[float, float]:
        """``(cos, |sin|)`` of the edge's angle from the pixel axis."""
        slope = self.fit.slope
        return 1.0 / math.hypot(1.0, slope), abs(slope) / math.hypot(1.0, slope)


def _find_edge(roi: _Roi, fit_order: int, bin_width_px: float) -> _Edge:
    """Step 2: the edge's polarity from the mean profile, a first straight fit to the
    per-row centroids of the whole profile, then :func:`_locate_edge`'s narrower passes.

    Raises
    ------
    SfrRefused
        Too few rows with a centroid (or the structure that caused it:
        :func:`~benchlab.analysis.sfr.refusals.structure_refusal`).
    """
    work = roi.work
    n_rows, n_cols = work.shape
    mean_prof = work.mean(axis=0)
    fifth = max(1, n_cols // 5)
    step = _mean(mean_prof[-fifth:]) - _mean(mean_prof[:fifth])
    polarity = 1.0 if step >= 0 else -1.0
    deriv = polarity * roi.col_diff
    dm = np.clip(polarity * np.diff(mean_prof), 0.0, None)
    x_half = np.arange(n_cols - 1, dtype=np.float64) + 0.5
    x0 = float(np.sum(x_half * dm) / np.sum(dm)) if np.sum(dm) > 0 else (n_cols - 1) / 2.0
    rows = np.arange(n_rows, dtype=np.float64)
    cents = _row_centroids(deriv, x0, max(n_cols / 2.0, 4.0))
    coeffs, _ = _fit_edge(rows - roi.r_mid, cents, 1)
    try:
        return _locate_edge(work, deriv, coeffs, max(n_cols / 4.0, 4.0), fit_order, roi.r_mid,
                            polarity, bin_width_px, roi.transposed)
    except SfrRefused as exc:
        raise roi.refusal(list(exc.reasons)) from None


@dataclass(frozen=True)
class _Esf:
    """The ESF read off a work frame about a located edge, with the levels and the noise the
    MTF needs (see :func:`_read_esf`)."""

    work: FloatArray  # the work frame it was read from (flattened, outliers clipped)
    samples: _Samples
    rise_px: float  # 10-90 % rise (the wide window's width)
    flat_half: float  # the wide window's flat half-width from the rise, px
    dark: float
    bright: float
    plateau_noise: _PlateauNoise
    model: _NoiseModel
    support: float  # the LSF's support as the data show it, px (0: off)

    @property
    def contrast(self) -> float:
        """Eq. 2.9 contrast of the plateaus (:func:`_contrast`)."""
        return _contrast(self.dark, self.bright)

    @property
    def wide_half_px(self) -> float:
        """Flat half-width of the wide LSF window: the rise's, or the data's support."""
        return max(self.flat_half, self.support)

    @property
    def narrow_half_px(self) -> float:
        """Flat half-width of the narrow LSF window on the core."""
        return max(NARROW_RISES * self.rise_px + NARROW_EXTRA_PX, NARROW_MIN_PX)

    def without_outliers(self, u: FloatArray, work: FloatArray, bin_width_px: float) -> _Esf:
        """Everything read off the ESF again from ``work`` (the outliers clipped), the noise
        per level kept: a hot pixel's spike in a plateau bin crosses 10 % far from the edge
        (the rise, and every window from it, read 34 px for 100 hot pixels in a 1 px edge)
        and moves the plateau levels."""
        samples, rise, flat_half = _esf_and_rise(u, work, bin_width_px,
                                                 _coarse_rise(u, work, bin_width_px))
        dark, bright = _plateau_levels(samples)
        model = _NoiseModel(dark, bright, self.model.var_dark, self.model.var_bright)
        return _Esf(work, samples, rise, flat_half, dark, bright, self.plateau_noise, model,
                    _support(samples, model))


def _read_esf(
    roi: _Roi, edge: _Edge, work: FloatArray, bin_width_px: float, *, check_usable: bool = False
) -> _Esf:
    """Step 3: the ESF projected onto the edge normal and binned, its plateau levels, the
    pixel noise per level (row differences on the plateaus: shot noise makes the bright side
    noisier) and the LSF's support as the data show it (a halo or flare around a sharp core:
    the 10-90 % rise sees only the core). ``check_usable``: first refuse a step lost in the
    noise or an edge too near the pixel axis (:func:`_refuse_unusable_edge`)."""
    samples, rise, flat_half = _esf_and_rise(edge.u, work, bin_width_px, edge.rise_px)
    dark, bright = _plateau_levels(samples)  # u runs from the dark side to the bright side
    if check_usable:
        _refuse_unusable_edge(roi, edge, dark, bright)
    plateau_noise = _plateau_noise(roi.row_diff, edge.u, flat_half, roi.noise, roi.code_step)
    model = _NoiseModel(dark, bright, plateau_noise.var_dark, plateau_noise.var_bright)
    return _Esf(work, samples, rise, flat_half, dark, bright, plateau_noise, model,
                _support(samples, model))


def _refuse_unusable_edge(roi: _Roi, edge: _Edge, dark: float, bright: float) -> None:
    """Refuse a step lost in the noise, an edge within :data:`MIN_ANGLE_DEG` of the pixel
    axis and one too short for its angle to span a phase cycle (or the structure that caused
    it: :func:`structure_refusal`)."""
    step_abs = abs(bright - dark)
    if step_abs <= MIN_STEP_NOISE_RATIO * roi.noise / math.sqrt(max(1, roi.n_rows)):
        raise roi.refusal([f"no edge: ESF step {step_abs:.3g} is lost in the noise "
                           f"{roi.noise:.3g}"])
    angle, shift = edge.angle_deg, roi.n_rows * abs(edge.fit.slope)
    if angle < MIN_ANGLE_DEG:
        raise roi.refusal([f"edge {angle:.2f} deg from the pixel axis (< {MIN_ANGLE_DEG:g} "
                           "deg): too few sample phases; tilt the edge 2-10 deg"])
    if shift < 1.0:
        raise roi.refusal([f"edge too short for its angle: {roi.n_rows} px at {angle:.2f} deg "
                           f"shifts {shift:.2f} px (< 1 px, one phase cycle)"])


def _correct_shading(
    roi: _Roi, edge: _Edge, esf: _Esf, fit_order: int, bin_width_px: float
) -> tuple[_Edge, _Esf, str | None]:
    """Step 4: planes through the plateaus beyond the LSF's support; where significant the
    ROI is flattened and everything the shading distorted is read again - the edge (its
    gradient pulled the centroids), the rise (a tilted plateau widens it), the ESF, the noise
    and the support - and the planes refitted nearer the edge from that narrower support.
    Returns the edge, the ESF and the warning (None: no significant shading)."""
    shading: Shading | None = None
    flattened: Shading | None = None
    for _ in range(SHADING_PASSES):
        shading = fit_shading(roi.work, edge.u, roi.r_mid, float(edge.coeffs[-1]),
                              esf.wide_half_px + PLATEAU_MARGIN_PX,
                              esf.plateau_noise.var_dark, esf.plateau_noise.var_bright)
        if shading is None or not shading.significant or not shading.correctable:
            break
        flattened = shading
        work = flatten(roi.work, shading)
        edge = _locate_edge(work, edge.polarity * np.diff(work, axis=1), edge.coeffs,
                            edge.half_window, fit_order, roi.r_mid, edge.polarity, bin_width_px,
                            roi.transposed)
        esf = _read_esf(roi, edge, work, bin_width_px)
    if flattened is not None:
        return edge, esf, (f"{flattened.describe()}; flattened by them (the MTF takes the "
                           "shading for illumination, not for the lens)")
    if shading is not None and shading.significant:
        return edge, esf, (f"{shading.describe()}: too strong to flatten (the step falls to "
                           f"{100 * shading.min_step_fraction:.0f} % of its value at the edge "
                           "centre); the MTF at low frequency may read low - use a smaller "
                           "ROI or a flat-fielded image")
    return edge, esf, None


@dataclass(frozen=True)
class _Outliers:
    """Pixels more than :data:`OUTLIER_SIGMAS` noise sigmas off the ESF, clipped to it."""

    count: int
    warning: str | None  # many, taken for compression or sensor structure (else None)


def _clip_outliers_and_check(
    roi: _Roi, edge: _Edge, esf: _Esf, fit_order: int, bin_width_px: float
) -> tuple[_Esf, _Outliers]:
    """Step 5: the pixels off the ESF clipped, and the refusals that need the whole reading
    (:func:`quality_gate`: other structure, a bright side clipped below full scale;
    :func:`stray_pixels`: many pixels off the ESF from a second edge or a bend); the ESF
    read again without the outliers where there were any."""
    located = esf.work
    work, n_outliers = _clip_outliers(edge.u, located, esf.samples, esf.model, bin_width_px)
    structure, clipping = quality_gate(work, edge.u, esf.flat_half, esf.model,
                                        edge.fit.rms_px, roi.code_step, roi.work)
    stray_warning = None
    if not structure and n_outliers > OUTLIER_REFUSE_FRACTION * work.size:
        refusal, stray_warning = stray_pixels(roi.img, roi.noise, n_outliers, work.size,
                                               _stray_centroids(roi, edge, located), fit_order,
                                               edge.fit.rms_px)
        if refusal is not None:
            raise SfrRefused([refusal] + clipping)
    if structure:
        raise roi.refusal(structure, also=clipping)
    if clipping:
        raise SfrRefused(clipping)
    if n_outliers:
        esf = esf.without_outliers(edge.u, work, bin_width_px)
    else:
        esf = replace(esf, work=work)
    return esf, _Outliers(n_outliers, stray_warning)


def _stray_centroids(roi: _Roi, edge: _Edge, located: FloatArray) -> FloatArray:
    """Per-row edge centroids on ``located`` (the frame the edge was found on) for the bend
    test, NaN on the rows whose window the ROI cuts: their centroids lean inwards, which
    reads as a bow."""
    at = _polyval(edge.coeffs, np.arange(roi.n_rows, dtype=np.float64) - roi.r_mid)
    cents = _row_centroids(edge.polarity * np.diff(located, axis=1), at, edge.half_window)
    cut = (at - edge.half_window < 0.0) | (at + edge.half_window > located.shape[1] - 1.0)
    cents[cut] = np.nan
    return np.asarray(cents, dtype=np.float64)


def _refuse_second_edge(roi: _Roi, esf: _Esf, free: _Spectrum, n_outliers: int) -> None:
    """Step 6 (after the model-free MTF, :func:`_mtf_from_samples`): refuse an ROI holding
    a second edge. The marks one leaves (a corner's short side, a bar's far edge near the
    ROI's end): its pixels clipped off the ESF, or the ESF cut short or reaching past its
    plateaus; a second step of the same sign leaves none of them: the ESF reads it as one wide
    edge (two equal steps 8 px apart read an MTF50 of 0.04 cycles/px, silently), so it is
    always looked for."""
    if (n_outliers or free.truncated
            or float(np.ptp(esf.samples.esf)) > ESF_SPAN_OF_STEP * abs(esf.bright - esf.dark)):
        found = find_two_edges(roi.img, roi.noise)
        if found is not None:
            raise SfrRefused([found.reason()])
    second = find_second_edge(roi.img, roi.noise)
    if second is not None:
        raise SfrRefused([second.reason()])


@dataclass(frozen=True)
class _Reading:
    """The MTF's uncertainty and its MTF50 (see :func:`_read_mtf50`, :func:`_bootstrap`)."""

    mtf_sigma: FloatArray | None
    mtf50: float | None
    mtf50_sigma: float | None
    method: str  # "analytic" or "bootstrap"


def _read_mtf50(choice: _Choice) -> _Reading:
    """Step 8: MTF50 and the analytic uncertainty of the chosen spectrum."""
    spec = choice.spec
    if choice.mtf50 is not None:  # already read off this very spectrum
        mtf50, mtf50_sigma = choice.mtf50
    else:
        mtf50 = _mtf50(FREQS_CYCLES_PER_PX, spec.mtf)
        mtf50_sigma = _mtf50_sigma(FREQS_CYCLES_PER_PX, spec.mtf, spec.sigma, mtf50)
    return _Reading(spec.sigma, mtf50, mtf50_sigma, "analytic")


def _bootstrap(
    roi: _Roi, edge: _Edge, esf: _Esf, choice: _Choice, mtf50: float | None, resamples: int,
    seed: int, bin_width_px: float,
) -> _Reading:
    """Step 8 on request: the uncertainty from ``resamples`` bootstraps over rows (the edge
    fit kept; the LSF model refitted where the chosen reading is the model's), MTF50 as read
    (``mtf50``)."""
    freqs = FREQS_CYCLES_PER_PX
    rng = np.random.default_rng(seed)
    curves = np.empty((resamples, freqs.size))
    m50s = []
    for b in range(resamples):
        pick = rng.integers(0, roi.n_rows, roi.n_rows)
        pb = _esf_samples(edge.u[pick], esf.work[pick], bin_width_px, esf.flat_half)
        sb = _mtf_from_samples(pb, esf.wide_half_px, esf.model,
                               narrow_half_px=esf.narrow_half_px, rise_px=esf.rise_px)
        mb = sb.mtf
        if choice.decision is not None and choice.decision.accepted:
            fb = _model_fit(sb, pb, esf.model, *edge.direction_cosines, esf.rise_px)
            if fb is not None:
                mb = fb.mtf(freqs)
        curves[b] = mb
        m50 = _mtf50(freqs, mb)
        if m50 is not None:
            m50s.append(m50)
    mtf_sigma = np.asarray(curves.std(axis=0, ddof=1) if resamples > 1 else
                           np.zeros(freqs.size), dtype=np.float64)
    mtf50_sigma = float(np.std(m50s, ddof=1)) if len(m50s) > 1 else None
    return _Reading(mtf_sigma, mtf50, mtf50_sigma, "bootstrap")


def _warnings(
    roi: _Roi, edge: _Edge, esf: _Esf, truncated: bool, outliers: _Outliers,
    mtf50: float | None, choice: _Choice,
) -> list[str]:
    """Step 9: what makes the reading less reliable without refusing it, in report order:
    the ROI's (:func:`_roi_warnings`), then the reading's (:func:`_reading_warnings`)."""
    return (_roi_warnings(roi, edge, esf)
            + _reading_warnings(edge, truncated, outliers, mtf50, choice))


def _roi_warnings(roi: _Roi, edge: _Edge, esf: _Esf) -> list[str]:
    """Warnings about the ROI as taken: the edge's angle and length, clipping, contrast and
    the pixel lattice's sampling of the ESF."""
    angle, n_rows, clipped = edge.angle_deg, roi.n_rows, roi.clipped
    warnings = []
    if angle < WARN_ANGLE_DEG:
        warnings.append(f"edge only {angle:.2f} deg from the pixel axis (2-10 deg recommended)")
    if n_rows < WARN_EDGE_ROWS:
        warnings.append(f"short edge: {n_rows} px along it (>= {WARN_EDGE_ROWS} px recommended); "
                        "expect more noise in the MTF")
    if clipped > 0:
        warnings.append(f"{100 * clipped:.2f} % of the pixels clipped (0 or {roi.top:g})")
    contrast = esf.contrast
    if math.isfinite(contrast) and contrast < LOW_CONTRAST:
        warnings.append(f"low contrast {contrast:.2f} (< {LOW_CONTRAST:g}): noisy, and sensitive "
                        "to any offset or non-linearity")
    if esf.samples.empty_core_fraction > EMPTY_BIN_WARN_FRACTION:
        warnings.append(f"{100 * esf.samples.empty_core_fraction:.0f} % of the 1/4-px ESF bins "
                        f"near the edge are empty: at {angle:.1f} deg the pixel centres fall on "
                        "a coarse lattice (e.g. 45 deg, atan 1/2), which alone samples the ESF; "
                        "MTF near Nyquist less reliable (aliasing)")
    return warnings


def _reading_warnings(
    edge: _Edge, truncated: bool, outliers: _Outliers, mtf50: float | None, choice: _Choice
) -> list[str]:
    """Warnings about the reading: pixels off the ESF, a truncated ESF, a poor edge fit, no
    MTF50, a rejected LSF model."""
    warnings = []
    if outliers.warning is not None:
        warnings.append(outliers.warning)
    elif outliers.count:
        warnings.append(f"{outliers.count} pixel(s) more than {OUTLIER_SIGMAS:g} noise sigmas "
                        "off the edge profile clipped to it (hot or dead pixels, dust?)")
    if truncated:
        warnings.append("ESF truncated: the ROI is narrow for this blur (widen it across the "
                        "edge); the MTF at low frequency may be off")
    if edge.fit.rms_px > FIT_RMS_WARN_PX:
        warnings.append(f"edge fit RMS {edge.fit.rms_px:.2f} px: edge bent or noisy "
                        "(try fit_order 2)")
    if mtf50 is None:
        warnings.append("MTF stays above 0.5 up to 1 cycle/px: MTF50 not defined")
    if choice.warning:
        warnings.append(choice.warning)
    return warnings


def _normal_theta(edge: _Edge, transposed: bool) -> float:
    """The edge normal (dark to bright) in the ROI's own frame, rad; in the work frame it is
    ``(cos, sin) = (1, -slope)`` times the polarity."""
    theta_work = math.atan2(-edge.fit.slope * edge.polarity, edge.polarity)
    if transposed:
        return math.atan2(math.cos(theta_work), math.sin(theta_work))
    return theta_work


def _result(
    roi: _Roi, edge: _Edge, esf: _Esf, free: _Spectrum, choice: _Choice, reading: _Reading,
    warnings: list[str],
) -> SfrResult:
    """Step 10: the :class:`SfrResult` of the pipeline's steps."""
    freqs = FREQS_CYCLES_PER_PX.copy()
    mtf = choice.spec.mtf
    noise = esf.plateau_noise
    return SfrResult(
        freqs_cycles_per_px=freqs,
        mtf=mtf,
        mtf_sigma=reading.mtf_sigma,
        uncertainty_method=reading.method,
        mtf50_cycles_per_px=reading.mtf50,
        mtf50_sigma=reading.mtf50_sigma,
        mtf_nyquist=float(np.interp(NYQUIST_CYCLES_PER_PX, freqs, mtf)),
        edge_angle_deg=edge.angle_deg,
        normal_theta_rad=_normal_theta(edge, roi.transposed),
        direction="vertical" if roi.transposed else "horizontal",
        dark=esf.dark,
        bright=esf.bright,
        contrast=float(esf.contrast),
        noise_sigma=roi.noise,
        noise_dark_sigma=math.sqrt(noise.var_dark),
        noise_bright_sigma=math.sqrt(noise.var_bright),
        noise_dark_measured=noise.measured_dark,
        noise_bright_measured=noise.measured_bright,
        noise_rounding_sigma=math.sqrt(noise.rounding_var),
        noise_rounding_floor=noise.floored(),
        clipped_fraction=roi.clipped,
        edge_rows=roi.n_rows,
        fit=edge.fit,
        esf_u_px=esf.samples.u,
        esf=esf.samples.esf,
        lsf=free.lsf,
        warnings=tuple(warnings),
        lsf_windows=choice.spec.windows,
        estimator=choice.estimator,
        estimator_reason=choice.reason,
        lsf_model=choice.model_summary(),
    )


def _locate_edge(
    work: FloatArray, deriv: FloatArray, coeffs: FloatArray, half_window: float,
    fit_order: int, r_mid: float, polarity: float, bin_width_px: float, transposed: bool,
) -> _Edge:
    """The edge: :data:`EDGE_PASSES` passes of :func:`_edge_pass` from ``coeffs`` (the
    coefficients, every pixel's distance from the edge, the coarse rise, the window and the
    fit as reported). Refused when too few rows have a centroid."""
    rise = float("nan")
    u: FloatArray | None = None
    keep = cents = np.zeros(0)
    for _ in range(EDGE_PASSES):
        coeffs, keep, cents, u, rise, half_window = _edge_pass(
            work, deriv, coeffs, half_window, fit_order, r_mid, polarity, bin_width_px)
    if u is None:
        u = _work_u(work.shape, coeffs, r_mid, polarity)
    if int(keep.sum()) <= fit_order + 1:
        raise SfrRefused(["no edge: too few rows have a derivative centroid"])
    drows = np.arange(work.shape[0], dtype=np.float64) - r_mid
    return _Edge(polarity, coeffs, u, rise, half_window,
                 _edge_fit_summary(transposed, coeffs, cents, keep, drows))


def _edge_pass(
    work: FloatArray, deriv: FloatArray, coeffs: FloatArray, half_window: float,
    fit_order: int, r_mid: float, polarity: float, bin_width_px: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float, float]:
    """One centroid pass of the edge fit within ``half_window`` of the last fit: the new
    coefficients, the rows kept, the centroids, every pixel's distance from the edge, the
    10-90 % rise on a coarse ESF and the window for the next pass (a few ESF widths)."""
    n_rows, n_cols = work.shape
    drows = np.arange(n_rows, dtype=np.float64) - r_mid
    cents = _row_centroids(deriv, _polyval(coeffs, drows), half_window)
    coeffs, keep = _fit_edge(drows, cents, fit_order)
    u = _work_u(work.shape, coeffs, r_mid, polarity)
    rise = _coarse_rise(u, work, bin_width_px)
    if math.isfinite(rise):
        half_window = float(np.clip(2.0 * rise + 3.0, 4.0, max(n_cols / 2.0, 4.0)))
    return coeffs, keep, cents, u, rise, half_window


def _coarse_rise(u: FloatArray, work: FloatArray, bin_width_px: float) -> float:
    """The 10-90 % rise (px) on an ESF of bins twice the ESF's, well-populated bins only (as
    the ESF keeps): in the corners of a wide ROI a bin holds a few pixels, and one noisy
    enough to cross 10 % reads the rise as the ROI."""
    coarse = bin_profile(u, work, 2.0 * bin_width_px)
    ok = coarse.filled & (coarse.count >= SPARSE_BIN_FRACTION * float(
        _finite_median(coarse.count[coarse.filled])))
    return _rise_10_90(coarse.u_px[ok], coarse.mean[ok])


def _esf_and_rise(
    u: FloatArray, work: FloatArray, bin_width_px: float, coarse_rise: float
) -> tuple[_Samples, float, float]:
    """The ESF samples, the 10-90 % rise and the wide window's flat half-width from it."""
    rise = coarse_rise if math.isfinite(coarse_rise) else 4.0
    flat_half = max(FLAT_RISES * rise + FLAT_EXTRA_PX, FLAT_MIN_PX)
    samples = _esf_samples(u, work, bin_width_px, flat_half)
    # The rise again on the ESF samples at their own positions: the coarse bins can misread
    # it where the pixel lattice is coarse (45 deg: one position every 0.71 px).
    fine_rise = _rise_10_90(samples.u, samples.esf)
    if math.isfinite(fine_rise) and fine_rise > 0:
        rise = max(rise, fine_rise)
        flat_half = max(FLAT_RISES * rise + FLAT_EXTRA_PX, FLAT_MIN_PX)
    return samples, rise, flat_half


def _contrast(dark: float, bright: float) -> float:
    """Eq. 2.9 contrast of the plateaus (NaN where their sum is not positive)."""
    return (bright - dark) / (bright + dark) if bright + dark > 0 else float("nan")


def _support(samples: _Samples, model: _NoiseModel) -> float:
    """:func:`_esf_support_half`, 0 where the data-driven support is off."""
    return _esf_support_half(samples, model) if SUPPORT_SIGMAS > 0 else 0.0


def _plateau_levels(samples: _Samples) -> tuple[float, float]:
    """Dark and bright levels: the means of the outer eighth of the ESF samples each side."""
    k = max(1, samples.esf.size // 8)
    return _mean(samples.esf[:k]), _mean(samples.esf[-k:])


def _edge_fit_summary(
    transposed: bool, coeffs: FloatArray, cents: FloatArray, keep: npt.NDArray[Any],
    drows: FloatArray,
) -> EdgeFit:
    """The edge fit as reported: its slope at the middle row and its RMS residual (px) over
    the rows it kept."""
    slope = float(coeffs[-2])  # d/d(row) at row 0
    residual = cents[keep] - _polyval(coeffs, drows[keep])
    rms = math.sqrt(_mean(residual**2))
    return EdgeFit(transposed, np.asarray(coeffs, dtype=np.float64), slope, rms,
                   int(keep.sum()))


def _work_u(
    shape: tuple[int, int], coeffs: FloatArray, r_mid: float, polarity: float
) -> FloatArray:
    """Signed distance (px) of each work-frame pixel centre from the fitted edge along its
    normal, positive on the bright side: the shared projection of the straight edge through
    the middle row, plus each row's offset from the line for a curved fit."""
    slope = float(coeffs[-2])  # d/d(row) at row 0
    x_mid = float(coeffs[-1])
    theta = math.atan2(-slope, 1.0)
    u = across_coordinate(shape, theta, origin_rc=(r_mid, x_mid))
    if coeffs.size > 2:
        rows = np.arange(shape[0], dtype=np.float64) - r_mid
        bend = _polyval(coeffs, rows) - (x_mid + slope * rows)
        u = u - (bend * math.cos(theta))[:, None]
    return np.asarray(polarity * u, dtype=np.float64)
