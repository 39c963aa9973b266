"""Property tests of the extremes (issue 29): no perfect bar pattern is ever "not resolved",
and clipped bars read as a bound (or, from a censoring model, a value) consistent with the
truth - never a plain value an estimator read from clipped codes."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from benchlab.analysis.bars.estimators import ESTIMATORS, estimate_modulation
from benchlab.analysis.bars.extremes import CENSORING
from benchlab.analysis.bars.result import CLIPPED_FRACTION_LIMIT
from benchlab.synthetic.bars import BarCase, render

#: A bound may exceed the truth by the codes' rounding and the noise of its levels.
BOUND_SLACK = 0.02
#: A censoring model's value (profilefit) within this of the truth.
VALUE_TOL = 0.05

FAST = settings(max_examples=40, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow])


@st.composite
def perfect_bars(draw: st.DrawFn) -> BarCase:
    """Noise-free, perfectly sharp, axis-aligned bars: any period from 4 px, phase, levels
    (dark 0 included), clipped or not, 8-bit, 12-bit or 12-bit MSB-aligned, ROIs from one
    pixel wide to 40 x 50 spanning at least two periods. (From 5 px per period: a single line
    at 4 px per period with its edges mid-pixel reads 40 48 40 32 ..., a sampled triangle that
    no test tells from a sine in noise; one-pixel-wide lines of 0.2 contrast, 16 codes, are
    left to the estimators - docs/analysis/extremes.md.)"""
    period = draw(st.floats(5.0, 24.0))
    bits, msb = draw(st.sampled_from([(8, False), (12, False), (12, True)]))
    vertical = draw(st.booleans())
    length = draw(st.integers(max(int(2 * period) + 1, 30), 60))
    width = draw(st.sampled_from([1, 7, 40]))
    modulation = draw(st.sampled_from([0.5, 0.8, 1.0] if width == 1 else [0.2, 0.5, 0.8, 1.0]))
    shape = (length, width) if vertical else (width, length)
    return BarCase(shape=shape, px_per_period=period, angle_deg=90.0 if vertical else 0.0,
                   modulation=modulation,
                   mean=draw(st.floats(40.0, 160.0)), psf_sigma_px=0.0, noise_sigma=0.0,
                   phase=draw(st.floats(0.0, 1.0)),
                   exposure_scale=draw(st.sampled_from([1.0, 1.0, 2.0])), bits=bits,
                   msb_aligned=msb)


@FAST
@given(case=perfect_bars(), name=st.sampled_from(sorted(ESTIMATORS)),
       freq_given=st.booleans())
def test_no_perfect_pattern_is_ever_not_resolved(case: BarCase, name: str,
                                                 freq_given: bool) -> None:
    roi = render(case, np.random.default_rng(0))
    # A one-pixel-wide line needs its frequency (the procedures always give it): without it,
    # 20 50 60 50 20 ... cannot be told from noise by its neighbour differences alone.
    freq_given = freq_given or min(case.shape) == 1
    r = estimate_modulation(roi, estimator=name,
                            freq_cycles_per_px=case.freq_cycles_per_px if freq_given else None)
    assert r.resolved, r.warnings
    if case.modulation == 1.0:  # dark level 0: exactly 1, whatever the bright level
        assert r.modulation == 1.0 and not r.lower_bound, r.warnings
    elif r.lower_bound:
        assert r.modulation <= case.truth + BOUND_SLACK, (r.modulation, case.truth, r.warnings)


@st.composite
def clipped_bars(draw: st.DrawFn) -> BarCase:
    """Resolved bars whose bright level really clips: any angle, blur up to 1.5 px, read noise
    up to 2 gray levels, 8/12-bit, 40 x 50 ROIs of at least two periods."""
    modulation, mean = draw(st.floats(0.3, 0.9)), draw(st.floats(90.0, 150.0))
    # the bright level 1.1-1.8 times full scale
    exposure = draw(st.floats(1.1, 1.8)) * 255.0 / (mean * (1.0 + modulation))
    return BarCase(shape=(40, 50), px_per_period=draw(st.floats(6.0, 20.0)),
                   angle_deg=draw(st.sampled_from([0.0, 90.0, 20.0, 45.0])),
                   modulation=modulation, mean=mean,
                   psf_sigma_px=draw(st.sampled_from([0.0, 0.5, 1.5])),
                   noise_sigma=draw(st.sampled_from([0.0, 0.7, 2.0])),
                   phase=draw(st.floats(0.0, 1.0)), exposure_scale=exposure,
                   bits=draw(st.sampled_from([8, 12])), msb_aligned=draw(st.booleans()))


@FAST
@given(case=clipped_bars(), name=st.sampled_from(sorted(ESTIMATORS)))
def test_clipped_bars_read_as_a_bound_consistent_with_the_truth(case: BarCase,
                                                                name: str) -> None:
    roi = render(case, np.random.default_rng(1))
    r = estimate_modulation(roi, estimator=name, freq_cycles_per_px=case.freq_cycles_per_px)
    # Blur can keep the imaged bright level under full scale: then nothing is clipped.
    assume(r.diagnostics.clipped_fraction > CLIPPED_FRACTION_LIMIT)
    axis = case.angle_deg in (0.0, 90.0)
    if axis or name not in ("sinefit", "variance"):
        # plainly resolved bars: never "not resolved" (sinefit and variance read oblique bars
        # along an axis and say so)
        assert r.resolved, r.warnings
    if r.lower_bound:
        assert r.bound_reason and r.shown.startswith("\u2265 ")
        assert r.modulation <= case.truth + BOUND_SLACK, (r.modulation, case.truth)
    elif r.resolved:
        # A value from clipped data only from a model carrying the level above full scale.
        assert name in CENSORING, (name, r.modulation, r.warnings)
        assert r.bright is not None and r.diagnostics.saturation_code is not None
        assert r.bright > r.diagnostics.saturation_code
        # The model's estimate: near the truth, or its (wider) interval holds it.
        lo, hi = r.interval
        assert (abs(r.modulation - case.truth) <= VALUE_TOL
                or lo - VALUE_TOL <= case.truth <= hi + VALUE_TOL), (r.modulation, r.interval,
                                                                     case.truth)
