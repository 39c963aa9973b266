"""benchlab.analysis.quantiles: numpy.percentile's default method and numpy.median bit for bit
(type, shape and every bit of the value), without importing numpy.ma (start-up of analyze
SESSION, issue 11)."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from benchlab.analysis.quantiles import median, percentile, percentiles

DTYPES = (np.float32, np.float64, np.uint8, np.uint16, np.int16)
SIZES = (1, 2, 3, 7, 100, 1001, 20_000)
QS = (0.0, 0.1, 2.0, 5.0, 15.87, 50.0, 98.0, 99.0, 99.9, 100.0)


def _same(ours: Any, numpy_says: Any) -> bool:
    a, b = np.asarray(ours), np.asarray(numpy_says)
    return (type(ours) is type(numpy_says) and a.dtype == b.dtype and a.shape == b.shape
            and a.tobytes() == b.tobytes())


def _sample(rng: np.random.Generator, dtype: Any, n: int) -> np.ndarray:
    if np.issubdtype(dtype, np.floating):
        return (rng.normal(100.0, 40.0, n) * rng.choice([1e-3, 1.0, 1e3])).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(max(info.min, -3000), min(info.max, 3000), n, endpoint=True,
                        dtype=dtype)


@pytest.mark.parametrize("dtype", DTYPES)
def test_bit_for_bit_numpys_percentile(dtype: Any) -> None:
    rng = np.random.default_rng(7)
    for n in SIZES:
        for _ in range(4):
            a = _sample(rng, dtype, n)
            shaped = a.reshape(-1, 1) if n % 2 else a  # any shape: the whole array
            assert _same(median(shaped), np.median(shaped)), n
            for q in (*QS, float(rng.uniform(0, 100))):
                assert _same(percentile(shaped, q), np.percentile(shaped, q)), (n, q)
            for qs in ((5.0, 99.0), [2.0, 98.0], [50.0, 15.87], list(rng.uniform(0, 100, 5))):
                assert _same(percentiles(shaped, qs), np.percentile(shaped, qs)), (n, qs)


def test_ties_plateaus_and_nan_as_numpy() -> None:
    flat = np.full(50, 3.25, np.float32)
    steps = np.repeat(np.arange(5, dtype=np.float64), 9)
    with_nan = np.array([1.0, np.nan, 2.0, 3.0], np.float32)
    for a in (flat, steps, with_nan, -steps, np.array([-0.0, 0.0])):
        for q in QS:
            assert _same(percentile(a, q), np.percentile(a, q)), (a, q)
        assert _same(percentiles(a, QS), np.percentile(a, QS))
        assert _same(median(a), np.median(a)) or (np.isnan(median(a))
                                                  and np.isnan(np.median(a)))
    assert np.isnan(percentile(with_nan, 10.0)) and np.isnan(median(with_nan))
    assert _same(median(np.arange(6, dtype=np.int16).reshape(2, 3)),
                 np.median(np.arange(6, dtype=np.int16).reshape(2, 3)))


def test_bad_percentiles_and_arrays_are_refused() -> None:
    for q in (-0.1, 100.5, float("nan")):
        with pytest.raises(ValueError, match="range"):
            percentile([1.0, 2.0], q)
    with pytest.raises(ValueError, match="range"):
        percentiles([1.0, 2.0], [50.0, 101.0])
    with pytest.raises(TypeError, match="real numbers"):
        percentile(np.array([1 + 1j]), 50.0)
    with pytest.raises(IndexError):
        percentile(np.array([], np.float32), 50.0)


def test_imports_no_numpy_ma() -> None:
    code = ("import sys, numpy as np; from benchlab.analysis.quantiles import percentile, "
            "percentiles, median; a = np.arange(10.0); percentile(a, 33.3); "
            "percentiles(a, [5, 95.5]); median(a); median(a[1:]); "
            "print('numpy.ma' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "False"
