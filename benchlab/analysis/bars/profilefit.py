"""``profilefit``: a model of the imaged bar pattern fitted to the ROI's across-bar profile.

1. The bars' direction, frequency and phase come from the ROI (:mod:`.geometry`); a given
   frequency is only a prior and cross-check.
2. Every pixel gets its bar phase ``w`` (cycles; the across-bar coordinate ``u = x cos t + y sin
   t`` of :mod:`.projection` times the frequency, plus the curvature of spokes or rings) and is
   binned finely in ``w`` with :func:`.projection.bin_profile`. Pixels from every period and at
   every sub-pixel offset fall into the same bins: oblique bars, and periods that are not whole
   pixels, sample the profile below one pixel.
3. The binned profile is fitted with the imaged bar pattern: a square wave of bright fraction
   ``duty`` blurred by a Gaussian of ``sigma`` and the exact pixel footprint at the measured
   angle (:func:`.model.fourier_gains`), between levels ``D`` and ``B``, times a linear
   illumination shading across and along the bars (each bin carries its pixels' mean position,
   so the shading of a bin is exact for linear shading). Levenberg-Marquardt on
   (phase, duty, PSF variance) with the levels and shading solved exactly at each step
   (variable projection), a weak prior holding the duty near 0.5 where the data cannot tell.
4. The direction and frequency are refined by Gauss-Newton on the per-pixel residuals (the
   spectral peak is pulled by its side lobes on few periods), and the profile refitted when
   that moves the bar phase noticeably at the ROI's edges.
5. Saturated pixels are censored data, not levels (see :func:`_censored`): the model carries
   the bright level beyond the top code.
6. The Eq. 2.9 contrast is the fitted model's maximum and minimum at the ROI centre, the
   levels never outside the samples (unless saturated). Noise comes from the per-pixel fit
   residuals (it does not depend on the bar angle). The interval holds the noise (propagated
   through the fit), a model term and a sampling-phase term (see :func:`_model_sd`).

A ``fast`` variant (``profilefit-fast``) skips the curvature, bins half as finely, fits at most
32 harmonics, iterates less and refines the geometry once; ``benchlab benchmark analysis``
states its accuracy cost.

Why one module of ~1,000 lines: the model, the variable-projection fit, the geometry refinement
and the interval work on one binned profile and its Jacobian; the bar geometry search, the
projection and the closed-form pattern already live in their own modules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars import model as barmodel
from benchlab.analysis.bars.geometry import (
    BarGeometry,
    frequency_disagreement,
    measure_geometry,
    phase_map,
    refine_by_folding,
)
from benchlab.analysis.bars.projection import across_coordinate, filled_bin_means
from benchlab.analysis.bars.result import (
    ModulationResult,
    eq29_modulation,
    not_measurable,
    resolved,
    sampling_phase_sd,
    unresolved,
)
from benchlab.analysis.bars.roi import TINY_CONTRAST_WARNING, PreparedROI, quiet_noise_sigma
from benchlab.analysis.noise import robust_sigma

NAME = "profilefit"
FAST_NAME = "profilefit-fast"
#: Significance of the fitted fundamental (amplitude over ``noise sqrt(2 / n)``) for
#: "resolved": the spectral search tries up to ~n/2 frequencies, whose noise maximum is ~4.5.
RESOLVED_Z = 6.0
#: Prior on the duty (bright fraction): 0.5 +- this, weighted like one pixel.
DUTY_PRIOR_SD = 0.1
DUTY_BOUNDS = (0.2, 0.8)
#: Most phase bins and harmonics (full and fast modes).
MAX_BINS, MAX_BINS_FAST = 64, 32
MAX_HARMONICS, MAX_HARMONICS_FAST = 48, 32
#: Shading terms only with at least this many filled phase bins ...
MIN_BINS_SHADING = 14
#: ... and shading across the bars only over this many periods (fewer: it mimics the bars).
MIN_PERIODS_ACROSS_SHADING = 3.0
#: Scale of the ridge on the shading terms (relative shading over the half span).
SHADING_PRIOR = 0.5
#: Relative model uncertainty of the contrast (PSF shape, duty and shading not exactly as
#: modelled), calibrated on ``benchlab benchmark analysis``.
MODEL_REL_SD = 0.01
#: Direction and frequency are refined by folding on ROIs narrower than 16 px spanning fewer
#: periods than this, where the spectral peak is biased by its side lobes.
FOLD_REFINE_PERIODS = 6.0
#: Below this many pixels the given frequency and orientation are used as they are (a few
#: dozen pixels cannot overrule the chart's design).
PRIORS_RULE_PIXELS = 100
#: The fast mode's model term: coarser bins and a shorter series (calibrated on ``benchlab
#: benchmark analysis``: 95 % intervals covering 93-98 % per bucket; 0.02 gave 95-100 %).
MODEL_REL_SD_FAST = 0.014
#: Angle disagreement (deg) with a given axis orientation tolerated before a warning.
ANGLE_TOLERANCE_DEG = 2.0
#: Spectral geometry spanning at least this many periods is fitted (the refined one must
#: span one).
MIN_PERIODS_TRIED = 0.75
#: Rounds of Gauss-Newton on the direction and frequency from the per-pixel residuals, and
#: when one is applied: significant (chi-square of the step over the noise) and moving the
#: bar phase by at least this many cycles at the ROI's edges.
REFINE_ROUNDS = 2
REFINE_CHI2 = 9.0
REFINE_MIN_CYCLES = 0.03
REFINE_MAX_PIXELS = 20_000
#: Largest direction (rad) and relative frequency correction applied.
REFINE_MAX_THETA_RAD = math.radians(6.0)
REFINE_MAX_FREQ_REL = 0.15
#: Given a frequency, bars whose sampling alias (1 - f cycles/px) lies fewer than this many
#: Rayleigh steps (1 / span cycles/px) from f: the spectral peak is pulled by its alias (issue
#: 37: 2.1-2.3 px bars across 10-14 px measured at 2.00-2.34 px, read "1.000" or 0.2-0.4 low),
#: so the given frequency rules.
ALIAS_RAYLEIGH_STEPS = 2.5
#: A fit residual over this many times the pixel noise (neighbour differences along the
#: bars) is the model's misfit: warned about, the pixel noise reported.
MISFIT_RATIO = 4.0
#: A misfit ROI is refitted without the pixels off the pattern (:func:`_trimmed`): rounds,
#: the least distance (pixel noise sigmas) of a pixel left out, the largest share left out.
TRIM_ROUNDS = 12
TRIM_SIGMAS = 5.0
TRIM_MAX_SHARE = 0.5
#: Trimmed only where the residual's rms exceeds this share of the data's span too.
TRIM_SPAN_SHARE = 0.1
#: ... and the relative periods scanned on the pixels kept.
TRIM_FREQ_SCAN = (0.96, 0.97, 0.98, 0.99, 1.01, 1.02, 1.03, 1.04)
#: ... never judged against a pixel noise below this (gray units): noise-free data leave a
#: model residual of a fraction of a code.
MISFIT_MIN_NOISE = 0.5
#: Above this frequency (cycles/px; under 2.1 px per period), the reading is a lower bound
#: (:func:`_sampled_phases_bound`): the bar phases drift across the ROI too slowly for the
#: sampling to pin the bars' shape (sharp 2.03 px bars, 40 x 50 px: 0.70 for 0.80).
NEAR_NYQUIST_CYCLES = 1.0 / 2.1
#: A profile spanning this many noise sigmas of its lines' mean shows bars (noise alone over a
#: few dozen lines spans ~6; as :data:`~.extremes.PLAIN_RANGE_SIGMAS`).
PLAIN_SPAN_SIGMAS = 20.0
#: Blur starts (PSF sigma per period): all tried at once, the best one starts the fit.
_SIGMA_STARTS = (0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.13, 0.16, 0.2, 0.25, 0.3, 0.36, 0.45)
_GRID_N = 256
#: Phase variance (cycles^2) within every bin up to which the bins are exact: each holds
#: pixels of one phase (lines across axis-aligned bars), no binning error.
EXACT_BIN_PHASE_VAR = 1e-10
_GRID = np.linspace(0.0, 1.0, _GRID_N, endpoint=False)
_TWO_PI = 2.0 * math.pi



def _load_lapack() -> Any:
    """numpy's own LAPACK gufuncs (a private module), used without np.linalg's Python
    wrappers; ``None`` (np.linalg then) unless they exist and give np.linalg's numbers."""
    try:
        from numpy.linalg import _umath_linalg as lapack

        a, b = np.array([[2.0, 1.0], [1.0, 3.0]]), np.array([1.0, 2.0])
        same = (
            np.array_equal(lapack.inv(a, signature="d->d"), np.linalg.inv(a))
            and np.array_equal(lapack.solve1(a, b, signature="dd->d"), np.linalg.solve(a, b))
            and all(np.array_equal(x, y) for x, y in
                    zip(lapack.eigh_lo(a, signature="d->dd"), np.linalg.eigh(a), strict=True))
        )
    except Exception:  # pragma: no cover - another numpy: its public functions then
        return None
    return lapack if same else None


