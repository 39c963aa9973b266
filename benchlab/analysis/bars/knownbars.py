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
   (:func:`.model.edge_response`): a pattern ``P(u; sigma)`` between 0 and 1. The bar ends
   (``v = +-2.5 w``) are blurred the same way along the bars, ``A(v; sigma_v)``, so the ROI may
   run up to and past them.
3. Pixel values are ``a + b_u u + b_v v + c P'(u) A(v) + s P(u) A(v)``: for fixed blurs a
   linear least-squares problem (ground level, linear shading, a small shift ``-c / s`` of the
   set across the bars, bar depth ``s``; ``s < 0`` for dark bars, ``> 0`` for a negative
   target), the shading and the shift held by weak priors (:data:`SHADING_PRIOR_PER_PX`,
   ``shift_prior_px``) so that a ROI of a few lines cannot trade them for contrast. The blurs
   are a 1-D search each (every blur of a grid solved at once; a parabola at the best), with an
   optional prior on ``sigma`` (the chart's other sets:
   :func:`benchlab.analysis.chart.reading.read_chart`).
4. The Eq. 2.9 levels are the fitted model at the middle bar's centre and the mean of the spaces
   either side of it (``u = 0`` and ``u = +-w``, ``v = 0``): the contrast a pixel centred on the
   bar and on the spaces would read (the simulated scene's truth is defined the same way).

Oblique bars put every pixel at another phase of the pattern (the slanted-edge trick), so a
model with known geometry is pinned down by the data even at 2-2.5 px per period. Bars on a
pixel axis sample only the phases the pixel grid gives; there the blur is less well determined
and the interval says so.

The interval holds the noise propagated through the linear fit (the noise estimated from the
residuals, at least the code step's quantisation; the shift's and shading's uncertainty
included), the spread of the reading over the blurs the data (and prior) allow
(``Delta chi^2 <= 1``), a sampling-phase term where no pixel comes near the bar centre or a
space centre (:data:`PHASE_GAP_REL`), and a model term (:data:`MODEL_REL_SD` relative,
:data:`MODEL_ABS_SD` absolute).

The PSF need not be Gaussian: across the bars the blur family also holds defocus, a uniform
disc (line spread ``2 sqrt(R^2 - u^2) / (pi R^2)``, spectrum ``2 J1(2 pi R f) / (2 pi R f)``,
:func:`disc_gain`) taking :data:`DISC_SHARES` of the PSF's variance, the rest Gaussian; every
shape on its grid of equivalent sigmas is solved in the same batch, and a disc shape is chosen
only when it pays :data:`DISC_PENALTY` / :data:`DISC_REL_GAIN` in chi-square (within that its
reading widens the interval through the blur spread). A disc past its first zero reverses the
contrast (spurious resolution): the reading keeps its sign (negative), with a warning, and its
interval may go below 0; given the target's polarity (``dark_bars``) a reversed set cannot pass
for bars of the other polarity. The along-bar blur is searched again in the chosen shape, and the
shape's size is held uncertain by at least :data:`DISC_SIGMA_FLOOR_PX` (a disc is not separable:
the separable model's best size is biased). Residual structure beyond the noise (the residual
variance minus the white noise's, estimated from successive differences in order of ``u``) adds a
misfit term that does not shrink with pixel count (:data:`MISFIT_Z`).

Pixels at the saturation code are censored: they are left out of the fit (the model carries the
level beyond the top code), with a warning; a set with too few pixels left, or whose bar depth
is not significant above the noise, is "not resolved" with the reason.

The blurred patterns tabulated at a set's pixels are kept a while (bounded:
:data:`TABULATION_CACHE_BYTES`) for a later fit at the same geometry that asks for them
(``reuse_tabulation``: a set imaged through a measured transfer at the setup its chart reading
used, :func:`benchlab.analysis.chart.threebar.predict_reading`): the same computation from the
same inputs, skipped.

Why one module of ~1100 lines: the model, its linear solve, the blur search and the interval
share one design matrix and its cached columns, and none of them is used apart from the others.
"""

from __future__ import annotations

import copy
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars.extremes import honest_reading
from benchlab.analysis.bars.model import edge_response
from benchlab.analysis.bars.projection import across_coordinate
from benchlab.analysis.bars.result import (
    Diagnostics,
    ModulationResult,
    eq29_modulation,
    resolved,
    unresolved,
)
from benchlab.analysis.bars.roi import PreparedROI, prepare_roi
from benchlab.analysis.mtf.jinc import jinc

NAME = "knownbars"
#: Significance of the bar depth (over its standard error) for "resolved".
RESOLVED_Z = 5.0
#: Fewest unclipped pixels: the four linear terms, the blur and at least this many more.
MIN_DOF = 4
#: Blur searched (PSF sigma, px): from sharp to this many bar widths, within these bounds
#: (beyond about 0.7 bar widths hardly any contrast is left; a blur of several px on wide
#: bars is defocus the chart's coarse sets would show; 0.75 cut the search short of a 2 px
#: defocus on 2.8 px bars).
MAX_SIGMA_WIDTHS = 1.0
MAX_SIGMA_BOUNDS_PX = (1.5, 4.0)
#: Blur search: this many blurs from 0 (denser towards sharp), then a parabola at the best.
SIGMA_GRID = 32
#: Prior (1 sigma) on the linear shading: relative change per px of the ROI's span (the forward
#: view's vignetting changes the light by at most ~0.3 % per px).
SHADING_PRIOR_PER_PX = 0.005
#: Default prior (1 sigma, px) on the set's shift across the bars from where the pose puts it
#: (``benchlab benchmark chart``: set centres within 0.06 px of the truth).
SHIFT_PRIOR_PX = 0.05
#: A fitted shift of at least this many px is applied to the coordinates and the fit repeated.
REFIT_SHIFT_PX = 0.015
#: Relative model term (1 sigma) of the modulation: shading that is not linear over the ROI,
#: the multiplicative vignetting, the pose's own error. Calibrated on ``benchlab benchmark
#: chart`` (40 + 8 frames): 95 % intervals holding the truth for 94.9 % of the oblique sets at
#: 2-2.25 px per period and 100 % elsewhere, with :data:`MODEL_ABS_SD` (0.01 alone gave
#: 98.7-100 % at 1.6 times the width).
MODEL_REL_SD = 0.005
#: Absolute model term (1 sigma): at low contrast (a defocused chart, 1-2 px of extra blur, 8-bit
#: frames) the relative term alone gave intervals of +-0.0015 that missed the truth by
#: 0.002-0.004 on a quarter of the sets.
MODEL_ABS_SD = 0.002
#: Sampling-phase term, relative: ``PHASE_GAP_REL * gap^2`` where ``gap`` (cycles) is how far
#: the nearest pixel phase stays from the bar centre or a space centre; there the levels rest
#: on the model's shape between samples (bars on a pixel axis near 2 px per period).
PHASE_GAP_REL = 2.0
#: Defocus across the bars: the uniform disc's share of the PSF's variance (disc radius
#: ``2 sigma sqrt(share)``, the rest Gaussian) tried besides the pure Gaussian, each on a grid of
#: this many equivalent sigmas (a disc reverses the contrast past its first OTF zero, which no
#: Gaussian can).
DISC_SHARES = (0.5, 1.0)
DISC_SIGMA_GRID = 32
#: A defocus shape is chosen over the Gaussian only when it lowers the chi-square by more than
#: this (twice the extra parameter's price in Akaike's criterion: chance alone rarely pays
#: it); within it, its reading widens the interval instead.
DISC_PENALTY = 4.0
#: ... and by more than this share of the Gaussian's residual sum of squares (noise-free frames
#: have a chi-square scale near zero: a slightly non-linear shading would otherwise buy a disc).
DISC_REL_GAIN = 0.25
#: Defocus shapes are tried from this equivalent sigma (px) up: below it the pixel footprint
#: dominates the blur and the shape only absorbs other model errors (a noise-free simulated
#: chart at sigma 0.16 px bought a disc share and read 0.007 low).
DISC_MIN_SIGMA_PX = 0.3
#: With a defocus shape chosen, its equivalent sigma is held uncertain by at least this (px):
#: the disc is not separable (its bar ends blur the pattern across too), so the separable
#: model's best size carries a bias a sharp chi-square does not show (``--psf-check``: disc of
#: 1.6 px on 1-1.5 px bars read up to 0.01 off at +-0.005 without it).
DISC_SIGMA_FLOOR_PX = 0.03
#: Misfit: residual variance beyond the white noise counts when above this many standard errors
#: (the difference estimate's relative variance about ``MISFIT_VAR_FACTOR / n``).
MISFIT_Z = 3.0
MISFIT_VAR_FACTOR = 5.0
#: The sharp pattern is tabulated every this many px (at most this many points) and blurred
#: through its spectrum.
GRID_STEP_PX = 0.02
MAX_GRID_POINTS = 1 << 14
#: A defocus row's disc gain is computed only where its Gaussian part is above e^-this
#: (1e-20); beyond, the gain is set to 0 (it changes a tabulated pattern by < 1e-20).
GAUSS_CUTOFF = 46.0
#: ``exp(x)`` is exactly 0 in float64 below x = -745.2; columns whose exponent is below this
#: (a margin for the rounding of the limit) are left at 0 without being evaluated.
EXP_UNDERFLOW = -750.0
#: The patterns of recent fits tabulated at their pixels are kept (at most this many bytes,
#: the least recently used dropped first; a set's entry above the second figure not kept) for
#: a fit at the same geometry: a set imaged at the setup its chart reading used
#: (:func:`benchlab.analysis.chart.threebar.predict_reading`, read with ``reuse_tabulation``)
#: skips the tabulation, about half of the fit of a small set.
TABULATION_CACHE_BYTES = 4 << 20
TABULATION_ENTRY_MAX_BYTES = 512 << 10


def three_bar_pattern(
    u_px: npt.ArrayLike, bar_width_px: float, sigma_px: float, theta_rad: float
) -> FloatArray:
    """Dark-bar fraction (0-1) of an imaged three-bar set at across-bar positions ``u_px``.

    Three bars of width ``bar_width_px`` centred at ``u = -2w, 0, 2w``, blurred by a Gaussian of
    ``sigma_px`` and integrated over the pixel footprint at ``theta_rad``
    (:func:`benchlab.analysis.bars.model.edge_response`), evaluated exactly.

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


