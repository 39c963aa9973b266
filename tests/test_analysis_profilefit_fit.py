"""``profilefit``'s fit itself: analytic derivatives, convergence from a poor start, the choice
between a given and a measured period, and honest intervals where the fit is hard."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis import estimate_modulation
from benchlab.analysis.profilefit import _Model
from benchlab.analysis.synthetic import bar_roi


@pytest.mark.parametrize("theta", [0.0, 0.5])
def test_model_derivatives_match_finite_differences(theta: float) -> None:
    """The phase, duty and blur derivatives of the model (the phase one had the wrong sign, so
    Levenberg-Marquardt could never move the phase off the spectral estimate)."""
    w = np.linspace(0.0, 1.0, 50, endpoint=False)
    model = _Model(w, 0.1, theta, 20)
    p = (0.1, 0.45, 1.0)
    value, deriv = model.eval(*p)
    assert deriv is not None
    h = 1e-6
    for j in range(3):
        q = list(p)
        q[j] += h
        numeric = (model.eval(*q, derivatives=False)[0] - value) / h
        assert np.abs(numeric - deriv[:, j]).max() < 1e-4 * max(np.abs(numeric).max(), 1.0)


@pytest.mark.parametrize(
    ("shape", "period", "angle", "sigma", "duty", "shading", "seed"),
    [
        ((40, 50), 32.15, 90.0, 0.39, 0.42, 0.22, 1),  # 1.25 periods: spectral phase off
        ((10, 40), 23.5, 61.9, 0.0, 0.52, 0.0, 2),
        ((20, 100), 17.5, 90.0, 0.78, 0.42, 0.0, 4),
    ],
)
def test_few_periods_fit_converges(
    shape: tuple[int, int], period: float, angle: float, sigma: float, duty: float,
    shading: float, seed: int,
) -> None:
    """One to three periods across the ROI: the fundamental's phase from the spectrum is pulled
    by its side lobes, and the fit must move it (before the fix: errors of 0.1-0.2)."""
    roi, case = bar_roi(
        seed, shape=shape, px_per_period=period, angle_deg=angle, psf_sigma_px=sigma,
        duty=duty, shading=shading, noise_sigma=0.4, electrons_per_dn=200.0,
    )
    axis = angle in (0.0, 90.0)
    r = estimate_modulation(
        roi, freq_cycles_per_px=1 / period,
        orientation=("vertical" if angle == 90.0 else "horizontal") if axis else None,
    )
    assert r.resolved
    assert r.modulation == pytest.approx(case.truth, abs=0.02)
    assert r.interval[0] <= case.truth <= r.interval[1]
    assert math.isfinite(r.uncertainty)
