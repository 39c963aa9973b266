"""Histogram-peak modulation (thesis section 4.3.1-4.3.2), automated the way a careful
technician would read the histogram.

1. Bins sit on the integer codes actually present (the code step is detected, so 12-bit data
   stored MSB-aligned in 16 bits - codes x 16 - gives no empty-bin comb); non-integer data
   (averaged frames) uses bins of a third of the noise sigma.
2. The histogram is smoothed with a Gaussian whose width comes from the data: Silverman's rule
   applied to the per-pixel noise (one mode = one noise Gaussian), never below ~one code.
3. Modes are picked by **mass**, not height: the smoothed histogram is cut at the valleys
   between its local maxima, and a mode counts when its basin holds at least
   ``MIN_MODE_FRACTION`` of the pixels (a narrow dark mode under Poisson noise or a saturation
   spike no longer beats a broad one). The darkest and the brightest such modes are the dark
   and bright levels. A bimodality test follows: the valley between them must be clearly lower
   than the smaller peak, each side must hold a real share of the pixels
   (``MIN_SIDE_FRACTION``), and the peaks must be more than ``MIN_SEPARATION_SIGMA`` noise
   sigmas apart (two equal Gaussian modes merge below 2 sigma).
4. Otherwise the answer is the thesis's N/A: not resolved, modulation 0, no levels - never a
   confident number from a single mode.

Before binning, the pixels are chosen from the bar pattern's phase (:mod:`.geometry`): only
the centres of the inner bars and spaces (within ``PHASE_WINDOW`` cycles of them, half a period
in from the ends of the ROI), so background beyond the outer bars and the blurred edges do not
make modes of their own; and the noise is the scatter of the pixels about the phase-binned
profile, which does not depend on the bar angle (neighbour differences along an image axis are
4-80x too high on oblique bars). With the frequency given, the phase comes from
:func:`.geometry.quick_geometry` (structure tensor and phase drift, a few passes over the
pixels; the 2-D spectral search only when it declines), and one pass of phase bins gives both
the noise and the bar and space centres (``PHASE_WINDOW`` rounded to whole bins).

No reading without bars: when the fundamental at the measured geometry is less than
``MIN_FUNDAMENTAL_Z`` standard errors above the noise, the ROI is "not resolved" whatever its
histogram (a shading ramp on a flat ROI, or a few quantisation codes on a small one, make two
modes).

References: thesis Eq. 2.9 and figs. 4.10-4.11; measurement-notes section 6 (comb artefacts,
unimodal histograms, mode bias).
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.geometry import (
    detrend,
    fundamental_is_clear,
    measure_geometry,
    quick_fundamental,
)
from benchlab.analysis.bars.result import (
    ModulationResult,
    eq29_modulation,
    resolved,
    sampling_phase_sd,
    unresolved,
)
from benchlab.analysis.bars.roi import FLAT_WARNING, PreparedROI

NAME = "histogram"
#: Minimum valley depth 1 - valley/smaller peak for two modes to count as two.
MIN_BIMODALITY = 0.25
#: Minimum share of pixels on each side of the valley.
MIN_SIDE_FRACTION = 0.08
#: Minimum peak separation in noise sigmas.
MIN_SEPARATION_SIGMA = 2.0
#: A mode counts when its basin (between the valleys around it) holds this share of the pixels.
MIN_MODE_FRACTION = 0.04
#: Pixels within this many cycles of a bar or space centre make the histogram.
PHASE_WINDOW = 0.1
#: The method's own error (modulation units, 1 sigma), part of every interval: ``benchlab
#: benchmark analysis`` puts its RMSE at ~0.015 (bias -0.008) over 2.2-40 px periods.
MODEL_SD = 0.015
#: Fewer centre pixels than this: the window is widened (tiny ROIs).
MIN_CENTRE_PIXELS = 48
#: Phase bins for the noise estimate (scatter about the phase-binned profile) and the bar and
#: space centres (a multiple of ``1 / PHASE_WINDOW``: the window is whole bins; a power of
#: two: the bin is the low bits of a scaled phase, see :func:`_phase_bins`).
NOISE_BINS = 32
#: Below this significance of the fundamental (amplitude over its standard error) the ROI
#: shows no bar pattern: not resolved, whatever its histogram (shading on a flat ROI, or a
#: few quantisation codes, make two modes). A noise maximum found by the spectral search is
#: at most ~4.5.
MIN_FUNDAMENTAL_Z = 6.0
#: Largest number of histogram bins (float data is re-binned coarser beyond this).
MAX_BINS = 1 << 16


def _binned(prep: PreparedROI) -> tuple[npt.NDArray[np.intp], float, bool]:
    """Counts per bin (the first bin centred on ``prep.vmin``), the bin width, and whether
    every pixel lies exactly on its bin centre (integer codes: then the counts up to a bin are
    exactly the pixels at or below its centre)."""
    values = prep.pixels.ravel()
    vmin, vmax = prep.vmin, prep.vmax
    if prep.integer_valued:
        width = prep.code_step or 1.0
    else:
        width = max(prep.noise_sigma / 3.0, (vmax - vmin) / 4096.0, 1e-12)
    n_bins = int(round((vmax - vmin) / width)) + 1
    if n_bins > MAX_BINS:
        width = (vmax - vmin) / (MAX_BINS - 1)
        n_bins = MAX_BINS
    # Single-frame integer data sits on the grid vmin + k * code_step exactly (the mean of
    # several frames only approximately, e.g. thirds).
    exact = prep.integer_valued and prep.n_frames == 1 and width == prep.code_step
    if prep.integer_valued and width == 1.0:
        idx = values.astype(np.intp)  # exact: values are integers
        idx -= int(vmin)
    else:
        scaled = values - vmin
        scaled /= width
        idx = np.rint(scaled, out=scaled).astype(np.intp)
    return np.bincount(idx, minlength=n_bins), width, exact


def _smoothed(
    prep: PreparedROI, counts: npt.NDArray[np.intp], width: float, scale: float
) -> tuple[npt.NDArray[np.float64], float, int]:
    """``counts`` smoothed by ``scale`` times the noise-based Gaussian: the padded smooth
    histogram, the sigma in gray units and the padding (bins on each side)."""
    n_half = max(prep.pixels.size / 2.0, 1.0)
    sigma_gray = 1.06 * prep.noise_sigma * n_half ** (-0.2)
    sigma_bins = max(scale * sigma_gray / width, 0.7 * scale)
    sigma_bins = round(sigma_bins, 2)  # a cached kernel per 0.01 bin
    kernel = _kernel(sigma_bins)
    pad = (kernel.size - 1) // 2
    # "full" convolution pads ``pad`` zero bins on each side: edge peaks stay detectable. The
    # kernel is symmetric, so correlating is convolving - and np.correlate skips
    # np.convolve's Python overhead; its result is bit-identical only while the data are at
    # least as long as the kernel (np.convolve swaps the operands otherwise).
    if counts.size >= kernel.size:
        smooth = np.correlate(counts, kernel, "full")
    else:
        smooth = np.convolve(counts, kernel, mode="full")
    return smooth, sigma_bins * width, pad


@lru_cache(maxsize=512)
def _kernel(sigma_bins: float) -> npt.NDArray[np.float64]:
    """Normalised Gaussian kernel, +-(3 sigma + 1) bins."""
    pad = int(math.ceil(3 * sigma_bins)) + 1
    kernel = np.exp(-0.5 * (np.arange(-pad, pad + 1) / sigma_bins) ** 2)
    kernel /= kernel.sum()
    kernel.setflags(write=False)
    return kernel


def _refine(y: npt.NDArray[np.float64], i: int) -> float:
    """Sub-bin peak position by a parabola through three bins."""
    if 0 < i < y.size - 1:
        left, mid, right = y.item(i - 1), y.item(i), y.item(i + 1)
        den = left - 2 * mid + right
        if den < 0:
            return i + 0.5 * (left - right) / den
    return float(i)


#: Bins where a rise ends (candidate tops, flat or not), their heights, and the maximum of y.
Rises = tuple[list[int], list[float], float]


def _rises(y: npt.NDArray[np.float64]) -> Rises:
    """Bins ``i`` with ``y[i - 1] < y[i] >= y[i + 1]`` (where a peak or a flat top starts),
    their heights, and ``max(y)`` - read off the candidates when the maximum is not at an end
    of ``y`` (then the first bin of its plateau is a candidate), which saves a pass over y."""
    up = y[1:] > y[:-1]  # = (y[1:] - y[:-1]) > 0 for finite floats (gradual underflow)
    starts = (np.nonzero(up[:-1] > up[1:])[0] + 1).tolist()
    item = y.item
    heights = [item(i) for i in starts]  # few candidates: cheaper than a gather and tolist
    top = max(heights) if heights else -math.inf
    if not heights or item(0) >= top or item(-1) >= top:
        top = float(y.max())
    return starts, heights, top


def _find_peaks(
    y: npt.NDArray[np.float64], min_height: float, rises: Rises | None = None
) -> tuple[list[int], list[float]]:
    """Local maxima at least ``min_height`` high and their heights, flat tops included (their
    middle bin), like :func:`scipy.signal.find_peaks` with ``height`` - in a handful of array
    operations, as the candidates are few.
    ``rises``: :func:`_rises` of ``y`` if already known."""
    starts, candidate_heights, _ = rises if rises is not None else _rises(y)
    peaks: list[int] = []
    heights: list[float] = []
    item = y.item
    for i, h in zip(starts, candidate_heights, strict=True):
        if h < min_height:
            continue
        if item(i + 1) < h:  # a single-bin top
            peaks.append(i)
            heights.append(h)
            continue
        # A flat top: it is a peak only if the first different bin after it is lower.
        differ = np.flatnonzero(y[i + 1 :] != h)
        if differ.size:
            j = i + 1 + int(differ[0])
            if item(j) < h:
                peaks.append((i + j - 1) // 2)  # middle of a flat top, as find_peaks
                heights.append(h)
    return peaks, heights


def _massive_modes(
    smooth: npt.NDArray[np.float64], peaks: list[int]
) -> tuple[list[int], int | None]:
    """The local maxima whose basins hold at least ``MIN_MODE_FRACTION`` of the mass, and
    the lowest bin between them when they are two neighbouring maxima (else ``None``).

    Basins are cut at the lowest bin between neighbouring maxima; a light basin is merged into
    the neighbour across its shallower valley, so the mass of a noise bump joins its mode.
    """
    if len(peaks) < 2:
        return peaks, None
    total = float(smooth.sum())
    if len(peaks) == 2:  # the common case, without the lists below (same numbers)
        p, q = peaks
        cut = p + int(smooth[p : q + 1].argmin())
        cs = smooth.cumsum()
        low = cs.item(cut)
        if min(low, cs.item(-1) - low) >= MIN_MODE_FRACTION * total:
            return peaks, cut  # two clear modes, nothing to merge
    cuts = [p + int(smooth[p : q + 1].argmin()) for p, q in zip(peaks[:-1], peaks[1:],
                                                                 strict=True)]
    # Basin masses from the running sum (cs[e - 1] is the mass below edge e; the same
    # numbers as differences of a cumulative sum with a leading 0).
    cs = smooth.cumsum()
    edges = [0, *[c + 1 for c in cuts], smooth.size]
    modes: list[tuple[int, float]] = [
        (p, cs.item(edges[i + 1] - 1) - (cs.item(edges[i] - 1) if edges[i] else 0.0))
        for i, p in enumerate(peaks)
    ]
    valleys = [smooth.item(c) for c in cuts]
    while len(modes) > 1:
        light = min(range(len(modes)), key=lambda i: modes[i][1])
        if modes[light][1] >= MIN_MODE_FRACTION * total:
            break
        # Merge across the higher valley (the shallower dip) into that neighbour.
        left = valleys[light - 1] if light > 0 else -math.inf
        right = valleys[light] if light < len(valleys) else -math.inf
        j = light - 1 if left >= right else light + 1
        keep = j if smooth[modes[j][0]] >= smooth[modes[light][0]] else light
        mass = modes[light][1] + modes[j][1]
        peak = modes[keep][0]
        lo = min(light, j)
        modes[lo : lo + 2] = [(peak, mass)]
        del valleys[lo]
    return [int(m[0]) for m in modes if m[1] >= MIN_MODE_FRACTION * total], None


def _read(
    prep: PreparedROI, binned: tuple[npt.NDArray[np.intp], float, bool], scale: float,
    n_roi: int,
) -> tuple[ModulationResult, bool]:
    """One reading at one smoothing of the histogram ``binned`` (from :func:`_binned`); also
    whether more smoothing could help (two or more local maxima, or a unimodal verdict from
    noise bumps). ``n_roi``: the ROI's pixel count, for the diagnostics."""
    warnings = list(prep.warnings)
    values = prep.pixels.ravel()
    counts, width, exact = binned
    origin = prep.vmin
    smooth, smoothing, pad = _smoothed(prep, counts, width, scale)
    peaks, _ = _find_peaks(smooth, 0.0)
    many = len(peaks) >= 2
    peaks, valley_pos_known = _massive_modes(smooth, peaks)
    base = {"smoothing_codes": smoothing}
    if len(peaks) < 2:
        warnings.append("histogram unimodal: dark and bright peaks cannot be told apart")
        diag0 = prep.diagnostics(n_pixels=n_roi, bimodality=0.0, **base)
        return unresolved(NAME, diag0, warnings), many
    # The technician's reading: the darkest and the brightest clear peaks.
    i_a, i_b = int(peaks[0]), int(peaks[-1])
    valley_pos = (valley_pos_known if valley_pos_known is not None
                  else i_a + int(smooth[i_a : i_b + 1].argmin()))
    valley = smooth.item(valley_pos)
    lower_peak = min(smooth.item(i_a), smooth.item(i_b))
    bimodality = 1.0 - valley / lower_peak if lower_peak > 0 else 0.0
    x_dark = origin + (_refine(smooth, i_a) - pad) * width
    x_bright = origin + (_refine(smooth, i_b) - pad) * width
    sigma = max(prep.noise_sigma, 1e-12)
    separation = (x_bright - x_dark) / sigma
    split_value = origin + (valley_pos - pad) * width
    if exact:  # pixels at or below the valley's bin centre = counts up to that bin
        n_low = int(np.add.reduce(counts[: max(valley_pos - pad + 1, 0)]))
    else:
        n_low = int(np.count_nonzero(values <= split_value + 1e-9 * width))
    side_fraction = min(n_low, values.size - n_low) / values.size
    diag = prep.diagnostics(n_pixels=n_roi, bimodality=bimodality,
                            separation_sigma=min(separation, 1e9), **base)
    reasons = []
    if bimodality < MIN_BIMODALITY:
        reasons.append(f"valley depth {bimodality:.2f} < {MIN_BIMODALITY}")
    if side_fraction < MIN_SIDE_FRACTION:
        reasons.append(f"minor mode holds only {100 * side_fraction:.1f}% of pixels")
    if separation < MIN_SEPARATION_SIGMA:
        reasons.append(f"peaks only {separation:.1f} noise sigma apart")
    if reasons:
        warnings.append("peaks cannot be told apart: " + "; ".join(reasons))
        return unresolved(NAME, diag, warnings), many
    if x_bright + x_dark <= 0:
        warnings.append("dark + bright <= 0 (dark-subtracted below zero?): contrast undefined")
        return unresolved(NAME, diag, warnings), False
    modulation = eq29_modulation(x_dark, x_bright)
    if modulation > 1.0:
        warnings.append("dark level below zero: modulation clipped to 1 (check dark subtraction)")
        modulation = 1.0
    # Analytic standard uncertainty of each mode: noise over sqrt(pixels in the mode), inflated
    # by n^(1/5) for a KDE mode (slower than a mean), never below the bin quantisation.
    n_hi = values.size - n_low
    floor = width / math.sqrt(12.0)
    n_a, n_b = (n_low if n_low > 1 else 1), (n_hi if n_hi > 1 else 1)
    sd_levels = [
        max(sigma * math.sqrt(1.0 / n_a) * n_a**0.2, floor),
        max(sigma * math.sqrt(1.0 / n_b) * n_b**0.2, floor),
    ]
    total = x_bright + x_dark
    dm_dd = -2.0 * x_bright / total**2
    dm_db = 2.0 * x_dark / total**2
    # Noise on the two modes, plus the method's own error: a mode of the sampled pixels is not
    # the profile's extreme (blur, mode bias; sized from the benchmark's RMSE), and where the
    # lines sample the bar phase in a few clusters, not at the extreme (sampling phase).
    sd = math.hypot(dm_dd * sd_levels[0], dm_db * sd_levels[1], MODEL_SD,
                    sampling_phase_sd(modulation, (prep.source or prep).line_phase_gap()))
    result = resolved(NAME, x_dark, x_bright, modulation, diag, sd, warnings)
    return result, False


