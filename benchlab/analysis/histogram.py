"""Histogram-peak modulation (thesis section 4.3.1-4.3.2), automated the way a careful
technician would read the histogram.

1. Bins sit on the integer codes actually present (the code step is detected, so 12-bit data
   stored MSB-aligned in 16 bits - codes x 16 - gives no empty-bin comb); non-integer data
   (averaged frames) uses bins of a third of the noise sigma.
2. The histogram is smoothed with a Gaussian whose width comes from the data: Silverman's rule
   applied to the per-pixel noise (one mode = one noise Gaussian), never below ~one code.
3. Local maxima are ranked by prominence (exactly :func:`scipy.signal.peak_prominences`,
   computed in-house for speed); of the clear ones
   (prominence at least a fifth of the most prominent) the darkest and the brightest are the
   dark and bright levels. A bimodality test follows: the valley between them must be clearly
   lower than the smaller peak, each side must hold a real share of the pixels, and the peaks
   must be more than two noise sigmas apart (two equal Gaussian modes merge below 2 sigma).
4. Otherwise the answer is the thesis's N/A: not resolved, modulation 0, no levels - never a
   confident number from a single mode.

References: thesis Eq. 2.9 and figs. 4.10-4.11; measurement-notes section 6 (comb artefacts,
unimodal histograms, mode bias).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from benchlab.analysis.result import ModulationResult, eq29_modulation, resolved, unresolved
from benchlab.analysis.roi import PreparedROI

NAME = "histogram"
#: Minimum valley depth 1 - valley/smaller peak for two modes to count as two.
MIN_BIMODALITY = 0.25
#: Minimum share of pixels on each side of the valley.
MIN_SIDE_FRACTION = 0.03
#: Minimum peak separation in noise sigmas.
MIN_SEPARATION_SIGMA = 2.0
#: Peaks lower than this fraction of the highest are ignored.
MIN_PEAK_HEIGHT = 0.02
#: Peaks less prominent than this fraction of the most prominent one are ignored.
MIN_RELATIVE_PROMINENCE = 0.2
#: Largest number of histogram bins (float data is re-binned coarser beyond this).
MAX_BINS = 1 << 16


def smoothed_histogram(
    prep: PreparedROI, scale: float = 1.0
) -> tuple[npt.NDArray[np.float64], float, float, float, int]:
    """Histogram on integer-code (or noise-scaled) bins, smoothed from the data (``scale``
    times the noise-based width).

    Returns
    -------
    smooth : ndarray
        Smoothed counts, padded on both sides so that edge peaks are detectable.
    origin : float
        Gray value of the first *unpadded* bin centre.
    width : float
        Bin width in gray units.
    smoothing : float
        Gaussian sigma applied, in gray units.
    pad : int
        Bins of padding on each side.
    """
    counts, width, _ = _binned(prep)
    smooth, smoothing, pad = _smoothed(prep, counts, width, scale)
    return smooth, prep.vmin, width, smoothing, pad


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
    up = (y[1:] - y[:-1]) > 0
    starts = np.nonzero(up[:-1] > up[1:])[0]  # bin starts + 1
    heights = y[1:-1][starts].tolist()
    top = max(heights) if heights else -math.inf
    if not heights or y.item(0) >= top or y.item(-1) >= top:
        top = float(y.max())
    return (starts + 1).tolist(), heights, top


def _find_peaks(
    y: npt.NDArray[np.float64], min_height: float, rises: Rises | None = None
) -> tuple[list[int], list[float]]:
    """Local maxima at least ``min_height`` high and their heights, flat tops included (their
    middle bin), like :func:`scipy.signal.find_peaks` with ``height`` - in a handful of array
    operations, since this estimator has a 100 us budget and the candidates are few.
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


def _peaks(y: npt.NDArray[np.float64], min_height: float) -> list[int]:
    """Local maxima at least ``min_height`` high, flat tops included (their middle bin), like
    :func:`scipy.signal.find_peaks` with ``height`` (see :func:`_find_peaks`)."""
    return _find_peaks(y, min_height)[0]


def _prominences(y: npt.NDArray[np.float64], peaks: list[int], heights: list[float]) -> list[float]:
    """:func:`scipy.signal.peak_prominences` of ``peaks`` (no window), exactly, when
    ``peaks`` are *all* the local maxima of ``y`` at least as high as the lowest of them.

    Then no bin between two neighbouring peaks rises above both, so the walk away from a peak
    (scipy's algorithm: on until a higher bin) always passes the lowest bin between it and the
    next peak. A peak's reference level is therefore the higher of two minima, each taken over
    whole gaps between peaks: on each side, up to and including the gap before the first
    higher peak (or the edge of ``y``).
    """
    # Minimum of y over [0, p0), [p0, p1), ..., [p_last, end]; gaps[g] (between peak g - 1
    # and peak g; 0 = head, m = tail) closed by the peak after it.
    gaps = np.minimum.reduceat(y, [0, *peaks]).tolist()
    m = len(peaks)
    for g in range(m):
        if heights[g] < gaps[g]:
            gaps[g] = heights[g]
    # Walking left from peak k: the minimum over the gaps back to the previous higher peak
    # (or the head), from a stack of the peaks not yet passed (heights decreasing); then the
    # same walking right.
    left: list[float] = []
    stack: list[tuple[float, float]] = []  # (height, its walk minimum)
    for k in range(m):
        h, low = heights[k], gaps[k]
        while stack and stack[-1][0] <= h:
            passed = stack.pop()[1]
            if passed < low:
                low = passed
        stack.append((h, low))
        left.append(low)
    out = [0.0] * m
    stack = []
    for k in range(m - 1, -1, -1):
        h, low = heights[k], gaps[k + 1]
        while stack and stack[-1][0] <= h:
            passed = stack.pop()[1]
            if passed < low:
                low = passed
        stack.append((h, low))
        out[k] = h - (left[k] if left[k] > low else low)
    return out


