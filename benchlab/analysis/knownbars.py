"""A three-bar set read at its known geometry: the levels of the imaged pattern, fitted.

An estimator that sees only an ROI has to find the bars' direction, period and phase from a few
dozen pixels before it can read a contrast; near Nyquist that search costs more accuracy than the
contrast itself. The chart finder already knows each set's geometry from the pose fitted to the
whole chart (bar angle, bar width, centre: every set's centre to a few hundredths of a pixel on
``benchlab benchmark chart``). Here that geometry is fixed and only what the pose cannot know is
fitted:

1. Every pixel centre gets its across-bar coordinate ``u`` (:func:`.projection.across_coordinate`,
   ``u = 0`` on the middle bar) and its along-bar coordinate ``v``.
2. The imaged set is the three dark bars of width ``w`` at ``u = -2w, 0, 2w`` (the ground beyond
   the outer bars is a space: the model is the finite set, not an endless square wave), blurred
   by a Gaussian PSF of ``sigma`` and integrated over the pixel's footprint at the bar angle
   (:func:`.barmodel.edge_response`): a pattern ``P(u; sigma)`` between 0 and 1.
3. Pixel values are ``a + b_u u + b_v v + s P(u; sigma)``: for a fixed ``sigma`` a linear
   least-squares problem (ground level, linear shading, bar depth ``s``; ``s < 0`` for dark bars,
   ``> 0`` for a negative target). ``sigma`` is found by a 1-D search on the residual.
4. The Eq. 2.9 levels are the fitted model at the middle bar's centre and the mean of the spaces
   either side of it (``u = 0`` and ``u = +-w``, ``v = 0``): the contrast a pixel centred on the
   bar and on the spaces would read (the simulated scene's truth is defined the same way).

Oblique bars put every pixel at another phase of the pattern (the slanted-edge trick), so a
model with known geometry is pinned down by the data even at 2-2.5 px per period. Bars on a
pixel axis sample only the phases the pixel grid gives; there the blur is less well determined
and the interval says so.

The interval holds three terms: the noise propagated through the linear fit (the noise estimated
from the residuals, at least the code step's quantisation), the spread of the reading over the
blurs the data allow (``Delta chi^2 <= 1``), and a relative model term (:data:`MODEL_REL_SD`:
shading that is not linear over the ROI, the multiplicative vignetting, the pose's own error).

Pixels at the saturation code are censored: they are left out of the fit (the model carries the
level beyond the top code), with a warning; a set with too few pixels left, or whose bar depth
is not significant above the noise, is "not resolved" with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.analysis.barmodel import edge_response
from benchlab.analysis.projection import across_coordinate
from benchlab.analysis.result import (
    NYQUIST_CYCLES_PER_PX,
    PHASE_SENSITIVE_CYCLES_PER_PX,
    Diagnostics,
    ModulationResult,
    eq29_modulation,
    resolved,
    unresolved,
)
from benchlab.analysis.roi import detect_code_step, infer_max_code

FloatArray = npt.NDArray[np.float64]

NAME = "knownbars"
#: Significance of the bar depth (over its standard error) for "resolved".
RESOLVED_Z = 5.0
#: Fewest unclipped pixels: the four linear terms, the blur and at least this many more.
MIN_DOF = 4
#: Blur searched (PSF sigma, px): from sharp to this many bar widths, within these bounds
#: (beyond about 0.7 bar widths the pattern is gone; a blur of several px on wide bars is
#: defocus the chart's coarse sets would show).
MAX_SIGMA_WIDTHS = 0.75
MAX_SIGMA_BOUNDS_PX = (1.5, 4.0)
#: Blur search: this many blurs from 0 (denser towards sharp), then a parabola at the best.
SIGMA_GRID = 32
#: Prior (1 sigma) on the linear shading: relative change per px of the ROI's span (the forward
#: view's vignetting changes the light by at most ~0.3 % per px).
SHADING_PRIOR_PER_PX = 0.005
#: Default prior (1 sigma, px) on the set's shift across the bars from where the pose puts it
#: (``benchlab benchmark chart``: set centres within 0.06 px of the truth).
SHIFT_PRIOR_PX = 0.05
#: Relative model term (1 sigma) of the modulation.
MODEL_REL_SD = 0.01
#: The sharp pattern is tabulated every this many px (at most this many points) and blurred
#: through its spectrum.
GRID_STEP_PX = 0.02
MAX_GRID_POINTS = 1 << 14
#: Fraction of clipped pixels above which the warning names the share.
CLIPPED_WARN_FRACTION = 0.0


def three_bar_pattern(
    u_px: npt.ArrayLike, bar_width_px: float, sigma_px: float, theta_rad: float
) -> FloatArray:
    """Dark-bar fraction (0-1) of an imaged three-bar set at across-bar positions ``u_px``.

    Three bars of width ``bar_width_px`` centred at ``u = -2w, 0, 2w``, blurred by a Gaussian of
    ``sigma_px`` and integrated over the pixel footprint at ``theta_rad``
    (:func:`benchlab.analysis.barmodel.edge_response`), evaluated exactly.

    Parameters
    ----------
    u_px : array_like
        Across-bar positions (px) from the middle bar's centre.
    bar_width_px : float
        Bar width (px, > 0).
    sigma_px : float
        Gaussian PSF sigma along ``u`` (px, >= 0).
    theta_rad : float
        Direction of intensity variation (from the column axis), for the pixel footprint.

    Returns
    -------
    ndarray
        Same shape as ``u_px``; 1 on a sharp bar, 0 on the ground.
    """
    u = np.asarray(u_px, dtype=np.float64)
    w = float(bar_width_px)
    out = np.zeros_like(u)
    for centre in (-2.0 * w, 0.0, 2.0 * w):
        out += edge_response(u - (centre - 0.5 * w), sigma_px, theta_rad)
        out -= edge_response(u - (centre + 0.5 * w), sigma_px, theta_rad)
    return out


class _Blurred:
    """Bars (intervals of a 1-D coordinate) seen through the pixel footprint and a Gaussian of
    many widths, fast: the sharp pattern (footprint alone, closed form) is tabulated once on a
    fine grid; each blur is a Gaussian gain on its spectrum (one inverse FFT for every blur at
    once), interpolated at the pixels' coordinates."""

    def __init__(
        self, pos: FloatArray, bars: list[tuple[float, float]], theta_rad: float,
        max_sigma_px: float,
    ) -> None:
        self.pos = pos
        pad = 6.0 * max_sigma_px + 1.0
        lo = min(float(pos.min()), min(b[0] for b in bars)) - pad
        hi = max(float(pos.max()), max(b[1] for b in bars)) + pad
        n = min(1 << max(8, math.ceil(math.log2((hi - lo) / GRID_STEP_PX))), MAX_GRID_POINTS)
        self.grid = lo + (hi - lo) * np.arange(n) / n
        sharp = np.zeros(n)
        for start, stop in bars:
            sharp += edge_response(self.grid - start, 0.0, theta_rad)
            sharp -= edge_response(self.grid - stop, 0.0, theta_rad)
        self.spectrum = np.fft.rfft(sharp)
        freqs = np.fft.rfftfreq(n, (hi - lo) / n)
        self.freqs2 = freqs * freqs

    def tables(self, sigmas: FloatArray) -> FloatArray:
        """The blurred pattern on the grid, one row per blur."""
        gain = np.exp(-2.0 * math.pi**2 * np.outer(sigmas * sigmas, self.freqs2))
        return np.fft.irfft(self.spectrum[None, :] * gain, n=self.grid.size, axis=1)

    def at(self, table: FloatArray, pos: FloatArray | None = None) -> FloatArray:
        """One blur's pattern at ``pos`` (default the pixels')."""
        return np.interp(self.pos if pos is None else pos, self.grid, table)

    def slope_at(self, table: FloatArray) -> FloatArray:
        """One blur's pattern's derivative at the pixels."""
        return np.interp(self.pos, self.grid, np.gradient(table, self.grid[1] - self.grid[0]))