def disc_gain(radius_px: npt.ArrayLike, freqs_cycles_per_px: npt.ArrayLike) -> FloatArray:
    """Spectrum of a uniform disc's line spread (defocus): ``2 J1(x) / x``, ``x = 2 pi R f``.

    Parameters
    ----------
    radius_px : array_like
        Disc radii (px, >= 0), shape (m,).
    freqs_cycles_per_px : array_like
        Frequencies (cycles/px, >= 0), shape (n,).

    Returns
    -------
    ndarray
        (m, n) gains; 1 at ``f = 0``, negative between the first zeros (``x`` = 3.83-7.02):
        the contrast reversal of a defocused lens. Within
        :data:`benchlab.analysis.mtf.jinc.JINC_MAX_ERROR` of the exact value (numpy alone:
        importing ``scipy.special`` for it cost ~0.2 s of a re-analysis).
    """
    x = 2.0 * math.pi * np.outer(np.asarray(radius_px, dtype=np.float64),
                                 np.asarray(freqs_cycles_per_px, dtype=np.float64))
    return jinc(x)


def gaussian_gain(rates: FloatArray, freqs2: FloatArray,
                  stop: npt.NDArray[np.intp] | None = None) -> FloatArray:
    """``exp(outer(rates, freqs2))`` (rates <= 0, ``freqs2`` ascending and finite), bit for
    bit, without evaluating the exponentials that underflow to 0 (a wide Gaussian's gain
    vanishes after a small share of the columns) nor those of a rate of 0 (``exp(+-0) == 1``
    exactly: the sharp row and every pure-disc row, whose Gaussian part has no variance): the
    exponentials were most of a tabulation's cost. ``stop`` (per row): the columns from which
    the caller needs no value, left 0 (a defocus row's beyond its Gaussian cutoff)."""
    gain = np.zeros((rates.size, freqs2.size))
    with np.errstate(divide="ignore"):
        limit = np.where(rates < 0, EXP_UNDERFLOW / np.where(rates < 0, rates, -1.0), np.inf)
    cols = np.searchsorted(freqs2, limit, side="right")
    if stop is not None:
        cols = np.minimum(cols, stop)
    for row, (rate, k) in enumerate(zip(rates, cols, strict=True)):
        if rate == 0.0:
            gain[row, :k] = 1.0
            continue
        # the same products and exponentials as the whole outer product, on the columns before
        # the underflow (each a contiguous run, so numpy's vector loop computes them alike)
        np.exp(rate * freqs2[:k], out=gain[row, :k])
    return gain


