"""The radial view's through-focus fits (:mod:`benchlab.protocols.depth.radial`): best focus from
the fundamental, the DOF ends from the Eq. 2.9 modulation, both as polynomials in the object
radius ``R`` (handed to :func:`benchlab.analysis.focus.through_focus.fit_through_focus` as
``1 / R``, whose "vergence" is then ``R``), and the model term of their intervals.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from benchlab.analysis.focus.through_focus import (
    FocusEstimate,
    FocusFitError,
    ThroughFocusFit,
    fit_through_focus,
    focus_estimate,
)
from benchlab.protocols.depth.params import DepthParams
from benchlab.protocols.depth.radial_rois import RadialReading

#: Fundamental modulations below this are left out of the best-focus fit: a reading's 1-sigma
#: is ~0.001 on these ROIs, and the rings (0.18 at best) fall below the forward view's 0.05
#: within +-1 mm of focus, leaving too few points for the fit.
MIN_FUNDAMENTAL = 0.01
#: Model term (1 sigma, mm) of every radial best focus and DOF end, added to the fit's
#: statistical interval: profilefit's fundamental on these ROIs departs from the closed form by
#: up to 2.5 % in a way that changes with the defocus (the spokes' period changes with R and
#: across the ROI), which moves the fitted peak by up to 0.0064 mm on noise-free renders of the
#: simulated bench (three field points, S and T) - where the noise alone gives 0.001-0.003 mm
#: (1 sigma).
MODEL_SD_MM = 0.004


def in_radius(fit: ThroughFocusFit, threshold: float, seed: int,
              threshold_sd: float = 0.0) -> FocusEstimate:
    """:func:`focus_estimate` of a fit made on ``1 / R``, back in the object radius ``R`` (the
    order flips: the fit's near end is the far end)."""
    e = focus_estimate(fit, threshold, seed=seed, threshold_sd=threshold_sd)

    def inv(v: float | None) -> float | None:
        return None if v is None else (math.inf if v == 0 else 1.0 / v)

    def ci(pair: tuple[float | None, float | None]) -> tuple[float | None, float | None]:
        return (inv(pair[1]), inv(pair[0]))

    return FocusEstimate(best_focus_mm=1.0 / e.best_focus_mm,
                         best_focus_ci95=ci(e.best_focus_ci95), peak_mtf=e.peak_mtf,
                         near_mm=inv(e.far_mm), near_ci95=ci(e.far_ci95),
                         far_mm=inv(e.near_mm), far_ci95=ci(e.near_ci95),
                         near_extrapolated=e.far_extrapolated,
                         far_extrapolated=e.near_extrapolated,
                         best_focus_draws=1.0 / e.best_focus_draws)


def estimate(pts: Sequence[tuple[float, RadialReading]], params: DepthParams, seed: int,
             threshold: float | None = None, threshold_sd: float = 0.0
             ) -> tuple[FocusEstimate, int, str]:
    """Best focus from the fundamental, ends (and peak) from the Eq. 2.9 modulation; object
    radii (mm from the axis). ``threshold``: the reading's (default ``radial.threshold``);
    ``threshold_sd`` its own 1-sigma (threshold x the target contrast's), drawn into the ends'
    intervals. Raises FocusFitError when best focus cannot be fitted."""
    thr = params.radial_threshold if threshold is None else threshold
    # fitted in the object radius R (module docstring): handed to the fit as 1 / R, whose
    # "vergence" is then R
    inverse = [1.0 / z for z, _ in pts]
    sig = [r.sigma for _, r in pts]
    fund = fit_through_focus(inverse, [r.fundamental for _, r in pts], sig,
                             min_mtf=MIN_FUNDAMENTAL)
    best = in_radius(fund, thr, seed)
    try:
        mod = fit_through_focus(inverse, [r.modulation for _, r in pts], sig,
                                min_mtf=params.min_mtf)
    except FocusFitError as exc:
        # too few readings above analysis.min_mtf (bars that never reach the threshold) or no
        # maximum: best focus stands, the ends are not measured
        peak = max(r.modulation for _, r in pts)
        return (dataclasses.replace(best, peak_mtf=peak, near_mm=None, near_ci95=(None, None),
                                    far_mm=None, far_ci95=(None, None), near_extrapolated=False,
                                    far_extrapolated=False),
                fund.n_points, f"Eq. 2.9 modulation fit: {exc}")
    ends = in_radius(mod, thr, seed + 1, threshold_sd)
    return (dataclasses.replace(ends, best_focus_mm=best.best_focus_mm,
                                best_focus_ci95=best.best_focus_ci95,
                                best_focus_draws=best.best_focus_draws),
            fund.n_points, "")


def with_model_term(est: FocusEstimate, seed: int) -> FocusEstimate:
    """``est`` with :data:`MODEL_SD_MM` in its intervals: added to each best-focus draw (so the
    S - T difference and the field curvature carry it), and in quadrature to each end's
    interval half-widths."""
    rng = np.random.default_rng(seed)
    draws = est.best_focus_draws + rng.normal(0.0, MODEL_SD_MM, est.best_focus_draws.size)
    finite = draws[np.isfinite(draws)]
    best_ci: tuple[float | None, float | None] = (None, None)
    if finite.size and finite.size >= 0.975 * draws.size:
        lo, hi = np.percentile(finite, [2.5, 97.5])
        best_ci = (float(lo), float(hi))
    wide = 1.96 * MODEL_SD_MM

    def widen(value: float | None, ci: tuple[float | None, float | None]
              ) -> tuple[float | None, float | None]:
        lo, hi = ci
        if value is None or not math.isfinite(value):
            return ci
        return (None if lo is None else value - math.hypot(value - lo, wide),
                None if hi is None or not math.isfinite(hi)
                else value + math.hypot(hi - value, wide))

    return dataclasses.replace(est, best_focus_ci95=best_ci, best_focus_draws=draws,
                               near_ci95=widen(est.near_mm, est.near_ci95),
                               far_ci95=widen(est.far_mm, est.far_ci95))
