"""The slanted-edge SFR's fast paths give the numbers of the plain formulas they replace: the
DFT from two small exponential tables, the window as a sum of products, the mean sinc of the
gaps, medians and means without numpy's overhead, the closed-form quadratic, the centroids
with one shared window, the outlier limits computed only where a pixel can exceed them."""

from __future__ import annotations

import math

import numpy as np
import pytest

import benchlab.analysis.sfr.measure as sfr
from benchlab.analysis.sfr.measure import (
    FREQ_STEP_CYCLES_PER_PX,
    FREQS_CYCLES_PER_PX,
    LsfWindow,
    measure_sfr,
    window_matrix,
    window_terms,
)
from benchlab.synthetic.edges import synthetic_edge

WINDOWS = (LsfWindow(4.9, 7.4, 0.0, 0.0), LsfWindow(3.1, 4.0, 0.15, 0.3),
           LsfWindow(2.0, 3.6, 0.375, 0.5625))


def _iterative_window(windows: tuple[LsfWindow, ...], x: np.ndarray,
                      f: np.ndarray) -> np.ndarray:
    """The window as first written: each narrower one blended over the last, per frequency."""
    def tukey(v: np.ndarray, flat: float, total: float) -> np.ndarray:
        a = np.abs(v)
        w = np.ones_like(a)
        taper = (a > flat) & (a < total)
        w[taper] = 0.5 * (1.0 + np.cos(math.pi * (a[taper] - flat) / (total - flat)))
        w[a >= total] = 0.0
        return w

    win = np.broadcast_to(tukey(x, windows[0].flat_half_px, windows[0].total_half_px),
                          (f.size, x.size))
    for w in windows[1:]:
        blend = tukey(f, w.from_cycles_per_px, w.full_from_cycles_per_px)
        win = blend[:, None] * win + (1.0 - blend)[:, None] * tukey(x, w.flat_half_px,
                                                                    w.total_half_px)
    return np.asarray(win)


@pytest.mark.parametrize("n", [1, 37, 300, 600])  # 600: several chunks below BLAS threading
def test_grid_dft_is_the_direct_dft(n: int) -> None:
    rng = np.random.default_rng(n)
    x = np.sort(rng.uniform(-20.0, 20.0, n))
    values = rng.normal(size=(3, n))
    tables = sfr._GridTables.of(x, FREQ_STEP_CYCLES_PER_PX, FREQS_CYCLES_PER_PX.size)
    got = tables.dft(values)
    direct = np.exp(2j * math.pi * np.outer(FREQS_CYCLES_PER_PX, x)) @ values.T
    assert got.shape == (FREQS_CYCLES_PER_PX.size, 3)
    assert float(np.max(np.abs(got - direct))) < 1e-10 * max(1.0, float(np.abs(values).sum()))
    rows = tables.rows(4)
    assert np.allclose(rows, np.exp(2j * math.pi * np.outer(FREQS_CYCLES_PER_PX[::4], x)),
                       atol=1e-12)


def test_window_terms_rebuild_the_blended_window() -> None:
    x = np.linspace(-8.0, 8.0, 65)
    f = FREQS_CYCLES_PER_PX
    want = _iterative_window(WINDOWS, x, f)
    blends, shapes = window_terms(WINDOWS, x, f)
    assert np.allclose(blends @ shapes, want, atol=1e-14)
    assert np.allclose(window_matrix(WINDOWS, x, f), want, atol=1e-14)
    # Flat top 1, beyond the taper 0, exactly.
    assert window_matrix(WINDOWS[:1], np.array([0.0, 4.9, 7.4, 9.0]), f[:1]).tolist() == \
        [[1.0, 1.0, 0.0, 0.0]]


