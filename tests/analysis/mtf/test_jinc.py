"""benchlab.analysis.mtf.jinc: the numpy-only ``2 J1(x) / x`` that replaced scipy.special.j1 in the
chart reading's defocus family (start-up, issue 11), checked against scipy."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.special import j0 as scipy_j0
from scipy.special import j1 as scipy_j1

from benchlab.analysis.bars.knownbars import disc_gain
from benchlab.analysis.mtf import jinc as jinc_module
from benchlab.analysis.mtf.jinc import (
    HANKEL_MIN_X,
    JINC_MAX_ERROR,
    SERIES_MAX_X,
    TABLE_MAX_X,
    TABLE_STEP,
    bessel_j0_j1,
    jinc,
)

#: Every region of both evaluations, densely (steps far finer than the table's).
GRID = np.concatenate([np.linspace(0.0, 64.0, 640_001), np.linspace(64.0, 3000.0, 300_001)])


def _scipy_jinc(x: np.ndarray) -> np.ndarray:
    out = np.ones_like(x)
    nz = x != 0
    out[nz] = 2.0 * scipy_j1(x[nz]) / x[nz]
    return out


@pytest.mark.slow
def test_bessel_j0_j1_match_scipy_to_near_double_precision() -> None:
    j0, j1 = bessel_j0_j1(GRID)
    assert np.max(np.abs(j0 - scipy_j0(GRID))) <= 3e-14
    assert np.max(np.abs(j1 - scipy_j1(GRID))) <= 3e-14


def test_bessel_region_boundaries_are_continuous() -> None:
    for edge in (SERIES_MAX_X, HANKEL_MIN_X):
        x = np.array([np.nextafter(edge, 0.0), edge, np.nextafter(edge, 100.0)])
        j0, j1 = bessel_j0_j1(x)
        assert np.all(np.abs(np.diff(j0)) < 1e-13) and np.all(np.abs(np.diff(j1)) < 1e-13)


def test_jinc_matches_scipy_within_its_stated_error_everywhere() -> None:
    err = np.abs(jinc(GRID) - _scipy_jinc(GRID))
    assert np.max(err) <= JINC_MAX_ERROR
    # beyond the table (Hankel's expansion) and at the table's nodes it is tighter still
    assert np.max(err[GRID >= TABLE_MAX_X]) <= 1e-12
    nodes = np.arange(0.0, 200.0, TABLE_STEP)
    assert np.max(np.abs(jinc(nodes) - _scipy_jinc(nodes))) <= 1e-13


def test_jinc_values_shape_and_symmetry() -> None:
    assert float(jinc(0.0)) == 1.0
    x = np.linspace(-50.0, 50.0, 2001).reshape(3, 667)
    out = jinc(x)
    assert out.shape == x.shape and out.dtype == np.float64
    np.testing.assert_array_equal(out, jinc(-x))
    # the first zero (3.8317) and the negative lobe up to the second (7.0156)
    assert jinc(3.83) > 0 > jinc(3.84) and jinc(7.01) < 0 < jinc(7.02)
    assert jinc(np.array([TABLE_MAX_X - 1e-9, TABLE_MAX_X, 1e6])).shape == (3,)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_jinc_refuses_non_finite_input(bad: float) -> None:
    with pytest.raises(ValueError, match="finite"):
        jinc(np.array([1.0, bad]))


@pytest.mark.parametrize("bad", [-1e-9, np.nan, np.inf])
def test_bessel_refuses_negative_or_non_finite_input(bad: float) -> None:
    with pytest.raises(ValueError, match="x >= 0"):
        bessel_j0_j1(np.array([1.0, bad]))


def test_disc_gain_is_jinc_of_2_pi_r_f() -> None:
    radius, freqs = np.array([0.0, 0.6, 3.0]), np.linspace(0.0, 25.0, 1001)
    gain = disc_gain(radius, freqs)
    assert gain.shape == (3, 1001)
    np.testing.assert_array_equal(gain[0], 1.0)
    np.testing.assert_allclose(gain, _scipy_jinc(2.0 * np.pi * np.outer(radius, freqs)),
                               rtol=0, atol=JINC_MAX_ERROR)


def test_table_is_built_once_per_process() -> None:
    jinc(1.0)
    table = jinc_module._table
    jinc(np.linspace(0.0, 10.0, 7))
    assert jinc_module._table is table


def test_the_defocus_family_imports_no_scipy() -> None:
    """Importing scipy.special for j1 cost ~0.2 s of CPU per re-analysis."""
    code = ("import sys, json, numpy as np; import benchlab.analysis.bars.knownbars as kb; "
            "kb.disc_gain([1.0], np.linspace(0, 25, 64)); "
            "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=60)
    assert json.loads(done.stdout) == []