class _Blurred:
    """Bars (intervals of a 1-D coordinate) seen through the pixel footprint and a Gaussian of
    many widths, fast: the sharp pattern (footprint alone, closed form) is tabulated once on a
    fine grid; each blur is a Gaussian gain on its spectrum (one inverse FFT for every blur at
    once), read at the pixels' coordinates by linear interpolation (weights computed once)."""

    def __init__(
        self, pos: FloatArray, bars: list[tuple[float, float]], theta_rad: float,
        max_sigma_px: float,
    ) -> None:
        pad = 6.0 * max_sigma_px + 1.0
        lo = min(float(pos.min()), min(b[0] for b in bars)) - pad
        hi = max(float(pos.max()), max(b[1] for b in bars)) + pad
        n = min(1 << max(8, math.ceil(math.log2((hi - lo) / GRID_STEP_PX))), MAX_GRID_POINTS)
        self.lo, self.step = lo, (hi - lo) / n
        grid = lo + self.step * np.arange(n)
        sharp = np.zeros(n)
        for start, stop in bars:
            sharp += edge_response(grid - start, 0.0, theta_rad)
            sharp -= edge_response(grid - stop, 0.0, theta_rad)
        self.spectrum = np.fft.rfft(sharp)
        freqs = np.fft.rfftfreq(n, self.step)
        self.freqs2 = freqs * freqs
        # the defocus gain's frequencies, as sqrt(freqs2) (not always freqs to the last bit)
        self.freqs = np.sqrt(self.freqs2)
        self.n = n
        self.idx, self.frac = self._weights(pos)

    def moved(self, pos: FloatArray) -> _Blurred:
        """The same tabulation read at other positions ``pos``."""
        out = copy.copy(self)
        out.idx, out.frac = self._weights(pos)
        return out

    def _weights(self, pos: FloatArray) -> tuple[npt.NDArray[np.intp], FloatArray]:
        x = (np.asarray(pos, dtype=np.float64) - self.lo) / self.step
        idx = np.clip(np.floor(x).astype(np.intp), 0, self.n - 2)
        return idx, x - idx

    def tables(self, sigmas: FloatArray, disc_shares: FloatArray | None = None) -> FloatArray:
        """The blurred pattern on the grid, one row per blur: ``sigmas`` the PSF's equivalent
        sigma (px), ``disc_shares`` the disc's share of its variance (default 0: Gaussian)."""
        sigmas = np.asarray(sigmas, dtype=np.float64)
        share = (np.zeros_like(sigmas) if disc_shares is None
                 else np.asarray(disc_shares, dtype=np.float64))
        gauss_var = sigmas * sigmas * (1.0 - share)
        disc = np.flatnonzero(share > 0)
        stop = None
        if disc.size:
            # a defocus row's gain is needed only up to its Gaussian cutoff (0 beyond), a pure
            # disc's not at all (the disc's gain alone)
            disc_cols = self._disc_cutoff(gauss_var[disc])
            stop = np.full(sigmas.size, self.freqs2.size)
            stop[disc] = np.where(gauss_var[disc] == 0.0, 0, disc_cols)
        gain = gaussian_gain((-2.0 * math.pi**2) * gauss_var, self.freqs2, stop)
        if disc.size:
            self._apply_disc(gain, disc, 2.0 * sigmas[disc] * np.sqrt(share[disc]),
                             gauss_var[disc], disc_cols)
        # the spectrum times a real gain, without a complex copy of the gain
        spec = np.empty(gain.shape, dtype=np.complex128)
        np.multiply(gain, self.spectrum.real, out=spec.real)
        np.multiply(gain, self.spectrum.imag, out=spec.imag)
        return np.fft.irfft(spec, n=self.n, axis=1)

    def _disc_cutoff(self, gauss_var: FloatArray) -> npt.NDArray[np.intp]:
        """Per defocus row (its Gaussian part of variance ``gauss_var``), the first column
        where that part is below ``e^-GAUSS_CUTOFF`` (the number of columns when none)."""
        with np.errstate(divide="ignore"):
            limit = np.where(gauss_var > 0, GAUSS_CUTOFF / (2.0 * math.pi**2 * gauss_var),
                             np.inf)
        return np.searchsorted(self.freqs2, limit, side="right")

    def _apply_disc(self, gain: FloatArray, rows: npt.NDArray[np.intp], radius: FloatArray,
                    gauss_var: FloatArray, cols: npt.NDArray[np.intp]) -> None:
        """Multiply ``gain``'s ``rows`` by a uniform disc's gain (:func:`disc_gain`; its line
        spread has a variance of ``R^2 / 4``), in place. Only where the row's Gaussian part
        (of variance ``gauss_var``) is above ``e^-GAUSS_CUTOFF``, before the row's ``cols``
        (:meth:`_disc_cutoff`): beyond, the product is below 1e-20 and 0 (:func:`gaussian_gain`
        left it 0 there). That leaves a partly Gaussian row a few per cent of its columns. A
        row without Gaussian part is assigned the disc's gain (its Gaussian gain, 1, was not
        tabulated)."""
        k_all = self.freqs2.size
        freqs = self.freqs
        whole = cols >= k_all
        if whole.any():
            # a row without Gaussian part has a gain of exactly 1: its product with the disc's
            # gain is that gain, unmultiplied
            pure = whole & (gauss_var == 0.0)
            mixed = whole & ~pure
            if pure.any():
                gain[rows[pure]] = jinc((2.0 * math.pi) * np.outer(radius[pure], freqs))
            if mixed.any():
                gain[rows[mixed]] *= jinc((2.0 * math.pi) * np.outer(radius[mixed], freqs))
        part = np.flatnonzero(~whole)
        if part.size:
            counts = cols[part]
            row_of = np.repeat(np.arange(part.size), counts)
            col = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
            at = (rows[part][row_of], col)
            gain[at] *= jinc((2.0 * math.pi) * radius[part][row_of] * freqs[col])

    def sample(self, tables: FloatArray, pos: FloatArray | None = None) -> FloatArray:
        """Each table's pattern at ``pos`` (default the pixels'): (blurs, positions)."""
        idx, frac = (self.idx, self.frac) if pos is None else self._weights(pos)
        left, right = tables.take(idx, axis=1), tables.take(idx + 1, axis=1)
        return np.asarray(left + frac * (right - left), dtype=np.float64)

    def slope(self, tables: FloatArray) -> FloatArray:
        """Each table's derivative at the pixels (the grid step's finite difference)."""
        return self.sample_and_slope(tables)[1]

    def sample_and_slope(self, tables: FloatArray) -> tuple[FloatArray, FloatArray]:
        """:meth:`sample` and :meth:`slope` at the pixels, from one gather."""
        left, right = tables.take(self.idx, axis=1), tables.take(self.idx + 1, axis=1)
        diff = right - left
        return (np.asarray(left + self.frac * diff, dtype=np.float64),
                np.asarray(diff / self.step, dtype=np.float64))