def histogram_peak(prep: PreparedROI) -> ModulationResult:
    """Dark and bright histogram peaks and their Eq. 2.9 modulation, or "not resolved".

    The smoothing starts at the noise-based width; when that reading is not bimodal but the
    histogram has several local maxima (shading or blur spreading each plateau into a broad,
    bumpy hump), it is doubled - up to an eighth of the gray range - the way a technician
    looks past the bumps. More Gaussian smoothing never creates a mode, so this cannot invent
    a second peak.

    Parameters
    ----------
    prep : PreparedROI
        From :func:`benchlab.analysis.bars.roi.prepare_roi`.

    Returns
    -------
    ModulationResult
        ``estimator="histogram"``; ``diagnostics.bimodality`` and ``separation_sigma`` say how
        clearly the two modes stood apart, ``smoothing_codes`` which smoothing was used.
    """
    if prep.vmax == prep.vmin:
        warnings = [*prep.warnings, FLAT_WARNING]
        return unresolved(NAME, prep.diagnostics(), warnings)
    n_roi = prep.n_pixels
    centres, z = _bar_centres(prep)
    if z is not None and z < MIN_FUNDAMENTAL_Z:
        warnings = [*prep.warnings, f"no bar pattern above the noise: fundamental {z:.1f} "
                    f"standard errors (< {MIN_FUNDAMENTAL_Z:g})"]
        return unresolved(NAME, prep.diagnostics(), warnings)
    result = _histogram_peak(centres, n_roi)
    if not result.resolved and centres is not prep:
        # The phase did not locate the bars (e.g. a chart rotated against the given
        # orientation): the whole ROI's histogram, as the thesis read it.
        whole = _histogram_peak(prep, n_roi)
        if whole.resolved:
            result = whole.with_updates(warnings=(
                *whole.warnings, "bar phase not found: levels from the whole ROI"))
    return result


