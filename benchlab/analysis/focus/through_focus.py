"""Through-focus curve: MTF at one image frequency against object distance, fitted; best focus
and the depth of field, with 95 % intervals.

The model. Defocus by an object at distance ``z`` when the lens is focused at ``z*`` spreads a
point over a blur whose width is proportional to ``|1/z - 1/z*|`` (thin lens, sensor fixed; see
:mod:`benchlab.scenes.focus`). For a Gaussian blur added in quadrature to the lens's own, the
MTF at a frequency is ``exp(-k sigma^2)``, so ``ln MTF`` is exactly a parabola in the object
vergence ``u = 1/z``::

    ln MTF(u) = a + b w + c w^2,    w = u - mean(u),    c < 0

For other blur shapes this is the second-order expansion about the peak (the fit keeps only
points whose MTF is at least ``min_mtf``, where the parabola holds best and the logarithm of a
noisy value is not dominated by noise). The fit is weighted least squares in the log domain
(weights ``(MTF / sigma)^2``: ``sigma`` is the reading's 1-sigma), the scale of the weights
estimated from the residuals (reduced chi-square), so intervals hold whether or not the given
sigmas are right in absolute terms.

Best focus ``u* = mean(u) - b / (2c)``; the DOF ends are the two roots of the parabola at
``ln threshold``. Their 95 % intervals are the 2.5 / 97.5 % points of those quantities over
draws of ``(a, b, c)`` from the fit's multivariate Student-t (``n - 3`` degrees of freedom);
an end whose root is missing in more than 2.5 % of the draws (threshold above the peak, or
the far root beyond infinity) gets an open interval on that side (None).

Pure numpy; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats

FloatArray = npt.NDArray[np.float64]

#: Points below this MTF are left out of the fit by default.
MIN_MTF = 0.05
#: Monte Carlo draws for the intervals.
DRAWS = 4000


class FocusFitError(ValueError):
    """The through-focus readings cannot be fitted (too few points, no peak)."""


@dataclass(frozen=True)
class ThroughFocusFit:
    """A fitted through-focus curve (see the module docstring).

    Attributes
    ----------
    coef : ndarray
        ``(a, b, c)`` of ``ln MTF = a + b w + c w^2``, ``w = 1/z - u_mean``.
    cov : ndarray
        Their covariance (3 x 3), scaled by the residuals.
    u_mean : float
        Centre of the vergences fitted, 1/mm.
    dof : int
        Residual degrees of freedom.
    n_points : int
        Points fitted.
    distance_range_mm : (float, float)
        Smallest and largest object distance fitted.
    reduced_chi2 : float
        Residual scatter over the given sigmas (1 when they are right).
    """

    coef: FloatArray
    cov: FloatArray
    u_mean: float
    dof: int
    n_points: int
    distance_range_mm: tuple[float, float]
    reduced_chi2: float

    def mtf(self, distance_mm: npt.ArrayLike) -> FloatArray:
        """The fitted curve at object distances (mm)."""
        w = 1.0 / np.asarray(distance_mm, dtype=np.float64) - self.u_mean
        a, b, c = self.coef
        return np.asarray(np.exp(a + b * w + c * w * w))

    @property
    def peak_mtf(self) -> float:
        a, b, c = self.coef
        return float(math.exp(a - b * b / (4.0 * c)))

    @property
    def best_focus_mm(self) -> float:
        a, b, c = self.coef
        return 1.0 / (self.u_mean - b / (2.0 * c))

    def ends_mm(self, threshold: float) -> tuple[float | None, float | None]:
        """(near, far) object distances where the fitted curve crosses ``threshold`` (None:
        never reaches it; far = inf when the far root lies beyond infinity)."""
        near, far = _ends(self.coef[None, :], self.u_mean, threshold)
        return (None if np.isnan(near[0]) else float(near[0]),
                None if np.isnan(far[0]) else float(far[0]))

    def draws(self, n: int = DRAWS, seed: int = 0) -> FloatArray:
        """Coefficient draws from the fit's multivariate Student-t (n x 3)."""
        rng = np.random.default_rng(seed)
        z = rng.multivariate_normal(np.zeros(3), self.cov, size=n, method="eigh")
        chi = rng.chisquare(self.dof, size=n) / self.dof
        return np.asarray(self.coef + z / np.sqrt(chi)[:, None])


