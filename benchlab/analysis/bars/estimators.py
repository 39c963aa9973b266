"""Modulation estimators beside the histogram peaks, the registry, and the public entry points.

- ``histogram`` - :mod:`benchlab.analysis.bars.histogram` (the thesis's method, automated).
- ``sinefit`` - least-squares fit of a harmonic series at the known bar frequency (refined
  within +-5 %, or found from the profile's spectrum when not given) to the bar profile (the ROI
  averaged along the bars), with a linear shading term. Harmonics are fitted up to Nyquist and
  kept only when significant; the Eq. 2.9 modulation is read from the fitted waveform's
  maximum and minimum, and the fundamental alone gives ``fundamental_modulation``
  (Sitter et al., Appl. Opt. 34(4):746, 1995; measurement-notes 3.4). Between ~0.225 and 1/3
  cycles/px only the fundamental fits below Nyquist, and for square-ish bars it alone
  over-reads the contrast by up to (4/pi) sinc(f); there the 3rd harmonic is fitted at its
  alias |3f - 1| (see :func:`_harmonic_orders`).
- ``variance`` - variance minus noise (Droege & Morin, Med. Phys. 1982), over a whole number of
  bar periods when the frequency is known: the signal variance ``var(ROI - shading along the
  bars) - sigma_noise^2`` times a crest factor gives the half peak-to-valley amplitude. The
  crest factor comes from the noise-corrected kurtosis through a table of Gaussian-blurred
  square waves (sharp bars: kurtosis 1, crest 1; sine: 1.5, sqrt(2)); it assumes 50 % duty.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import replace
from typing import Literal, TypeAlias

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars import wholeperiod
from benchlab.analysis.bars.extremes import honest_reading
from benchlab.analysis.bars.geometry import measure_geometry
from benchlab.analysis.bars.histogram import histogram_peak, manual_peaks
from benchlab.analysis.bars.profilefit import _model_sd, profile_fit
from benchlab.analysis.bars.result import (
    NYQUIST_CYCLES_PER_PX,
    ModulationResult,
    eq29_modulation,
    not_measurable,
    resolved,
    unresolved,
)
from benchlab.analysis.bars.roi import (
    FLAT_WARNING,
    TINY_CONTRAST_WARNING,
    PreparedROI,
    prepare_roi,
)

#: Significance (in standard errors) for the fundamental to count as resolved.
FUNDAMENTAL_Z = 5.0
#: Harmonics closer than this to Nyquist (cycles/px) are left out of the fit.
NYQUIST_MARGIN = 0.05
#: Gibbs correction (Lanczos sigma factors) only for series this long: with fewer harmonics it
#: would cost more resolution than the overshoot it removes (benchmark: 8 px periods).
LANCZOS_MIN_HARMONICS = 6
#: Relative strength k A_k / A_1 of the last fitted harmonics above which the bars count as
#: sharper than the sampling (1 for an ideal square wave).
SHARP_HARMONIC_RATIO = 0.25
#: Significance for a higher harmonic to enter the waveform.
HARMONIC_Z = 3.0
#: Highest harmonic fitted.
MAX_HARMONIC = 15
#: The aliased 3rd harmonic is fitted only below this frequency (cycles/px): towards 1/3 its
#: alias |3f - 1| runs into the mean and the shading term.
ALIASED_THIRD_MAX_F = 1.0 / 3.0 - 0.01
#: ... and only when its alias is at least this many Rayleigh steps (1/n cycles/px, n = profile
#: length) from the fundamental and from 0 (at f = 1/4 the alias *is* the fundamental; near 0
#: it is the mean and shading). 0.7 rather than 1: the forward-view USAF elements G1E5 / G1E6
#: (7-10 px ROIs) sit at 0.72-0.74 steps; on blurred to pixel-sharp synthetic bars at
#: 0.226-0.323 cycles/px, 7-24 px, 0.7 cuts the RMSE from 0.039 to 0.033 (1.0: 0.035) and
#: 0.5 starts to mistake noise for the harmonic near 0 (one error grew by 0.10).
ALIASED_THIRD_MIN_SEPARATION = 0.7
#: Significance of the signal variance for the variance estimator.
VARIANCE_Z = 5.0


def bar_profile(prep: PreparedROI) -> npt.NDArray[np.float64]:
    """Mean of the ROI along the bars: the 1-D intensity profile across them."""
    return prep.pixels.mean(axis=1 - prep.axis)


def _fold_alias(f: float) -> float:
    """Apparent frequency of ``f`` cycles/px after sampling: |f - round(f)|."""
    return abs(f - round(f))


def _find_frequency(profile: npt.NDArray[np.float64]) -> float | None:
    """Strongest spectral peak of the detrended profile (cycles/px), at least one period."""
    n = profile.size
    if n < 4:
        return None
    x = np.arange(n, dtype=np.float64)
    resid = profile - np.polyval(np.polyfit(x, profile, 1), x)
    nfft = 1 << int(math.ceil(math.log2(n * 8)))
    spec = np.abs(np.fft.rfft(resid * np.hanning(n), nfft))
    freqs = np.fft.rfftfreq(nfft)
    ok = freqs >= 1.0 / n
    if not np.any(ok):
        return None
    return float(freqs[ok][int(np.argmax(spec[ok]))])


def _design(n: int, f: float, orders: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Columns: mean, linear shading, then cos/sin of the harmonics ``orders`` of ``f``
    cycles/px (a harmonic above Nyquist is, at whole pixels, identical to its alias)."""
    x = np.arange(n, dtype=np.float64)
    arg = 2 * np.pi * f * np.outer(x, orders)
    design = np.empty((n, 2 + 2 * orders.size))
    design[:, 0] = 1.0
    design[:, 1] = (x - x.mean()) / n
    design[:, 2::2] = np.cos(arg)
    design[:, 3::2] = np.sin(arg)
    return design