def _histogram_peak(prep: PreparedROI, n_roi: int | None = None) -> ModulationResult:
    """:func:`histogram_peak` on the selected pixels (diagnostics count ``n_roi`` pixels,
    default: those held)."""
    if n_roi is None:
        n_roi = prep.n_pixels
    if prep.vmax == prep.vmin:
        warnings = [*prep.warnings, "one gray level at the bar and space centres: no bars"]
        return unresolved(NAME, prep.diagnostics(n_pixels=n_roi), warnings)
    binned = _binned(prep)
    first, retry = _read(prep, binned, 1.0, n_roi)
    if first.resolved or not retry:
        return first
    base = max(prep.noise_sigma, 1e-12)
    scale = 2.0
    while scale * base <= (prep.vmax - prep.vmin) / 8.0:
        result, retry = _read(prep, binned, scale, n_roi)
        if result.resolved:
            return result
        if not retry:
            break
        scale *= 2.0
    return first


def _phase_tables(n_bins: int) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Which of ``n_bins`` phase bins (bin ``i`` covers ``[i, i + 1) / n_bins`` cycles) lie
    within ``PHASE_WINDOW`` and twice that of a bar (0) or space (1/2) centre."""
    lo = np.arange(n_bins) / n_bins
    mid = (lo + 0.5 / n_bins) % 1.0
    dist = np.minimum(np.abs(mid - np.rint(mid)), np.abs(mid - 0.5))
    return dist <= PHASE_WINDOW, dist <= 2 * PHASE_WINDOW


_NEAR, _NEAR_WIDE = _phase_tables(NOISE_BINS)
#: The phase windows of the bar and space centres: ``PHASE_WINDOW``, twice that, all bins.
_WINDOWS = {"near": _NEAR, "wide": _NEAR_WIDE, "all": np.ones(NOISE_BINS, bool)}


def _scatter_about_bins(
    idx: npt.NDArray[np.intp], flat: npt.NDArray[np.float64], n_bins: int
) -> float:
    """Pooled scatter of ``flat`` within the bins ``idx`` (the noise about the phase-binned
    profile: it does not depend on the bar angle)."""
    count = np.bincount(idx, minlength=n_bins)
    sums = np.bincount(idx, flat, n_bins)
    # Sum of squares about each bin's mean, pooled (empty bins add 0).
    squares = float(np.einsum("i,i->", flat, flat))
    within = max(squares - float(np.einsum("i,i->", sums, sums / np.maximum(count, 1))), 0.0)
    return math.sqrt(within / max(flat.size - int(np.count_nonzero(count)), 1))


class _Phases(NamedTuple):
    """Where every pixel lies on the bar pattern: its phase ``bin`` (of ``NOISE_BINS`` per
    cycle, bin 0 starting at the bright-bar centres) and whether it lies on the inner bars and
    spaces (half a period in from the ROI's ends; ``None``: all do). Also the noise about the
    phase-binned profile and the fundamental's significance (``None``: unknown)."""

    bins: npt.NDArray[np.intp]
    inner_bars: npt.NDArray[np.bool_] | None
    noise: float
    z: float | None

    def centres(self, window: str) -> npt.NDArray[np.bool_]:
        """Which pixels lie on the inner bars and spaces, in the phase bins of ``window``
        (a key of :data:`_WINDOWS`)."""
        near = _WINDOWS[window][self.bins]
        if self.inner_bars is not None:
            near &= self.inner_bars
        return near


def _phase_bins(
    shape: tuple[int, int], kx: float, ky: float, phase: float, half_f: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.intp], npt.NDArray[np.bool_] | None]:
    """Each pixel's ``NOISE_BINS (phi + whole cycles)`` (phi its phase in cycles) for straight
    bars at ``(kx, ky)`` (cycles/px) and ``phase`` (cycles at the ROI centre), ``half_f``
    cycles from the centre to the far ends; its phase bin; and whether it lies on the inner
    bars, ``|phi - phase| <= half_f - 1/2`` (``None`` when the ROI spans under two)."""
    y, x = _centred_grid(*shape)
    # Whole cycles added keep every value positive (truncation is then the floor) and are a
    # multiple of NOISE_BINS (the phase bin is then the low bits).
    whole = math.ceil(half_f) + 2
    centre = NOISE_BINS * (phase + whole)
    scaled = np.add.outer((NOISE_BINS * ky) * y + centre, (NOISE_BINS * kx) * x)
    bins = scaled.astype(np.intp)
    bins &= NOISE_BINS - 1
    inner = None
    if half_f >= 1.0:
        inner = np.abs(scaled - centre) <= NOISE_BINS * (half_f - 0.5)
    return scaled, bins, inner