@dataclass(frozen=True)
class _Fit:
    """The linear fit at one blur: coefficients, residual sum of squares, inverse normal
    matrix, and the pattern at the bar centre and (mean) at the spaces beside it."""

    coef: FloatArray
    rss: float
    penalty: float
    inv: FloatArray
    p_bar: float
    p_space: float


def _solve(
    design: FloatArray, values: FloatArray, ridge: FloatArray | None = None
) -> tuple[FloatArray, float, float, FloatArray]:
    """Least squares with an optional ridge (prior precision per coefficient, in units of the
    noise variance): coefficients, residual sum of squares, the ridge's penalty, inverse
    normal matrix."""
    gram = design.T @ design
    if ridge is not None:
        gram = gram + np.diag(ridge)
    try:
        inv: FloatArray = np.asarray(np.linalg.inv(gram), dtype=np.float64)
    except np.linalg.LinAlgError:
        inv = np.asarray(np.linalg.pinv(gram), dtype=np.float64)
    coef = inv @ (design.T @ values)
    resid = values - design @ coef
    penalty = float(ridge @ (coef * coef)) if ridge is not None else 0.0
    return coef, float(resid @ resid), penalty, inv


@dataclass(frozen=True)
class ThreeBarReading:
    """:func:`fit_three_bars`'s answer: the reading, and the across-bar blur behind it.

    ``blur_sigma_px`` is the blur the reading used (None when none was fitted);
    ``blur_range_px`` the blurs the data alone allow (``Delta chi^2 <= 1`` without any prior):
    narrow on sets that pin the blur down, wide where the pixels sample too few phases.
    """

    result: ModulationResult
    blur_sigma_px: float | None = None
    blur_range_px: tuple[float, float] | None = None


