"""Through-focus curve: MTF at one image frequency against object distance, fitted; best focus
and the depth of field, with 95 % intervals.

The model. Defocus by an object at distance ``z`` when the lens is focused at ``z*`` spreads a
point over a blur whose width is proportional to ``|1/z - 1/z*|`` (thin lens, sensor fixed; see
:mod:`benchlab.scenes.focus`). For a Gaussian blur added in quadrature to the lens's own, the
MTF at a frequency is ``exp(-k sigma^2)``, so ``ln MTF`` is a parabola in the object vergence
``u = 1/z``. On a bench the field point moves in the image as the magnification changes
(``h ~ 1/z``), and the lens's own blur and its best focus change with ``h``: ``ln MTF`` becomes
a low-order polynomial in ``u`` (a quartic when the blur and the best-focus vergence vary with
``h^2``). So the fit is a polynomial of degree ``degree`` (default 4) in the scaled vergence
``w = (u - u_mean) / u_half``::

    ln MTF(u) = sum_k c_k w^k

keeping only readings with MTF >= ``min_mtf`` (where the logarithm of a noisy value is not
dominated by noise), weighted least squares in the log domain (weights ``(MTF / sigma)^2``;
``sigma`` the reading's 1-sigma), the weights' scale estimated from the residuals (reduced
chi-square) so intervals hold whether or not the given sigmas are right in absolute terms.

Best focus is the curve's maximum inside the fitted range; the DOF ends are where it falls to
the threshold on either side (searched to 50 % of the fitted range beyond it: further is
reported as not reached). Their 95 % intervals are the 2.5 / 97.5 % points over draws of the
coefficients from the fit's multivariate Student-t (``n - degree - 1`` degrees of freedom),
each draw's curve evaluated on a fine vergence grid; an end undefined in more than 2.5 % of
the draws gets no interval (None). A threshold known only to +- its own 1-sigma is drawn with
the coefficients (one threshold per draw), so the ends' intervals carry both.

Pure numpy; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray

#: Points below this MTF are left out of the fit by default.
MIN_MTF = 0.05
#: Monte Carlo draws for the intervals.
DRAWS = 2000
#: Polynomial degree of ln MTF in vergence.
DEGREE = 4
#: Vergence grid points over the fitted range (and as many again beyond it).
_GRID = 500
#: How far past the fitted range (fraction of it, each side) the ends are searched.
_REACH = 0.5


class FocusFitError(ValueError):
    """The through-focus readings cannot be fitted (too few points, no peak)."""


@dataclass(frozen=True)
class ThroughFocusFit:
    """A fitted through-focus curve (see the module docstring).

    Attributes
    ----------
    coef : ndarray
        Ascending coefficients of ``ln MTF`` in ``w = (1/z - u_mean) / u_half``.
    cov : ndarray
        Their covariance, scaled by the residuals.
    u_mean, u_half : float
        Centre and half-span of the vergences fitted, 1/mm.
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
    u_half: float
    dof: int
    n_points: int
    distance_range_mm: tuple[float, float]
    reduced_chi2: float

    def _w(self, distance_mm: npt.ArrayLike) -> FloatArray:
        return np.asarray((1.0 / np.asarray(distance_mm, dtype=np.float64) - self.u_mean)
                          / self.u_half)

    def mtf(self, distance_mm: npt.ArrayLike) -> FloatArray:
        """The fitted curve at object distances (mm)."""
        return np.asarray(np.exp(np.polynomial.polynomial.polyval(self._w(distance_mm),
                                                                  self.coef)))

    def _grid(self) -> FloatArray:
        n = int(_GRID * (1 + 2 * _REACH))
        w = np.linspace(-1.0 - 2 * _REACH, 1.0 + 2 * _REACH, n)
        # vergence must stay > 0 (distance finite); u = u_mean + w u_half
        return np.asarray(w[self.u_mean + w * self.u_half > 0])

    def summary(self, threshold: float | None = None) -> FloatArray:
        """``[best_mm, peak_mtf, near_mm, far_mm]`` of the fitted curve (NaN: undefined)."""
        return _quantities(self.coef[None, :], self, threshold)[0]

    @property
    def best_focus_mm(self) -> float:
        return float(self.summary()[0])

    @property
    def peak_mtf(self) -> float:
        return float(self.summary()[1])

    def ends_mm(self, threshold: float) -> tuple[float | None, float | None]:
        """(near, far) object distances where the fitted curve falls to ``threshold`` (None:
        not reached within the search)."""
        q = self.summary(threshold)
        return (None if np.isnan(q[2]) else float(q[2]), None if np.isnan(q[3]) else float(q[3]))

    def draws(self, n: int = DRAWS, seed: int = 0) -> FloatArray:
        """Coefficient draws from the fit's multivariate Student-t (n x len(coef))."""
        rng = np.random.default_rng(seed)
        z = rng.multivariate_normal(np.zeros(self.coef.size), self.cov, size=n, method="eigh")
        chi = rng.chisquare(self.dof, size=n) / self.dof
        return np.asarray(self.coef + z / np.sqrt(chi)[:, None])