def _bar_centres(prep: PreparedROI) -> tuple[PreparedROI, float | None]:
    """``prep`` holding only the pixels near the centres of the inner bars and spaces, with the
    noise measured about the phase-binned profile (see the module docstring), and the
    significance of the bars' fundamental (amplitude over its standard error; ``None`` when
    unknown). ``prep`` is returned unchanged when the bar phase cannot be found (fewer than 16
    pixels, a zero or aliased frequency, no spectral peak); without a frequency the bars'
    geometry is searched for."""
    img = prep.pixels
    f = prep.freq_cycles_per_px
    if img.size < 16 or (f is not None and (f == 0 or f > 0.5)):
        return prep, None
    phases = _axis_phases(prep, f) if prep.orientation_given and f else None
    if phases is None or (phases.z is not None and phases.z < MIN_FUNDAMENTAL_Z):
        # No orientation, or no bars along it (a chart rotated against the given
        # orientation): the bars' own geometry.
        measured = _measured_phases(prep, f)
        phases = measured if measured is not None else phases
    if phases is None:
        return prep, None
    noise = prep.noise_sigma if prep.noise_given else phases.noise
    values = img[phases.centres("near")]
    if values.size < MIN_CENTRE_PIXELS:  # tiny ROI: a wider window, then all
        values = img[phases.centres("wide")]
        if values.size < MIN_CENTRE_PIXELS:
            values = img[phases.centres("all")]
    if values.size < 8:
        return prep.selected(img, noise, prep.vmin, prep.vmax), phases.z
    vmin, vmax = float(values.min()), float(values.max())
    if vmax == vmin:
        return prep.selected(img, noise, prep.vmin, prep.vmax), phases.z
    return prep.selected(values[None, :], noise, vmin, vmax), phases.z


