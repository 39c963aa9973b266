"""benchlab.analysis.normal_cdf.ndtr: the numpy-only normal CDF that replaced
scipy.special.ndtr (start-up time), checked against scipy and against a 50-digit reference."""

from __future__ import annotations

import math
from decimal import Decimal, getcontext

import numpy as np
import pytest
from scipy.special import ndtr as scipy_ndtr

from benchlab.analysis.normal_cdf import ROOT32, THRESHOLD, X_HIGH, X_LOW, ndtr


def _upper_tail_50_digits(x: float) -> Decimal:
    """``Q(x) = 1 - Phi(x)`` for x >= 5 by Laplace's continued fraction, 50 digits."""
    getcontext().prec = 50
    d = Decimal(x)
    cf = Decimal(0)
    for k in range(4000, 0, -1):
        cf = Decimal(k) / (d + cf)
    two_pi = 2 * Decimal("3.14159265358979323846264338327950288419716939937510")
    return (-(d * d) / 2).exp() / two_pi.sqrt() / (d + cf)


def test_matches_scipy_to_double_precision_on_a_dense_grid() -> None:
    x = np.linspace(-40.0, 10.0, 500_001)
    ours, ref = ndtr(x), scipy_ndtr(x)
    assert np.max(np.abs(ours - ref)) <= 2.3e-16
    # Relative error where Phi is a normal double: scipy rounds x / sqrt(2), which costs it
    # ~x^2 eps relative in the lower tail (2.4e-13 at x = -37): the bound grows with x^2.
    normal = ref > 1e-300
    rel = np.abs(ours[normal] - ref[normal]) / ref[normal]
    assert np.all(rel <= (x[normal] ** 2 + 8.0) * 2.3e-16)


@pytest.mark.parametrize("x", [5.0, 6.0, 9.15, 21.2, 30.17, 36.9])
def test_far_tail_keeps_full_relative_precision(x: float) -> None:
    truth = _upper_tail_50_digits(x)
    assert abs(Decimal(float(ndtr(-x))) - truth) / truth < (2e-15 if x < ROOT32 else 4e-16)


def test_region_boundaries_are_continuous() -> None:
    for edge in (THRESHOLD, ROOT32):
        for sign in (-1.0, 1.0):
            x = sign * np.array([np.nextafter(edge, 0.0), edge, np.nextafter(edge, 10.0)])
            values = ndtr(x)
            assert np.all(np.abs(np.diff(values)) < 1e-15)
            assert np.all(np.abs(values - scipy_ndtr(x)) <= 2.3e-16)


def test_values_symmetry_and_saturation() -> None:
    assert ndtr(0.0) == 0.5
    assert ndtr(-0.0) == 0.5
    assert float(ndtr(1.0)) == pytest.approx(0.5 * math.erfc(-1.0 / math.sqrt(2.0)), rel=1e-15)
    x = np.linspace(-8.0, 8.0, 1601)
    assert np.max(np.abs(ndtr(x) + ndtr(-x) - 1.0)) <= 2.3e-16
    assert np.all(np.diff(ndtr(np.linspace(-37.0, 8.0, 100_001))) >= 0.0)  # monotone
    assert ndtr(X_LOW - 1e-9) == 0.0 and ndtr(-1e300) == 0.0
    assert ndtr(X_HIGH) == 1.0 and ndtr(1e300) == 1.0


def test_special_values_shapes_and_dtypes() -> None:
    out = ndtr(np.array([np.nan, -np.inf, np.inf]))
    assert np.isnan(out[0]) and out[1] == 0.0 and out[2] == 1.0
    assert ndtr(0.3).shape == () and ndtr(0.3).dtype == np.float64
    grid = np.arange(12.0).reshape(3, 4) - 6.0
    assert ndtr(grid).shape == (3, 4)
    np.testing.assert_array_equal(ndtr(grid), ndtr(grid.ravel()).reshape(3, 4))
    strided = np.linspace(-3.0, 3.0, 20)[::3]  # non-contiguous input
    np.testing.assert_allclose(ndtr(strided), scipy_ndtr(strided), rtol=0, atol=2.3e-16)
    assert ndtr(np.array([1, 2], dtype=np.int32)).dtype == np.float64
    assert ndtr(np.empty(0)).shape == (0,)
    assert ndtr([[-1.0], [1.0]]).shape == (2, 1)


def test_uninitialised_scratch_never_warns(monkeypatch: pytest.MonkeyPatch) -> None:
    """The centre region's scratch entries are never computed on (np.empty may hold NaN)."""
    import warnings

    import benchlab.analysis.normal_cdf as module

    def signalling_nans(a: np.ndarray, *args: object, **kwargs: object) -> np.ndarray:
        # What an uninitialised buffer may hold: a signalling NaN raises "invalid" when used.
        return np.full(np.shape(a), 0x7FF0000000000001, dtype=np.uint64).view(np.float64)

    monkeypatch.setattr(module.np, "empty_like", signalling_nans)
    x = np.array([-9.0, -3.0, -0.2, 0.0, 0.3, 0.6, 2.0, 9.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = ndtr(x)
    np.testing.assert_allclose(got, scipy_ndtr(x), rtol=1e-13, atol=0.0)