def _quantities(coefs: FloatArray, fit: ThroughFocusFit,
                threshold: float | FloatArray | None) -> FloatArray:
    """Per coefficient row: best focus (mm), peak MTF, near and far ends (mm) at
    ``threshold`` (NaN: undefined), one number or one per row. The peak is searched inside the
    fitted range only."""
    w = fit._grid()
    vals = coefs @ np.vander(w, coefs.shape[1], increasing=True).T  # rows x grid
    inside = np.abs(w) <= 1.0
    idx_in = np.flatnonzero(inside)  # one run of the ascending grid: searched as a view
    k = idx_in[0] + np.argmax(vals[:, idx_in[0]:idx_in[-1] + 1], axis=1)
    rows = np.arange(coefs.shape[0])
    # parabolic refinement of the grid maximum
    k0 = np.clip(k, 1, w.size - 2)
    y0, y1, y2 = vals[rows, k0 - 1], vals[rows, k0], vals[rows, k0 + 1]
    den = y0 - 2 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.clip(np.where(den < 0, 0.5 * (y0 - y2) / den, 0.0), -1, 1)
    step = w[1] - w[0]
    w_best = w[k0] + shift * step
    peak = y1 - 0.25 * (y0 - y2) * shift
    at_edge = (k == idx_in[0]) | (k == idx_in[-1])  # no maximum inside the range
    u_best = fit.u_mean + w_best * fit.u_half
    out = np.full((coefs.shape[0], 4), np.nan)
    with np.errstate(divide="ignore"):
        out[:, 0] = np.where(at_edge | (u_best <= 0), np.nan, 1.0 / u_best)
    out[:, 1] = np.where(at_edge, np.nan, np.exp(peak))
    if threshold is None:
        return out
    lt: float | FloatArray
    if isinstance(threshold, float | int):
        lt = math.log(threshold)
        below = vals < lt
    else:
        # a threshold per row (drawn with the coefficients): one <= 0 is never crossed
        with np.errstate(divide="ignore", invalid="ignore"):
            lt = np.log(np.asarray(threshold, dtype=np.float64))
        below = vals < lt[:, None]
    ok = ~at_edge & (peak >= lt)
    idx = np.arange(w.size)
    # larger vergence = nearer: the near end is the first grid point below past the peak
    up = below & (idx[None, :] > k[:, None])
    j = np.argmax(up, axis=1)
    has_up = ok & up[rows, j]  # argmax finds a True wherever a row has one
    u_near = _cross(w, vals, rows, j - 1, j, lt, fit)
    dn = below & (idx[None, :] < k[:, None])
    i = w.size - 1 - np.argmax(dn[:, ::-1], axis=1)
    has_dn = ok & dn[rows, i]
    u_far = _cross(w, vals, rows, i, i + 1, lt, fit)
    with np.errstate(divide="ignore", invalid="ignore"):
        out[:, 2] = np.where(has_up & (u_near > 0), 1.0 / u_near, np.nan)
        out[:, 3] = np.where(has_dn, np.where(u_far > 0, 1.0 / u_far, np.inf), np.nan)
    return out


def _cross(w: FloatArray, v: FloatArray, rows: npt.NDArray[np.intp], i: npt.NDArray[np.intp],
           j: npt.NDArray[np.intp], level: float | FloatArray, fit: ThroughFocusFit
           ) -> FloatArray:
    """Vergence where each row's curve crosses ``level`` (one, or one per row) between grid
    points i and j."""
    i = np.clip(i, 0, w.size - 1)
    j = np.clip(j, 0, w.size - 1)
    vi, vj = v[rows, i], v[rows, j]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(vj != vi, (level - vi) / (vj - vi), 0.5)
    return np.asarray(fit.u_mean + (w[i] + t * (w[j] - w[i])) * fit.u_half)