def _axis_phases(prep: PreparedROI, f: float) -> _Phases:
    """Axis-aligned bars of known frequency: the phase of the line-averaged profile."""
    img = prep.pixels
    line = img.mean(axis=1 - prep.axis)
    x = np.arange(line.size, dtype=np.float64) - (line.size - 1) / 2.0
    value = complex(((line - line.mean()) * np.exp(-2j * math.pi * f * x)).sum())
    phase = math.atan2(value.imag, value.real) / (2 * math.pi)
    kx, ky = (f, 0.0) if prep.axis == 1 else (0.0, f)
    half_f = f * (line.size - 1) / 2.0
    _, bins, inner = _phase_bins(img.shape, kx, ky, phase, half_f)
    resid = img - (line[None, :] if prep.axis == 1 else line[:, None])
    along = img.shape[1 - prep.axis]
    noise = max(math.sqrt(float((resid * resid).sum()) / max(img.size - line.size, 1)),
                prep.quantisation_sd)
    if along < 2:
        noise = prep.noise_sigma
    z = None
    if line.size >= 3:
        # The fundamental's significance on the profile without its straight line (shading
        # on a flat ROI is no bar pattern).
        xx = float((x * x).sum())
        slope = float((line * x).sum()) / xx if xx > 0 else 0.0
        flat_line = line - line.mean() - slope * x
        value = complex((flat_line * np.exp(-2j * math.pi * f * x)).sum())
        z_noise = prep.noise_sigma if prep.noise_given else noise
        z = _significance(2.0 * abs(value) / line.size, z_noise, img.size)
    return _Phases(bins, inner, noise, z)