def test_mean_sinc_is_the_weighted_sinc_and_takes_zero_gaps() -> None:
    rng = np.random.default_rng(3)
    gaps = np.round(rng.uniform(0.05, 0.8, 50), 4)
    gaps[[4, 9]] = 0.0  # two samples at the same place: sinc(0) = 1
    weight = rng.uniform(0.0, 2.0, 50)
    f = FREQS_CYCLES_PER_PX
    want = (np.sinc(np.outer(f, gaps)) @ weight) / weight.sum()
    assert np.allclose(sfr._mean_sinc(gaps, weight, f), want, atol=1e-12)


@pytest.mark.parametrize("values", [
    np.array([3.0, -1.0, 7.5, 2.0, 2.0]),
    np.arange(10, dtype=np.int64)[::-1],
    np.random.default_rng(1).normal(size=(40, 37)),
])
def test_finite_median_and_mean_are_numpys(values: np.ndarray) -> None:
    assert sfr._finite_median(values) == float(np.median(values))
    assert sfr._mean(values) == float(np.mean(values))


def test_quadratic_fit_is_polyfit() -> None:
    rng = np.random.default_rng(5)
    x = np.linspace(-0.03, 0.03, 13)
    y = 0.4 - 3.0 * x + 20.0 * x * x + rng.normal(0.0, 0.01, x.size)
    assert np.allclose(sfr._quadratic_fit(x, y), np.polyfit(x, y, 2), rtol=1e-9, atol=1e-12)


def test_polyval_is_numpys() -> None:
    c = np.array([0.3, -1.2, 4.0])
    x = np.linspace(-5.0, 5.0, 11)
    assert np.array_equal(sfr._polyval(c, x), np.polyval(c, x))
    assert sfr._polyval(c, 2.0) == float(np.polyval(c, 2.0))


def test_one_shared_centre_gives_the_per_row_centroids() -> None:
    rng = np.random.default_rng(7)
    deriv = rng.normal(1.0, 0.5, (30, 40))
    shared = sfr._row_centroids(deriv, 17.3, 20.0)
    per_row = sfr._row_centroids(deriv, np.full(30, 17.3), 20.0)
    assert np.array_equal(shared, per_row)


def test_outlier_limits_only_where_a_pixel_can_exceed_them() -> None:
    # The clipped pixels and their new values are those of the limit computed everywhere.
    rng = np.random.default_rng(11)
    img = synthetic_edge((60, 70), 6.0, 1.0, noise_sigma=0.004, rng=rng)
    img[[5, 20, 40], [10, 35, 60]] += [0.3, -0.25, 0.2]
    res = measure_sfr(img, method="free")
    assert any("3 pixel(s)" in w for w in res.warnings)
    u = rng.uniform(-30.0, 30.0, (60, 70))
    esf_u = np.linspace(-30.0, 30.0, 241)
    s = sfr._Samples(esf_u, 0.2 + 0.6 * (esf_u > 0), np.zeros(241), np.full(241, 17.0), 0.0)
    noise = sfr._NoiseModel(0.2, 0.8, 1e-5, 4e-5)
    work = np.interp(u, s.u, s.esf) + rng.normal(0.0, 0.005, u.shape)
    work[3, 4] += 0.5
    work[50, 60] -= 0.4
    got, n = sfr._clip_outliers(u, work, s, noise)
    pred = np.interp(u, s.u, s.esf)
    curv = np.zeros_like(s.esf)
    curv[1:-1] = np.abs(np.diff(s.esf, 2))
    limit = (sfr.OUTLIER_SIGMAS * np.sqrt(noise.pixel_var(pred))
             + 0.25 * np.interp(u, s.u, curv) + sfr.OUTLIER_FLOOR_OF_STEP * 0.6)
    out = np.abs(work - pred) > limit
    assert n == int(out.sum()) >= 2
    assert np.array_equal(got, np.where(out, pred + np.clip(work - pred, -limit, limit), work))
    # A transposed (Fortran-ordered) work frame is clipped at the same pixels.
    got_t, n_t = sfr._clip_outliers(u, np.asfortranarray(work), s, noise)
    assert n_t == n and np.array_equal(got_t, got)
