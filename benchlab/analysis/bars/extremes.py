"""Honest readings at the extremes: clipped bars read as a bound, plain bars never "not resolved".

Every estimator in :data:`benchlab.analysis.bars.estimators.ESTIMATORS` passes its reading
through :func:`honest_reading`:

- **Bright level clipped** (more than :data:`~.result.CLIPPED_FRACTION_LIMIT` of the pixels at
  the saturation code): the data only say the bright bars are *at least* that bright, and the
  Eq. 2.9 contrast grows with the bright level (d/dB of (B - D) / (B + D) = 2 D / (B + D)^2
  >= 0), so the reading is a lower bound of the contrast: ``lower_bound`` with the reason.
  Only a reading whose model carried the bright level above the code (:data:`CENSORING`:
  ``profilefit`` and ``knownbars`` treat saturated pixels as censored) is the model's estimate
  and stays a value; a harmonic series or a variance overshooting the code is not.
- **Dark level clipped at code 0**: the dark level read is at least the true one, so again the
  contrast read is a lower bound (unless it already is 1).
- **Dark level 0**: the contrast is exactly 1 whatever the bright level, clipped or not - a
  value, never a bound (a reading within :data:`ONE_TOLERANCE` of 1 is 1).
- **Plainly resolved but "not resolved"**: a noise-free or sharp pattern can defeat a fit (all
  bright phases censored, two distinct phases, a residual of exactly 0). When the profile
  across the bars swings through at least one period by :data:`PLAIN_RANGE_SIGMAS` times its
  noise, the bars are there: the contrast of the profile's extremes, moved inwards by
  :data:`EXTREME_MARGIN_SIGMAS` noise sigmas, is returned as a lower bound (pixel integration
  and blur only narrow the range of the samples, so their contrast never exceeds the bars').

Readings of ROIs without clipping that the estimator resolved are returned unchanged.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.result import (
    CLIPPED_FRACTION_LIMIT,
    ModulationResult,
    eq29_modulation,
)
from benchlab.analysis.bars.roi import PreparedROI, quantisation_sd, robust_noise_sigma

#: The profile across the bars must span this many of its noise sigmas for the bars to count
#: as plainly resolved (20: noise alone over a few hundred samples spans ~6-7 sigma).
PLAIN_RANGE_SIGMAS = 20.0
#: The fallback bound's levels: the profile's extremes moved inwards by this many noise sigmas
#: (the extreme of a few hundred noisy samples lies ~3 sigma beyond the level).
EXTREME_MARGIN_SIGMAS = 3.0
#: How an estimator's warning that it found no bars ends (folded into the fallback's note).
NOT_RESOLVED = ": bars not resolved"
#: Estimators that treat saturated pixels as censored: a model that carries the bright level
#: above the top code gives a value, not a bound (their other readings of clipped bars are
#: bounds like everyone's).
CENSORING = frozenset({"profilefit", "profilefit-fast", "knownbars"})
#: A censoring model's reading of clipped bars stays a value only with an uncertainty (1
#: sigma) up to this; a larger one says the bright level above the code is a guess (limits
#: benchmark: 0.563 +- 0.20 for 0.459; below 0.1 the values lie within 0.03 of the truth).
CENSORED_VALUE_MAX_SD = 0.1
#: Estimators whose levels are a fitted waveform's extremes (not data): held to the data's
#: range for a bound (:func:`_within_data`).
WAVEFORM = frozenset({"sinefit", "variance"})
#: Pixels within this many noise sigmas of 0 make a dark level of 0 possible.
ZERO_SIGMAS = 3.0
#: A contrast within this of 1 is 1 (a dark level of 0 read with rounding residue, 3e-6).
ONE_TOLERANCE = 1e-5
#: Swings between the profile's lower and upper quarters that make one full period
#: (dark-bright-dark) of blurred bars.
MIN_CROSSINGS = 2


#: Full-scale codes of the cameras' bit depths (8, 10, 12, 14, 16 bits; 12-bit MSB-aligned).
FULL_SCALE_CODES = frozenset({255.0, 1023.0, 4095.0, 16383.0, 65520.0, 65535.0})


def bright_clipped(prep: PreparedROI) -> bool:
    """Whether more than :data:`CLIPPED_FRACTION_LIMIT` of the pixels sit at the saturation
    code (the ROI's warnings already say so). A plateau below full scale in noise-free data
    is no evidence of clipping (every level of sharp noise-free bars is a plateau)."""
    if prep.max_code is None or prep.clipped_fraction <= CLIPPED_FRACTION_LIMIT:
        return False
    return prep.max_code in FULL_SCALE_CODES or not _noise_free(prep)


def _noise_free(prep: PreparedROI) -> bool:
    """No noise measured above the rounding of the codes (or none at all)."""
    return prep.noise_sigma <= prep.quantisation_sd * 1.0001


def dark_clipped(prep: PreparedROI) -> bool:
    """Whether the ROI's lowest code is 0 and more than :data:`CLIPPED_FRACTION_LIMIT` of the
    pixels sit there with noise above the quantisation: a dark level clipped at the floor
    (noise-free data at 0 are not clipped, they are exactly 0)."""
    if prep.vmin != 0.0 or not prep.integer_valued:
        return False
    if _noise_free(prep):
        return False
    at_floor = float(np.count_nonzero(prep.pixels == 0.0)) / prep.pixels.size
    return at_floor > CLIPPED_FRACTION_LIMIT


def _bound_reason(prep: PreparedROI, bright: bool) -> str:
    if bright:
        return (f"bright level clipped at code {prep.max_code:g}: the true bright level is at "
                "least that, so the contrast is at least the reading")
    return ("dark level clipped at code 0: the true dark level is at most the one read, so the "
            "contrast is at least the reading")


def _within_data(prep: PreparedROI, r: ModulationResult) -> ModulationResult:
    """``r`` with a fitted waveform's levels held to the data for a bound (:data:`WAVEFORM`):
    a harmonic series or a crest factor overshoots sharp clipped bars (sinefit put the dark
    level at 20 below pixels from 64 and read 0.87 for a contrast of 0.75), and a bound from
    levels beyond every pixel is no bound. Histogram peaks are data already."""
    if r.estimator not in WAVEFORM or r.dark is None or r.bright is None:
        return r
    top = prep.max_code if prep.max_code is not None else prep.vmax
    dark, bright = max(r.dark, prep.vmin), min(r.bright, top)
    if (dark, bright) == (r.dark, r.bright) or bright <= dark or dark + bright <= 0.0:
        return r
    return r.with_updates(dark=dark, bright=bright, modulation=eq29_modulation(dark, bright))


def _as_bound(r: ModulationResult, reason: str) -> ModulationResult:
    """``r`` marked as a lower bound: its number and interval kept, the reason said."""
    return r.with_updates(lower_bound=True, bound_reason=reason,
                          warnings=(*r.warnings, f"lower bound: {reason}"))


def _swings(profile: npt.NDArray[np.float64]) -> int:
    """How often ``profile`` goes from its lower quarter to its upper quarter or back (a ramp
    or shading: once; one bar period: twice)."""
    lo, hi = float(profile.min()), float(profile.max())
    low, high = lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo)
    state, swings = 0, 0
    for v in profile.tolist():
        now = -1 if v <= low else (1 if v >= high else state)
        if state and now != state:
            swings += 1
        state = now
    return swings


#: Lower quartile of |N(0, 2 sigma^2)| over sigma: the noise from the quietest quarter of the
#: neighbour differences, robust to up to 3 in 4 of them being bar edges.
_Q25_HALF_NORMAL = 0.31863936 * math.sqrt(2.0)


def _line_noise(prep: PreparedROI, line: npt.NDArray[np.float64]) -> float:
    """Per-pixel noise of a ROI that is one line across the bars: the smaller of the ROI's
    estimate and the one from the lower quartile of the absolute neighbour differences. The
    ROI's estimate falls back to differences across the bars there and counts the edges as
    noise (every other difference at 4 px per period). On whole codes the quartile is 0 for
    noise under ~0.9 codes, whose range over a line stays under the plainness test's
    :data:`PLAIN_RANGE_SIGMAS` times the codes' rounding."""
    if line.size < 2 or prep.noise_given:
        return prep.noise_sigma
    q25 = float(np.percentile(np.abs(np.diff(line)), 25.0)) / _Q25_HALF_NORMAL
    f = prep.freq_cycles_per_px
    if f and 1.0 / line.size < f < 0.5:  # a whole period on the line (and 1 / f finite)
        # A whole number of pixels per period: samples one period apart differ by noise
        # alone (mixed edge pixels included), e.g. 20 50 60 50 20 at 5 px per period.
        lag = round(1.0 / f)
        if abs(lag - 1.0 / f) < 1e-6 and line.size > lag:
            lagged = np.abs(line[lag:] - line[:-lag])
            q25 = min(q25, float(np.percentile(lagged, 25.0)) / _Q25_HALF_NORMAL)
    return min(prep.noise_sigma, q25)


#: A profile is two-level (sharp bars) when at least this share of its samples lies within
#: :data:`PLATEAU_TOLERANCE` of the range (or 3 noise sigmas) of its minimum or maximum.
PLATEAU_SHARE = 0.5
PLATEAU_TOLERANCE = 0.05


def _two_level(profile: npt.NDArray[np.float64], noise: float) -> bool:
    """Whether ``profile`` sits mostly on two plateaus (sharp bars), not on a blurred wave
    (whose reading is the estimators' job: blur is not an extreme)."""
    lo, hi = float(profile.min()), float(profile.max())
    tol = max(3.0 * noise, PLATEAU_TOLERANCE * (hi - lo))
    on = (profile <= lo + tol) | (profile >= hi - tol)
    return float(np.count_nonzero(on)) >= PLATEAU_SHARE * profile.size


def _measured_noise(prep: PreparedROI) -> float:
    """The ROI's noise as measured, without the codes' rounding floor: along the bars, or
    along the line of a one-pixel-wide ROI (:func:`_line_noise`); the given noise if given."""
    if prep.noise_given:
        return prep.noise_sigma
    img = prep.pixels
    if min(img.shape) == 1:
        return _line_noise(prep, img.ravel())
    return robust_noise_sigma(img, prep.axis)


def _plain_profile(prep: PreparedROI) -> tuple[npt.NDArray[np.float64], float, float] | None:
    """A profile across the bars that plainly shows at least one bar period, its noise sigma
    for the test and its noise sigma for the margin; else ``None``.

    Plain: :data:`MIN_CROSSINGS` swings between its lower and upper quarters, a range of
    :data:`PLAIN_RANGE_SIGMAS` noise sigmas (never below the rounding to whole codes), and
    either sharp bars (:func:`_two_level`; then one swing, a sharp edge, is enough: a
    one-period ROI may hold only one) or a clipped level: a blurred wave the estimator calls
    "not resolved" keeps its answer.
    Tried in turn: the line-averaged profile along the detected axis, along the other axis,
    then the middle row and the middle column alone (oblique bars average out along an axis);
    a one-pixel-wide ROI is its own profile (:func:`_line_noise`)."""
    img = prep.pixels
    rows, cols = img.shape
    clipped = bright_clipped(prep) or dark_clipped(prep)
    # Rounding to whole codes; not the ROI's code step, which on two-level data is their gap.
    quant = quantisation_sd(prep.integer_valued, 1.0)
    # (profile, lines averaged, per-pixel noise); the ROI's noise is measured along the bars.
    candidates: list[tuple[npt.NDArray[np.float64], int, float]] = []
    if min(rows, cols) == 1:
        line = img.ravel()
        candidates.append((line, 1, _line_noise(prep, line)))
    else:
        # Given, or measured without the code step's rounding floor (noise-free data have none).
        noise = prep.noise_sigma if prep.noise_given else robust_noise_sigma(img, prep.axis)
        for axis in (prep.axis, 1 - prep.axis):
            candidates.append((img.mean(axis=1 - axis), img.shape[1 - axis], noise))
        # Oblique bars average out along an axis, but a line still crosses them sharply.
        candidates += [(line, 1, min(noise, _line_noise(prep, line)))
                       for line in (img[rows // 2, :], img[:, cols // 2])]
    for profile, lines, noise_px in candidates:
        if profile.size < 2:
            continue
        test = max(noise_px, quant) / math.sqrt(lines)
        margin = (noise_px if noise_px > quant * 1.0001 else 0.0) / math.sqrt(lines)
        span = float(profile.max() - profile.min())
        if span <= 0.0 or span < PLAIN_RANGE_SIGMAS * test:
            continue
        # Sharp bars show themselves in one edge (a one-period ROI may hold only one).
        sharp = _two_level(profile, margin)
        if (sharp or clipped) and _swings(profile) >= (1 if sharp else MIN_CROSSINGS):
            return profile, test, margin
    return None


def _fallback(prep: PreparedROI, r: ModulationResult) -> ModulationResult | None:
    """A bound (or the exact 1 of a dark level of 0) from the extremes of a plainly resolved
    profile, for a reading that said "not resolved"; ``None`` when the bars are not plain."""
    plain = _plain_profile(prep)
    if plain is None:
        return None
    profile, noise, margin_sd = plain
    margin = EXTREME_MARGIN_SIGMAS * margin_sd
    dark = float(profile.min()) + margin
    bright = float(profile.max()) - margin
    if bright <= dark or bright + dark <= 0.0:
        return None
    span = float(profile.max() - profile.min())
    # One voice: the estimator's "bars not resolved" becomes the reason in this one line.
    failed = [w for w in r.warnings if w.endswith(NOT_RESOLVED)]
    kept = tuple(w for w in r.warnings if w not in failed)
    why = "; ".join(w.removesuffix(NOT_RESOLVED) for w in failed) or "its reading discarded"
    note = (f"bars plainly resolved (profile range {span / noise if noise else math.inf:.3g} "
            f"noise sigmas) but {r.estimator} could not read them ({why})")
    if dark == 0.0:
        # A dark level of exactly 0: Eq. 2.9 is 1 whatever the bright level.
        return r.with_updates(dark=0.0, bright=bright, modulation=1.0, resolved=True,
                              uncertainty=0.0, interval=(1.0, 1.0),
                              warnings=(*kept, f"{note}: dark level 0, contrast 1"))
    m = min(eq29_modulation(dark, bright), 1.0)
    # Noise of the levels propagated through Eq. 2.9 (dM/dD = -2B/S^2, dM/dB = 2D/S^2).
    total = dark + bright
    sd = 2.0 * margin_sd * math.hypot(bright, dark) / total**2
    reason = (f"{note}: the contrast of the profile's extremes (moved {EXTREME_MARGIN_SIGMAS:g} "
              "noise sigmas inwards) is a lower bound")
    return r.with_updates(dark=dark, bright=bright, modulation=m, resolved=True, uncertainty=sd,
                          interval=(max(0.0, m - 1.96 * sd), 1.0), lower_bound=True,
                          bound_reason=reason, warnings=(*kept, f"lower bound: {reason}"))


def honest_reading(prep: PreparedROI, r: ModulationResult) -> ModulationResult:
    """``r`` as a bound where clipping makes it one, and a bound instead of "not resolved" for a
    plainly resolved pattern; see the module docstring.

    Parameters
    ----------
    prep : PreparedROI
        The ROI the reading was made on.
    r : ModulationResult
        An estimator's reading of it.

    Returns
    -------
    ModulationResult
        ``r`` itself when none of the extremes applies.
    """
    if (not r.measurable or r.diagnostics.aliased or prep.vmax == prep.vmin
            or prep.freq_cycles_per_px == 0):  # a frequency of 0 asks for no bars
        return r
    if not r.resolved:
        fallback = _fallback(prep, r)
        return r if fallback is None else fallback
    if r.lower_bound or r.dark is None or r.bright is None or r.modulation < 0.0:
        return r  # a contrast reversal (knownbars) is no clipped reading
    if prep.vmin == 0.0 and r.modulation > 0.0 and _measured_noise(prep) == 0.0:
        # Noise-free pixels at exactly 0: the dark level is 0 (no pixel lies below it), so
        # Eq. 2.9 is exactly 1 - whatever the bright level and the estimator's smoothing.
        return r.with_updates(dark=0.0, modulation=1.0, uncertainty=0.0, interval=(1.0, 1.0),
                              lower_bound=False, bound_reason="")
    near_zero = prep.vmin <= ZERO_SIGMAS * prep.noise_sigma  # the data reach a dark level 0
    if r.dark < 0.0 and not near_zero:
        # A dark level below zero where every pixel is well above it: negative light, a fit
        # that ran off (a censored model on sharp clipped bars read dark -67 for pixels of 96).
        fallback = _fallback(prep, r.with_updates(warnings=(
            *r.warnings, f"fitted dark level {r.dark:.3g} below zero, pixels from "
            f"{prep.vmin:.3g}: reading discarded")))
        if fallback is not None:
            return fallback
    if r.modulation >= 1.0 - ONE_TOLERANCE and near_zero:
        # Dark level 0 (to rounding): Eq. 2.9 is 1 whatever the bright level - and no contrast
        # exceeds 1, so a bound there is the value.
        return r if r.modulation == 1.0 else r.with_updates(modulation=1.0)
    top = prep.max_code or math.inf
    censored = r.estimator in CENSORING and r.bright > top
    if censored and bright_clipped(prep) and r.uncertainty > CENSORED_VALUE_MAX_SD:
        # The model's bright level above the code is too uncertain to be a value (issue 37:
        # over-exposed ROIs read values neither right nor bounds): the reading with the
        # bright level held at the code is a bound.
        m = eq29_modulation(r.dark, top)
        r = r.with_updates(bright=top, modulation=m,
                           interval=(max(0.0, m - 1.96 * r.uncertainty), 1.0))
        censored = False
    if bright_clipped(prep) and not censored:
        return _as_bound(_within_data(prep, r), _bound_reason(prep, bright=True))
    if dark_clipped(prep) and r.modulation < 1.0:
        return _as_bound(r, _bound_reason(prep, bright=False))
    return r