def _measured_phases(prep: PreparedROI, f: float | None) -> _Phases | None:
    """The phase from the bars' measured geometry (quick path first); ``None`` without a
    spectral peak."""
    img = prep.pixels
    # quick_geometry's numbers, without the uncertainties it would add (not needed here); its
    # noise test follows with the noise about the bars' profile (it does not depend on the
    # bars' angle, as the neighbour differences of PreparedROI.noise_sigma do).
    quick = quick_fundamental(img, None, f, None, prep.sums_for(img)) if f else None
    if quick is not None:
        phases = _phases_at(prep, quick.theta_rad, quick.freq_cycles_per_px,
                            quick.phase_cycles, quick.amplitude)
        if fundamental_is_clear(quick, prep.noise_sigma if prep.noise_given else phases.noise):
            return phases
    geom = measure_geometry(img, prep.noise_sigma, f or None, curvature=False,
                            sums=prep.sums_for(img))
    if geom is None:
        return None
    return _phases_at(prep, geom.theta_rad, geom.freq_cycles_per_px, geom.phase_cycles,
                      geom.amplitude)


def _phases_at(
    prep: PreparedROI, theta: float, f: float, phase: float, amplitude: float
) -> _Phases:
    """:class:`_Phases` of straight bars at direction ``theta``, frequency ``f``, ``phase``
    (cycles at the ROI centre) and fundamental ``amplitude``."""
    img = prep.pixels
    rows, cols = img.shape
    n = img.size
    kx, ky = f * math.cos(theta), f * math.sin(theta)  # as BarGeometry.k_xy
    half_f = 0.5 * f * (abs((cols - 1) * math.cos(theta)) + abs((rows - 1) * math.sin(theta)))
    scaled, bins, inner = _phase_bins((rows, cols), kx, ky, phase, half_f)
    flat = img.ravel()
    noise = max(_scatter_about_bins(bins.ravel(), flat, NOISE_BINS), prep.quantisation_sd)
    z_noise = noise
    if n < 8 * NOISE_BINS:
        # Few pixels per bin, and a geometry from few periods that smears the bins: the
        # least of the noise estimates (coarser bins, the residual of the fundamental,
        # neighbour differences) - none of them is inflated by the bars on a flat ROI.
        phi = scaled / NOISE_BINS  # + whole cycles
        w = phi - np.floor(phi)
        n_z = max(4, n // 8)
        coarse = _scatter_about_bins((w * n_z).astype(np.intp).ravel(), flat, n_z + 1)
        fundamental = amplitude * np.cos(2.0 * math.pi * phi)  # phi + whole cycles
        misfit = detrend(img) - fundamental
        residual = math.sqrt(float((misfit * misfit).sum()) / max(n - 7, 1))
        z_noise = max(min(coarse, residual, prep.noise_sigma), prep.quantisation_sd)
    z = _significance(amplitude, prep.noise_sigma if prep.noise_given else z_noise, n)
    return _Phases(bins, inner, noise, z)


@lru_cache(maxsize=64)
def _centred_grid(rows: int, cols: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Row and column coordinates from the ROI centre (cached, read-only)."""
    y = np.arange(rows, dtype=np.float64) - (rows - 1) / 2.0
    x = np.arange(cols, dtype=np.float64) - (cols - 1) / 2.0
    y.setflags(write=False)
    x.setflags(write=False)
    return y, x


def _significance(amplitude: float, noise: float, n_pixels: int) -> float:
    """Fundamental amplitude over its standard error ``noise sqrt(2 / n)`` (large when the
    noise is 0)."""
    se = max(noise, 1e-12) * math.sqrt(2.0 / max(n_pixels, 1))
    return amplitude / se


def manual_peaks(prep: PreparedROI, peaks: tuple[float, float]) -> ModulationResult:
    """The technician's own dark and bright levels (thesis practice), with the ROI's
    diagnostics. ``peaks`` may be given in either order.

    Raises
    ------
    ValueError
        Non-finite levels or ``dark + bright <= 0``.
    """
    dark, bright = sorted(float(p) for p in peaks)
    modulation = eq29_modulation(dark, bright)
    warnings = [*prep.warnings, "levels supplied by hand (--peaks)"]
    if modulation > 1.0:
        warnings.append("dark level below zero: modulation clipped to 1")
        modulation = 1.0
    return (
        ModulationResult(
            estimator="manual",
            dark=dark,
            bright=bright,
            modulation=float(modulation),
            resolved=dark != bright,
            diagnostics=prep.diagnostics(),
            warnings=tuple(warnings),
        )
        if dark != bright
        else unresolved("manual", prep.diagnostics(), warnings)
    )