def _harmonics(f: float) -> int:
    """Harmonics fitted at ``f``: those at least ``NYQUIST_MARGIN`` below Nyquist (>= 1)."""
    # min before int: a subnormal frequency makes the ratio infinite (hypothesis: f=5e-324)
    return max(1, int(min(float(MAX_HARMONIC), (NYQUIST_CYCLES_PER_PX - NYQUIST_MARGIN) / f)))


def _harmonic_orders(f: float, n: int, k_max: int) -> npt.NDArray[np.float64]:
    """Harmonic numbers fitted at ``f`` cycles/px on an ``n``-sample profile.

    Parameters
    ----------
    f : float
        Refined bar frequency (cycles/px), below Nyquist.
    n : int
        Profile length (samples across the bars).
    k_max : int
        Harmonics ``1..k_max`` that fit below Nyquist (:func:`_harmonics`, already reduced so
        the fit keeps at least two degrees of freedom).

    Returns
    -------
    ndarray
        ``1..k_max``; or ``[1, 3]`` when only the fundamental fits (``k_max == 1``) and
        ``f < ALIASED_THIRD_MAX_F``, the alias ``a = |3f - 1|`` of the 3rd harmonic lies at
        least ``ALIASED_THIRD_MIN_SEPARATION / n`` from ``f`` and from 0, and the profile
        still leaves two degrees of freedom with two more columns.

    Notes
    -----
    Sampled at whole pixels, ``cos(2 pi 3f x) = cos(2 pi (3f - 1) x)``: the 3rd harmonic is
    in the samples, at its alias. Fitting the fundamental alone there (about 0.225-1/3
    cycles/px) over-reads square-ish bars by up to ``(4/pi) sinc(f)`` (~1.1 at 0.27 c/px), with
    a fitted dark level below every sample. With the 3rd harmonic the waveform reaches the
    plateaus, and the sharp-bar check holds it to the profile's extremes. Near ``f = 1/4`` the
    alias coincides with the fundamental and near 1/3 with the mean / shading, so it cannot be
    told apart there and the fit stays fundamental-only. (At ``k_max == 2``, 1/6-0.225
    cycles/px, the alias of the 3rd is already close to the 2nd harmonic, which absorbs it.)
    """
    if k_max == 1 and f < ALIASED_THIRD_MAX_F and n - 6 >= 2:
        alias = abs(3.0 * f - 1.0)
        sep = ALIASED_THIRD_MIN_SEPARATION / n
        if abs(alias - f) >= sep and alias >= sep:
            return np.array([1.0, 3.0])
    return np.arange(1, k_max + 1, dtype=np.float64)


