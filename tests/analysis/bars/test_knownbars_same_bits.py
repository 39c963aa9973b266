"""The known-bar fit's shortcuts (issue 39) give the bits of the plain expressions they replace:
a re-analysis must write byte-identical CSVs. Each shortcut is pinned here to the code it
replaced (kept below as the reference) on many inputs, bit for bit: the Gaussian gain without
the exponentials of a zero rate nor those past a defocus row's cutoff, the pure disc's gain
unmultiplied, ``jinc`` from per-interval coefficients, the batch solve with the base products
once per set, and a set's tabulation taken from an earlier fit at the same geometry."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from benchlab.analysis.bars import knownbars as kb
from benchlab.analysis.bars.knownbars import fit_three_bars, three_bar_pattern
from benchlab.analysis.bars.projection import across_coordinate
from benchlab.analysis.chart.threebar import ReadingSetup, predict_reading
from benchlab.analysis.mtf import jinc as jinc_mod


def _plain_jinc(x: Any) -> Any:
    """``jinc`` as it was: the Hermite polynomial formed per value, the values beyond the table
    gathered apart."""
    xa = np.abs(np.asarray(x, dtype=np.float64))
    value, slope = jinc_mod._jinc_table()
    flat = xa.ravel()
    out = np.empty_like(flat)
    inside = flat < jinc_mod.TABLE_MAX_X
    out[inside] = _hermite(flat[inside], value, slope)
    far = flat[~inside]
    out[~inside] = 2.0 * jinc_mod._hankel(far, 1, terms=4) / far
    return out.reshape(xa.shape)


def _plain_tables(self: Any, sigmas: Any, disc_shares: Any = None) -> Any:
    """``_Blurred.tables`` as it was: every exponential before the underflow, every defocus
    row multiplied by the disc's gain and zeroed past its cutoff."""
    sigmas = np.asarray(sigmas, dtype=np.float64)
    share = np.zeros_like(sigmas) if disc_shares is None else np.asarray(disc_shares)
    gauss_var = sigmas * sigmas * (1.0 - share)
    gain = np.exp(np.outer((-2.0 * math.pi**2) * gauss_var, self.freqs2))
    disc = np.flatnonzero(share > 0)
    if disc.size:
        freqs = np.sqrt(self.freqs2)
        gv = gauss_var[disc]
        with np.errstate(divide="ignore"):
            limit = np.where(gv > 0, kb.GAUSS_CUTOFF / (2.0 * math.pi**2 * gv), np.inf)
        cols = np.searchsorted(self.freqs2, limit, side="right")
        radius = 2.0 * sigmas[disc] * np.sqrt(share[disc])
        for r, rad, k in zip(disc, radius, cols, strict=True):
            # as it was: 2 pi (R f) on whole rows, (2 pi R) f on rows cut short
            x = ((2.0 * math.pi) * np.outer([rad], freqs)[0] if k >= freqs.size
                 else (2.0 * math.pi) * rad * freqs[:k])
            gain[r, :k] *= _plain_jinc(x)
            gain[r, k:] = 0.0
    spec = np.empty(gain.shape, dtype=np.complex128)
    np.multiply(gain, self.spectrum.real, out=spec.real)
    np.multiply(gain, self.spectrum.imag, out=spec.imag)
    return np.fft.irfft(spec, n=self.n, axis=1)


def _plain_solve(base: Any, extra: Any, y: Any, ridge: Any) -> tuple[Any, Any, Any]:
    """``_solve_batch`` as it was (coefficients, cost, inverse normal matrices)."""
    m, kb_, k = extra[0].shape[0], base.shape[1], base.shape[1] + len(extra)
    cols = np.stack(extra, axis=1)
    gram = np.empty((m, k, k))
    gram[:, :kb_, :kb_] = base.T @ base
    cross = cols @ base
    gram[:, kb_:, :kb_] = cross
    gram[:, :kb_, kb_:] = cross.transpose(0, 2, 1)
    gram[:, kb_:, kb_:] = cols @ cols.transpose(0, 2, 1)
    if ridge is not None:
        gram[:, np.arange(k), np.arange(k)] += ridge
    inv = np.linalg.inv(gram)
    rhs = np.empty((m, k))
    rhs[:, :kb_] = base.T @ y
    rhs[:, kb_:] = cols @ y
    coef = (inv @ rhs[:, :, None])[:, :, 0]
    fitted = coef[:, :kb_] @ base.T + (coef[:, kb_:, None] * cols).sum(axis=1)
    resid = y[None, :] - fitted
    rss = np.einsum("mn,mn->m", resid, resid)
    penalty = (coef * coef) @ ridge if ridge is not None else np.zeros(m)
    return coef, rss + penalty, inv