def fit_through_focus(
    distances_mm: npt.ArrayLike, mtf: npt.ArrayLike, mtf_sigma: npt.ArrayLike | None = None,
    *, min_mtf: float = MIN_MTF, degree: int = DEGREE,
) -> ThroughFocusFit:
    """Fit ``ln MTF`` as a polynomial in object vergence (module docstring).

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
    degree : int
        Polynomial degree (2: the plain Gaussian-defocus parabola).

    Raises
    ------
    FocusFitError
        Fewer than ``degree + 3`` usable readings, or no maximum inside the range fitted.
    """
    if degree < 2:
        raise ValueError(f"degree must be >= 2, got {degree}")
    z = np.asarray(distances_mm, dtype=np.float64)
    m = np.asarray(mtf, dtype=np.float64)
    if z.shape != m.shape or z.ndim != 1:
        raise FocusFitError(f"distances ({z.shape}) and MTF ({m.shape}) must be 1-D, same size")
    s = (np.full_like(m, 0.01) if mtf_sigma is None
         else np.asarray(mtf_sigma, dtype=np.float64))
    use = np.isfinite(z) & np.isfinite(m) & np.isfinite(s) & (z > 0) & (m >= min_mtf) & (s > 0)
    n = int(use.sum())
    need = degree + 3
    if n < need or np.unique(z[use]).size < degree + 2:
        raise FocusFitError(f"{n} readings at or above MTF {min_mtf:g}; a degree-{degree} "
                            f"through-focus fit needs {need} at {degree + 2} distances")
    u = 1.0 / z[use]
    u_mean = float((u.max() + u.min()) / 2)
    u_half = float((u.max() - u.min()) / 2)
    w = (u - u_mean) / u_half
    y = np.log(m[use])
    wt = m[use] / s[use]
    design = np.vander(w, degree + 1, increasing=True)
    a = design * wt[:, None]
    coef, *_ = np.linalg.lstsq(a, y * wt, rcond=None)
    resid = (y - design @ coef) * wt
    dof = n - degree - 1
    chi2 = float(resid @ resid) / dof
    cov = np.linalg.inv(a.T @ a) * chi2
    fit = ThroughFocusFit(coef=np.asarray(coef, np.float64), cov=np.asarray(cov, np.float64),
                          u_mean=u_mean, u_half=u_half, dof=dof, n_points=n,
                          distance_range_mm=(float(z[use].min()), float(z[use].max())),
                          reduced_chi2=chi2)
    if np.isnan(fit.best_focus_mm):
        raise FocusFitError("the readings have no maximum inside the sweep: widen the range "
                            "about best focus")
    return fit


@dataclass(frozen=True)
class FocusEstimate:
    """Best focus and the DOF ends at one threshold, each with its 95 % interval.

    ``near_mm`` / ``far_mm`` are None when the fitted curve does not reach the threshold
    within the search (``far_mm`` inf: beyond infinity); an interval end is None when
    undefined (module docstring). ``*_extrapolated`` says the value lies outside the distances
    fitted.
    """

    best_focus_mm: float
    best_focus_ci95: tuple[float | None, float | None]
    peak_mtf: float
    near_mm: float | None
    near_ci95: tuple[float | None, float | None]
    far_mm: float | None
    far_ci95: tuple[float | None, float | None]
    near_extrapolated: bool
    far_extrapolated: bool
    #: The best-focus draws behind ``best_focus_ci95`` (NaN: a draw without a maximum).
    best_focus_draws: FloatArray = field(default_factory=lambda: np.empty(0), compare=False,
                                         repr=False)


def _interval(values: FloatArray) -> tuple[float | None, float | None]:
    """2.5 / 97.5 % points; None, None when more than 2.5 % of draws are undefined (NaN)."""
    bad = np.isnan(values)
    if bad.mean() > 0.025:
        return (None, None)
    lo, hi = np.percentile(values[~bad], [2.5, 97.5])
    return (float(lo), float(hi) if math.isfinite(hi) else None)


def focus_estimate(fit: ThroughFocusFit, threshold: float, *, draws: int = DRAWS,
                   seed: int = 0, threshold_sd: float = 0.0) -> FocusEstimate:
    """Best focus and DOF at ``threshold`` with 95 % intervals (module docstring).

    ``threshold_sd``: the threshold's own 1-sigma (e.g. a threshold on a share of a target
    contrast known to +- its sigma). Each coefficient draw then finds its ends at its own
    threshold, drawn from a normal about ``threshold`` (an own random stream, so the
    coefficient draws are those of ``threshold_sd = 0``): the ends' intervals carry both. A
    drawn threshold <= 0 or above the draw's peak leaves that draw's end undefined.
    """
    if not 0.0 < threshold < 1.0:
        raise ValueError(f"threshold must be in (0, 1), got {threshold}")
    if not (threshold_sd >= 0.0 and math.isfinite(threshold_sd)):
        raise ValueError(f"threshold_sd must be finite and >= 0, got {threshold_sd}")
    level: float | FloatArray = threshold
    if threshold_sd > 0.0:
        level = np.random.default_rng([seed, 1]).normal(threshold, threshold_sd, draws)
    q = _quantities(fit.draws(draws, seed), fit, level)
    near, far = fit.ends_mm(threshold)
    lo_z, hi_z = fit.distance_range_mm
    return FocusEstimate(
        best_focus_mm=fit.best_focus_mm, best_focus_ci95=_interval(q[:, 0]),
        peak_mtf=fit.peak_mtf, near_mm=near, near_ci95=_interval(q[:, 2]), far_mm=far,
        far_ci95=_interval(q[:, 3]),
        near_extrapolated=near is not None and near < lo_z,
        far_extrapolated=far is not None and far > hi_z, best_focus_draws=q[:, 0],
    )


def best_focus_draws(fit: ThroughFocusFit, *, draws: int = DRAWS, seed: int = 0) -> FloatArray:
    """Draws of the best-focus distance (NaN where a draw has no maximum inside the range)."""
    return np.asarray(_quantities(fit.draws(draws, seed), fit, None)[:, 0])