def _ends(coefs: FloatArray, u_mean: float, threshold: float) -> tuple[FloatArray, FloatArray]:
    """Near / far distances (NaN: no root) for coefficient rows; far is inf when its vergence
    is <= 0 (beyond infinity)."""
    a, b, c = coefs[:, 0], coefs[:, 1], coefs[:, 2]
    disc = b * b - 4.0 * c * (a - math.log(threshold))
    ok = (c < 0) & (disc >= 0)
    root = np.sqrt(np.where(ok, disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        # c < 0: the larger vergence (near) is (-b - root) / (2c)
        u_near = u_mean + (-b - root) / (2.0 * c)
        u_far = u_mean + (-b + root) / (2.0 * c)
        near = np.where(ok & (u_near > 0), 1.0 / u_near, np.nan)
        far = np.where(ok, np.where(u_far > 0, 1.0 / u_far, np.inf), np.nan)
    return near, far


def fit_through_focus(
    distances_mm: npt.ArrayLike, mtf: npt.ArrayLike, mtf_sigma: npt.ArrayLike | None = None,
    *, min_mtf: float = MIN_MTF,
) -> ThroughFocusFit:
    """Fit ``ln MTF`` as a parabola in object vergence (module docstring).

    Parameters
    ----------
    distances_mm : array_like
        Object distance of each reading (repeats allowed: overlapping segments).
    mtf : array_like
        MTF at the chosen frequency.
    mtf_sigma : array_like, optional
        1-sigma of each MTF (equal weights when None).
    min_mtf : float
        Readings below this are left out.

    Raises
    ------
    FocusFitError
        Fewer than 5 usable readings, or no peak (the parabola opens upwards).
    """
    z = np.asarray(distances_mm, dtype=np.float64)
    m = np.asarray(mtf, dtype=np.float64)
    if z.shape != m.shape or z.ndim != 1:
        raise FocusFitError(f"distances ({z.shape}) and MTF ({m.shape}) must be 1-D, same size")
    s = (np.full_like(m, 0.01) if mtf_sigma is None
         else np.asarray(mtf_sigma, dtype=np.float64))
    use = np.isfinite(z) & np.isfinite(m) & np.isfinite(s) & (z > 0) & (m >= min_mtf) & (s > 0)
    n = int(use.sum())
    if n < 5:
        raise FocusFitError(f"{n} readings at or above MTF {min_mtf:g}; a through-focus fit "
                            "needs 5")
    u = 1.0 / z[use]
    u_mean = float(u.mean())
    w = u - u_mean
    y = np.log(m[use])
    sy = s[use] / m[use]
    design = np.stack([np.ones_like(w), w, w * w], axis=1)
    wt = 1.0 / sy
    coef, *_ = np.linalg.lstsq(design * wt[:, None], y * wt, rcond=None)
    resid = (y - design @ coef) * wt
    dof = n - 3
    chi2 = float(resid @ resid) / dof
    base = np.linalg.inv((design * wt[:, None]).T @ (design * wt[:, None]))
    if not coef[2] < 0:
        raise FocusFitError("the readings have no peak in the sweep (the fitted curve opens "
                            "upwards): widen the range about best focus")
    return ThroughFocusFit(coef=np.asarray(coef), cov=np.asarray(base * chi2, np.float64),
                           u_mean=u_mean, dof=dof, n_points=n, distance_range_mm=(float(z[use].min()),
                                                          float(z[use].max())),
                           reduced_chi2=chi2)


@dataclass(frozen=True)
class FocusEstimate:
    """Best focus and the DOF ends at one threshold, each with its 95 % interval.

    ``near_mm`` / ``far_mm`` are None when the fitted curve never reaches the threshold; an
    interval end is None when it is open (module docstring). ``*_extrapolated`` says the value
    lies outside the distances fitted.
    """

    best_focus_mm: float
    best_focus_ci95: tuple[float, float]
    peak_mtf: float
    near_mm: float | None
    near_ci95: tuple[float | None, float | None]
    far_mm: float | None
    far_ci95: tuple[float | None, float | None]
    near_extrapolated: bool
    far_extrapolated: bool


def _interval(values: FloatArray) -> tuple[float | None, float | None]:
    """2.5 / 97.5 % points; a side with more than 2.5 % of draws undefined (NaN) is open."""
    bad = np.isnan(values)
    if bad.mean() > 0.025:  # the end itself is in doubt: no interval to state
        return (None, None)
    lo, hi = np.percentile(values[~bad], [2.5, 97.5])
    return (float(lo), float(hi) if math.isfinite(hi) else None)


def focus_estimate(fit: ThroughFocusFit, threshold: float, *, draws: int = DRAWS,
                   seed: int = 0) -> FocusEstimate:
    """Best focus and DOF at ``threshold`` with 95 % intervals (module docstring)."""
    if not 0.0 < threshold < 1.0:
        raise ValueError(f"threshold must be in (0, 1), got {threshold}")
    coefs = fit.draws(draws, seed)
    b, c = coefs[:, 1], coefs[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u_best = fit.u_mean - b / (2.0 * c)
        best = np.where((c < 0) & (u_best > 0), 1.0 / u_best, np.nan)
    near_d, far_d = _ends(coefs, fit.u_mean, threshold)
    b_lo, b_hi = _interval(best)
    near, far = fit.ends_mm(threshold)
    lo_z, hi_z = fit.distance_range_mm
    return FocusEstimate(
        best_focus_mm=fit.best_focus_mm,
        best_focus_ci95=(b_lo if b_lo is not None else float("nan"),
                         b_hi if b_hi is not None else float("nan")),
        peak_mtf=fit.peak_mtf, near_mm=near, near_ci95=_interval(near_d), far_mm=far,
        far_ci95=_interval(far_d),
        near_extrapolated=near is not None and near < lo_z,
        far_extrapolated=far is not None and far > hi_z,
    )


def difference_interval(a_draws: FloatArray, b_draws: FloatArray) -> tuple[float, float]:
    """95 % interval of ``a - b`` from independent draws of each (same length)."""
    d = np.asarray(a_draws) - np.asarray(b_draws)
    d = d[np.isfinite(d)]
    lo, hi = np.percentile(d, [2.5, 97.5])
    return float(lo), float(hi)


def best_focus_draws(fit: ThroughFocusFit, *, draws: int = DRAWS, seed: int = 0) -> FloatArray:
    """Draws of the best-focus distance (NaN where a draw has no peak)."""
    coefs = fit.draws(draws, seed)
    b, c = coefs[:, 1], coefs[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u_best = fit.u_mean - b / (2.0 * c)
        return np.asarray(np.where((c < 0) & (u_best > 0), 1.0 / u_best, np.nan))


def t_quantile(dof: int, p: float = 0.975) -> float:
    """Student-t quantile (for callers combining fitted values)."""
    return float(stats.t.ppf(p, dof))