@dataclass(frozen=True)
class _Batch:
    """Linear fits at several blurs: coefficients (m, k), residual sum of squares plus the
    ridge's penalty (m,), the penalty (m,), inverse normal matrices (m, k, k), and the
    pattern at the bar centre and (mean) at the spaces beside it (m,)."""

    coef: FloatArray
    cost: FloatArray
    penalty: FloatArray
    inv: FloatArray
    p_bar: FloatArray
    p_space: FloatArray

    def modulations(self, dark_bars: bool | None = None) -> FloatArray:
        """Eq. 2.9 contrast of each fit (NaN where undefined), its sign from the polarity
        (``dark_bars``) or, without it, from each fit's depth."""
        bar = self.coef[:, 0] + self.coef[:, -1] * self.p_bar
        space = self.coef[:, 0] + self.coef[:, -1] * self.p_space
        total = bar + space
        sign = (np.where(self.coef[:, -1] > 0, -1.0, 1.0) if dark_bars is None
                else np.full(total.shape, 1.0 if dark_bars else -1.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(total > 0, sign * (space - bar) / total, np.nan)


@dataclass(frozen=True)
class _Normal:
    """The data ``y`` (n,), the base columns (n, kb) and the products of the two that every
    batch of fits of a set shares (computed once: the same products each time)."""

    base: FloatArray
    y: FloatArray
    gram: FloatArray
    rhs: FloatArray

    @classmethod
    def of(cls, base: FloatArray, y: FloatArray) -> _Normal:
        return cls(base, y, base.T @ base, base.T @ y)


def _solve_batch(
    normal: _Normal, cols: FloatArray, ridge: FloatArray | None, p_bar: FloatArray,
    p_space: FloatArray,
) -> _Batch:
    """Least squares of ``normal.y`` on the base columns (n, kb) plus, per blur, the columns
    ``cols`` (m, ke, n); ``ridge``: prior precision per coefficient in units of the noise
    variance (0 = free)."""
    base, y = normal.base, normal.y
    m, ke = cols.shape[:2]
    kb = base.shape[1]
    k = kb + ke
    # the normal matrices by blocks: the base columns' block is the same for every blur
    gram = np.empty((m, k, k))
    gram[:, :kb, :kb] = normal.gram
    cross = cols @ base  # (m, ke, kb)
    gram[:, kb:, :kb] = cross
    gram[:, :kb, kb:] = cross.transpose(0, 2, 1)
    gram[:, kb:, kb:] = cols @ cols.transpose(0, 2, 1)
    if ridge is not None:
        gram[:, np.arange(k), np.arange(k)] += ridge
    try:
        inv = np.linalg.inv(gram)
    except np.linalg.LinAlgError:
        inv = np.linalg.pinv(gram)
    rhs = np.empty((m, k))
    rhs[:, :kb] = normal.rhs
    rhs[:, kb:] = cols @ y
    coef = (inv @ rhs[:, :, None])[:, :, 0]
    # the per-blur columns' part summed first (in column order), then added to the base
    # columns' part, as ``base_part + (coef * cols).sum(axis=1)``; in place
    part = cols[:, 0] * coef[:, kb, None]
    for j in range(1, ke):
        part += cols[:, j] * coef[:, kb + j, None]
    resid = coef[:, :kb] @ base.T
    resid += part
    np.subtract(y[None, :], resid, out=resid)
    rss = np.einsum("mn,mn->m", resid, resid)
    penalty = (coef * coef) @ ridge if ridge is not None else np.zeros(m)
    return _Batch(np.asarray(coef, dtype=np.float64), rss + penalty, penalty,
                  np.asarray(inv, dtype=np.float64), p_bar, p_space)


@dataclass(frozen=True)
class _Tabulation:
    """A set's patterns tabulated and read at its pixels (what the first fit takes from the
    tables): the tabulations across and along the bars, the per-blur columns (blurs, 2,
    pixels; :attr:`_FitState.sp_pix`), the pattern at the probes (bar centre, spaces), and the
    along-bar pattern at the pixels and at the middle (None: the bar ends out of reach).
    Read-only once kept: fits share it."""

    across: _Blurred
    along: _Blurred | None
    sp_pix: FloatArray
    p_probe: FloatArray
    along_samples: tuple[FloatArray, FloatArray] | None

    @property
    def arrays(self) -> list[npt.NDArray[Any]]:
        out: list[npt.NDArray[Any]] = [self.sp_pix, self.p_probe]
        out += list(self.along_samples or ())
        for b in (self.across, self.along):
            if b is not None:
                out += [b.spectrum, b.freqs2, b.freqs, b.idx, b.frac]
        return out

    @property
    def nbytes(self) -> int:
        return sum(int(a.nbytes) for a in self.arrays)


class _Tabulations:
    """A bounded store of :class:`_Tabulation` by the exact inputs of the tabulation (least
    recently used dropped first; thread-safe: the chart reading reads sets on threads)."""

    def __init__(self, max_bytes: int, entry_max_bytes: int) -> None:
        self.max_bytes, self.entry_max_bytes = max_bytes, entry_max_bytes
        self._entries: OrderedDict[tuple[object, ...], tuple[_Tabulation, int]] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def get(self, key: tuple[object, ...]) -> _Tabulation | None:
        with self._lock:
            hit = self._entries.get(key)
            if hit is None:
                return None
            self._entries.move_to_end(key)
            return hit[0]

    def put(self, key: tuple[object, ...], tab: _Tabulation) -> None:
        size = tab.nbytes + sum(len(k) for k in key if isinstance(k, bytes))
        if size > min(self.entry_max_bytes, self.max_bytes):
            return
        for a in tab.arrays:
            a.flags.writeable = False
        with self._lock:
            old = self._entries.pop(key, None)
            if old is not None:
                self._bytes -= old[1]
            self._entries[key] = (tab, size)
            self._bytes += size
            while self._bytes > self.max_bytes:
                _, (_, dropped) = self._entries.popitem(last=False)
                self._bytes -= dropped

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            self._bytes = 0

    @property
    def nbytes(self) -> int:
        """Bytes held (the entries' arrays and keys)."""
        return self._bytes

    def __len__(self) -> int:
        return len(self._entries)


_TABULATIONS = _Tabulations(TABULATION_CACHE_BYTES, TABULATION_ENTRY_MAX_BYTES)


def clear_tabulations() -> None:
    """Drop the kept tabulations (:data:`TABULATION_CACHE_BYTES`)."""
    _TABULATIONS.clear()


def _tabulation_key(u: FloatArray, v: FloatArray, bar_width_px: float, theta: float
                    ) -> tuple[object, ...]:
    """Every input of a set's tabulation at its pixels: the pixels' coordinates (exactly),
    the bar width and angle, and the constants of the blur family and grid."""
    return (bar_width_px, theta, u.tobytes(), v.tobytes(), SIGMA_GRID, DISC_SHARES,
            DISC_SIGMA_GRID, DISC_MIN_SIGMA_PX, MAX_SIGMA_WIDTHS, MAX_SIGMA_BOUNDS_PX,
            GRID_STEP_PX, MAX_GRID_POINTS, GAUSS_CUTOFF, EXP_UNDERFLOW)


@dataclass(frozen=True)
class ThreeBarReading:
    """:func:`fit_three_bars`'s answer: the reading, and the across-bar blur behind it.

    ``blur_sigma_px`` is the blur the reading used (None when none was fitted);
    ``blur_range_px`` the blurs the data alone allow (``Delta chi^2 <= 1`` without any prior):
    narrow on sets that pin the blur down, wide where the pixels sample too few phases.
    :meth:`with_blur_prior` reads the same fits again under a prior on the blur.
    """

    result: ModulationResult
    blur_sigma_px: float | None = None
    blur_range_px: tuple[float, float] | None = None
    _state: _FitState | None = None
    blur_disc_share: float = 0.0

    def with_blur_prior(self, blur_prior_px: tuple[float, float]) -> ThreeBarReading:
        """The reading under a Gaussian prior (mean, sd; px) on the blur across the bars (the
        fits are reused: only the choice of blur and the interval change)."""
        _check_prior(blur_prior_px)
        if self._state is None:
            return self
        return self._state.conclude(blur_prior_px)


def _check_prior(blur_prior_px: tuple[float, float] | None) -> None:
    if blur_prior_px is not None and not (
        math.isfinite(blur_prior_px[0]) and blur_prior_px[1] > 0
        and math.isfinite(blur_prior_px[1])
    ):
        raise ValueError(f"blur_prior_px must be (mean, sd > 0), got {blur_prior_px}")


def read_three_bars(
    roi: npt.ArrayLike,
    *,
    centre_rc: tuple[float, float],
    bar_width_px: float,
    theta_deg: float,
    max_code: float | None = None,
    blur_prior_px: tuple[float, float] | None = None,
    shift_prior_px: float = SHIFT_PRIOR_PX,
    dark_bars: bool | None = None,
) -> ModulationResult:
    """Eq. 2.9 modulation of a three-bar set whose geometry is known (see the module docstring).

    Parameters
    ----------
    roi : array_like
        2-D gray levels (rows, cols), any integer or float dtype, or a 3-D stack (frames, rows,
        cols), which is averaged. Should hold the set with its bar ends trimmed (e.g.
        :attr:`benchlab.analysis.chart.pose.PosedBarSet.whole_period_roi`).
    centre_rc : (float, float)
        The set's centre (middle of the middle bar) in ROI pixel coordinates (row, col).
    bar_width_px : float
        Bar width (px); the period is twice that.
    theta_deg : float
        Direction in which the intensity varies (across the bars), degrees from the column
        axis towards the row axis (:mod:`benchlab.analysis.bars.projection`'s angle).
    max_code : float, optional
        Saturation code; inferred for integer data (255, 4095, 65520, 65535). Pixels at or
        above it are left out of the fit.
    blur_prior_px : (float, float), optional
        Gaussian prior (mean, standard deviation; px) on the PSF sigma across the bars, e.g.
        from the chart's other sets at the same image height
        (:func:`benchlab.analysis.chart.reading.read_chart`). Without it the blur is whatever
        fits the ROI best.
    shift_prior_px : float
        Prior (1 sigma, px) on the set's shift across the bars from ``centre_rc`` (the pose's
        error; default :data:`SHIFT_PRIOR_PX`).
    dark_bars : bool, optional
        The target's polarity when known (True: dark bars on a bright ground, False: a negative
        target; e.g. :attr:`benchlab.analysis.chart.finder.ChartFit.polarity`). Fits whose bar
        depth has the other sign are left out (unless all have it) and the modulation's sign
        follows the polarity: a reversed contrast cannot pass for the other polarity. Without
        it the fitted depth's sign decides.

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
                          blur_prior_px=blur_prior_px, shift_prior_px=shift_prior_px,
                          dark_bars=dark_bars).result


def fit_three_bars(
    roi: npt.ArrayLike,
    *,
    centre_rc: tuple[float, float],
    bar_width_px: float,
    theta_deg: float,
    max_code: float | None = None,
    blur_prior_px: tuple[float, float] | None = None,
    shift_prior_px: float = SHIFT_PRIOR_PX,
    dark_bars: bool | None = None,
    noise_floor: float = 0.0,
    reuse_tabulation: bool = False,
) -> ThreeBarReading:
    """:func:`read_three_bars` with the blur it used and the blurs the pixels allow.

    ``noise_floor`` (ROI units, default 0: none): the pixel noise is taken as at least this, as
    it is taken as at least the codes' rounding. A noise-free image (e.g. a set imaged through
    a measured transfer: :mod:`benchlab.analysis.chart.threebar`) read with the noise of the
    frame it stands for weighs its blurs against a blur prior as that frame's reading did;
    without it, its chi-square would rest on the model's numerical misfit alone.

    ``reuse_tabulation``: the blurred patterns at the pixels are taken from a recent fit at the
    same geometry (the same pixel coordinates, bar width and angle) where one is kept
    (:data:`TABULATION_CACHE_BYTES`): the same computation from the same inputs, so the same
    reading; e.g. a set imaged at the setup its chart reading read it with. Every fit keeps
    its own for such a later fit."""
    try:
        bar_width_px, theta_deg = float(bar_width_px), float(theta_deg)
        row, col = (float(v) for v in centre_rc)
    except (TypeError, ValueError) as exc:
        raise ValueError("bar_width_px and theta_deg must be numbers and centre_rc a (row, "
                         f"col) pair, got {bar_width_px!r}, {theta_deg!r}, {centre_rc!r}") from exc
    centre_rc = (row, col)
    if not (bar_width_px > 0 and math.isfinite(bar_width_px)):
        raise ValueError(f"bar_width_px must be a positive number, got {bar_width_px}")
    if not (math.isfinite(theta_deg) and all(math.isfinite(v) for v in centre_rc)):
        raise ValueError("theta_deg and centre_rc must be finite")
    _check_prior(blur_prior_px)
    if not (shift_prior_px > 0 and math.isfinite(shift_prior_px)):
        raise ValueError(f"shift_prior_px must be a positive number, got {shift_prior_px}")
    if not (noise_floor >= 0 and math.isfinite(noise_floor)):
        raise ValueError(f"noise_floor must be a number >= 0, got {noise_floor}")
    period = 2.0 * bar_width_px
    freq = 1.0 / period
    # The ROI's checks and shared facts (frames averaged, code step, saturation code), as
    # every estimator has them; the axis and noise are not measured (not used here).
    prep = prepare_roi(roi, freq_cycles_per_px=freq, max_code=max_code)
    img, top = prep.pixels, prep.max_code
    arr = np.asarray(roi)
    if top is not None:
        # A pixel clipped in any frame is out of the fit.
        clip_px = arr >= top if arr.ndim == 2 else (arr >= top).any(axis=0)
    else:
        clip_px = np.zeros(img.shape, dtype=bool)
    diag = prep.diagnostics_with(
        px_per_period=period, clipped_fraction=float(clip_px.mean()),
        noise_sigma=0.0, bar_angle_deg=theta_deg % 180.0,
        saturation_code=top if clip_px.any() else None,
    )
    if diag.aliased:
        return ThreeBarReading(unresolved(NAME, diag, ["not resolved (aliased): period < 2 px"]))
    warnings: list[str] = []
    if clip_px.any():
        warnings.append(f"{int(clip_px.sum())} of {img.size} pixels clipped at code {top:g}: "
                        "left out of the fit (the model carries the level beyond it)")
    theta = math.radians(theta_deg)
    u_all = across_coordinate(img.shape, theta, centre_rc)
    v_all = across_coordinate(img.shape, theta + 0.5 * math.pi, centre_rc)
    keep = ~clip_px
    u, v, y = u_all[keep], v_all[keep], img[keep]
    n = int(y.size)
    span_u, span_v = float(np.ptp(u)), float(np.ptp(v))
    # ground, shading across (and along, given two lines along the bars), shift, bar depth
    base_cols = [np.ones(n), u / max(span_u, 1.0)] + ([v / span_v] if span_v >= 1.0 else [])
    n_params = len(base_cols) + 2
    if n < n_params + 1 + MIN_DOF:
        warnings.append(f"too few pixels: {n} unclipped, a fit of the levels, shading and blur "
                        f"needs at least {n_params + 1 + MIN_DOF}")
        r = unresolved(NAME, diag, warnings)
        return ThreeBarReading(honest_reading(prep, r) if noise_floor == 0.0 else r)
    base = np.stack(base_cols, axis=1)
    quantum_sd = max(prep.quantisation_sd, float(noise_floor))
    key = _tabulation_key(u, v, bar_width_px, theta)
    state = _FitState(base, u, v, y, bar_width_px, theta, shift_prior_px, quantum_sd, diag,
                      warnings, dark_bars=dark_bars, noise_floor=noise_floor,
                      tabulations=_TABULATIONS, tabulation_key=key, look_up=reuse_tabulation)
    # The shift column is a first-order term: a shift of a few hundredths of a px leaves a
    # second-order bias (0.012 at 0.06 px on 2.3 px periods), so a fitted shift is applied to
    # the coordinates and the fit repeated once.
    shift = state.shift_px()
    if abs(shift) >= REFIT_SHIFT_PX:
        state = _FitState(base, u - shift, v, y, bar_width_px, theta, shift_prior_px,
                          quantum_sd, diag, warnings, reuse=state, dark_bars=dark_bars,
                          noise_floor=noise_floor)
    # The tabulated patterns (MBs per set) served only the fits; the reading keeps the state
    # for a later blur prior, which needs the fits alone.
    state.t_across = state.t_along = state.t_along_shape = None
    state.along_samples = None
    state.prep = prep if noise_floor == 0.0 else None
    return state.conclude(blur_prior_px)


class _FitState:
    """The fits of one set at every blur (across and along the bars), kept so that a prior on
    the blur only re-weighs them (:meth:`conclude`)."""

    def __init__(
        self, base: FloatArray, u: FloatArray, v: FloatArray, y: FloatArray, w: float,
        theta: float, shift_prior_px: float, quantum_sd: float, diag: Diagnostics,
        warnings: list[str], reuse: _FitState | None = None, dark_bars: bool | None = None,
        noise_floor: float = 0.0, tabulations: _Tabulations | None = None,
        tabulation_key: tuple[object, ...] = (), look_up: bool = False,
    ) -> None:
        """``reuse``: a state of the same set at other ``u`` (a shift applied), whose tabulated
        patterns serve again (the grid reaches several px beyond any shift); ``noise_floor``:
        the least noise the priors' scale assumes (:func:`fit_three_bars`); ``tabulations``:
        where the patterns at the pixels are kept (by ``tabulation_key``, every input of the
        tabulation), and first looked up given ``look_up``; without ``reuse``."""
        self.base, self.y, self.w, self.diag, self.warnings = base, y, w, diag, warnings
        # a refit at other u shares the data and base columns (and their products)
        self.normal: _Normal = (reuse.normal if reuse is not None and reuse.base is base
                                and reuse.y is y else _Normal.of(base, y))
        self.dark_bars = dark_bars
        #: The ROI, for :func:`~benchlab.analysis.bars.extremes.honest_reading` (None: a
        #: noise-free stand-in read with a noise floor, whose extremes are not its frame's).
        self.prep: PreparedROI | None = None
        self.phase_gap = _phase_gap(u, w)
        n = y.size
        max_sigma = min(max(MAX_SIGMA_BOUNDS_PX[0], MAX_SIGMA_WIDTHS * w),
                        MAX_SIGMA_BOUNDS_PX[1])
        self.sigmas = max_sigma * np.linspace(0.0, 1.0, SIGMA_GRID) ** 2
        # across the bars the family holds defocus too: the disc's share of the PSF's variance
        # at DISC_SHARES, each on a coarser grid of the equivalent sigma (rows after the
        # Gaussian ones; ``groups`` the row ranges, each in ascending sigma)
        coarse_sigmas = max_sigma * np.linspace(0.0, 1.0, DISC_SIGMA_GRID)[1:] ** 2
        coarse_sigmas = coarse_sigmas[coarse_sigmas >= DISC_MIN_SIGMA_PX]
        sig_rows, share_rows = [self.sigmas], [np.zeros(SIGMA_GRID)]
        self.groups = [(0, SIGMA_GRID)]
        for share in DISC_SHARES:
            start = self.groups[-1][1]
            sig_rows.append(coarse_sigmas)
            share_rows.append(np.full(coarse_sigmas.size, share))
            self.groups.append((start, start + coarse_sigmas.size))
        self.sig_all, self.share_all = np.concatenate(sig_rows), np.concatenate(share_rows)
        self.t_across: FloatArray | None = None
        self.t_along: FloatArray | None = None
        self.across: _Blurred
        self.along: _Blurred | None
        if reuse is not None:
            # the same tables (and, along the bars, the same v), read at the shifted u
            self.across, self.along = reuse.across.moved(u), reuse.along
            t_across = (reuse.t_across if reuse.t_across is not None
                        else self.across.tables(self.sig_all, self.share_all))
            self.t_across = t_across
            p_pix, s_pix = self.across.sample_and_slope(t_across)
            sp_pix = np.stack([s_pix, p_pix], axis=1)
            p_probe = reuse.p_probe
            along_samples = reuse.along_samples
        else:
            hit = (tabulations.get(tabulation_key) if tabulations is not None and look_up
                   else None)
            if hit is None:
                hit = self._tabulate(u, v, theta, max_sigma)
                if tabulations is not None:
                    tabulations.put(tabulation_key, hit)
            self.across, self.along = hit.across, hit.along
            sp_pix, p_probe, along_samples = hit.sp_pix, hit.p_probe, hit.along_samples
        #: The per-blur columns of the fits, (blurs, 2, pixels): the pattern's slope (the
        #: shift) and the pattern (the bar depth); :attr:`s_pix` and :attr:`p_pix` views of it.
        self.sp_pix = sp_pix
        self.s_pix, self.p_pix = sp_pix[:, 0], sp_pix[:, 1]
        self.p_probe: FloatArray = p_probe
        #: The along-bar tables at the pixels and at the middle (None: the bar ends out of
        #: reach, a factor of 1).
        self.along_samples: tuple[FloatArray, FloatArray] | None = along_samples
        a_pix: FloatArray | None
        a_pix, a_mid = along_samples if along_samples is not None else (
            None, np.ones(self.sigmas.size))
        every = np.arange(self.sigmas.size)
        # the priors' scale: a free fit on a coarse blur grid gives noise, ground and depth
        coarse = every[::4]
        first = self._fit(coarse, coarse, a_pix, a_mid, None)
        j = int(np.argmin(first.cost))
        noise0_sq = max(float(first.cost[j]) / max(n - _n_params(base) - 1, 1), 1e-300,
                        noise_floor**2)
        ground, depth = abs(float(first.coef[j, 0])), abs(float(first.coef[j, -1]))
        sds = [math.inf, SHADING_PRIOR_PER_PX * max(float(np.ptp(u)), 1.0) * ground]
        if base.shape[1] == 3:
            sds.append(SHADING_PRIOR_PER_PX * max(float(np.ptp(v)), 1.0) * ground)
        sds += [depth * shift_prior_px, math.inf]
        self.ridge = np.array([noise0_sq / sd**2 if 0 < sd < math.inf else 0.0 for sd in sds])
        # one blur for both directions, then along the bars at the best, then across at that
        tied = self._fit(every, every, a_pix, a_mid, self.ridge)
        i_u = int(np.argmin(tied.cost))
        self.along_fits: _Batch | None = None
        i_v = i_u
        if self.along is not None:
            self.along_fits = self._fit(np.full_like(every, i_u), every, a_pix, a_mid, self.ridge)
            i_v = int(np.argmin(self.along_fits.cost))
        self.a_best = (None if a_pix is None else a_pix[i_v], float(a_mid[i_v]))
        rows = np.arange(self.sig_all.size)
        self.fits = self._fit(rows, np.full_like(rows, i_v), a_pix, a_mid, self.ridge)
        self._score(quantum_sd)
        # a defocus shape across the bars blurs the bar ends the same way: the along-bar blur
        # searched again in that shape, and the fits across redone at its best
        self.t_along_shape: FloatArray | None = None
        self.along_group = (0, 0)
        best_group = next(g for g in self.groups if g[0] <= self.best_row < g[1])
        if a_pix is not None and self.along is not None and self.share_all[self.best_row] > 0:
            lo, hi = best_group
            self.t_along_shape = (
                reuse.t_along_shape if reuse is not None and reuse.along_group == best_group
                and reuse.t_along_shape is not None
                else self.along.tables(self.sig_all[lo:hi], self.share_all[lo:hi]))
            self.along_group = best_group
            a_pix = np.concatenate([a_pix, self.along.sample(self.t_along_shape)])
            a_mid = np.concatenate([a_mid,
                                    self.along.sample(self.t_along_shape, np.zeros(1))[:, 0]])
            every_v = np.arange(a_mid.size)
            self.along_fits = self._fit(np.full_like(every_v, self.best_row), every_v, a_pix,
                                        a_mid, self.ridge)
            i_v2 = int(np.argmin(self.along_fits.cost))
            if i_v2 != i_v:
                i_v = i_v2
                self.a_best = (a_pix[i_v], float(a_mid[i_v]))
                self.fits = self._fit(rows, np.full_like(rows, i_v), a_pix, a_mid, self.ridge)
                self._score(quantum_sd)
        self.misfit_rms = self._misfit(self.best_row, u, None if a_pix is None else a_pix[i_v],
                                       quantum_sd)

    def _tabulate(self, u: FloatArray, v: FloatArray, theta: float, max_sigma: float
                  ) -> _Tabulation:
        """The patterns across (every row of :attr:`sig_all`) and along the bars (the
        Gaussian rows) tabulated and read at the pixels; the table across kept as
        :attr:`t_across` for a refit."""
        w = self.w
        across = _Blurred(
            u, [(c - 0.5 * w, c + 0.5 * w) for c in (-2 * w, 0.0, 2 * w)], theta, max_sigma)
        # the bar ends (at v = +-2.5 w), blurred along the bars by their own PSF width: only
        # when the ROI comes within their reach (the ROI trims the ends by a fraction of a px)
        foot = 0.5 * (abs(math.cos(theta)) + abs(math.sin(theta)))
        near_ends = float(np.abs(v).max()) + foot + 4.0 * max_sigma > 2.5 * w
        along = _Blurred(v, [(-2.5 * w, 2.5 * w)], theta, max_sigma) if near_ends else None
        t_across = across.tables(self.sig_all, self.share_all)
        self.t_across = t_across
        p_pix, s_pix = across.sample_and_slope(t_across)
        p_probe = across.sample(t_across, np.array([0.0, -w, w]))
        along_samples = None
        if along is not None:
            t_along = along.tables(self.sigmas)
            along_samples = (along.sample(t_along), along.sample(t_along, np.zeros(1))[:, 0])
        return _Tabulation(across, along, np.stack([s_pix, p_pix], axis=1), p_probe,
                           along_samples)

    def _score(self, quantum_sd: float) -> None:
        """Noise, chi-square scale, allowed blurs and the best row of :attr:`fits`."""
        n = self.y.size
        rss_data = float(np.min(self.fits.cost - self.fits.penalty))
        dof = n - _n_params(self.base) - 1
        noise = math.sqrt(rss_data / dof) if dof > 0 else 0.0
        self.noise = max(noise, quantum_sd)
        self.scale = self.noise**2 if self.noise > 0 else max(float(self.fits.cost.min()), 1e-300)
        chi2 = (self.fits.cost - self.fits.cost.min()) / self.scale
        allowed = self.sig_all[chi2 <= 1.0]
        self.blur_range = (float(allowed.min()), float(allowed.max()))
        # the best fit, a defocus shape paying its price (:data:`DISC_PENALTY`)
        gauss_rss = float(np.min((self.fits.cost - self.fits.penalty)[:SIGMA_GRID]))
        self.disc_price = max(DISC_PENALTY, DISC_REL_GAIN * gauss_rss / self.scale)
        self.shape_price = np.where(self.share_all > 0, self.disc_price, 0.0)
        if self.dark_bars is not None:
            # the known polarity: a depth of the other sign is not this target
            wrong = (self.fits.coef[:, -1] > 0) == self.dark_bars
            if not wrong.all():
                self.shape_price = np.where(wrong, np.inf, self.shape_price)
        self.best_row = int(np.argmin(chi2 + self.shape_price))

    def _misfit(self, row: int, u: FloatArray, a: FloatArray | None, quantum_sd: float
                ) -> float:
        """RMS of the residuals' structure beyond the noise at fit ``row`` (0 when not
        significant): the residual variance minus the white noise's, the latter from
        successive differences of the residuals in order of ``u`` (a misfit is smooth in ``u``
        and cancels there; noise does not). A term that does not shrink with pixel count.
        ``a``: the bar ends' factor at the pixels (None: 1)."""
        design = np.column_stack([self.base, self.s_pix[row], self.p_pix[row]] if a is None
                                 else [self.base, self.s_pix[row] * a, self.p_pix[row] * a])
        resid = self.y - design @ self.fits.coef[row]
        n = resid.size
        dof = n - _n_params(self.base) - 1
        if dof <= 0 or n < 3:
            return 0.0
        steps = np.diff(resid[np.argsort(u, kind="stable")])
        white_sq = max(0.5 * float(np.mean(steps * steps)), quantum_sd**2)
        excess = float(resid @ resid) / dof - white_sq
        if excess <= MISFIT_Z * white_sq * math.sqrt(MISFIT_VAR_FACTOR / n):
            return 0.0
        return math.sqrt(excess)

    def shift_px(self) -> float:
        """The set's shift across the bars (px) in the best fit: the shift column's
        coefficient over the bar depth, ``-c / s`` (0 when the depth vanishes); at most half a
        bar width."""
        i = self.best_row
        c, depth = float(self.fits.coef[i, -2]), float(self.fits.coef[i, -1])
        if depth == 0.0:
            return 0.0
        return float(np.clip(-c / depth, -0.5 * self.w, 0.5 * self.w))

    def _fit(
        self, i_u: npt.NDArray[np.intp], i_v: npt.NDArray[np.intp], a_pix: FloatArray | None,
        a_mid: FloatArray, ridge: FloatArray | None,
    ) -> _Batch:
        """Fits at the across-bar blurs ``sigmas[i_u]`` with the along-bar ones ``[i_v]``
        (``a_pix`` None: no bar ends, a factor of 1)."""
        probe = self.p_probe[i_u] * a_mid[i_v][:, None]
        # the columns times the bar ends' factor, each product as ``s_pix[i_u] * a_pix[i_v]``
        # (a blur repeated over every fit broadcast instead of gathered: the same products)
        one_v = bool(np.all(i_v == i_v[0]))
        every_u = np.array_equal(i_u, np.arange(self.sp_pix.shape[0]))
        if a_pix is None:
            cols = self.sp_pix if every_u else self.sp_pix[i_u]  # read, never written
        elif np.all(i_u == i_u[0]) and not one_v:
            cols = self.sp_pix[i_u[0]] * a_pix[i_v][:, None, :]
        elif one_v and every_u:
            cols = self.sp_pix * a_pix[i_v[0]]  # every row: no gathered copy first
        else:
            cols = self.sp_pix[i_u]
            cols *= a_pix[i_v[0]] if one_v else a_pix[i_v][:, None, :]
        return _solve_batch(self.normal, cols, ridge, probe[:, 0],
                            0.5 * (probe[:, 1] + probe[:, 2]))

    def _fit_at(self, sigma: float, disc_share: float) -> _Batch:
        """One fit at an off-grid blur across the bars (the along-bar blur at its best)."""
        table = self.across.tables(np.array([sigma]), np.array([disc_share]))
        a_pix, a_mid = self.a_best
        probe = self.across.sample(table, np.array([0.0, -self.w, self.w]))[0] * a_mid
        p_pix, s_pix = self.across.sample_and_slope(table)
        cols = np.stack([s_pix, p_pix], axis=1)
        if a_pix is not None:
            cols *= a_pix
        return _solve_batch(self.normal, cols, self.ridge, np.array([probe[0]]),
                            np.array([0.5 * (probe[1] + probe[2])]))

    def conclude(self, blur_prior_px: tuple[float, float] | None) -> ThreeBarReading:
        """The reading at the blur the fits (and the prior) favour, with its interval."""
        sigmas, fits = self.sig_all, self.fits

        def objective(sig: FloatArray, cost: FloatArray, price: FloatArray) -> FloatArray:
            out = cost / self.scale + price
            if blur_prior_px is not None:
                out = out + ((sig - blur_prior_px[0]) / blur_prior_px[1]) ** 2
            return np.asarray(out, dtype=np.float64)

        obj = objective(sigmas, fits.cost, self.shape_price)
        i = int(np.argmin(obj))
        best, k, sigma_best, obj_best = fits, i, float(sigmas[i]), float(obj[i])
        share_best = float(self.share_all[i])
        lo, hi = next(g for g in self.groups if g[0] <= i < g[1])
        if lo < i < hi - 1:  # parabola through the best grid point and its neighbours
            x0, x1, x2 = sigmas[i - 1:i + 2]
            y0, y1, y2 = obj[i - 1:i + 2]
            den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0)
            if den != 0:
                vertex = x1 - 0.5 * ((x1 - x0) ** 2 * (y1 - y2) - (x1 - x2) ** 2 * (y1 - y0)) / den
                if x0 < vertex < x2:
                    cand = self._fit_at(float(vertex), share_best)
                    cand_obj = float(objective(np.array([vertex]), cand.cost,
                                               self.shape_price[i:i + 1])[0])
                    if cand_obj < obj_best:
                        best, k, sigma_best, obj_best = cand, 0, float(vertex), cand_obj
        coef, inv = best.coef[k], best.inv[k]
        p_bar, p_space = float(best.p_bar[k]), float(best.p_space[k])
        noise = self.noise
        warnings = list(self.warnings)
        bar = float(coef[0] + coef[-1] * p_bar)
        space = float(coef[0] + coef[-1] * p_space)
        depth = float(coef[-1])
        depth_sd = noise * math.sqrt(max(float(inv[-1, -1]), 0.0))
        diag_fit = _with(self.diag, noise_sigma=noise, blur_sigma_px=sigma_best,
                         phase_cycles=0.0)
        if not abs(depth) > RESOLVED_Z * depth_sd:
            warnings.append(f"bar depth {abs(depth):.3g} within {RESOLVED_Z:g} standard errors "
                            f"({depth_sd:.3g}) of zero: bars not resolved")
            return ThreeBarReading(self._honest(unresolved(NAME, diag_fit, warnings)), sigma_best,
                                   self.blur_range, self)
        dark, bright = min(bar, space), max(bar, space)
        if dark < 0 or dark + bright <= 0:
            warnings.append("fitted dark level below zero: contrast undefined")
            return ThreeBarReading(self._honest(unresolved(NAME, diag_fit, warnings)), sigma_best,
                                   self.blur_range, self)
        # Eq. 2.9 with its sign: the level at the bars' centre against the spaces' (dark bars
        # have depth < 0, a negative target's bright bars > 0); negative = contrast reversed
        dark_target = depth < 0 if self.dark_bars is None else self.dark_bars
        sign = 1.0 if dark_target else -1.0
        modulation = sign * eq29_modulation(bar, space)
        # noise: m = sign (space - bar) / (bar + space), bar and space linear in (ground, depth)
        total = bar + space
        dm_dspace, dm_dbar = sign * 2.0 * bar / total**2, -sign * 2.0 * space / total**2
        grad = np.zeros(coef.size)
        grad[0] = dm_dbar + dm_dspace
        grad[-1] = dm_dbar * p_bar + dm_dspace * p_space
        noise_sd = noise * math.sqrt(max(float(grad @ inv @ grad), 0.0))
        # blur: the spread of the readings over the blurs the data (and prior) allow
        blur_sd = 0.0
        spreads = [(fits, obj - obj_best)]
        if self.along_fits is not None:
            spreads.append((self.along_fits, (self.along_fits.cost - best.cost[k]) / self.scale))
        allowed_mods = np.array([modulation])
        for batch, excess in spreads:
            mods = batch.modulations(self.dark_bars)[(excess <= 1.0)]
            mods = np.append(mods[np.isfinite(mods)], modulation)
            allowed_mods = np.append(allowed_mods, mods)
            blur_sd = math.hypot(blur_sd, 0.5 * float(mods.max() - mods.min()))
        # misfit: residual structure beyond the noise, as an error of both levels
        misfit_sd = self.misfit_rms * math.hypot(dm_dbar, dm_dspace)
        if share_best > 0:
            # a defocus shape is the separable model's nearest to a non-separable blur: its
            # size is known to DISC_SIGMA_FLOOR_PX at best, however sharp the chi-square
            near = [self._fit_at(max(sigma_best + d, 0.0), share_best).modulations(
                self.dark_bars)[0] for d in (-DISC_SIGMA_FLOOR_PX, DISC_SIGMA_FLOOR_PX)]
            near = [x for x in near if math.isfinite(x)]
            if near:
                blur_sd = math.hypot(blur_sd, 0.5 * (max(near) - min(near)))
        model_sd = math.hypot(
            math.hypot(MODEL_REL_SD, PHASE_GAP_REL * self.phase_gap**2) * modulation,
            MODEL_ABS_SD)
        model_sd = math.hypot(model_sd, misfit_sd)
        if misfit_sd > 0:
            warnings.append(f"the residuals show structure beyond the noise (rms "
                            f"{self.misfit_rms:.3g}): the model misfits; interval widened by "
                            f"{misfit_sd:.3g}")
        sd = math.sqrt(noise_sd**2 + blur_sd**2 + model_sd**2)
        diag_fit = _with(diag_fit, uncertainty_noise=noise_sd,
                         uncertainty_model=math.hypot(blur_sd, model_sd))
        reversal_allowed = bool(np.any(allowed_mods < 0)) or modulation < 0
        if modulation < 0 or (reversal_allowed and modulation - 1.96 * sd < 0):
            if modulation < 0:
                warnings.append(
                    f"contrast reversed (spurious resolution): the bars image "
                    f"{'brighter' if dark_target else 'darker'} than the spaces (a PSF past its "
                    f"first OTF zero, e.g. defocus); modulation {modulation:.3f} +- "
                    f"{1.96 * sd:.3f}, not a resolved reading")
            result = ModulationResult(
                estimator=NAME, dark=bar if dark_target else space,
                bright=space if dark_target else bar, modulation=modulation, resolved=True,
                diagnostics=diag_fit, uncertainty=sd,
                interval=(max(-1.0, modulation - 1.96 * sd), min(1.0, modulation + 1.96 * sd)),
                warnings=tuple(warnings))
        else:
            result = resolved(NAME, dark, bright, min(modulation, 1.0), diag_fit, sd, warnings)
        return ThreeBarReading(self._honest(result), sigma_best, self.blur_range, self,
                               share_best)

    def _honest(self, result: ModulationResult) -> ModulationResult:
        """``result`` through :func:`~benchlab.analysis.bars.extremes.honest_reading`."""
        return result if self.prep is None else honest_reading(self.prep, result)


def _phase_gap(u: FloatArray, bar_width_px: float) -> float:
    """How far (cycles) the pixels' phases of the pattern come to the bar centre and to the
    spaces' centres at best: the larger of the two smallest distances (0 = a pixel centred on
    each). Within the set only (``|u| <= 2.5 w``)."""
    inside = u[np.abs(u) <= 2.5 * bar_width_px]
    if inside.size == 0:
        return 0.5
    phase = np.mod(inside / (2.0 * bar_width_px), 1.0)  # 0 = a bar centre, 0.5 = a space
    to_bar = np.minimum(phase, 1.0 - phase)
    to_space = np.abs(phase - 0.5)
    return float(max(to_bar.min(), to_space.min()))


def _n_params(base: FloatArray) -> int:
    """Linear terms of the fit: the base columns, the shift and the bar depth."""
    return int(base.shape[1]) + 2


def _with(diag: Diagnostics, **changes: object) -> Diagnostics:
    """``diag`` with some fields replaced."""
    return Diagnostics(**{**diag.__dict__, **changes})  # type: ignore[arg-type]