def read_three_bars(
    roi: npt.ArrayLike,
    *,
    centre_rc: tuple[float, float],
    bar_width_px: float,
    theta_deg: float,
    max_code: float | None = None,
    blur_prior_px: tuple[float, float] | None = None,
    shift_prior_px: float = SHIFT_PRIOR_PX,
) -> ModulationResult:
    """Eq. 2.9 modulation of a three-bar set whose geometry is known (see the module docstring).

    Parameters
    ----------
    roi : array_like
        2-D gray levels (rows, cols), any integer or float dtype, or a 3-D stack (frames, rows,
        cols), which is averaged. Should hold the set with its bar ends trimmed (e.g.
        :attr:`benchlab.analysis.chart_pose.PosedBarSet.whole_period_roi`).
    centre_rc : (float, float)
        The set's centre (middle of the middle bar) in ROI pixel coordinates (row, col).
    bar_width_px : float
        Bar width (px); the period is twice that.
    theta_deg : float
        Direction in which the intensity varies (across the bars), degrees from the column
        axis towards the row axis (:mod:`benchlab.analysis.projection`'s angle).
    max_code : float, optional
        Saturation code; inferred for integer data (255, 4095, 65520, 65535). Pixels at or
        above it are left out of the fit.
    blur_prior_px : (float, float), optional
        Gaussian prior (mean, standard deviation; px) on the PSF sigma across the bars, e.g.
        from the chart's other sets at the same image height
        (:func:`benchlab.analysis.chart_reading.read_chart`). Without it the blur is whatever
        fits the ROI best.

    Returns
    -------
    ModulationResult
        Estimator ``"knownbars"``: levels, modulation, a 1-sigma uncertainty (noise, blur and
        model terms) and its 95 % interval; "not resolved" with the reason when the period is
        under 2 px (aliased), too few pixels remain, or the bars do not stand out of the noise.

    Raises
    ------
    ValueError
        For an empty or non-finite ROI, a ROI that is not 2-D or 3-D, non-finite / non-positive
        geometry or a bad prior.
    """
    return fit_three_bars(roi, centre_rc=centre_rc, bar_width_px=bar_width_px,
                          theta_deg=theta_deg, max_code=max_code,
                          blur_prior_px=blur_prior_px, shift_prior_px=shift_prior_px).result