_lapack = _load_lapack()


def _inv(a: FloatArray) -> FloatArray:
    """``np.linalg.inv`` of a float64 matrix: the same LAPACK gufunc (bit-identical) without
    the wrapper's checks and error-state context, ~6 us of its ~7 us on the fit's small
    matrices. Singular: ``LinAlgError`` as numpy raises it (LAPACK then returns NaNs; call
    under ``np.errstate(invalid="ignore")``, once per fit, to keep that quiet)."""
    if _lapack is not None:
        out: FloatArray = _lapack.inv(a, signature="d->d")
        if math.isfinite(out.item(0)):
            return out
    return np.asarray(np.linalg.inv(a), dtype=np.float64)


def _solve(a: FloatArray, b: FloatArray) -> FloatArray:
    """``np.linalg.solve(a, b)`` for a float64 matrix and vector (see :func:`_inv`)."""
    if _lapack is not None:
        out: FloatArray = _lapack.solve1(a, b, signature="dd->d")
        if math.isfinite(out.item(0)):
            return out
    return np.asarray(np.linalg.solve(a, b), dtype=np.float64)


def _eigh(a: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``np.linalg.eigh`` of a symmetric float64 matrix (see :func:`_inv`; ~19 us less)."""
    if _lapack is not None:
        vals, vecs = _lapack.eigh_lo(a, signature="d->dd")
        if math.isfinite(vals.item(0)):
            return vals, vecs
    return np.linalg.eigh(a)  # type: ignore[return-value]


def _phasors(w: FloatArray, n_harm: int, damp: FloatArray | None = None) -> FloatArray:
    """``[cos | sin](2 pi k w)`` (n, 2 n_harm), ``k = 1..n_harm``: the real and imaginary
    parts of the phasors side by side, so that every product is a real one (a complex
    matrix-vector product wakes OpenBLAS's threads: milliseconds), each harmonic times
    ``damp`` when given."""
    # Harmonic k's phasor is the fundamental's k-th power: one complex exp per sample and a
    # running product (rounding grows ~k eps, 1e-14 at 48 harmonics) instead of cos and sin
    # of every harmonic, several times faster.
    z = np.empty((w.size, n_harm), dtype=np.complex128)
    z[:] = np.exp((2j * math.pi) * np.asarray(w, dtype=np.float64))[:, None]
    np.cumprod(z, axis=1, out=z)
    if damp is not None:  # (n, n_harm) real factors of both parts
        z *= damp
    out = np.empty((w.size, 2 * n_harm))
    out[:, :n_harm] = z.real
    out[:, n_harm:] = z.imag
    return out


@lru_cache(maxsize=64)
def _grid_phasors(n_harm: int) -> FloatArray:
    """:func:`_phasors` on the phase grid (read-only, cached per harmonic count)."""
    e = _phasors(_GRID, n_harm)
    e.setflags(write=False)
    return e


class _Model:
    """The blurred square wave on fixed phase samples, with its derivatives.

    Harmonic ``k`` of the bright fraction is ``alpha_k cos(2 pi k (w - delta))`` with
    ``alpha_k = 2 sin(pi k duty) / (pi k) * gain_k(sigma)``: with the phasors
    ``E = exp(2 pi i k w)`` fixed, the value and its three derivatives are the real part of
    ``E @ Z``, one small real product (few numpy calls: the fit evaluates it many times).
    """

    def __init__(
        self, w: FloatArray, freq: float, theta: float, n_harm: int,
        w_var: FloatArray | None = None,
    ) -> None:
        self.k = np.arange(1, n_harm + 1, dtype=np.float64)
        damp = None
        if w_var is not None:
            # A bin averages the profile over its pixels' spread of phases (variance w_var):
            # each harmonic is damped like a Gaussian average of that variance.
            damp = np.exp(-2.0 * math.pi**2 * np.multiply.outer(w_var, self.k * self.k))
        self.e: FloatArray = _phasors(w, n_harm, damp)
        self.fk = freq * self.k
        a, b = barmodel.footprint_sides(theta)
        sides = np.sinc(np.multiply.outer((a, b), self.fk))  # one call: np.sinc costs ~4 us
        self.footprint = sides[0] * sides[1]
        self._blur = -2.0 * math.pi**2 * self.fk**2  # log gain per sigma^2
        self._two_over_pik = 2.0 / (math.pi * self.k)
        self._two_pi_k = 2.0 * math.pi * self.k
        self._minus_two_pi_k = -self._two_pi_k
        self._blur2 = np.concatenate([self._blur, self._blur])
        # For coefficients(): the angles' factors (2 pi k, k) as rows, the amplitudes'
        # factors (2 / (pi k), 2) and the derivative's (-2 pi k, 2 pi k).
        rows = np.empty((3, 2, n_harm))  # filled by rows: np.stack costs ~3 us a call
        rows[0, 0], rows[0, 1] = self._two_pi_k, self.k
        rows[1, 0], rows[1, 1] = self._two_over_pik, 2.0
        rows[2, 0], rows[2, 1] = self._minus_two_pi_k, self._two_pi_k
        self._k_rows, self._amp_rows, self._d_rows = rows
        # The last coefficients computed, shared with the copies made by at() and at_rows():
        # the fit's last step, the phase grid and the levels ask for the same parameters.
        self._recent: dict[tuple[float, float, float], FloatArray] = {}

    def at(self, w: FloatArray | None) -> _Model:
        """The same model on other phase samples (``None``: the cached phase grid)."""
        other = _Model.__new__(_Model)
        other.__dict__.update(self.__dict__)
        if w is None:
            other.e = _grid_phasors(self.k.size)
        else:
            other.e = _phasors(w, self.k.size)
        return other

    def at_rows(self, rows: list[int]) -> _Model:
        """The same model on some of its own phase samples (no phasors recomputed)."""
        other = _Model.__new__(_Model)
        other.__dict__.update(self.__dict__)
        other.e = self.e[rows]
        return other

    def coefficients(self, delta: float, duty: float, var: float) -> FloatArray:
        """``[Re Z | -Im Z]`` (4, 2 n_harm) for value, d/d(delta), d/d(duty), d/d(var)
        (without the duty's own constant and unit derivative); ``var`` is the PSF's
        variance (px^2): the gains are log-linear in it, and its derivative does not vanish
        at zero blur as the sigma's does (Levenberg-Marquardt then stalls on the bound).
        Read-only: the result may be shared with later calls at the same parameters."""
        key = (delta, duty, var)
        recent = self._recent
        got = recent.get(key)
        if got is not None:
            return got
        if len(recent) >= 4:
            recent.clear()
        out = self._coefficients(delta, duty, var)
        recent[key] = out
        return out

    def _coefficients(self, delta: float, duty: float, var: float) -> FloatArray:
        # Z = exp(-2 pi i k delta) gain a_k: [Re | -Im] = [cos | sin](2 pi k delta) gain a_k,
        # and d/d(delta) multiplies Z by -2 pi i k: [Re | -Im] -> 2 pi k [-(-Im) | Re].
        # Real arithmetic throughout (complex temporaries cost more numpy calls).
        # Each product below is the one of the straightforward code (ang = 2 pi k delta,
        # pk = pi duty k, amp = 2 / (pi k) sin(pk) gain, amp_duty = 2 cos(pk) gain, then
        # [cos | sin](ang) times those), in stacked rows: half the numpy calls.
        n_harm = self.k.size
        gain = np.exp(self._blur * var)
        gain *= self.footprint
        arg = np.multiply(self._k_rows, ((delta,), (math.pi * duty,)))  # [ang; pk]
        trig = np.empty((4, n_harm))  # [cos ang; cos pk; sin ang; sin pk]
        np.cos(arg, out=trig[:2])
        np.sin(arg, out=trig[2:])
        amps = np.multiply(self._amp_rows, trig[3::-2])  # [2/(pi k) sin pk; 2 cos pk]
        amps *= gain
        out = np.empty((4, 2 * n_harm))
        rows = out.reshape(4, 2, n_harm)
        np.multiply(trig[0::2], amps[0], out=rows[0])  # [cos ang; sin ang] amp
        np.multiply(rows[0, ::-1], self._d_rows, out=rows[1])
        np.multiply(trig[0::2], amps[1], out=rows[2])
        np.multiply(out[0], self._blur2, out=out[3])
        return out

    def eval(
        self, delta: float, duty: float, var: float, derivatives: bool = True
    ) -> tuple[FloatArray, FloatArray | None]:
        """Bright fraction at the samples and its derivatives (n, 3) in (delta, duty, var)."""
        z = self.coefficients(delta, duty, var)
        if not derivatives:
            value: FloatArray = self.e @ z[0] + duty
            return value, None
        out = self.e @ z.T
        out[:, 0] += duty
        out[:, 2] += 1.0
        return out[:, 0], out[:, 1:]

    def eval_many(self, duty: float, variances: FloatArray) -> FloatArray:
        """Bright fraction (n, len(variances)) at ``delta = 0`` for several blurs at once."""
        gains = np.exp(np.multiply.outer(self._blur, variances)) * self.footprint[:, None]
        alpha = (self._two_over_pik * np.sin(math.pi * duty * self.k))[:, None] * gains
        out: FloatArray = self.e[:, : self.k.size] @ alpha + duty
        return out


class _Fit:
    """Levenberg-Marquardt fit of levels, shading, phase, duty and blur to the binned profile.

    Parameters: ``[D, B - D, (shading along: v, s v), (across: u, s u), delta, duty, var]``
    (``var``: the PSF's variance, px^2). The linear ones are solved exactly at each
    ``(delta, duty, var)`` (variable projection),
    with fixed-size arrays allocated once.
    """

    def __init__(
        self, model: _Model, y: FloatArray, weight: FloatArray, ub: FloatArray,
        vb: FloatArray, n_lin: int, prior_scale: float, fit_duty: bool, sigma_max: float,
    ) -> None:
        self.model, self.y, self.n_lin = model, y, n_lin
        sw = np.sqrt(weight)
        self.sw = sw
        self.extra = [vb, ub][: (n_lin - 2) // 2]
        self.prior_scale, self.fit_duty = prior_scale, fit_duty
        self.var_max = sigma_max * sigma_max
        self.grid = model.at(None)
        # Ridge on the shading terms: a relative shading of SHADING_PRIOR over the half span
        # costs as much as one pixel one noise sigma off (keeps them finite when the bins'
        # positions hardly differ).
        self.ridge = prior_scale / (SHADING_PRIOR * max(float(np.abs(y).max()), 1e-9))
        m, n_shade = y.size, n_lin - 2
        self.m = m
        # Weighted design (m rows) and the shading ridge's rows below it; the columns that
        # do not depend on the model are filled once.
        xa = np.zeros((m + n_shade, n_lin))
        xa[:m, 0] = sw
        for j, t in enumerate(self.extra):
            xa[:m, 2 + 2 * j] = t * sw
        if n_shade:
            xa[m:, 2:] = self.ridge * np.eye(n_shade)
        self.xa = xa
        self.ya = np.zeros(m + n_shade)
        self.ya[:m] = y * sw
        self.swt = [t * sw for t in self.extra]
        self.prior_d = prior_scale / DUTY_PRIOR_SD

    def _fill(self, s: FloatArray) -> FloatArray:
        xa, m = self.xa, self.m
        xa[:m, 1] = s * self.sw
        for j, t in enumerate(self.swt):
            xa[:m, 3 + 2 * j] = s * t
        return xa

    def design(self, s: FloatArray) -> FloatArray:
        """Unweighted design matrix of the linear parameters at model values ``s``."""
        x = np.empty((s.size, self.n_lin))
        x[:, 0] = 1.0
        x[:, 1] = s
        for j, t in enumerate(self.extra):
            x[:, 2 + 2 * j] = t
            x[:, 3 + 2 * j] = s * t
        return x

    def start(self, sigmas: tuple[float, ...]) -> FloatArray:
        """Starting ``(delta, duty, var)``: the blur (of ``sigmas``) whose linear fit of
        levels at duty 0.5 leaves the smallest residual (the blur is the poorly conditioned
        one), all candidates in one pass (weighted regression on the model, in closed form)."""
        sig = np.asarray(sigmas, dtype=np.float64)
        s = self.model.eval_many(0.5, sig * sig)  # (m, n_sigma)
        w = self.sw * self.sw
        sw_tot = float(np.add.reduce(w))
        ybar = float(w @ self.y) / sw_tot
        sbar = (w @ s) / sw_tot
        ds = s - sbar
        sxx = w @ (ds * ds)
        dy = self.y - ybar
        sxy = (w * dy) @ ds
        slope = np.where(sxx > 0, sxy / np.maximum(sxx, 1e-300), 0.0)
        resid = float(w @ dy**2) - slope * sxy
        best = int(np.argmin(resid))
        return np.array([0.0, 0.5, float(sig[best]) ** 2])

    def _projected(
        self, nl: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, float, FloatArray, FloatArray]:
        """Variable projection: the linear parameters solved exactly at the nonlinear ones
        ``nl = (delta, duty, var)``; the residual and its Jacobian in ``nl`` with the linear
        parameters' column space projected out (Kaufman), the cost, and the model and its
        derivatives at the bins."""
        m, n_lin = self.m, self.n_lin
        delta, duty, var = nl.tolist()
        s, ds = self.model.eval(delta, duty, var)
        assert ds is not None
        xa = self._fill(s)
        xt = xa.T
        gram = xt @ xa
        # Keeps it invertible (the diagonal through a view of the contiguous product: the
        # flat iterator costs more).
        diag = gram.ravel()[:: n_lin + 1]
        trace = 0.0  # summed in order, as ndarray.trace sums these few
        for v in diag.tolist():
            trace += v
        diag += 1e-12 * (trace + 1e-300)
        try:
            g_inv = _inv(gram)
        except np.linalg.LinAlgError:
            g_inv = np.asarray(np.linalg.pinv(gram), dtype=np.float64)
        lin = g_inv @ (xt @ self.ya)
        n_rows = xa.shape[0]
        r = np.empty(n_rows + 1)
        r[:n_rows] = self.ya - xa @ lin
        slope = self.sw * lin[1]
        for j, t in enumerate(self.swt):
            slope += lin[3 + 2 * j] * t
        # Rows: the bins, the shading ridge's (no nonlinear dependence), the duty prior.
        jac = np.empty((n_rows + 1, 3))
        np.multiply(ds, -slope[:, None], out=jac[:m])
        jac[m:] = 0.0
        jac[:n_rows] -= xa @ (g_inv @ (xt @ jac[:n_rows]))
        r[n_rows] = self.prior_d * (nl[1] - 0.5)
        jac[n_rows, 1] = self.prior_d
        if not self.fit_duty:
            jac[:, 1] = 0.0
        params = np.concatenate([lin, nl])
        return params, r, jac, float(r @ r), s, ds

    def run(self, sigmas: tuple[float, ...], max_iter: int) -> tuple[FloatArray, FloatArray]:
        """Fitted parameters and ``J^T J`` of all of them (for the covariance)."""
        with np.errstate(invalid="ignore"):  # a singular step is caught (see _inv)
            return self._run(sigmas, max_iter)

    def _run(self, sigmas: tuple[float, ...], max_iter: int) -> tuple[FloatArray, FloatArray]:
        nl = self.start(sigmas)
        params, r, jac, cost, s, ds = self._projected(nl)
        lam = 1e-3
        # Converged when the next step is predicted to lower the cost by less than a
        # hundredth of the noise variance: a move of a tenth of a standard error at most.
        enough = 1e-2 * cost / max(self.m - 3, 1)
        tiny = (1e-5, 1e-5, 1e-5 * self.var_max)
        lo = np.array([-0.5, DUTY_BOUNDS[0], 0.0])
        hi = np.array([0.5, DUTY_BOUNDS[1], self.var_max])
        if not self.fit_duty:
            lo[1] = hi[1] = 0.5
        for _ in range(max_iter):
            jtj = jac.T @ jac
            grad = jac.T @ r
            scale = jtj.diagonal()
            jtj.ravel()[::4] += lam * np.where(scale > 0, scale, 1.0)
            try:
                step = -_solve(jtj, grad)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            if -float(grad @ step) < enough or all(
                    abs(a) < t for a, t in zip(step.tolist(), tiny, strict=True)):
                break
            trial = np.minimum(np.maximum(nl + step, lo), hi)
            got = self._projected(trial)
            if got[3] < cost:
                rel = (cost - got[3]) / max(cost, 1e-300)
                nl = trial
                params, r, jac, cost, s, ds = got
                lam = max(lam / 10, 1e-9)
                enough = 1e-2 * cost / max(self.m - 3, 1)
                if rel < 1e-6:
                    break
            else:
                lam *= 10
        return params, self._full_jtj(params, s, ds)

    def _full_jtj(self, p: FloatArray, s: FloatArray, ds: FloatArray) -> FloatArray:
        """``J^T J`` of every parameter (linear ones included) at the solution."""
        n_lin, m = self.n_lin, self.m
        n_shade = n_lin - 2
        x = self.design(s)
        slope = p[1] + sum(p[3 + 2 * j] * t for j, t in enumerate(self.extra))
        jac = np.zeros((m + 1 + n_shade, p.size))
        jac[:m, :n_lin] = -self.sw[:, None] * x
        jac[:m, n_lin:] = -(self.sw * slope)[:, None] * ds
        jac[m, -2] = self.prior_d
        for j in range(n_shade):
            jac[m + 1 + j, 2 + j] = self.ridge
        if not self.fit_duty:
            jac[:, -2] = 0.0
        jtj: FloatArray = jac.T @ jac
        if not self.fit_duty:  # the duty is fixed: no variance
            jtj[:, -2] = 0.0
            jtj[-2, :] = 0.0
            jtj[-2, -2] = 1e30 * (float(np.abs(jtj).max()) + 1.0)
        return jtj

    def levels(
        self, p: FloatArray, s: FloatArray
    ) -> tuple[float, float, FloatArray, FloatArray]:
        """Dark and bright levels at the ROI centre (min and max over phase of the model
        ``s`` on the phase grid) and their gradients in the parameters (envelope theorem: at
        the extremes' fixed phases)."""
        delta, duty, var = float(p[-3]), float(p[-2]), float(p[-1])
        level = p[0] + p[1] * s
        i_lo, i_hi = int(np.argmin(level)), int(np.argmax(level))
        ext = self.grid.at_rows([i_lo, i_hi])
        s2, ds2 = ext.eval(delta, duty, var)
        assert ds2 is not None
        grads = np.zeros((2, p.size))
        grads[:, 0] = 1.0
        grads[:, 1] = s2
        grads[:, -3:] = p[1] * ds2
        return float(level[i_lo]), float(level[i_hi]), grads[0], grads[1]


#: Pixels per filled phase bin above which the model term shrinks as 1/sqrt(pixels per bin).
DENSE_PIXELS_PER_BIN = 200.0


def _model_sd(
    modulation: float, max_gap_cycles: float, n_bins: int, rel_sd: float | None = None,
    n_pixels: int | None = None, exact_bins: bool = False,
) -> float:
    """Model and sampling-phase uncertainty of the contrast (1 sigma): a relative model term,
    and a term growing with the largest gap between filled phase bins (where the model alone
    says what the profile does between samples). With ``n_pixels`` fitted, beyond
    ``DENSE_PIXELS_PER_BIN`` pixels per bin the whole term shrinks as 1/sqrt(pixels per bin):
    every phase is then sampled many times over and the model's misfit averages out (on the
    analysis benchmark the 200 x 200 ROIs' intervals covered 99 % without it). The binning
    term ``0.5 / n_bins^2`` (a bin averages the profile over its width) is left out with
    ``exact_bins``, where each bin holds pixels of one phase (issue 37: near-Nyquist bars in
    10-14 px ROIs, 10-14 filled bins, covered 100 % with it, 96-98 % without). The fast
    variant keeps it: its shorter series leaves a misfit the term covers (without it its
    ROIs of <= 640 px covered 92 % on the analysis benchmark)."""
    phase_term = sampling_phase_sd(modulation, max_gap_cycles)
    rel = MODEL_REL_SD if rel_sd is None else rel_sd
    bins = max(n_bins, 1)
    sd = math.hypot(rel * modulation, phase_term) + (0.0 if exact_bins else 0.5 / bins**2)
    if n_pixels:
        sd *= min(1.0, math.sqrt(DENSE_PIXELS_PER_BIN * bins / n_pixels))
    return sd


def profile_fit(prep: PreparedROI, fast: bool = False) -> ModulationResult:
    """Fit the imaged bar pattern to the ROI; see the module docstring.

    Parameters
    ----------
    prep : PreparedROI
        The prepared ROI (:func:`benchlab.analysis.bars.roi.prepare_roi`).
    fast : bool
        The ``profilefit-fast`` variant (no curvature, coarser bins, fewer harmonics).

    Returns
    -------
    ModulationResult
        "not resolved" (with the reason in ``warnings``) when the fitted bar amplitude is
        not significant, the ROI is too small, or the frequency is zero.
    """
    name = FAST_NAME if fast else NAME
    warnings = list(prep.warnings)
    img = prep.pixels
    rows, cols = img.shape
    n = img.size
    f_prior = prep.freq_cycles_per_px
    if f_prior == 0:
        return unresolved(name, prep.diagnostics(), warnings)
    if n < 4 or prep.vmax == prep.vmin:
        warnings.append("too few pixels or a single gray level: no bar profile")
        return unresolved(name, prep.diagnostics(), warnings)
    if prep.contrast_underflows:
        # The fit's normal matrix and (dark + bright)^2 underflow: divisions by zero below.
        warnings.append(TINY_CONTRAST_WARNING)
        return unresolved(name, prep.diagnostics(), warnings)
    geom = measure_geometry(img, prep.noise_sigma, f_prior, curvature=not fast, quick_start=True,
                            sums=prep.sums_for(img))
    if geom is None:
        warnings.append("no bar period found in the ROI")
        return unresolved(name, prep.diagnostics(), warnings)
    geom = _apply_priors(prep, geom, warnings)
    f, theta = geom.freq_cycles_per_px, geom.theta_rad
    span = abs((cols - 1) * math.cos(theta)) + abs((rows - 1) * math.sin(theta)) + 1.0
    if span * f < FOLD_REFINE_PERIODS and min(rows, cols) < 16:
        axis_fixed = prep.orientation_given and (math.sin(2 * theta) == 0.0 or abs(
            math.sin(2 * theta)) < 1e-12)
        if not axis_fixed:
            fixed_f = bool(f_prior) and span * f_prior < 2.0
            geom = refine_by_folding(img, geom, fix_freq=fixed_f)
            f, theta = geom.freq_cycles_per_px, geom.theta_rad
    if span * f < MIN_PERIODS_TRIED:
        warnings.append(f"less than one bar period across the ROI ({span:.1f} px)")
        return not_measurable(name, prep.diagnostics(), warnings)

    n_warnings = len(warnings)
    clipped = _clipped_mask(prep)
    fit = _fit_at(prep, geom, fast, clipped)
    fit_geom0 = geom
    if isinstance(fit, str):
        warnings.append(fit)
        if f > NEAR_NYQUIST_CYCLES * (1.0 + 1e-9):
            bound = _alternation_bound(prep, name, f, warnings)
            if bound is not None:
                return bound
        return unresolved(name, prep.diagnostics(), warnings)
    # As in _apply_priors: on a few dozen pixels, or under two periods, the priors rule.
    few = prep.n_pixels < PRIORS_RULE_PIXELS
    fix_theta = prep.orientation_given and (few or abs(math.sin(2 * theta)) < 1e-12)
    fix_freq = bool(f_prior) and (few or span * (f_prior or 0.0) < 2.0 or alias_unresolved(
        f_prior or 0.0, span))
    for _ in range(1 if fast else REFINE_ROUNDS):
        better = _refined(prep, fit, fast, clipped, fix_theta, fix_freq)
        if better is None:
            break
        fit = better
    quiet = quiet_noise_sigma(img)
    pixel_noise = prep.noise_sigma if quiet is None else max(
        min(prep.noise_sigma, quiet), prep.quantisation_sd, MISFIT_MIN_NOISE)
    n_off = 0
    if not prep.noise_given and prep.n_pixels >= PRIORS_RULE_PIXELS:
        fit, n_off = _trimmed(prep, fit, fast, clipped, pixel_noise, (fix_theta, fix_freq))
        if n_off:
            warnings.append(
                f"{n_off} of {prep.n_pixels} pixels ({100.0 * n_off / prep.n_pixels:.0f} %) "
                f"lie more than {TRIM_SIGMAS:g} noise sigmas off the bar pattern (ground or bar "
                "ends around a finite bar set?): left out of the fit")
    geom, params, jtj, fitter, n_lin = fit.geom, fit.params, fit.jtj, fit.fitter, fit.n_lin
    f, theta, n, n_f, wb = geom.freq_cycles_per_px, geom.theta_rad, fit.n, fit.n_f, fit.wb
    span = abs((cols - 1) * math.cos(theta)) + abs((rows - 1) * math.sin(theta)) + 1.0
    if span * f < 1.0:
        warnings.append(f"less than one bar period across the ROI ({span:.1f} px)")
        return not_measurable(name, prep.diagnostics(), warnings)
    if f_prior and geom is not fit_geom0 and len(warnings) > n_warnings - 1 >= 0 and (
        "disagrees with the given frequency" in warnings[n_warnings - 1]
    ) and frequency_disagreement(geom, f_prior) is None:
        del warnings[n_warnings - 1]  # the refined period agrees after all
    model, fit_duty, period = fitter.model, fitter.fit_duty, 1.0 / geom.freq_cycles_per_px
    if fit.n_bad >= 0:
        warnings.append(
            f"saturated pixels taken as censored ({fit.n_bad} of {fit.n_bins} bar phases "
            "mostly saturated, fitted without them): the bright level is the model's"
        )
    grid_s = fit.grid_s
    dark, bright, g_dark, g_bright = fitter.levels(params, grid_s)
    # Levels, shading, phase, blur (and duty), and the direction and frequency found.
    n_params = n_lin + 2 + (2 if fit_duty else 1)
    dof = max(n - n_params, 1)
    noise = max(math.sqrt(fit.resid_ss / dof), prep.quantisation_sd)
    if prep.noise_given:
        noise = prep.noise_sigma
    reported_noise = noise
    if n_off:
        # The pixels kept still hold the pattern's edges against the ground: the residuals'
        # robust scale is the pixels' noise (the interval keeps the whole residual).
        reported_noise = min(noise, max(robust_sigma(fit.resid), prep.quantisation_sd))
    if not prep.noise_given and n >= PRIORS_RULE_PIXELS and noise > MISFIT_RATIO * pixel_noise:
        # The residual is the model's misfit, not the pixels' noise (issue 37: 40 DN for 3 on
        # a 26 px ROI over a three-bar element and its ground); the interval keeps it.
        reported_noise = pixel_noise
        warnings.append(
            f"fit residual {noise:.3g} is {noise / pixel_noise:.0f} x the pixel noise "
            f"({pixel_noise:.3g}): the ROI holds more than a bar pattern (ground around a "
            "finite bar set?); crop it to the bars")

    cov = noise**2 * _scaled_pinv(jtj)
    total = bright + dark
    grad_m = (2.0 * dark * g_bright - 2.0 * bright * g_dark) / total**2 if total > 0 else g_dark * 0
    mean_level = params[0] + params[1] * params[-2]
    a1 = abs(params[1]) * 2.0 * math.sin(math.pi * params[-2]) / math.pi * float(
        math.exp(-2.0 * math.pi**2 * float(params[-1]) * f * f) * model.footprint[0]
    )
    # Significance of the fundamental against the noise of n pixels: the fitted one, and the
    # one of the ROI with its mean and plane removed (a shading ramp is not bars).
    se_a1 = noise * math.sqrt(2.0 / n)
    a1_test = min(a1, geom.amplitude)
    z = float(a1_test) / se_a1 if se_a1 > 0 else (math.inf if a1_test > 0 else 0.0)
    # The reading's fields go into prep.diagnostics (dataclasses.replace costs ~10 us a call).
    fields = dict(
        noise_sigma=reported_noise,
        px_per_period=period,
        freq_cycles_per_px=f,
        bar_angle_deg=math.degrees(theta),
        bar_angle_sd_deg=math.degrees(geom.theta_sd_rad),
        period_sd_px=geom.freq_sd / f**2,
        phase_cycles=float(geom.phase_cycles + params[-3]),
        duty=float(params[-2]),
        blur_sigma_px=math.sqrt(max(float(params[-1]), 0.0)),
        separation_sigma=min(z, 1e9),
    )
    if not z >= RESOLVED_Z:
        warnings.append(
            f"bar fundamental {a1_test:.3g} within {RESOLVED_Z:g} standard errors "
            f"({se_a1:.3g}) of zero: bars not resolved"
        )
        return unresolved(name, prep.diagnostics_with(**fields), warnings)
    # Levels never beyond the samples by more than the model itself says the sampled phases
    # fall short of the extremes (plus two noise sigmas): no overshoot below every sample.
    at_bins = params[0] + params[1] * grid_s[(wb * _GRID_N + 0.5).astype(np.intp) % _GRID_N]
    dark = max(dark, prep.vmin - (float(at_bins.min()) - dark) - 2.0 * noise)
    if clipped is None:  # above the top code the model alone says where the bright level is
        bright = min(bright, prep.vmax + (bright - float(at_bins.max())) + 2.0 * noise)
    if bright + dark <= 0 or bright <= dark:
        warnings.append("fitted dark + bright <= 0: contrast undefined")
        return unresolved(name, prep.diagnostics_with(**fields), warnings)
    modulation = min(eq29_modulation(dark, bright), 1.0)
    sd_noise = math.sqrt(max(float(grad_m @ cov @ grad_m), 0.0))
    # Largest gap between the filled bins' phases, around the period (they are ascending).
    max_gap = max(float(np.diff(wb).max()) if wb.size > 1 else 0.0, float(wb[0] + 1.0 - wb[-1]))
    sd_model = _model_sd(modulation, max_gap, n_f,
                         MODEL_REL_SD_FAST if fast else None, n_pixels=n,
                         exact_bins=fit.exact_bins and not fast)
    sd = math.hypot(sd_noise, sd_model)
    diag = prep.diagnostics_with(**fields, uncertainty_noise=sd_noise,
                                 uncertainty_model=sd_model)
    fundamental = a1 / mean_level if mean_level > 0 else None
    if f > NEAR_NYQUIST_CYCLES * (1.0 + 1e-9) or (not f_prior and alias_unresolved(f, span)):
        # Bins' data means, each held 2 noise sigmas inwards: the model at the phases
        # sampled can still overshoot sharp bars (2.02 px: 0.471 for 0.446).
        margin = 2.0 * noise / np.sqrt(np.maximum(fitter.sw * fitter.sw, 1e-300))
        data_lo = float(np.min(fitter.y + margin))
        data_hi = float(np.max(fitter.y - margin))
        return _sampled_phases_bound(
            resolved(name, dark, bright, modulation, diag, sd, warnings, fundamental),
            at_bins, (data_lo, data_hi), sd_noise, max_gap, f)
    return resolved(name, dark, bright, modulation, diag, sd, warnings, fundamental)


def _trimmed(
    prep: PreparedROI, fit: _Fitted, fast: bool, clipped: npt.NDArray[np.bool_] | None,
    pixel_noise: float, fixed: tuple[bool, bool],
) -> tuple[_Fitted, int]:
    """``fit``, or where its residual is the model's misfit (over :data:`MISFIT_RATIO` x the
    pixel noise) the fit without the pixels off the bar pattern, and how many were left out.

    An ROI over a finite bar set holds ground beyond the bar ends and the outer bars, where
    the periodic pattern predicts bars (issue 37: a 26 px ROI over a three-bar element of
    contrast 0.8 read 0.5, its residual 10 x the pixel noise). Pixels more than twice the
    residual's rms off the fit are left out and the pattern refitted, until none lie further
    off than that or :data:`TRIM_SIGMAS` pixel noise sigmas; the bars themselves, a majority
    of the pixels at each phase, pull the fit back to them round by round. The ground also
    pulls the spectral period of a few bars (1-3 %): unless the frequency is fixed, the
    period is then scanned (:data:`TRIM_FREQ_SCAN`), the rounds rerun at each, and the
    period that leaves the fewest pixels off the pattern kept. At most
    :data:`TRIM_MAX_SHARE` of the pixels go; unless the pixels kept then fit, nothing does."""
    rms = math.sqrt(fit.resid_ss / max(fit.n - 6, 1))
    span = float(prep.vmax - prep.vmin)
    if clipped is not None or rms <= max(MISFIT_RATIO * pixel_noise, TRIM_SPAN_SHARE * span):
        # Sharp bars leave a misfit of a few % of the data's span at their edges; ground in
        # the ROI tens of % (the three-bar element: 25 %). Censored fits are left alone.
        return fit, 0

    def fits(f: _Fitted) -> bool:
        return math.sqrt(f.resid_ss / max(f.n - 6, 1)) <= MISFIT_RATIO * pixel_noise

    start = fit
    fit, exclude = _trim_rounds(prep, fit, fast, clipped, pixel_noise)
    if not exclude.any():
        return start, 0
    if not fixed[1]:
        # Of the periods whose pixels kept fit (residual within MISFIT_RATIO pixel noise
        # sigmas), the one that leaves the fewest off the pattern (then the least residual).
        score = (0 if fits(fit) else 1, int(exclude.sum()), fit.resid_ss / fit.n)
        for scale in TRIM_FREQ_SCAN:
            geom = replace(start.geom, freq_cycles_per_px=start.geom.freq_cycles_per_px * scale)
            other = _fit_at(prep, geom, fast, clipped)
            if isinstance(other, str):
                continue
            fit2, exclude2 = _trim_rounds(prep, other, fast, clipped, pixel_noise)
            score2 = (0 if fits(fit2) else 1, int(exclude2.sum()), fit2.resid_ss / fit2.n)
            if exclude2.any() and score2 < score:
                fit, exclude, score = fit2, exclude2, score2
    if not fits(fit):
        # Leaving pixels out did not make the rest fit: not a bar set on a ground but a
        # pattern the model misses (e.g. sharp bars with shading); the misfit is reported.
        return start, 0
    return fit, int(exclude.sum())


def _trim_rounds(
    prep: PreparedROI, fit: _Fitted, fast: bool, clipped: npt.NDArray[np.bool_] | None,
    pixel_noise: float,
) -> tuple[_Fitted, npt.NDArray[np.bool_]]:
    """The rounds of :func:`_trimmed` at ``fit``'s geometry: the fit and the pixels left out
    (flat)."""
    n_all = prep.n_pixels
    exclude = np.zeros(n_all, dtype=bool)
    rms = math.sqrt(fit.resid_ss / max(fit.n - 6, 1))
    for _ in range(TRIM_ROUNDS):
        threshold = max(2.0 * rms, TRIM_SIGMAS * pixel_noise)
        off = np.abs(fit.resid) > threshold
        if not off.any():
            break
        idx = np.flatnonzero(fit.keep) if fit.keep is not None else np.arange(n_all)
        trial = exclude.copy()
        trial[idx[off]] = True
        if int(trial.sum()) > TRIM_MAX_SHARE * n_all:
            break
        other = _fit_at(prep, fit.geom, fast, clipped, trial.reshape(prep.pixels.shape))
        if isinstance(other, str):
            break
        fit, exclude = other, trial
        rms = math.sqrt(fit.resid_ss / max(fit.n - 6, 1))
    return fit, exclude


def _alternation_bound(
    prep: PreparedROI, name: str, f: float, warnings: list[str]
) -> ModulationResult | None:
    """A lower bound for bars at about 2 px per period whose phases the fit cannot resolve
    (e.g. measured at exactly 2 px: two phases): the contrast of the line-averaged profile's
    extremes, each moved 3 noise sigmas inwards - sampled levels lie within the imaged bars'
    range. ``None`` unless that range spans :data:`PLAIN_SPAN_SIGMAS` noise sigmas (issue 37:
    blind 2.03 px bars read "not resolved")."""
    img = prep.pixels
    axis = prep.axis
    profile = img.mean(axis=1 - axis)
    sd = prep.noise_sigma / math.sqrt(img.shape[1 - axis])
    lo, hi = float(profile.min()) + 3.0 * sd, float(profile.max()) - 3.0 * sd
    if profile.size < 4 or hi <= lo or lo + hi <= 0.0 or hi - lo < PLAIN_SPAN_SIGMAS * sd:
        return None
    m = eq29_modulation(lo, hi)
    reason = (f"{1.0 / f:.2f} px per period, near 2, bar phases not resolved by the fit: the "
              "contrast of the profile's extremes (3 noise sigmas inwards) is a lower bound")
    sd_m = 2.0 * sd * math.hypot(lo, hi) / (lo + hi) ** 2
    return resolved(name, lo, hi, m, prep.diagnostics(), sd_m, warnings).with_updates(
        interval=(m, 1.0), lower_bound=True, bound_reason=reason,
        warnings=(*warnings, f"lower bound: {reason}"))


def _sampled_phases_bound(
    r: ModulationResult, at_bins: FloatArray, data: tuple[float, float], sd_noise: float,
    max_gap: float, f_px: float
) -> ModulationResult:
    """``r`` as a lower bound: the contrast of the fitted profile at the phases sampled, less
    two noise sigmas. Bars within a few percent of 2 px per period are sampled at phases that
    drift by less than a period across the ROI: the fit extrapolates the unsampled ones (issue
    37: 0.310 [0.21, 0.41] for 0.75 at 2.0-2.05 px), while the sampled levels lie within the
    imaged pattern's range, so their contrast never exceeds the bars'."""
    lo, hi = float(at_bins.min()), float(at_bins.max())
    if hi <= lo or hi + lo <= 0.0:
        return r
    m = min(eq29_modulation(lo, hi), r.modulation) - 2.0 * sd_noise
    if data[1] > data[0] and data[0] + data[1] > 0.0:
        m = min(m, eq29_modulation(*data))
    m = max(0.0, m)
    reason = (f"{1.0 / f_px:.2f} px per period, near 2 (largest gap between the bar phases "
              f"sampled {max_gap:.2f} periods): the contrast at the phases sampled is a lower "
              "bound")
    return r.with_updates(dark=lo, bright=hi, modulation=m, interval=(m, 1.0),
                          uncertainty=sd_noise, lower_bound=True, bound_reason=reason,
                          warnings=(*r.warnings, f"lower bound: {reason}"))


@dataclass
class _Fitted:
    """The profile fitted at one bar geometry, with what the refinement and the reading
    need (pixels kept for the fit, their coordinates and residuals)."""

    geom: BarGeometry
    fitter: _Fit
    params: FloatArray
    jtj: FloatArray
    n_lin: int
    n: int  # pixels fitted
    n_f: int  # filled phase bins
    n_bins: int
    n_bad: int  # phase cells left out as saturated (-1: nothing saturated)
    wb: FloatArray  # bins' mean phases
    keep: npt.NDArray[np.bool_] | None  # pixels fitted (None: all)
    s_pix: FloatArray  # model bright fraction at each fitted pixel
    slope_pix: FloatArray | float  # d(value)/d(bright fraction) at each fitted pixel
    resid: FloatArray  # per-pixel residuals
    resid_ss: float
    grid_s: FloatArray  # model bright fraction on the phase grid
    at_grid: npt.NDArray[np.intp]  # each fitted pixel's place on the grid (0.._GRID_N)
    u_px: FloatArray  # across- and along-bar coordinates (px) of the fitted pixels
    v_px: FloatArray
    exact_bins: bool = False  # every phase bin holds pixels of a single phase


def _fit_at(
    prep: PreparedROI, geom: BarGeometry, fast: bool, clipped: npt.NDArray[np.bool_] | None,
    exclude: npt.NDArray[np.bool_] | None = None,
) -> _Fitted | str:
    """Bin the ROI on the bar phase of ``geom`` and fit the model (a reason when it cannot);
    pixels flagged in ``exclude`` (the ROI's shape) are left out."""
    img = prep.pixels
    rows, cols = img.shape
    n = img.size
    f, theta = geom.freq_cycles_per_px, geom.theta_rad
    span = abs((cols - 1) * math.cos(theta)) + abs((rows - 1) * math.sin(theta)) + 1.0
    u_px = across_coordinate((rows, cols), theta)
    v_px = across_coordinate((rows, cols), theta + math.pi / 2)
    if any(geom.hessian):
        phi = phase_map((rows, cols), geom)
    else:  # phase_map's straight-bar case, without computing u again
        phi = u_px * f
        phi += geom.phase_cycles
    w = np.subtract(phi, np.floor(phi), out=phi)  # phase within the period, in place
    half = max(span / 2.0, 1.0)
    u, v = u_px * (1.0 / half), v_px * (1.0 / half)
    n_bins = int(min(MAX_BINS_FAST if fast else MAX_BINS, max(8, n // 6)))
    vals, w_fit, u_fit, v_fit = img, w, u, v
    keep = None
    n_bad = -1
    if clipped is not None:
        # Saturated pixels only say "at least the top code", and the unclipped pixels at the
        # same phases are the noise's low tail: see _censored. Mostly saturated phases are
        # left out and the model carries the bright level over them (their gap in the
        # sampled phases widens the interval, see _model_sd).
        vals, keep, n_bad = _censored(img, clipped, w, n_bins, float(prep.max_code or 0.0))
        if int(keep.sum()) < 4:
            return "every bar phase saturated: no bar profile"
    if exclude is not None:
        keep = ~exclude if keep is None else keep & ~exclude
        if int(keep.sum()) < 4:
            return "too few pixels on the bar pattern"
    if keep is not None:
        vals, w_fit, u_fit, v_fit = vals[keep], w[keep], u[keep], v[keep]
        n = int(vals.size)
        n_bins = int(min(n_bins, max(8, n // 6)))
    width = 1.0 / n_bins
    n_filled, (y, sq, wb, w2b, ub, vb) = filled_bin_means(
        w_fit, [vals, vals * vals, w_fit, w_fit * w_fit, u_fit, v_fit], width
    )
    # Pooled scatter within the bins: an upper bound of the noise that does not depend on the
    # bar angle (neighbour differences along an image axis do).
    within = float(np.add.reduce(n_filled * np.maximum(sq - y**2, 0.0)))
    scale_noise = math.sqrt(within / max(n - n_filled.size, 1))
    if prep.noise_given or scale_noise <= 0:
        scale_noise = prep.noise_sigma
    count = n_filled.astype(np.float64)
    w_var = np.maximum(w2b - wb * wb, 0.0)
    n_f = int(y.size)
    if n_f < 3:
        return f"only {n_f} distinct bar phases sampled: cannot fit the profile"
    n_lin = 2
    # Shading along the bars only where the bins' mean along-bar positions differ (not on
    # axis-aligned bars, where every bin holds whole lines).
    if n_f >= MIN_BINS_SHADING and _spread(vb) > 0.15:
        across = span * f >= MIN_PERIODS_ACROSS_SHADING and _spread(ub) > 0.15
        n_lin = 6 if across else 4
    fit_duty = n_f >= 6
    n_harm = int(min(MAX_HARMONICS_FAST if fast else MAX_HARMONICS, max(1, math.ceil(3.0 / f))))
    model = _Model(wb, f, theta, n_harm, w_var)
    period = 1.0 / f
    fitter = _Fit(
        model, y, count, ub, vb, n_lin, prior_scale=max(min(scale_noise, prep.noise_sigma), 1e-9),
        fit_duty=fit_duty, sigma_max=period,
    )
    starts = tuple(t * period for t in _SIGMA_STARTS)
    params, jtj = fitter.run(starts, max_iter=6 if fast else 12)
    # Per-pixel residuals: the noise, whatever the bar angle.
    grid_s = fitter.grid.eval(float(params[-3]), float(params[-2]), float(params[-1]),
                              derivatives=False)[0]
    # The grid with its first point repeated at w = 1: rounding needs no modulo.
    grid_wrap = np.concatenate((grid_s, grid_s[:1]))
    at_grid = (w_fit.ravel() * _GRID_N + 0.5).astype(np.intp)
    s_pix = grid_wrap[at_grid]
    lin = params[:n_lin]
    shading = list(zip((v_fit.ravel(), u_fit.ravel()), range(2, n_lin, 2), strict=False))
    # value = D + shading offsets + slope * s, built in place (few full-size temporaries);
    # without shading the slope is one number.
    slope: FloatArray | float = float(lin[1])
    if shading:
        slope = np.full(s_pix.shape, float(lin[1]))
        for t, j in shading:
            slope += lin[j + 1] * t
    resid = vals.ravel() - lin[0]
    for t, j in shading:
        resid -= lin[j] * t
    resid -= slope * s_pix
    return _Fitted(
        geom=geom, fitter=fitter, params=params, jtj=jtj, n_lin=n_lin, n=n, n_f=n_f,
        n_bins=n_bins, n_bad=n_bad, wb=wb, keep=None if keep is None else keep.ravel(),
        s_pix=s_pix, slope_pix=slope, resid=resid, resid_ss=float((resid * resid).sum()),
        grid_s=grid_s, at_grid=at_grid,
        u_px=(u_px if keep is None else u_px[keep]).ravel(),
        v_px=(v_px if keep is None else v_px[keep]).ravel(),
        exact_bins=bool(float(w_var.max()) <= EXACT_BIN_PHASE_VAR),
    )


def _refined(
    prep: PreparedROI, fit: _Fitted, fast: bool, clipped: npt.NDArray[np.bool_] | None,
    fix_theta: bool, fix_freq: bool,
) -> _Fitted | None:
    """The fit at a corrected direction and frequency, or ``None`` when no correction is
    significant or the corrected one fits worse.

    The per-pixel residuals are regressed on the model's response to a rotation, a change of
    frequency and a phase shift (Gauss-Newton on the geometry the spectrum measured): on few
    periods or long bars the spectral peak is pulled by its side lobes, and an angle off by
    a degree moves the bar phase by a tenth of a cycle at the ends of a 100 px ROI.
    """
    geom = fit.geom
    f = geom.freq_cycles_per_px
    delta = float(fit.params[-3])
    # Slope of the model's bright fraction in phase, at each fitted pixel (from the grid).
    grid_s = fit.grid_s
    # With the first point repeated at w = 1: the pixels' places on the grid run 0.._GRID_N.
    ds_grid = np.empty(grid_s.size + 1)
    ds_grid[1:-2] = grid_s[2:] - grid_s[:-2]
    ds_grid[0] = grid_s[1] - grid_s[-1]
    ds_grid[-2] = grid_s[0] - grid_s[-2]
    ds_grid[:-1] *= 0.5 * _GRID_N
    ds_grid[-1] = ds_grid[0]
    names = ["phase"]
    if not fix_theta:
        names.append("theta")
    if not fix_freq:
        names.append("freq")
    if len(names) == 1:
        return None
    # A Gauss-Newton step needs no more than REFINE_MAX_PIXELS pixels (evenly strided): the
    # cost stays bounded on large ROIs, whose spectral geometry is close already.
    stride = max(1, fit.n // REFINE_MAX_PIXELS)
    u_px, v_px = fit.u_px[::stride], fit.v_px[::stride]
    resid = fit.resid[::stride]
    slope = fit.slope_pix if isinstance(fit.slope_pix, float) else fit.slope_pix[::stride]
    # The design's rows written in place (np.stack costs a copy).
    design = np.empty((len(names), u_px.size))
    g = design[0]
    np.multiply(slope, ds_grid[fit.at_grid[::stride]], out=g)
    row = 1
    if not fix_theta:
        np.multiply(g, f * v_px, out=design[row])
        row += 1
    if not fix_freq:
        np.multiply(g, u_px, out=design[row])
    # Normal equations in two einsums (numpy's own loops: no BLAS threads on large ROIs).
    normal = np.einsum("in,jn->ij", design, design)
    rhs = np.einsum("in,n->i", design, resid)
    try:
        with np.errstate(invalid="ignore"):
            step = _solve(normal, rhs)
    except np.linalg.LinAlgError:
        return None
    noise2 = fit.resid_ss / max(fit.n - 6, 1)
    # Chi-square of the step over every pixel (the strided sums are 1/stride of theirs).
    significance = float(step @ normal @ step) * stride / max(noise2, 1e-300)
    # Phase moved at the ROI's edges by the change of direction and frequency (cycles).
    moved = 0.0
    whole = stride == 1 and fit.keep is None
    for name, d in zip(names, step, strict=True):
        if name == "theta":
            moved += abs(d) * f * _abs_max(v_px, prep.pixels.shape, whole)
        elif name == "freq":
            moved += abs(d) * _abs_max(u_px, prep.pixels.shape, whole)
    if significance < REFINE_CHI2 or moved < REFINE_MIN_CYCLES:
        return None
    # A linearised step is trusted only for small corrections (a larger one means the
    # spectral geometry was wrong altogether, or the noise is fitted).
    for name, d in zip(names, step, strict=True):
        if (name == "theta" and abs(d) > REFINE_MAX_THETA_RAD) or (
            name == "freq" and abs(d) > REFINE_MAX_FREQ_REL * f
        ):
            return None
    new = geom
    for name, d in zip(names, step, strict=True):
        if name == "theta":
            new = replace(new, theta_rad=new.theta_rad + float(d))
        elif name == "freq":
            new = replace(new, freq_cycles_per_px=max(new.freq_cycles_per_px + float(d), 1e-6))
    new = replace(new, phase_cycles=new.phase_cycles - delta + float(step[0]))
    other = _fit_at(prep, new, fast, clipped)
    if isinstance(other, str) or other.resid_ss / max(other.n, 1) >= fit.resid_ss / max(
        fit.n, 1
    ):
        return None
    return other


def _abs_max(a: FloatArray, shape: tuple[int, ...], whole: bool) -> float:
    """``max |a|`` of a coordinate (``u`` or ``v`` of :func:`.projection.across_coordinate`,
    flattened); with ``whole`` (every pixel of the ``shape`` ROI, in order) read off its four
    corners: the coordinate is a rounded sum of a row and a column term, monotonic in each,
    so its extremes sit at corners - the same number without two passes."""
    if whole:
        cols = shape[1]
        item = a.item
        return max(abs(item(0)), abs(item(cols - 1)), abs(item(a.size - cols)), abs(item(-1)))
    return float(np.abs(a).max())


def _spread(x: FloatArray) -> float:
    """Standard deviation of ``x`` (two reductions; ``ndarray.std`` costs several calls)."""
    m = float(x.sum()) / x.size
    return math.sqrt(max(float((x * x).sum()) / x.size - m * m, 0.0))


def _clipped_mask(prep: PreparedROI) -> npt.NDArray[np.bool_] | None:
    """Pixels at the saturation code (``None`` when none is clipped)."""
    if prep.max_code is None or prep.clipped_fraction <= 0:
        return None
    mask: npt.NDArray[np.bool_] = prep.pixels >= prep.max_code
    return mask if bool(mask.any()) else None


def _censored(
    img: FloatArray, clipped: npt.NDArray[np.bool_], w: FloatArray, n_bins: int, top: float
) -> tuple[FloatArray, npt.NDArray[np.bool_], int]:
    """Pixel values with the saturated ones replaced by their expected value, the pixels to
    fit, and how many phase cells were left out.

    In each of ``n_bins`` phase cells holding saturated pixels the noise is taken as normal:
    where under half of the cell is saturated, its median ``m`` and the spread of its lower
    half ``s`` are unaffected, and a saturated pixel stands for the normal's mean above the top
    code ``T``: ``m + s phi(a) / (1 - Phi(a))``, ``a = (T - m) / s`` (the cell's mean is then
    unbiased). Cells at least half saturated are left out.
    """
    cell = (w * n_bins).astype(np.intp) % n_bins
    flat_cell, flat_clip = cell.ravel(), clipped.ravel()
    n_cell = np.bincount(flat_cell, minlength=n_bins)
    n_clip = np.bincount(flat_cell[flat_clip], minlength=n_bins)
    bad = 2 * n_clip >= np.maximum(n_cell, 1)
    out = img.ravel().copy()
    for c in np.flatnonzero((n_clip > 0) & ~bad):
        members = flat_cell == c
        x = out[members]
        m, q16 = (float(v) for v in np.percentile(x, [50.0, 15.87]))
        s = max(m - q16, 1e-9)
        a = (top - m) / s
        upper = max(0.5 * math.erfc(a / math.sqrt(2.0)), 1e-12)  # 1 - Phi(a)
        tail = math.exp(-0.5 * a * a) / math.sqrt(2.0 * math.pi) / upper
        x[x >= top] = m + s * tail
        out[members] = x
    keep = ~bad[flat_cell]
    return out.reshape(img.shape), keep.reshape(img.shape), int(bad.sum())


def _scaled_pinv(jtj: FloatArray) -> FloatArray:
    """Pseudo-inverse of ``J^T J`` after scaling its columns to unit diagonal (parameters of
    very different units), dropping directions the data do not constrain."""
    diag = jtj.diagonal()
    d = np.sqrt(np.where(diag > 0, diag, 1.0))
    dd = np.multiply.outer(d, d)
    # Symmetric: its eigen-decomposition is its SVD (a tenth of numpy.linalg.pinv's cost on
    # these small matrices), cut at the same relative threshold.
    try:
        with np.errstate(invalid="ignore"):
            vals, vecs = _eigh(jtj / dd)
    except np.linalg.LinAlgError:
        return np.full(jtj.shape, np.inf)
    mag = np.abs(vals)
    inv_vals = np.where(mag > 1e-10 * float(mag.max()), 1.0 / np.where(mag > 0, vals, 1.0), 0.0)
    out: FloatArray = (vecs * inv_vals) @ vecs.T / dd
    return out


def alias_unresolved(f_prior: float, span_px: float) -> bool:
    """Whether bars of the given frequency ``f_prior`` (cycles/px) and their sampling alias
    ``1 - f_prior`` lie fewer than :data:`ALIAS_RAYLEIGH_STEPS` Rayleigh steps apart over
    ``span_px``: the ROI cannot measure the period then, and the given one rules."""
    return (1.0 - 2.0 * f_prior) * span_px < ALIAS_RAYLEIGH_STEPS


def narrow_roi_note(shape: tuple[int, int], px_per_period: float | None,
                    bar_angle_deg: float | None, freq_given: bool) -> str | None:
    """A warning when an ROI of ``shape`` (rows, cols) is too narrow across bars of
    ``px_per_period`` at ``bar_angle_deg`` (direction of intensity variation, from the
    columns) for their period to be measured (:func:`alias_unresolved`), with the width that
    would do; ``None`` when it is wide enough, or when the frequency is given (then it rules).

    The live view reads without a frequency: its default 12 x 10 px ROI on 2.2 px bars can only
    give a bound (issue 37); 28 px across reads them."""
    if freq_given or not px_per_period or px_per_period < 2.0:
        return None  # aliased bars are said so by the reading
    theta = math.radians(bar_angle_deg or 0.0)
    rows, cols = shape
    span = abs((cols - 1) * math.cos(theta)) + abs((rows - 1) * math.sin(theta)) + 1.0
    f = 1.0 / px_per_period
    if not alias_unresolved(f, span):
        return None
    wider = (f"make it >= {math.ceil(ALIAS_RAYLEIGH_STEPS / (1.0 - 2.0 * f))} px across the "
             "bars or give the frequency") if 1.0 - 2.0 * f > 1e-3 else "give the frequency"
    return (f"ROI too narrow for {px_per_period:.2f} px bars: {span:.0f} px across cannot "
            f"measure their period near Nyquist (a bound at best); {wider}")


def _apply_priors(prep: PreparedROI, geom: BarGeometry, warnings: list[str]) -> BarGeometry:
    """Cross-check the measured geometry with the given frequency and orientation."""
    f_prior = prep.freq_cycles_per_px
    rows, cols = prep.pixels.shape
    if prep.orientation_given:
        axis_theta = 0.0 if prep.axis == 1 else math.pi / 2
        if math.cos(axis_theta - geom.theta_rad) < 0:  # the same sense as the measured one
            axis_theta -= math.pi
        diff = abs((geom.theta_rad - axis_theta + math.pi / 2) % math.pi - math.pi / 2)
        tol = max(3.0 * geom.theta_sd_rad, math.radians(ANGLE_TOLERANCE_DEG))
        significant = geom.amplitude > 6.0 * prep.noise_sigma * math.sqrt(2.0 / prep.n_pixels)
        if diff > tol and significant and prep.n_pixels >= PRIORS_RULE_PIXELS:
            warnings.append(
                f"measured bar direction {math.degrees(geom.theta_rad):.1f} deg disagrees with "
                f"the given orientation ({math.degrees(axis_theta) % 180:.0f} deg); the "
                "measured one is used"
            )
        else:
            # Within its uncertainty of the axis (or too weak to tell): exactly on the axis,
            # so every bin holds whole lines of pixels.
            geom = replace(geom, theta_rad=axis_theta)
    if f_prior:
        theta = geom.theta_rad
        span = abs((cols - 1) * math.cos(theta)) + abs((rows - 1) * math.sin(theta)) + 1.0
        if span * f_prior < 2.0:
            # Under two periods the data cannot pin the period down: the prior rules.
            return replace(geom, freq_cycles_per_px=f_prior)
        message = frequency_disagreement(geom, f_prior)
        if message and prep.n_pixels >= PRIORS_RULE_PIXELS and not alias_unresolved(
                f_prior, span):
            warnings.append(message)
        else:
            # Consistent with the given frequency, which is known better (chart design and
            # magnification) than a period measured over a few periods. (Built directly:
            # dataclasses.replace costs a few us.)
            geom = BarGeometry(geom.theta_rad, f_prior, geom.phase_cycles, geom.amplitude,
                               geom.theta_sd_rad, geom.freq_sd, geom.phase_sd, geom.hessian)
    return geom
