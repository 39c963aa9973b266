"""ROIs whose pixel values span less than ``MIN_CONTRAST`` (1e-100; e.g. bars scaled by
1e-200, or zeros beside a few subnormal values): the fits' squares underflow there -
profilefit divided by zero (``(bright + dark)**2``) and overflowed (its scaled pseudo-inverse)
with RuntimeWarnings and NaN uncertainties, sinefit read 0.215 for 0.238. Every estimator now
reads them as flat, with the warning, and no RuntimeWarning; just above the bound they read
what the same bars read at any scale."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_analysis_extremes import check_labelled

from benchlab.analysis import ESTIMATORS, estimate_modulation
from benchlab.analysis.bars.profilefit import profile_fit
from benchlab.analysis.bars.roi import MIN_CONTRAST, TINY_CONTRAST_WARNING, prepare_roi
from benchlab.synthetic.bars import BarCase, render

NAMES = sorted(ESTIMATORS)


def _bars() -> np.ndarray:
    return render(BarCase(shape=(30, 40), px_per_period=8.0, angle_deg=10.0, noise_sigma=2.0),
                  np.random.default_rng(0)).astype(np.float64) + 0.25


def _sharp_cancelling(a: float) -> np.ndarray:
    """Noise-free square bars of -a and a few ulps above a: the profilefit levels nearly
    cancel (its scaled pseudo-inverse overflowed up to a ~ 1e-144)."""
    row = np.where(np.arange(48) % 8 < 4, -a, a * (1 + 2.0**-52))
    return np.tile(row, (12, 1))


def _tiny_rois() -> dict[str, np.ndarray]:
    subnormal = np.zeros((9, 7))
    subnormal[::2, 1::3] = 5e-324
    return {
        "bars-1e-200": _bars() * 1e-200,  # the reported one: divide by zero at (b + d)**2
        "bars-1e-170": _bars() * 1e-170,
        "bars-1e-120": _bars() * 1e-120,
        "sharp-cancelling-1e-146": _sharp_cancelling(1e-146),
        "zeros-and-subnormals": subnormal,
        "negative-1e-300": -_bars() * 1e-300,
    }


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("case", sorted(_tiny_rois()))
def test_tiny_contrast_reads_as_flat_without_runtime_warnings(name: str, case: str) -> None:
    roi = _tiny_rois()[case]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = estimate_modulation(roi, estimator=name, freq_cycles_per_px=0.125)
        bare = profile_fit(prepare_roi(roi, freq_cycles_per_px=0.125))  # without the wrapper
    check_labelled(r)
    assert not r.resolved and TINY_CONTRAST_WARNING in r.warnings
    check_labelled(bare)
    assert not bare.resolved and TINY_CONTRAST_WARNING in bare.warnings


@pytest.mark.parametrize("name", ["profilefit", "profilefit-fast", "sinefit", "variance"])
def test_contrast_just_above_the_bound_reads_as_at_any_tiny_scale(name: str) -> None:
    """Bars spanning 8e-100 (just above the bound) read what the same bars scaled by 2^-200
    read (a power of two: the same arithmetic, exponents apart), without a RuntimeWarning:
    the bound rejects no readable ROI."""
    bars = _bars()
    near_scale = 2.0**-336
    assert MIN_CONTRAST < float(bars.max() - bars.min()) * near_scale < 10 * MIN_CONTRAST
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        near = estimate_modulation(bars * near_scale, estimator=name, freq_cycles_per_px=0.125)
        far = estimate_modulation(bars * 2.0**-200, estimator=name, freq_cycles_per_px=0.125)
    assert near.resolved and far.resolved
    assert near.modulation == pytest.approx(far.modulation, rel=1e-12)
    assert near.uncertainty == pytest.approx(far.uncertainty, rel=1e-9)
    assert TINY_CONTRAST_WARNING not in near.warnings


def test_single_valued_float_rois_are_flat() -> None:
    """All-zero and single-valued float ROIs (tiny or not): flat, never resolved - sinefit and
    variance read rounding residue (1e-17) as bars above a noise of 0 (e.g. 0.3, 77.3)."""
    for value in (0.0, 1e-300, 1e-100, 0.1, 0.3, 77.3, 1e100):
        roi = np.full((10, 12), value)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            for name in NAMES:
                r = estimate_modulation(roi, estimator=name, freq_cycles_per_px=0.125)
                check_labelled(r)
                assert not r.resolved, (value, name)
                assert TINY_CONTRAST_WARNING not in r.warnings
                assert any("gray level" in w for w in r.warnings), (value, name, r.warnings)