def _rss_batch(
    profile: npt.NDArray[np.float64], freqs: npt.NDArray[np.float64], k_max: int
) -> npt.NDArray[np.float64]:
    """Residual sum of squares of the harmonic model at each of ``freqs`` (one batched solve)."""
    n = profile.size
    x = np.arange(n, dtype=np.float64)
    ks = np.arange(1, k_max + 1, dtype=np.float64)
    arg = (2 * np.pi) * freqs[:, None, None] * x[None, :, None] * ks[None, None, :]
    design = np.empty((freqs.size, n, 2 + 2 * k_max))
    design[:, :, 0] = 1.0
    design[:, :, 1] = (x - x.mean()) / n
    design[:, :, 2::2] = np.cos(arg)
    design[:, :, 3::2] = np.sin(arg)
    design_t = design.transpose(0, 2, 1)
    gram = design_t @ design
    rhs = design_t @ profile
    try:
        coef = np.linalg.solve(gram, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        coef = np.stack([np.linalg.lstsq(d, profile, rcond=1e-2)[0] for d in design])
    resid = profile[None, :] - (design @ coef[..., None])[..., 0]
    return (resid * resid).sum(axis=1)


def _refine_frequency(profile: npt.NDArray[np.float64], f0: float, span: float) -> float:
    """Frequency within ``f0 * (1 +- span)`` minimising the residual of the harmonic model
    (up to 3 harmonics): a coarse grid, a fine grid around its best point, then a parabola.
    Returns ``f0`` when fewer than two periods fit or the search would reach Nyquist."""
    n = profile.size
    if n * f0 < 2.0 or f0 * (1 + span) >= NYQUIST_CYCLES_PER_PX - NYQUIST_MARGIN:
        return f0
    k_max = min(_harmonics(f0 * (1 + span)), 3, max(1, (n - 4) // 2))
    grid = np.linspace(f0 * (1 - span), f0 * (1 + span), 21)
    best = int(np.argmin(_rss_batch(profile, grid, k_max)))
    step = grid[1] - grid[0]
    fine = np.linspace(grid[best] - step, grid[best] + step, 21)
    rss = _rss_batch(profile, fine, k_max)
    i = int(np.argmin(rss))
    if 0 < i < fine.size - 1:
        den = rss[i - 1] - 2 * rss[i] + rss[i + 1]
        if den > 0:
            return float(fine[i] + 0.5 * (rss[i - 1] - rss[i + 1]) / den * (fine[1] - fine[0]))
    return float(fine[i])


def sine_fit(prep: PreparedROI) -> ModulationResult:
    """Least-squares harmonic fit at the bar frequency; see the module docstring.

    Parameters
    ----------
    prep : PreparedROI
        The prepared ROI (:func:`benchlab.analysis.bars.roi.prepare_roi`).

    Returns
    -------
    ModulationResult
        Needs at least one bar period in the ROI and a frequency below Nyquist after aliasing;
        otherwise "not resolved" with the reason in ``warnings``.

    Notes
    -----
    Harmonics ``1..k`` at least ``NYQUIST_MARGIN`` below Nyquist are fitted. Where that is the
    fundamental alone (about 0.225 to 1/3 - 0.01 cycles/px) the 3rd harmonic is also fitted,
    at its alias ``|3f - 1|`` (identical at whole pixels), provided the alias is at least
    ``ALIASED_THIRD_MIN_SEPARATION / n`` cycles/px from ``f`` and from 0: without it a
    square-ish bar profile reads ~(4/pi) sinc(f) too high (fitted dark level below every
    sample). A significant aliased 3rd marks the bars as sharp, so the levels are held to the
    profile's extremes. See :func:`_harmonic_orders`.
    """
    name = "sinefit"
    warnings = list(prep.warnings)
    profile = bar_profile(prep)
    n = profile.size
    f_given = prep.freq_cycles_per_px
    if f_given == 0:
        return unresolved(name, prep.diagnostics(), warnings)
    if n < 4:
        warnings.append(f"only {n} samples across the bars: cannot fit a period")
        return unresolved(name, prep.diagnostics(), warnings)
    if f_given is None:
        f = _find_frequency(profile)
        if f is None:
            return unresolved(name, prep.diagnostics(), warnings)
        f = _refine_frequency(profile, f, 0.02)
    else:
        f = _fold_alias(f_given) if f_given > NYQUIST_CYCLES_PER_PX else f_given
        if f * n < 1.0:
            warnings.append(f"less than one bar period in {n} px at {f:.4f} cycles/px: cannot fit")
            return not_measurable(name, prep.diagnostics(), warnings)
        f = _refine_frequency(profile, f, 0.05)
    k_max = _harmonics(f)
    while k_max > 1 and n - (2 + 2 * k_max) < 2:
        k_max -= 1
    orders = _harmonic_orders(f, n, k_max)
    aliased_third = orders.size > k_max
    design = _design(n, f, orders)
    coef, _, rank, _ = np.linalg.lstsq(design, profile, rcond=1e-2)
    dof = n - rank
    resid = profile - design @ coef
    if dof >= 1:
        sigma_prof = math.sqrt(float(resid @ resid) / dof)
    else:
        sigma_prof = 0.0
    # Never trust a residual below the noise expected from the pixels averaged per sample.
    per_sample = prep.noise_sigma / math.sqrt(prep.pixels.shape[1 - prep.axis])
    sigma_prof = max(sigma_prof, per_sample)
    se_amp = sigma_prof * math.sqrt(2.0 / n)
    mean = float(coef[0])
    amps = np.hypot(coef[2::2], coef[3::2])
    diag = prep.diagnostics()
    diag = diag.__class__(**{**diag.__dict__, "px_per_period": 1.0 / f, "freq_cycles_per_px": f})
    if mean <= 0:
        warnings.append("mean gray level <= 0: contrast undefined")
        return unresolved(name, diag, warnings)
    fundamental = float(amps[0]) / mean
    if amps[0] <= FUNDAMENTAL_Z * se_amp:
        warnings.append(
            f"fundamental amplitude {amps[0]:.3g} within {FUNDAMENTAL_Z:g} standard errors "
            f"({se_amp:.3g}) of zero: bars not resolved"
        )
        return unresolved(name, diag, warnings)
    keep = amps > HARMONIC_Z * se_amp
    keep[0] = True
    phase = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    kept = np.nonzero(keep)[0]
    weights = np.ones(kept.size)
    # Truncated with signal left in the last harmonics: the bars are sharper than the samples
    # can describe (harmonics above Nyquist alias back into the fit).
    # A sharp square wave has harmonics A_k ~ A_1 / k; blur makes them fall much faster.
    # With only two harmonics below Nyquist a significant second one is the third aliased back
    # (even harmonics vanish at 50 % duty), so any significant one counts.
    # The aliased 3rd harmonic (k_max == 1, see _harmonic_orders) is read the same way.
    top = [k for k in range(max(1, orders.size - 2), orders.size) if keep[k]]  # last two, 0-based
    sharp = any(orders[k] * amps[k] >= SHARP_HARMONIC_RATIO * amps[0] for k in top) or (
        (k_max == 2 or aliased_third) and bool(top)
    )
    if sharp and k_max >= LANCZOS_MIN_HARMONICS:
        # The series is cut while its last harmonics still carry signal (sharp bars): Lanczos
        # sigma factors remove most of the Gibbs overshoot that would read as extra contrast.
        weights = np.sinc((kept + 1.0) / (k_max + 1.0))
        warnings.append("sharp bars: harmonic series truncated at Nyquist (Lanczos-smoothed)")
    arg = np.outer(phase, orders[kept])
    wave = (
        mean
        + np.cos(arg) @ (weights * coef[2 + 2 * kept])
        + np.sin(arg) @ (weights * coef[3 + 2 * kept])
    )
    dark, bright = float(wave.min()), float(wave.max())
    if sharp:
        # Sharp bars put many samples on the plateaus: the levels cannot lie beyond the
        # (line-averaged) profile's own extremes, whatever overshoot the series keeps.
        detrended = profile - coef[1] * design[:, 1]
        dark = max(dark, float(detrended.min()))
        bright = min(bright, float(detrended.max()))
    if dark + bright <= 0:
        warnings.append("fitted dark + bright <= 0: contrast undefined")
        return unresolved(name, diag, warnings)
    modulation = eq29_modulation(dark, bright)
    if modulation > 1.0:
        warnings.append("fitted dark level below zero: modulation clipped to 1")
        modulation = 1.0
    sd = math.sqrt(int(keep.sum())) * se_amp / mean
    return resolved(name, dark, bright, modulation, diag, sd, warnings, fundamental)


@functools.cache
def _crest_table() -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Kurtosis -> crest factor (half peak-to-valley / RMS) of Gaussian-blurred 50 %-duty
    square waves, from sharp (1, 1) to fully blurred = sine (1.5, sqrt 2).

    Built on first use (~10 ms) and kept: only the ``variance`` estimator reads it, and
    building it at import cost every ``benchlab analyze`` that start-up time (issue 11)."""
    x = np.linspace(0.0, 1.0, 2048, endpoint=False)
    k = np.arange(1, 200, 2, dtype=np.float64)
    basis = np.sin(2 * np.pi * np.outer(x, k)) / k
    kurts, crests = [1.0], [1.0]
    for blur in np.linspace(0.01, 0.2, 40):  # PSF sigma in periods
        w = basis @ np.exp(-2 * (np.pi * blur * k) ** 2)
        w -= w.mean()
        var = float(np.mean(w**2))
        kurts.append(float(np.mean(w**4)) / var**2)
        crests.append(float(w.max() - w.min()) / 2.0 / math.sqrt(var))
    kurts.append(1.5)
    crests.append(math.sqrt(2.0))
    order = np.argsort(kurts)
    return np.asarray(kurts)[order], np.asarray(crests)[order]



def _whole_periods(prep: PreparedROI) -> npt.NDArray[np.float64]:
    """The ROI cut to a whole number of bar periods across the bars (centred), when the
    frequency is known and at least one period fits: a partial period biases the mean and the
    variance (the dark and bright shares differ)."""
    f = prep.freq_cycles_per_px
    length = prep.pixels.shape[prep.axis]
    if not f or f > NYQUIST_CYCLES_PER_PX or length * f < 1.0:
        return prep.pixels
    keep = int(round(math.floor(length * f + 1e-9) / f))
    keep = min(max(keep, 1), length)
    start = (length - keep) // 2
    if prep.axis == 1:
        return prep.pixels[:, start : start + keep]
    return prep.pixels[start : start + keep, :]


def _remove_along_bar_slope(img: npt.NDArray[np.float64], axis: int) -> npt.NDArray[np.float64]:
    """``img`` minus its mean and its least-squares slope **along the bars** (perpendicular to
    ``axis``), where the scene is flat: shading there is variance that is not bar contrast. (A
    slope across the bars cannot be removed this way: a periodic signal correlates with it.)"""
    along = 1 - axis
    n = img.shape[along]
    centred = img - float(img.mean())
    if n < 2:
        return centred
    t = np.arange(n, dtype=np.float64) - (n - 1) / 2
    per_line = img.mean(axis=axis)  # mean of each line along ``along``
    slope = float(t @ per_line) / float(t @ t)
    return centred - slope * (t[:, None] if along == 0 else t[None, :])


def variance_minus_noise(prep: PreparedROI) -> ModulationResult:
    """Signal variance above the noise, turned into a half peak-to-valley amplitude by the crest
    factor implied by the noise-corrected kurtosis; see the module docstring."""
    name = "variance"
    warnings = list(prep.warnings)
    region = _whole_periods(prep)
    values = _remove_along_bar_slope(region, prep.axis).ravel()
    n = values.size
    diag = prep.diagnostics()
    if n < 2:
        warnings.append("one pixel: no variance")
        return unresolved(name, diag, warnings)
    mean = float(region.mean())
    var = float(values @ values) / n
    if not var > 0.0:
        warnings.append("no variance in the ROI: bars not resolved")
        return unresolved(name, diag, warnings)
    z2 = values * values / var  # standardised: the moments stay O(1) at any gray scale
    m4_ratio = float(z2 @ z2) / n  # m4 / var^2
    noise2 = prep.noise_sigma**2
    signal2 = var - noise2
    # Standard error of var - noise^2 under "no signal": sample variance plus a MAD-based noise
    # estimate (37 % efficient) - or none when the noise was given.
    n_noise = max(n, 2)
    se = noise2 * math.sqrt(2.0 / n + (0.0 if prep.noise_given else 2.0 / (0.37 * n_noise)))
    if signal2 <= VARIANCE_Z * se or signal2 <= 0:
        warnings.append("ROI variance not significantly above the noise: bars not resolved")
        return unresolved(name, diag, warnings)
    if mean <= 0:
        warnings.append("mean gray level <= 0: contrast undefined")
        return unresolved(name, diag, warnings)
    r_noise, r_signal = noise2 / var, signal2 / var
    kurt = (m4_ratio - 6.0 * r_noise * r_signal - 3.0 * r_noise * r_noise) / (r_signal * r_signal)
    crest = float(np.interp(kurt, *_crest_table()))
    half = crest * math.sqrt(signal2)
    dark, bright = mean - half, mean + half
    modulation = half / mean
    if modulation > 1.0:
        warnings.append("estimated dark level below zero: modulation clipped to 1")
        modulation = 1.0
    sd = crest / mean * (se + noise2 * math.sqrt(2.0 / n)) / (2.0 * math.sqrt(signal2))
    return resolved(name, dark, bright, modulation, diag, sd, warnings)


def _aliased(name: str, prep: PreparedROI) -> ModulationResult:
    """Period under 2 px: never a number - "not resolved (aliased)"."""
    return unresolved(
        name, prep.diagnostics(), (*prep.warnings, "not resolved (aliased): period < 2 px")
    )


PreparedEstimator = Callable[[PreparedROI], ModulationResult]
#: Below this many pixels, on axis-aligned bars of given frequency (the forward view's USAF
#: elements, 3 x 5 to 9 x 10 px), the square-wave model has more freedom than the few lines
#: across the bars can pin down; the harmonic series of ``sinefit`` is fitted instead.
TINY_ROI_PIXELS = 100


def _tiny_model_sd(series: ModulationResult, bars: ModulationResult, gap: float) -> float:
    """Model term (1 sigma) of the harmonic-series reading on a tiny ROI: the sampling-phase
    term of its largest phase ``gap``, and the disagreement with the bar-pattern model fitted
    to the same pixels (``bars``). A handful of lines across cannot tell a sine from a blurred
    square wave (both fit, e.g. 5 lines at 4.7 px per period: series 0.43, bar model 0.29,
    truth 0.28), so where the two models read differently the data do not pin the contrast
    down."""
    term = _model_sd(series.modulation, gap, 8)
    if bars.resolved:
        term = math.hypot(term, series.modulation - bars.modulation)
    return term


#: A tiny ROI's bar-model reading within this (plus twice its noise term) of the contrast of
#: the harmonic series' levels clamped into the data range confirms that the series rang past
#: the data (G1E5T: 0.004-0.009 apart); on fine bars the bar model reads 0.1 away (G2E4S).
CLAMPED_AGREEMENT = 0.01


def _levels_outside_data(prep: PreparedROI, r: ModulationResult) -> bool:
    """Whether a reading's dark or bright level lies outside the ROI's pixel values: a fitted
    waveform overshooting the data (on the forward view's G1E5T the harmonic series put the
    dark level at 19.4 below every pixel, min 22, and read 0.814 for a truth of 0.782 - more
    than the scene's largest possible contrast)."""
    if r.dark is None or r.bright is None:
        return False
    lo, hi = float(np.min(prep.pixels)), float(np.max(prep.pixels))
    return min(r.dark, r.bright) < lo or max(r.dark, r.bright) > hi


#: Bars within this angle (deg) of an image axis are axis-aligned for :func:`_few_periods`.
AXIS_ALIGNED_DEG = 1.0
#: Axis-aligned ROIs spanning fewer bar periods than this widen the model term (x N / periods).
FEW_PERIODS = 2.0


def _few_periods(prep: PreparedROI, r: ModulationResult) -> ModulationResult:
    """``r`` with its model term times ``FEW_PERIODS / periods`` when axis-aligned bars span
    fewer than ``FEW_PERIODS`` periods across the ROI.

    Across one or two axis-aligned bars the shading plane and the bar levels are fitted to the
    same few bars, and the lines sample the bar phase only where they happen to fall: on the
    analysis benchmark such readings (e.g. 40 x 50 px at 33 px per period) missed their
    intervals by 2-5 sigma, axis-aligned coverage 91 %. Oblique bars cross the ROI along its
    diagonal at many phases and keep the term."""
    d = r.diagnostics
    angle, period, model = d.bar_angle_deg, d.px_per_period, d.uncertainty_model
    if not r.resolved or angle is None or not period or not model:
        return r
    off_deg = abs((angle + 45.0) % 90.0 - 45.0)
    if off_deg > AXIS_ALIGNED_DEG:
        return r
    rows, cols = prep.pixels.shape
    theta = math.radians(angle)
    span_px = abs((cols - 1) * math.cos(theta)) + abs((rows - 1) * math.sin(theta)) + 1.0
    periods = span_px / period
    if periods >= FEW_PERIODS:
        return r
    model *= FEW_PERIODS / periods
    sd = math.hypot(d.uncertainty_noise or 0.0, model)
    m = r.modulation
    return r.with_updates(
        uncertainty=sd,
        interval=(max(0.0, m - 1.96 * sd), min(1.0, m + 1.96 * sd)),
        diagnostics=replace(d, uncertainty_model=model),
    )


def _series_starved(prep: PreparedROI) -> bool:
    """Too few lines across for the harmonics below Nyquist: ``sine_fit`` would cut its series
    to a sine, which reads sharp bars up to 4/pi too high (e.g. 5 lines at 4.7 px per period:
    0.43 for a truth of 0.28); the bar-pattern model is fitted instead."""
    f = prep.freq_cycles_per_px or 0.0
    k = _harmonics(_fold_alias(f) if f > NYQUIST_CYCLES_PER_PX else f)
    return k > 1 and prep.pixels.shape[prep.axis] - (2 + 2 * k) < 2


def _profilefit(prep: PreparedROI, fast: bool = False) -> ModulationResult:
    """``profilefit``; on tiny ROIs of axis-aligned bars of given frequency with lines enough
    for the harmonics (:func:`_series_starved`), the harmonic series of ``sinefit`` along the
    axis, relabelled, with the model and sampling-phase term (:func:`_tiny_model_sd`) in its
    uncertainty; elsewhere the bar-pattern fit (:func:`_few_periods` widening its interval)."""
    name = "profilefit-fast" if fast else "profilefit"
    if (prep.orientation_given and prep.freq_cycles_per_px and prep.pixels.size < TINY_ROI_PIXELS
            and not _series_starved(prep)):
        r = sine_fit(prep)
        warns = (*r.warnings, "bar phases sampled in a few clusters: harmonic-series fit")
        if not r.resolved:
            return r.with_updates(estimator=name, warnings=warns)
        bars = profile_fit(prep, fast)
        model = _tiny_model_sd(r, bars, prep.line_phase_gap())
        if _levels_outside_data(prep, r):
            # Levels beyond every pixel: the truncated series rings past the plateaus of
            # coarse bars (G1E5T), or - on fine bars sampled at a few phases - the pixels
            # never reach the true levels and the series is right (G2E4S). The contrast of
            # its levels clamped into the data range bounds the overshoot.
            lo, hi = float(np.min(prep.pixels)), float(np.max(prep.pixels))
            dark = min(max(float(r.dark or 0.0), lo), hi)
            bright = min(max(float(r.bright or 0.0), lo), hi)
            clamped = eq29_modulation(dark, bright) if dark + bright > 0 else 0.0
            overshoot = abs(r.modulation - clamped)
            noise = bars.diagnostics.uncertainty_noise or bars.uncertainty
            if (bars.resolved and not _levels_outside_data(prep, bars)
                    and abs(bars.modulation - clamped) <= 2.0 * noise + CLAMPED_AGREEMENT):
                # The bar model (levels within the data) reads the contrast the data's range
                # gives: the series rang past the plateaus; the bar model reads the set, the
                # two models' disagreement in its interval.
                return _with_model_term(_few_periods(prep, bars), model, (
                    "harmonic-series levels outside the data range: bar-model fit"))
            model = math.hypot(model, overshoot)  # the series, its interval widened
            warns = (*warns, "harmonic-series levels outside the data range: interval widened")
        sd = math.hypot(r.uncertainty, model)
        # The terms in the diagnostics too: a bootstrap (noise only) adds the model term back.
        diag = replace(r.diagnostics, uncertainty_noise=r.uncertainty, uncertainty_model=model)
        return resolved(name, float(r.dark or 0.0), float(r.bright or 0.0), r.modulation,
                        diag, sd, warns, r.fundamental_modulation)
    return _integer_period(prep, _few_periods(prep, profile_fit(prep, fast)))


#: Whole periods (px) at which axis-aligned lines sample only this many bar phases: the bars'
#: blur cannot be told from their contrast (:func:`_integer_period`).
INTEGER_PERIODS_PX = wholeperiod.PERIODS_PX
#: ... when the phases drift by less than this (cycles) across the ROI (48.08 lp/mm at 5.2 um
#: is 3.9997 px per period).
PHASE_DRIFT_CYCLES = 0.01


def _phase_levels(prep: PreparedROI, period: int) -> tuple[npt.NDArray[np.float64], float] | None:
    """The mean level of each of the ``period`` bar phases sampled by the lines across
    axis-aligned bars (a linear shading across them removed), and the standard error of one
    level; ``None`` when a phase is sampled by fewer than two lines."""
    profile = bar_profile(prep)
    n = profile.size
    if n < 2 * period + 2:
        return None
    x = np.arange(n, dtype=np.float64)
    design = np.zeros((n, period + 1))
    design[np.arange(n), np.arange(n) % period] = 1.0
    design[:, period] = (x - x.mean()) / n
    coef, *_ = np.linalg.lstsq(design, profile, rcond=None)
    resid = profile - design @ coef
    dof = max(n - period - 1, 1)
    line_sd = max(math.sqrt(float(resid @ resid) / dof),
                  prep.noise_sigma / math.sqrt(prep.pixels.shape[1 - prep.axis]))
    levels: npt.NDArray[np.float64] = np.asarray(coef[:period], dtype=np.float64)
    return levels, line_sd / math.sqrt(n // period)


def _integer_period(prep: PreparedROI, r: ModulationResult) -> ModulationResult:
    """``r``, or on axis-aligned bars of a given whole period of 3-5 px the contrast of the
    imaged bars that give the phase levels sampled, modelled on the pixel grid
    (:func:`_phase_levels`, :func:`.wholeperiod.whole_period_reading`).

    Lines at a whole period sample the same few bar phases: sharp bars and blurred ones of
    higher contrast give the same samples, and the fit on a fine phase grid reads them as a
    smooth wave (issue 37: the row ``80 50 170 200`` repeated, sharp bars of levels 50 and
    200, read 0.700 for 0.600). The reading is that of bars as sharp as the pixels (PSF sigma
    up to 0.25 px), its interval the spread of the bars that give the samples; the fit's
    (blurred) reading is named in a warning."""
    f = prep.freq_cycles_per_px
    if not r.resolved or r.lower_bound or not f or not prep.orientation_given:
        return r
    period = round(1.0 / f)
    n_lines = prep.pixels.shape[prep.axis]
    if period not in INTEGER_PERIODS_PX or abs(f - 1.0 / period) * n_lines > PHASE_DRIFT_CYCLES:
        return r
    found = _phase_levels(prep, period)
    if found is None:
        return r
    sharp = wholeperiod.whole_period_reading(*found)
    if sharp is None or not 0.0 < sharp.modulation <= 1.0:
        return r
    m, (lo, hi) = sharp.modulation, sharp.interval
    # The samples lie within the imaged profile's range: their contrast (held 2 standard errors
    # inwards) is the least the bars can have. The posterior gives the patterns reaching it (a
    # full dark and a full bright pixel at once, e.g. edges on pixel boundaries) no volume at
    # 3 px, so the interval reaches down to it.
    levels, se = found
    floor_lo, floor_hi = float(levels.min()) + 2.0 * se, float(levels.max()) - 2.0 * se
    if floor_hi > floor_lo and floor_lo + floor_hi > 0.0:
        lo = min(lo, eq29_modulation(floor_lo, floor_hi))
    lo, hi = max(0.0, min(lo, m)), min(1.0, max(hi, m))
    sd = (hi - lo) / (2.0 * 1.96)
    sd_model = math.sqrt(max(sd * sd - sharp.sd_noise**2, 0.0))
    note = (f"whole period of {period} px on axis-aligned bars: the lines sample {period} bar "
            "phases, which cannot tell sharp bars from blurred ones; the reading is that of "
            f"bars as sharp as the pixels (PSF sigma <= {wholeperiod.SIGMA_MAX_PX:g} px), the "
            f"fit's {r.modulation:.3f} that of blurred ones")
    return r.with_updates(
        dark=sharp.dark, bright=sharp.bright, modulation=m, uncertainty=sd, interval=(lo, hi),
        diagnostics=replace(r.diagnostics, uncertainty_noise=sharp.sd_noise,
                            uncertainty_model=sd_model),
        warnings=(*r.warnings, note))


def _with_model_term(r: ModulationResult, extra: float, warning: str) -> ModulationResult:
    """``r`` with ``extra`` added (in quadrature) to its model term and ``warning`` added."""
    if not r.resolved:
        return r.with_updates(warnings=(*r.warnings, warning))
    d = r.diagnostics
    model = math.hypot(d.uncertainty_model or 0.0, extra)
    sd = math.hypot(d.uncertainty_noise if d.uncertainty_noise is not None else r.uncertainty,
                    model)
    m = r.modulation
    return r.with_updates(
        uncertainty=sd, interval=(max(0.0, m - 1.96 * sd), min(1.0, m + 1.96 * sd)),
        diagnostics=replace(d, uncertainty_model=model), warnings=(*r.warnings, warning))


#: ``sinefit`` and ``variance`` read the bars along an image axis: measured bars more than this
#: (deg, beyond twice the angle's uncertainty) off the nearest pixel axis get a warning. The
#: issue's check: sinefit RMSE 0.023 on axis-aligned bars, 0.509 on oblique ones, variance 0.052
#: and 0.246, with no word of it.
OBLIQUE_WARN_DEG = 1.0


def _oblique_warning(prep: PreparedROI, name: str) -> str | None:
    """A warning when the bars' measured direction (:func:`measure_geometry`) is more than
    :data:`OBLIQUE_WARN_DEG` off the pixel axes; None when not, or not measurable."""
    f = prep.freq_cycles_per_px
    prior = f if f and 0.0 < f < NYQUIST_CYCLES_PER_PX else None
    try:
        geom = measure_geometry(prep.pixels, prep.noise_sigma, prior, curvature=False)
    except ValueError:
        return None
    if geom is None:
        return None
    angle = math.degrees(geom.theta_rad)
    off = abs((angle + 45.0) % 90.0 - 45.0)
    if off - 2.0 * math.degrees(geom.theta_sd_rad) <= OBLIQUE_WARN_DEG:
        return None
    return (f"bars {off:.1f} deg off the pixel axes: {name} reads along an axis, so its "
            "reading is not the bars' contrast (use profilefit, which measures the direction)")


def _axis_checked(estimator: PreparedEstimator, name: str) -> PreparedEstimator:
    """``estimator`` with :func:`_oblique_warning` added to its result."""
    def run(prep: PreparedROI) -> ModulationResult:
        r = estimator(prep)
        note = _oblique_warning(prep, name)
        return r if note is None else r.with_updates(warnings=(*r.warnings, note))
    return run


def _contrast_checked(estimator: PreparedEstimator, name: str) -> PreparedEstimator:
    """``estimator``, except on a ROI of one gray level, or whose values span less than
    :data:`~benchlab.analysis.bars.roi.MIN_CONTRAST` (e.g. values ~1e-200): not resolved, with a
    warning saying which. Flat float data gave sinefit and variance rounding residue (1e-17)
    to read as bars above a noise of 0; below the bound the fits' squares underflow
    (profilefit divided by zero, sinefit read 0.215 for 0.238). Every other reading passes
    :func:`~benchlab.analysis.bars.extremes.honest_reading` (clipping: a bound)."""
    def run(prep: PreparedROI) -> ModulationResult:
        if prep.vmax == prep.vmin:
            return unresolved(name, prep.diagnostics(), (*prep.warnings, FLAT_WARNING))
        if prep.contrast_underflows:
            return unresolved(name, prep.diagnostics(), (*prep.warnings, TINY_CONTRAST_WARNING))
        two = _two_codes(prep, name)
        return two if two is not None else honest_reading(prep, estimator(prep))
    return run


#: Each of the two codes of a two-code ROI holds at least this share of the pixels.
TWO_CODE_MIN_SHARE = 0.05
#: ... and the codes lie at least this far apart (gray units): blurred bars spanning a few
#: codes would show codes between them.
TWO_CODE_MIN_GAP = 4.0


def _two_codes(prep: PreparedROI, name: str) -> ModulationResult | None:
    """The exact reading of a noise-free ROI of two codes, each on at least
    :data:`TWO_CODE_MIN_SHARE` of the pixels (bars with their edges on pixel boundaries):
    any blur or an edge inside a pixel would give a code between them, so the two codes are
    the bars' levels and Eq. 2.9 of them is the contrast, known to the codes' rounding. A fit
    of a blurred model to such data overshoots (issue 37: 50 / 200 read 0.627, or ">= 0.600"
    when the top code was taken for saturation). ``None`` for any other ROI."""
    if not prep.integer_valued or prep.n_frames > 1 or prep.freq_cycles_per_px == 0:
        return None
    px = prep.pixels
    lo, hi = prep.vmin, prep.vmax
    n_lo = int(np.count_nonzero(px == lo))
    n_hi = int(np.count_nonzero(px == hi))
    if n_lo + n_hi != px.size or min(n_lo, n_hi) < TWO_CODE_MIN_SHARE * px.size:
        return None
    if hi - lo < TWO_CODE_MIN_GAP:
        return None  # adjacent codes: blurred bars under the rounding look the same
    if hi + lo <= 0.0 or (prep.max_code is not None and hi >= prep.max_code):
        return None  # a top at full scale may be clipped: the estimators' bound rules
    m = eq29_modulation(lo, hi)
    sd = 2.0 * prep.quantisation_sd * math.hypot(lo, hi) / (lo + hi) ** 2
    return resolved(name, lo, hi, m, prep.diagnostics(), sd, (
        *prep.warnings, "two codes only (sharp bars, edges on pixel boundaries): the levels "
        "are the two codes"))


_PREPARED: dict[str, PreparedEstimator] = {
    "profilefit": _contrast_checked(_profilefit, "profilefit"),
    "profilefit-fast": _contrast_checked(lambda prep: _profilefit(prep, fast=True),
                                         "profilefit-fast"),
    "histogram": _contrast_checked(histogram_peak, "histogram"),
    "sinefit": _contrast_checked(_axis_checked(sine_fit, "sinefit"), "sinefit"),
    "variance": _contrast_checked(_axis_checked(variance_minus_noise, "variance"), "variance"),
}


def _public(name: str) -> Callable[..., ModulationResult]:
    def estimator(
        roi: npt.ArrayLike,
        *,
        freq_cycles_per_px: float | None = None,
        orientation: str | None = None,
        max_code: float | None = None,
        noise_sigma: float | None = None,
    ) -> ModulationResult:
        prep = prepare_roi(
            roi,
            freq_cycles_per_px=freq_cycles_per_px,
            orientation=orientation,
            max_code=max_code,
            noise_sigma=noise_sigma,
        )
        return _PREPARED[name](prep)

    estimator.__name__ = name
    estimator.__doc__ = f"Estimator ``{name}`` on a raw ROI (see :func:`estimate_modulation`)."
    return estimator


#: Name -> ``fn(roi, *, freq_cycles_per_px, orientation, max_code, noise_sigma)``.
ESTIMATORS: dict[str, Callable[..., ModulationResult]] = {n: _public(n) for n in _PREPARED}
#: THE default estimator of the library, the CLI, the procedures (both views), the TUI live view
#: and re-analysis: ``auto`` resolves to it. Chosen from ``benchlab benchmark analysis``: the
#: only one accurate at every bar angle (see the README's benchmark table).
DEFAULT_ESTIMATOR = "profilefit"
#: The name that asks for the default.
AUTO = "auto"
#: The estimators' names (the keys of :data:`ESTIMATORS`; a test keeps the two equal).
EstimatorName = Literal["profilefit", "profilefit-fast", "histogram", "sinefit", "variance"]
#: What an ``estimator`` option takes: a name, or ``"auto"`` for :data:`DEFAULT_ESTIMATOR`.
EstimatorChoice: TypeAlias = EstimatorName | Literal["auto"]


def resolve_estimator(name: str | None) -> str:
    """``None``, ``""`` and ``"auto"`` -> :data:`DEFAULT_ESTIMATOR`; other names unchanged."""
    return DEFAULT_ESTIMATOR if name in (None, "", AUTO) else str(name)

#: Disagreement between estimators (modulation units) above which a warning is added.
DISAGREEMENT_TOLERANCE = 0.05


def estimate_modulation(
    roi: npt.ArrayLike,
    *,
    estimator: str = AUTO,
    freq_cycles_per_px: float | None = None,
    orientation: str | None = None,
    peaks: tuple[float, float] | None = None,
    max_code: float | None = None,
    noise_sigma: float | None = None,
    bootstrap: int = 0,
    seed: int | None = 0,
) -> ModulationResult:
    """Eq. 2.9 bar modulation of one ROI.

    Parameters
    ----------
    roi : array_like
        2-D gray levels (rows, cols), any integer or float dtype; or a 3-D stack
        (frames, rows, cols) which is averaged (noise then comes from the frame-to-frame spread).
    estimator : str
        ``"auto"`` (= :data:`DEFAULT_ESTIMATOR`) or a key of :data:`ESTIMATORS`:
        ``"profilefit"``, ``"profilefit-fast"``, ``"histogram"``, ``"sinefit"``, ``"variance"``.
    freq_cycles_per_px : float, optional
        Bar frequency on the sensor in cycles/pixel (``frequency.cycles_per_px``). Above 0.5 the
        result is flagged ``aliased``; 0.35-0.5 ``phase_sensitive``; 0 gives "not resolved" for
        ``sinefit``. ``None``: ``sinefit`` finds it from the profile.
    orientation : str, optional
        Direction in which the intensity varies: ``"horizontal"`` (along columns, vertical bars),
        ``"vertical"`` (along rows), or the forward-view aliases ``"sagittal"`` (= horizontal)
        and ``"tangential"`` (= vertical); ``None`` detects it. See :mod:`.roi`.
    peaks : (float, float), optional
        Manual dark and bright levels: overrides every estimator (``estimator="manual"``).
    max_code : float, optional
        Saturation code; inferred for integer data (255, 4095, 65520, 65535).
    noise_sigma : float, optional
        Known per-pixel noise (gray units); estimated from the ROI otherwise.
    bootstrap : int
        If > 0, replace the analytic uncertainty by a bootstrap over lines along the bars with
        this many resamples (:func:`benchlab.analysis.bars.uncertainty.bootstrap_result`).
    seed : int, optional
        Seed of the bootstrap.

    Returns
    -------
    ModulationResult
        Never NaN; "not resolved" is modulation 0 with ``dark = bright = None``.

    Raises
    ------
    ValueError
        Unknown estimator, empty / non-finite ROI, bad frequency, orientation or noise.
    """
    estimator = resolve_estimator(estimator)
    if peaks is None and estimator not in _PREPARED:
        raise ValueError(
            f"unknown estimator {estimator!r}; choose auto or one of {sorted(_PREPARED)}"
        )
    prep = prepare_roi(
        roi,
        freq_cycles_per_px=freq_cycles_per_px,
        orientation=orientation,
        max_code=max_code,
        noise_sigma=noise_sigma,
    )
    if peaks is not None:
        if len(peaks) != 2:
            raise ValueError(f"peaks must be (dark, bright), got {peaks!r}")
        return manual_peaks(prep, (float(peaks[0]), float(peaks[1])))
    if prep.aliased:
        return _aliased(estimator, prep)
    result = _PREPARED[estimator](prep)
    if bootstrap > 0:
        from benchlab.analysis.bars.uncertainty import bootstrap_result

        result = bootstrap_result(prep, result, _PREPARED[estimator], bootstrap, seed)
    return result


def compare_estimators(
    roi: npt.ArrayLike,
    *,
    estimators: tuple[str, ...] | None = None,
    freq_cycles_per_px: float | None = None,
    orientation: str | None = None,
    max_code: float | None = None,
    noise_sigma: float | None = None,
    tolerance: float = DISAGREEMENT_TOLERANCE,
) -> dict[str, ModulationResult]:
    """Run several estimators on one ROI and record how far apart they are.

    Every result gets ``diagnostics.disagreement`` = the largest |difference| in modulation
    between any two estimators (counting "not resolved" as 0), and a warning when it exceeds
    ``tolerance``. Estimators agree for wide bars and split near the resolution limit - the
    split is itself a diagnostic (measurement-notes section 7.2).
    """
    names = estimators or tuple(_PREPARED)
    unknown = [n for n in names if n not in _PREPARED]
    if unknown:
        raise ValueError(f"unknown estimator(s) {unknown}; choose from {sorted(_PREPARED)}")
    prep = prepare_roi(
        roi,
        freq_cycles_per_px=freq_cycles_per_px,
        orientation=orientation,
        max_code=max_code,
        noise_sigma=noise_sigma,
    )
    results = {n: _aliased(n, prep) if prep.aliased else _PREPARED[n](prep) for n in names}
    mods = [r.modulation for r in results.values()]
    spread = float(max(mods) - min(mods)) if mods else 0.0
    out: dict[str, ModulationResult] = {}
    for n, r in results.items():
        diag = r.diagnostics.__class__(**{**r.diagnostics.__dict__, "disagreement": spread})
        warns = r.warnings
        if spread > tolerance:
            warns = (*warns, f"estimators disagree by {spread:.3f} (> {tolerance:g})")
        out[n] = r.with_updates(diagnostics=diag, warnings=warns)
    return out