def test_jinc_is_the_per_value_hermite_bit_for_bit() -> None:
    rng = np.random.default_rng(2)
    step = jinc_mod.TABLE_STEP
    for x in (rng.uniform(0.0, 3000.0, 200_000), rng.uniform(0.0, 8.0, 20_000),
              np.arange(0.0, 1500.0, step), np.arange(0.0, 1500.0, step) - 1e-12,
              np.array([0.0, -0.0, jinc_mod.TABLE_MAX_X, np.nextafter(jinc_mod.TABLE_MAX_X, 0),
                        1e6]),
              -rng.uniform(0.0, 2000.0, 1000), rng.uniform(0.0, 100.0, (30, 40))):
        assert jinc_mod.jinc(x).tobytes() == _plain_jinc(x).tobytes()


@pytest.mark.parametrize(("w", "theta_deg", "max_sigma"),
                         [(1.05, 0.0, 1.5), (1.3, 7.0, 1.5), (2.9, 33.0, 2.9), (6.0, 81.0, 4.0),
                          (9.0, 90.0, 4.0)])
def test_tables_are_the_plain_expressions_bit_for_bit(w: float, theta_deg: float,
                                                       max_sigma: float) -> None:
    """Every row of the blur family (Gaussian, half and whole defocus disc; the grids of
    :class:`knownbars._FitState`, and random ones) and the off-grid rows of a conclusion."""
    rng = np.random.default_rng(int(10 * w))
    pos = rng.uniform(-3.0 * w, 3.0 * w, 300)
    bars = [(c - 0.5 * w, c + 0.5 * w) for c in (-2 * w, 0.0, 2 * w)]
    blurred = kb._Blurred(pos, bars, math.radians(theta_deg), max_sigma)
    grid = max_sigma * np.linspace(0.0, 1.0, 32) ** 2
    coarse = grid[grid >= kb.DISC_MIN_SIGMA_PX]
    sigmas = np.concatenate([grid, coarse, coarse, rng.uniform(0.0, max_sigma, 20)])
    shares = np.concatenate([np.zeros(32), np.full(coarse.size, 0.5), np.full(coarse.size, 1.0),
                             rng.choice([0.0, 0.25, 0.5, 1.0], 20)])
    assert (blurred.tables(sigmas, shares).tobytes()
            == _plain_tables(blurred, sigmas, shares).tobytes())
    assert blurred.tables(grid).tobytes() == _plain_tables(blurred, grid).tobytes()
    for sigma, share in zip(sigmas[-20:], shares[-20:], strict=True):
        one = (np.array([sigma]), np.array([share]))
        assert blurred.tables(*one).tobytes() == _plain_tables(blurred, *one).tobytes()


@pytest.mark.parametrize("seed", range(6))
def test_the_batch_solve_is_the_plain_one_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(12, 900)), int(rng.choice([1, 8, 32, 89]))
    base = np.stack([np.ones(n), rng.uniform(-1, 1, n)] + (
        [rng.uniform(-1, 1, n)] if seed % 2 else []), axis=1)
    y = rng.normal(1000.0, 30.0, n)
    cols = rng.normal(0.0, 1.0, (m, 2, n))
    cols[:, 1] = np.abs(cols[:, 1])
    ridge = None if seed % 3 == 0 else np.abs(rng.normal(0, 1, base.shape[1] + 2))
    ours = kb._solve_batch(kb._Normal.of(base, y), cols, ridge, np.zeros(m), np.zeros(m))
    coef, cost, inv = _plain_solve(base, [cols[:, 0], cols[:, 1]], y, ridge)
    assert ours.coef.tobytes() == coef.tobytes()
    assert ours.cost.tobytes() == cost.tobytes()
    assert ours.inv.tobytes() == inv.tobytes()


def _set(rng: np.random.Generator, w: float, theta_deg: float, shape: tuple[int, int],
         sigma: float) -> tuple[np.ndarray, tuple[float, float]]:
    centre = (shape[0] / 2 + rng.uniform(-0.5, 0.5), shape[1] / 2 + rng.uniform(-0.5, 0.5))
    u = across_coordinate(shape, math.radians(theta_deg), centre)
    img = 3000.0 - 2000.0 * three_bar_pattern(u + rng.uniform(-0.1, 0.1), w, sigma,
                                              math.radians(theta_deg))
    img = np.clip(np.round(img + rng.normal(0.0, 15.0, shape)), 0, 4095).astype(np.uint16)
    return img, centre


def _bits(reading: kb.ThreeBarReading) -> list[Any]:
    state = reading._state
    assert state is not None
    out: list[Any] = [repr(reading.result), reading.blur_sigma_px, reading.blur_range_px]
    for batch in (state.fits, state.along_fits):
        if batch is not None:
            out += [batch.coef.tobytes(), batch.cost.tobytes(), batch.inv.tobytes()]
    return out


