"""The through-focus quantities of every Monte Carlo draw, bit for bit what the direct
formulation gives (issue 39 searched the peak in a view of the grid and read "a grid point below
the threshold exists" from the search itself instead of a second pass)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.focus.through_focus import (
    ThroughFocusFit,
    _quantities,
    fit_through_focus,
)

Z = np.arange(40.0, 96.0, 2.0)


def _direct(coefs: np.ndarray, fit: ThroughFocusFit, threshold: float) -> np.ndarray:
    """The quantities as first written: the peak searched in a copy of the inside columns,
    the ends' existence from ``any`` over each row."""
    w = fit._grid()
    vals = coefs @ np.vander(w, coefs.shape[1], increasing=True).T
    idx_in = np.flatnonzero(np.abs(w) <= 1.0)
    k = idx_in[np.argmax(vals[:, idx_in], axis=1)]
    rows = np.arange(coefs.shape[0])
    k0 = np.clip(k, 1, w.size - 2)
    y0, y1, y2 = vals[rows, k0 - 1], vals[rows, k0], vals[rows, k0 + 1]
    den = y0 - 2 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.clip(np.where(den < 0, 0.5 * (y0 - y2) / den, 0.0), -1, 1)
    w_best = w[k0] + shift * (w[1] - w[0])
    peak = y1 - 0.25 * (y0 - y2) * shift
    at_edge = (k == idx_in[0]) | (k == idx_in[-1])
    u_best = fit.u_mean + w_best * fit.u_half
    out = np.full((coefs.shape[0], 4), np.nan)
    with np.errstate(divide="ignore"):
        out[:, 0] = np.where(at_edge | (u_best <= 0), np.nan, 1.0 / u_best)
    out[:, 1] = np.where(at_edge, np.nan, np.exp(peak))
    lt = math.log(threshold)
    ok = ~at_edge & (peak >= lt)
    below = vals < lt
    idx = np.arange(w.size)

    def cross(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        i, j = np.clip(i, 0, w.size - 1), np.clip(j, 0, w.size - 1)
        vi, vj = vals[rows, i], vals[rows, j]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(vj != vi, (lt - vi) / (vj - vi), 0.5)
        return np.asarray(fit.u_mean + (w[i] + t * (w[j] - w[i])) * fit.u_half)

    up = below & (idx[None, :] > k[:, None])
    has_up = ok & up.any(axis=1)
    j = np.argmax(up, axis=1)
    u_near = cross(j - 1, j)
    dn = below & (idx[None, :] < k[:, None])
    has_dn = ok & dn.any(axis=1)
    i = w.size - 1 - np.argmax(dn[:, ::-1], axis=1)
    u_far = cross(i, i + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        out[:, 2] = np.where(has_up & (u_near > 0), 1.0 / u_near, np.nan)
        out[:, 3] = np.where(has_dn, np.where(u_far > 0, 1.0 / u_far, np.inf), np.nan)
    return out


@pytest.mark.parametrize(("best_mm", "width", "noise", "threshold", "ends_missing"), [
    (60.0, 22000.0, 0.003, 0.5, False),  # both ends inside the sweep
    (43.0, 22000.0, 0.08, 0.3, False),  # the peak at the sweep's end: 42 % of draws at the edge
    (60.0, 4000.0, 0.02, 0.5, True),    # a shallow curve: most draws' ends beyond the reach
    (60.0, 22000.0, 0.05, 0.9, True),   # the threshold at the peak: a fifth of draws below it
])
def test_quantities_equal_the_direct_formulation_bit_for_bit(
        best_mm: float, width: float, noise: float, threshold: float, ends_missing: bool) -> None:
    rng = np.random.default_rng(7)
    mtf = 0.9 * np.exp(-width * (1.0 / Z - 1.0 / best_mm) ** 2)
    mtf = np.clip(mtf + rng.normal(0.0, noise, Z.size), 0.06, None)
    fit = fit_through_focus(Z, mtf, np.full(Z.size, max(noise, 0.003)))
    coefs = fit.draws(3000, seed=3)
    got, want = _quantities(coefs, fit, threshold), _direct(coefs, fit, threshold)
    assert np.array_equal(got, want, equal_nan=True)
    # each case reaches what it is named for: draws without a best focus (a peak at the edge),
    # without ends (column 2, 3), and with them
    assert np.isnan(got[:, 0]).any() == (best_mm == 43.0)
    assert (np.isnan(got[:, 2]).mean() > 0.1) == (ends_missing or best_mm == 43.0)
    assert np.isfinite(got[:, 2]).any() and np.isfinite(got[:, 3]).any()