def _read(
    prep: PreparedROI, binned: tuple[npt.NDArray[np.intp], float, bool], scale: float
) -> tuple[ModulationResult, bool]:
    """One reading at one smoothing of the histogram ``binned`` (from :func:`_binned`); also
    whether more smoothing could help (two or more local maxima, or a unimodal verdict from
    noise bumps)."""
    warnings = list(prep.warnings)
    values = prep.pixels.ravel()
    counts, width, exact = binned
    origin = prep.vmin
    smooth, smoothing, pad = _smoothed(prep, counts, width, scale)
    rises = _rises(smooth)
    top = rises[2]
    peaks, heights = _find_peaks(smooth, top * MIN_PEAK_HEIGHT, rises)
    base = {"smoothing_codes": smoothing}
    many = len(peaks) >= 2
    # The highest peak's prominence is its height (zero padding), and no peak's prominence
    # exceeds its height: peaks lower than the prominence threshold can go straight away.
    clear = top * MIN_RELATIVE_PROMINENCE
    if heights and min(heights) < clear:
        kept = [(p, h) for p, h in zip(peaks, heights, strict=True) if h >= clear]
        peaks = [p for p, _ in kept]
        heights = [h for _, h in kept]
    if len(peaks) == 2:
        # Two peaks in a zero-padded histogram: the higher one's prominence is its height, the
        # lower one's is its height above the valley between them; equal peaks both keep their
        # full height (all as scipy.signal.peak_prominences).
        h_a, h_b = smooth.item(peaks[0]), smooth.item(peaks[1])
        valley2 = float(smooth[peaks[0] : peaks[1] + 1].min())
        if h_a != h_b and min(h_a, h_b) - valley2 < max(h_a, h_b) * MIN_RELATIVE_PROMINENCE:
            peaks = [peaks[0] if h_a >= h_b else peaks[1]]
    elif len(peaks) > 2:
        # Every local maximum at least as high as the lowest kept peak is kept: exact.
        prominence = _prominences(smooth, peaks, heights)
        threshold = max(prominence) * MIN_RELATIVE_PROMINENCE
        peaks = [p for p, pr in zip(peaks, prominence, strict=True) if pr >= threshold]
    if len(peaks) < 2:
        warnings.append("histogram unimodal: dark and bright peaks cannot be told apart")
        return unresolved(NAME, prep.diagnostics(bimodality=0.0, **base), warnings), many
    # The technician's reading: the darkest and the brightest clear peaks.
    i_a, i_b = int(peaks[0]), int(peaks[-1])
    valley_pos = i_a + int(smooth[i_a : i_b + 1].argmin())
    valley = smooth.item(valley_pos)
    lower_peak = min(smooth.item(i_a), smooth.item(i_b))
    bimodality = 1.0 - valley / lower_peak if lower_peak > 0 else 0.0
    x_dark = origin + (_refine(smooth, i_a) - pad) * width
    x_bright = origin + (_refine(smooth, i_b) - pad) * width
    sigma = max(prep.noise_sigma, 1e-12)
    separation = (x_bright - x_dark) / sigma
    split_value = origin + (valley_pos - pad) * width
    if exact:  # pixels at or below the valley's bin centre = counts up to that bin
        n_low = int(counts[: max(valley_pos - pad + 1, 0)].sum())
    else:
        n_low = int(np.count_nonzero(values <= split_value + 1e-9 * width))
    side_fraction = min(n_low, values.size - n_low) / values.size
    diag = prep.diagnostics(bimodality=bimodality, separation_sigma=min(separation, 1e9), **base)
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
    sd = math.hypot(dm_dd * sd_levels[0], dm_db * sd_levels[1])
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
        From :func:`benchlab.analysis.roi.prepare_roi`.

    Returns
    -------
    ModulationResult
        ``estimator="histogram"``; ``diagnostics.bimodality`` and ``separation_sigma`` say how
        clearly the two modes stood apart, ``smoothing_codes`` which smoothing was used.
    """
    if prep.vmax == prep.vmin:
        warnings = [*prep.warnings, "single-valued ROI: one gray level, no bars"]
        return unresolved(NAME, prep.diagnostics(), warnings)
    binned = _binned(prep)
    first, retry = _read(prep, binned, 1.0)
    if first.resolved or not retry:
        return first
    base = max(prep.noise_sigma, 1e-12)
    scale = 2.0
    while scale * base <= (prep.vmax - prep.vmin) / 8.0:
        result, retry = _read(prep, binned, scale)
        if result.resolved:
            return result
        if not retry:
            break
        scale *= 2.0
    return first


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