@pytest.mark.parametrize(("w", "theta_deg", "shape", "sigma"),
                         [(1.6, 8.0, (12, 14), 0.6), (2.4, 0.0, (16, 18), 1.4),
                          (3.3, 83.0, (24, 22), 2.0), (10.0, 0.0, (8, 60), 1.0)])
def test_a_fit_at_the_same_geometry_reads_the_same_with_the_kept_tabulation(
        w: float, theta_deg: float, shape: tuple[int, int], sigma: float,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Another image at the same pixels, bar width and angle (a set's predicted reading):
    taken from the kept tabulation, the fit is the one it computes afresh (a refit at a shift
    too: its tables are tabulated again from the kept inputs)."""
    monkeypatch.setattr(kb._TABULATIONS, "entry_max_bytes", kb.TABULATION_CACHE_BYTES)
    rng = np.random.default_rng(int(w * 10))
    img, centre = _set(rng, w, theta_deg, shape, sigma)
    other, _ = _set(rng, w, theta_deg, shape, 0.5 * sigma)

    def read(pixels: np.ndarray, reuse: bool) -> kb.ThreeBarReading:
        return fit_three_bars(pixels, centre_rc=centre, bar_width_px=w, theta_deg=theta_deg,
                              dark_bars=True, noise_floor=3.0, reuse_tabulation=reuse)

    kb.clear_tabulations()
    fresh = _bits(read(other, False))
    kb.clear_tabulations()
    read(img, False)  # keeps its tabulation
    held = len(kb._TABULATIONS)
    assert held == 1
    hits: list[bool] = []
    get = kb._TABULATIONS.get

    def spy(key: tuple[object, ...]) -> Any:
        hit = get(key)
        hits.append(hit is not None)
        return hit

    kb._TABULATIONS.get = spy  # type: ignore[method-assign]
    try:
        assert _bits(read(other, True)) == fresh
    finally:
        del kb._TABULATIONS.get
    assert hits == [True]
    kb.clear_tabulations()


def test_the_kept_tabulations_are_bounded_and_read_only() -> None:
    kb.clear_tabulations()
    rng = np.random.default_rng(4)
    for k in range(40):
        img, centre = _set(rng, 1.4 + 0.05 * k, 10.0, (14, 16), 0.8)
        fit_three_bars(img, centre_rc=centre, bar_width_px=1.4 + 0.05 * k, theta_deg=10.0)
        assert kb._TABULATIONS.nbytes <= kb.TABULATION_CACHE_BYTES
    assert 0 < len(kb._TABULATIONS) < 40
    key = next(iter(kb._TABULATIONS._entries))
    tab = kb._TABULATIONS._entries[key][0]
    with pytest.raises(ValueError, match="read-only"):
        tab.sp_pix[0, 0, 0] = 1.0
    # a set too large to keep is not kept
    big = kb._Tabulations(1 << 20, 1 << 10)
    big.put(("k",), tab)
    assert len(big) == 0
    kb.clear_tabulations()
    assert len(kb._TABULATIONS) == 0 and kb._TABULATIONS.nbytes == 0


def test_a_predicted_reading_after_its_chart_reading_is_the_one_read_alone() -> None:
    """:func:`predict_reading` at the setup a reading used takes that reading's tabulation:
    the same prediction as without it."""
    rng = np.random.default_rng(9)
    w, theta = 1.7, 8.0
    img, centre = _set(rng, w, theta, (13, 15), 0.7)
    setup = ReadingSetup((100, 200, 113, 215), (centre[0] + 100, centre[1] + 200), w, theta,
                         True, (0.6, 0.2), 12.0, 3000.0)

    def gauss(s: float) -> Any:
        return lambda f: np.exp(-2.0 * math.pi**2 * s * s * np.asarray(f) ** 2)

    kb.clear_tabulations()
    alone = predict_reading(setup, gauss(0.8), gauss(0.7), contrast=0.7)
    kb.clear_tabulations()
    fit_three_bars(img, centre_rc=centre, bar_width_px=w, theta_deg=theta, dark_bars=True)
    after = predict_reading(setup, gauss(0.8), gauss(0.7), contrast=0.7)
    assert _bits(after.reading) == _bits(alone.reading)
    assert after.image.tobytes() == alone.image.tobytes()
    kb.clear_tabulations()


def _hermite(x, value, slope):  # type: ignore[no-untyped-def]
    """The per-value cubic Hermite interpolation jinc used before its coefficients were
    tabulated per interval (``slope`` already times the step)."""
    s = x * (1.0 / jinc_mod.TABLE_STEP)
    i = s.astype(np.intp)
    t = s - i
    f0, f1 = value.take(i), value.take(i + 1)
    d0, d1 = slope.take(i), slope.take(i + 1)
    df = f1 - f0
    return np.asarray(f0 + t * (d0 + t * ((3.0 * df - 2.0 * d0 - d1)
                                          + t * (d0 + d1 - 2.0 * df))), dtype=np.float64)