def fit_three_bars(
    roi: npt.ArrayLike,
    *,
    centre_rc: tuple[float, float],
    bar_width_px: float,
    theta_deg: float,
    max_code: float | None = None,
    blur_prior_px: tuple[float, float] | None = None,
    shift_prior_px: float = SHIFT_PRIOR_PX,
) -> ThreeBarReading:
    """:func:`read_three_bars` with the blur it used and the blurs the data allow."""
    arr = np.asarray(roi)
    if arr.dtype.kind == "b":
        arr = arr.astype(np.uint8)
    if arr.dtype.kind not in "uif":
        raise ValueError(f"ROI must hold numbers, got dtype {arr.dtype}")
    if arr.ndim not in (2, 3) or arr.size == 0:
        raise ValueError(f"ROI must be a non-empty 2-D or 3-D array, got shape {arr.shape}")
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise ValueError("ROI contains NaN or infinite pixels")
    if not (bar_width_px > 0 and math.isfinite(bar_width_px)):
        raise ValueError(f"bar_width_px must be a positive number, got {bar_width_px}")
    if not (math.isfinite(theta_deg) and all(math.isfinite(v) for v in centre_rc)):
        raise ValueError("theta_deg and centre_rc must be finite")
    if max_code is not None and not (max_code > 0 and math.isfinite(max_code)):
        raise ValueError(f"max_code must be positive, got {max_code}")
    if blur_prior_px is not None and not (
        math.isfinite(blur_prior_px[0]) and blur_prior_px[1] > 0 and math.isfinite(blur_prior_px[1])
    ):
        raise ValueError(f"blur_prior_px must be (mean, sd > 0), got {blur_prior_px}")
    if not (shift_prior_px > 0 and math.isfinite(shift_prior_px)):
        raise ValueError(f"shift_prior_px must be a positive number, got {shift_prior_px}")
    n_frames = arr.shape[0] if arr.ndim == 3 else 1
    img = arr.astype(np.float64).mean(axis=0) if arr.ndim == 3 else arr.astype(np.float64)
    integer = arr.dtype.kind in "ui"
    step = detect_code_step(arr.ravel()) if integer else 0.0
    top = max_code if max_code is not None else (
        infer_max_code(arr, step, float(arr.max())) if integer else None)
    period = 2.0 * bar_width_px
    freq = 1.0 / period
    theta = math.radians(theta_deg)
    warnings: list[str] = []

    def diag(**extra: object) -> Diagnostics:
        return Diagnostics(
            n_pixels=int(img.size), px_per_period=period, freq_cycles_per_px=freq,
            clipped_fraction=clipped_fraction, aliased=freq > NYQUIST_CYCLES_PER_PX + 1e-12,
            phase_sensitive=PHASE_SENSITIVE_CYCLES_PER_PX <= freq <= NYQUIST_CYCLES_PER_PX + 1e-12,
            code_step=(step / n_frames) if integer else None, n_frames=n_frames,
            bar_angle_deg=theta_deg % 180.0,
            saturation_code=top if clipped_fraction > 0 else None,
            **extra,  # type: ignore[arg-type]
        )

    if top is not None:
        clip_px = arr >= top if arr.ndim == 2 else (arr >= top).any(axis=0)
    else:
        clip_px = np.zeros(img.shape, dtype=bool)
    clipped_fraction = float(clip_px.mean())
    if freq > NYQUIST_CYCLES_PER_PX + 1e-12:
        return ThreeBarReading(
            unresolved(NAME, diag(), ["not resolved (aliased): period < 2 px"]))
    if clipped_fraction > CLIPPED_WARN_FRACTION:
        warnings.append(f"{int(clip_px.sum())} of {img.size} pixels clipped at code {top:g}: "
                        "left out of the fit (the model carries the level beyond it)")
    u_all = across_coordinate(img.shape, theta, centre_rc)
    v_all = across_coordinate(img.shape, theta + 0.5 * math.pi, centre_rc)
    keep = ~clip_px
    u, v, y = u_all[keep], v_all[keep], img[keep]
    n = int(y.size)
    n_params = 5
    if n < n_params + 1 + MIN_DOF:
        warnings.append(f"too few pixels: {n} unclipped, a fit of the levels, shading and blur "
                        f"needs at least {n_params + 1 + MIN_DOF}")
        return ThreeBarReading(unresolved(NAME, diag(), warnings))
    # shading along u only when the ROI spans the pattern and ground both sides of it; along v
    # only when there are at least two lines along the bars
    design = np.empty((n, n_params))
    design[:, 0] = 1.0
    design[:, 1] = u / max(float(np.ptp(u)), 1.0)
    span_v = float(np.ptp(v))
    design[:, 2] = v / span_v if span_v >= 1.0 else 0.0
    cols = [0, 1, 2, 3, 4] if span_v >= 1.0 else [0, 1, 3, 4]
    max_sigma = min(max(MAX_SIGMA_BOUNDS_PX[0], MAX_SIGMA_WIDTHS * bar_width_px),
                    MAX_SIGMA_BOUNDS_PX[1])
    w = bar_width_px
    across = _Blurred(u, [(c - 0.5 * w, c + 0.5 * w) for c in (-2 * w, 0.0, 2 * w)], theta,
                      max_sigma)
    # the bar ends (at v = +-2.5 w), blurred along the bars by their own PSF width: only when
    # the ROI comes within their reach (the ROI trims the ends by a fraction of a pixel only)
    foot = 0.5 * (abs(math.cos(theta)) + abs(math.sin(theta)))
    near_ends = float(np.abs(v).max()) + foot + 4.0 * max_sigma > 2.5 * w
    along = _Blurred(v, [(-2.5 * w, 2.5 * w)], theta, max_sigma) if near_ends else None
    sigmas = max_sigma * np.linspace(0.0, 1.0, SIGMA_GRID) ** 2
    t_across = across.tables(sigmas)
    t_along = along.tables(sigmas) if along is not None else None
    probe = np.array([0.0, -w, w])  # the bar centre and the spaces beside it

    ridge: FloatArray | None = None

    def fit(tu: FloatArray, tv: FloatArray | None) -> _Fit:
        """Linear fit at one blur across (``tu``) and along (``tv``) the bars."""
        a_pix = along.at(tv) if along is not None and tv is not None else 1.0
        a_mid = float(along.at(tv, np.zeros(1))[0]) if along is not None and tv is not None \
            else 1.0
        design[:, 3] = across.slope_at(tu) * a_pix
        design[:, 4] = across.at(tu) * a_pix
        coef, rss, penalty, inv = _solve(design[:, cols], y, ridge)
        p0, pm, pp = across.at(tu, probe) * a_mid
        return _Fit(coef, rss + penalty, penalty, inv, float(p0), 0.5 * float(pm + pp))

    # The scale of the priors on shading and shift: a free fit on a coarse blur grid gives the
    # noise, the ground level and the bar depth.
    coarse = [fit(t_across[i], None if t_along is None else t_along[i])
              for i in range(0, sigmas.size, 4)]
    first = min(coarse, key=lambda f: f.rss)
    noise0_sq = max(first.rss / max(n - len(cols) - 1, 1), 1e-300)
    prior_sd = np.array([math.inf, SHADING_PRIOR_PER_PX * max(float(np.ptp(u)), 1.0),
                         SHADING_PRIOR_PER_PX * max(span_v, 1.0), math.inf, math.inf])
    prior_sd[1:3] *= abs(float(first.coef[0]))
    prior_sd[3] = abs(float(first.coef[-1])) * shift_prior_px
    ridge = np.array([noise0_sq / sd**2 if 0 < sd < math.inf else 0.0 for sd in prior_sd[cols]])

    # one blur for both directions, then along the bars at the best, then across at that
    tied = [fit(t_across[i], None if t_along is None else t_along[i]) for i in range(sigmas.size)]
    i_u = i_v = int(np.argmin([f.rss for f in tied]))
    along_fits: list[_Fit] = []
    if t_along is not None:
        along_fits = [fit(t_across[i_u], t_along[j]) for j in range(sigmas.size)]
        i_v = int(np.argmin([f.rss for f in along_fits]))
    tv_best = None if t_along is None else t_along[i_v]
    across_fits = [fit(t_across[i], tv_best) for i in range(sigmas.size)]
    rss = np.array([f.rss for f in across_fits])
    rss_free = float(rss.min())
    rss_data = min(f.rss - f.penalty for f in across_fits)
    dof = n - len(cols) - 1
    noise = math.sqrt(rss_data / dof) if dof > 0 else 0.0
    if integer:
        noise = max(noise, (step / n_frames) / math.sqrt(12.0))
    scale = noise * noise if noise > 0 else max(rss_free, 1e-300)

    def objective(sig: FloatArray, r: FloatArray) -> FloatArray:
        """Chi-square of the fit plus the blur prior's (the noise from the best free fit)."""
        out = r / scale
        if blur_prior_px is not None:
            out = out + ((sig - blur_prior_px[0]) / blur_prior_px[1]) ** 2
        return np.asarray(out, dtype=np.float64)

    obj = objective(sigmas, rss)
    allowed = sigmas[rss / scale - rss_free / scale <= 1.0]
    blur_range = (float(allowed.min()), float(allowed.max()))
    i = int(np.argmin(obj))
    sigma_best, best, obj_best = float(sigmas[i]), across_fits[i], float(obj[i])
    if 0 < i < sigmas.size - 1:  # parabola through the best grid point and its neighbours
        x0, x1, x2 = sigmas[i - 1:i + 2]
        y0, y1, y2 = obj[i - 1:i + 2]
        den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0)
        if den != 0:
            vertex = x1 - 0.5 * ((x1 - x0) ** 2 * (y1 - y2) - (x1 - x2) ** 2 * (y1 - y0)) / den
            if x0 < vertex < x2:
                cand = fit(across.tables(np.array([vertex]))[0], tv_best)
                cand_obj = float(objective(np.array([vertex]), np.array([cand.rss]))[0])
                if cand_obj < obj_best:
                    sigma_best, best, obj_best = float(vertex), cand, cand_obj
    coef, inv, p_bar, p_space = best.coef, best.inv, best.p_bar, best.p_space

    def levels(c: FloatArray, p0: float, p_sp: float) -> tuple[float, float]:
        """(bar, space) levels of the fitted model at v = 0."""
        return float(c[0]) + float(c[-1]) * p0, float(c[0]) + float(c[-1]) * p_sp

    bar, space = levels(coef, p_bar, p_space)
    depth = float(coef[-1])
    depth_sd = noise * math.sqrt(max(float(inv[-1, -1]), 0.0))
    extra: dict[str, object] = {"noise_sigma": noise, "blur_sigma_px": sigma_best,
                                "phase_cycles": 0.0}
    if not abs(depth) > RESOLVED_Z * depth_sd or p_bar - p_space <= 0:
        warnings.append(f"bar depth {abs(depth):.3g} within {RESOLVED_Z:g} standard errors "
                        f"({depth_sd:.3g}) of zero: bars not resolved")
        return ThreeBarReading(unresolved(NAME, diag(**extra), warnings), sigma_best, blur_range)
    dark, bright = min(bar, space), max(bar, space)
    if dark + bright <= 0 or dark < 0:
        warnings.append("fitted dark level below zero: contrast undefined")
        return ThreeBarReading(unresolved(NAME, diag(**extra), warnings), sigma_best, blur_range)
    modulation = eq29_modulation(dark, bright)
    # noise: m = |bar - space| / (bar + space), bar and space linear in (ground, depth)
    total = bar + space
    sign = 1.0 if space >= bar else -1.0
    dm_dspace = sign * 2.0 * bar / total**2
    dm_dbar = -sign * 2.0 * space / total**2
    grad = np.zeros(len(cols))
    grad[0] = dm_dbar + dm_dspace
    grad[-1] = dm_dbar * p_bar + dm_dspace * p_space
    noise_sd = noise * math.sqrt(max(float(grad @ inv @ grad), 0.0))
    # blur: the spread of the reading over the blurs the data allow (Delta chi^2 <= 1)
    blur_sd = 0.0
    if noise > 0:
        for profile, objs in ((across_fits, obj), (along_fits, None)):
            mods = [modulation]
            for k, f in enumerate(profile):
                excess = (objs[k] - obj_best) if objs is not None else (f.rss - best.rss) / scale
                if excess <= 1.0:
                    b_s, sp_s = levels(f.coef, f.p_bar, f.p_space)
                    if b_s + sp_s > 0:
                        mods.append(abs(sp_s - b_s) / (b_s + sp_s))
            blur_sd = math.hypot(blur_sd, 0.5 * (max(mods) - min(mods)))
    model_sd = MODEL_REL_SD * modulation
    sd = math.sqrt(noise_sd**2 + blur_sd**2 + model_sd**2)
    extra.update(uncertainty_noise=noise_sd, uncertainty_model=math.hypot(blur_sd, model_sd))
    if modulation > 1.0:
        modulation = 1.0
    return ThreeBarReading(resolved(NAME, dark, bright, modulation, diag(**extra), sd, warnings),
                           sigma_best, blur_range)
