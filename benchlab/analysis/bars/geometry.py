"""Bar geometry measured from the ROI itself: direction, period and phase, with uncertainties.

The bar pattern's fundamental is the strongest peak of the ROI's 2-D spectrum (mean and plane
removed). Its position ``k = f (cos t, sin t)`` (cycles/px along columns x and rows y) gives the
direction ``t`` in which the intensity varies and the frequency ``f``; its phase says where the
bright bars are. The peak is read off a 2x zero-padded FFT (``numpy.fft``, of a central crop of
at most ``FFT_CROP_PX`` for large ROIs), then refined on the whole ROI: by the phase drift of
the DFT at ``k`` between the ROI's halves (a few passes, each one complex product and two block
sums; see :func:`_drift_refine`) when each half holds enough periods, else by parabolic
interpolation of the DFT magnitude on small grids of frequencies. Either way the refinement
sees every pixel and costs linear time (numpy reductions, no BLAS products on the pixels).

:func:`quick_geometry` skips the spectrum when the frequency is known: the direction comes from
the gradient structure tensor and the same phase-drift refinement follows. The histogram-peak
method uses it (falling back to :func:`measure_geometry` when it declines), and
``measure_geometry(..., quick_start=True)`` (profilefit) starts its refinement from it instead of
the spectrum's peak when it accepts the ROI.

Spokes and rings (the radial view) are not straight parallel bars: the local frequency vector
drifts across the ROI. When the ROI is large enough, the peak is also refined in its four
quadrants and the drift is kept as a phase curvature ``1/2 r^T H r`` (cycles) when it moves the
phase by more than ``CURVATURE_MIN_CYCLES`` at the ROI corners.

A frequency given by the caller (``--freq``) is a prior: the search is limited to 0.6-1.6 times
it, and a measured frequency that disagrees beyond its uncertainty is reported as a warning.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars.roi import row_major

#: Largest square (px) the initial FFT looks at; the refinement uses the whole ROI.
FFT_CROP_PX = 128
#: Search band around a given frequency (fraction of it).
PRIOR_BAND = (0.6, 1.6)
#: Phase curvature smaller than this at the ROI corners (cycles) is ignored.
CURVATURE_MIN_CYCLES = 0.05
#: A peak outside the prior's band wins when this many times stronger than the band's best.
WIDE_PEAK_RATIO = 1.3
#: :func:`quick_geometry` only on ROIs of at least this many pixels ...
QUICK_MIN_PIXELS = 256
#: ... spanning at least this many bar periods across the bars ...
QUICK_MIN_PERIODS = 3.0
#: ... when its refinement settles (phase drift over half the ROI, cycles) within this many
#: rounds ...
QUICK_SETTLED_CYCLES = 0.05
QUICK_ITERATIONS = 3
#: Larger ROIs are measured on a centred crop of at most this many rows and columns.
QUICK_CROP_PX = 256
#: ... and from this size on a start that does not settle gets one step between quarters.
QUICK_COARSE_MIN_PX = 32
#: :func:`measure_geometry` refines the frequency vector on a centred crop of at most this.
REFINE_CROP_PX = 512
#: :func:`measure_geometry` refines by phase drift to this (cycles), in at most so many passes.
DRIFT_SETTLED_CYCLES = 0.01
DRIFT_PASSES = 5
#: ... and the fundamental is this many standard errors above the noise.
QUICK_MIN_Z = 8.0
#: ... and carries at least this share of the ROI's power above the noise.
QUICK_MIN_POWER_SHARE = 0.5
#: Relative frequency disagreement always tolerated (the USAF magnification is nominal).
FREQ_TOLERANCE = 0.03


@dataclass(frozen=True)
class BarGeometry:
    """Direction, frequency and phase of the bars in one ROI.

    Attributes
    ----------
    theta_rad : float
        Direction in which the intensity varies, from the column axis towards the row axis.
    freq_cycles_per_px : float
        Bar frequency along that direction (at the ROI centre).
    phase_cycles : float
        Fundamental phase at the ROI centre: the bright-bar centre sits where
        ``f u + phase_cycles`` is an integer.
    amplitude : float
        Fundamental amplitude (gray units).
    theta_sd_rad, freq_sd, phase_sd : float
        Standard uncertainties from the noise.
    hessian : (float, float, float)
        Phase curvature ``(hxx, hxy, hyy)`` in cycles/px^2 (zeros for straight bars).
    """

    theta_rad: float
    freq_cycles_per_px: float
    phase_cycles: float
    amplitude: float
    theta_sd_rad: float
    freq_sd: float
    phase_sd: float
    hessian: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def k_xy(self) -> tuple[float, float]:
        """Frequency vector (cycles/px along x = columns, y = rows)."""
        f = self.freq_cycles_per_px
        return f * math.cos(self.theta_rad), f * math.sin(self.theta_rad)

    @property
    def px_per_period(self) -> float:
        return 1.0 / self.freq_cycles_per_px


@lru_cache(maxsize=64)
def _centred_grid(shape: tuple[int, int]) -> tuple[FloatArray, FloatArray]:
    """Row and column coordinates from the ROI centre (cached, read-only)."""
    rows, cols = shape
    y = np.arange(rows, dtype=np.float64) - (rows - 1) / 2.0
    x = np.arange(cols, dtype=np.float64) - (cols - 1) / 2.0
    y.setflags(write=False)
    x.setflags(write=False)
    return y, x


def detrend(img: FloatArray, sums: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
    """``img`` minus its mean and least-squares plane (numpy reductions, no BLAS).
    ``sums``: ``(img.sum(axis=0), img.sum(axis=1))`` if already known."""
    rows, cols = img.shape[0], img.shape[1]
    y, x = _centred_grid((rows, cols))
    add = np.add.reduce  # = ndarray.sum without its Python wrapper
    if sums is not None and sums[0].shape == (cols,) and sums[1].shape == (rows,):
        col_sums, row_sums = sums
    else:
        col_sums, row_sums = add(img, axis=0), add(img, axis=1)
    mean = float(add(col_sums)) / (rows * cols)
    # x and y sum to zero, so the slopes need no mean removed first; sum x^2 = n(n^2 - 1)/12.
    gx = float(add(col_sums * x)) * 12.0 / (rows * cols * (cols * cols - 1)) if cols > 1 else 0.0
    gy = float(add(row_sums * y)) * 12.0 / (rows * cols * (rows * rows - 1)) if rows > 1 else 0.0
    resid = img - (mean + gy * y)[:, None]
    resid -= (gx * x)[None, :]
    return resid


def dft_at(img: FloatArray, kx: float, ky: float) -> complex:
    """``sum I exp(-2 pi i (kx x + ky y))`` over the ROI, coordinates from its centre."""
    y, x = _centred_grid((img.shape[0], img.shape[1]))
    ex = np.exp(-2j * math.pi * kx * x)
    ey = np.exp(-2j * math.pi * ky * y)
    return complex(((img * ex[None, :]).sum(axis=1) * ey).sum())


def _dft_grid(img: FloatArray, kxs: FloatArray, kys: FloatArray) -> npt.NDArray[np.complex128]:
    """DFT on the grid ``kys x kxs`` (rows, cols) by two separable passes."""
    y, x = _centred_grid((img.shape[0], img.shape[1]))
    arg = -2.0 * math.pi * np.outer(x, kxs)  # (cols, nkx)
    # Real einsums (numpy's own loops, no BLAS thread wake-ups; cost linear in the pixel
    # count), a third of the time of a complex broadcast product.
    per_row = np.einsum("rc,ck->rk", img, np.cos(arg)) + 1j * np.einsum(
        "rc,ck->rk", img, np.sin(arg))  # (rows, nkx)
    ey = np.exp(-2j * math.pi * np.outer(kys, y))  # (nky, rows)
    return np.einsum("kr,rj->kj", ey, per_row)  # (nky, rows) x (rows, nkx): small


def _parabola_offset(m: FloatArray) -> float:
    """Vertex offset (in steps) of a parabola through three samples, within +-1."""
    den = m[0] - 2.0 * m[1] + m[2]
    if den >= 0:
        return 0.0
    return float(np.clip(0.5 * (m[0] - m[2]) / den, -1.0, 1.0))


def refine_peak(
    img: FloatArray, kx: float, ky: float, step: float, iterations: int = 2
) -> tuple[float, float]:
    """Refine a spectral peak: a 3x3 grid of direct DFTs at ``step`` around it, a parabola on
    each axis of the log magnitude, repeated with half the step."""
    for _ in range(iterations):
        offsets = step * np.arange(-1, 2, dtype=np.float64)
        grid = _dft_grid(img, np.asarray(kx + offsets, np.float64),
                         np.asarray(ky + offsets, np.float64))
        mag = np.log(np.abs(grid) + 1e-300)
        j, i = np.unravel_index(int(np.argmax(mag)), mag.shape)
        if (i, j) != (1, 1):  # the peak moved: recentre before interpolating
            kx += (int(i) - 1) * step
            ky += (int(j) - 1) * step
            continue
        kx += step * _parabola_offset(mag[1, :])
        ky += step * _parabola_offset(mag[:, 1])
        step /= 2.0
    return kx, ky


def _fast_len(n: int) -> int:
    """Smallest integer >= ``n`` without prime factors above 11 (a fast FFT length; the same
    as ``scipy.fft.next_fast_len``, without importing scipy)."""
    m = max(n, 1)
    while True:
        rest = m
        for p in (2, 3, 5, 7, 11):
            while rest % p == 0:
                rest //= p
        if rest == 1:
            return m
        m += 1


@dataclass(frozen=True)
class _Spectrum:
    """Magnitude of the zero-padded 2-D spectrum (half plane kx >= 0) and each bin's |k|."""

    magnitude: FloatArray
    kx: FloatArray  # (1, ncols)
    ky: FloatArray  # (nrows, 1)
    k_norm: FloatArray


def _spectrum(img: FloatArray) -> _Spectrum:
    """2x zero-padded ``numpy.fft`` spectrum of the central ``FFT_CROP_PX`` square."""
    rows, cols = img.shape
    r0, c0 = max(0, (rows - FFT_CROP_PX) // 2), max(0, (cols - FFT_CROP_PX) // 2)
    crop = img[r0 : r0 + FFT_CROP_PX, c0 : c0 + FFT_CROP_PX]
    nr = _fast_len(max(2 * crop.shape[0], 16))
    nc = _fast_len(max(2 * crop.shape[1], 16))
    mag = np.abs(np.fft.rfft2(crop, s=(nr, nc)))
    ky = np.asarray(np.fft.fftfreq(nr), dtype=np.float64)[:, None]
    kx = np.asarray(np.fft.rfftfreq(nc), dtype=np.float64)[None, :]
    return _Spectrum(mag, kx, ky, np.hypot(kx, ky))


def _fft_peak(spec: _Spectrum, f_lo: float, f_hi: float) -> tuple[float, float, float] | None:
    """Strongest peak ``(kx, ky, magnitude)`` of ``spec`` with ``f_lo <= |k| <= f_hi``;
    ``None`` when no bin qualifies."""
    ok = (spec.k_norm >= f_lo) & (spec.k_norm <= f_hi)
    if not ok.any():
        return None
    masked = np.where(ok, spec.magnitude, -1.0)
    j, i = np.unravel_index(int(np.argmax(masked)), masked.shape)
    return float(spec.kx[0, i]), float(spec.ky[j, 0]), float(masked[j, i])


def structure_tensor_direction(resid: FloatArray) -> tuple[float, float]:
    """Direction of the strongest intensity variation and its coherence, from the gradient
    structure tensor.

    The gradients are those of each 2 x 2 pixel cell (both components at the cell centre), so
    the tensor sums are three reductions over the two diagonal differences.

    Parameters
    ----------
    resid : ndarray, shape (rows, cols)
        The ROI, mean (and preferably the plane) removed; both sides at least 2.

    Returns
    -------
    (float, float)
        ``theta`` (radians, in (-pi/2, pi/2], as :class:`BarGeometry`) and the coherence
        ``|J1 - J2| / (J1 + J2)`` of the tensor's eigenvalues (0 = isotropic, 1 = one direction).
    """
    rows, cols = resid.shape
    cells = np.empty((2, rows - 1, cols - 1))
    np.subtract(resid[1:, 1:], resid[:-1, :-1], out=cells[0])  # along (x, y) = (1, 1)
    np.subtract(resid[1:, :-1], resid[:-1, 1:], out=cells[1])  # along (-1, 1)
    flat = cells.reshape(2, -1)
    # The three sums in one einsum (numpy's own loop: no BLAS threads on large crops).
    (s11, s12), (_, s22) = np.einsum("kn,ln->kl", flat, flat).tolist()
    # gx = (d1 - d2) / 2, gy = (d1 + d2) / 2: Jxx - Jyy = -s12, 2 Jxy = (s11 - s22) / 2.
    a, b = -s12, 0.5 * (s11 - s22)
    total = 0.5 * (s11 + s22)
    theta = 0.5 * math.atan2(b, a)
    if theta <= -math.pi / 2 + 1e-12:
        theta += math.pi
    return theta, (math.hypot(a, b) / total if total > 0 else 0.0)


def _cell_gradient_direction(theta: float, f: float) -> float:
    """Direction the 2 x 2-cell gradients report for a sinusoid at ``f (cos t, sin t)``: they
    scale x by ``sin(pi kx) cos(pi ky)`` and y by ``cos(pi kx) sin(pi ky)``."""
    kx, ky = math.pi * f * math.cos(theta), math.pi * f * math.sin(theta)
    return math.atan2(math.cos(kx) * math.sin(ky), math.sin(kx) * math.cos(ky))


def _quadrant_sums(resid: FloatArray, kx: float, ky: float) -> npt.NDArray[np.complex128]:
    """DFT at ``(kx, ky)`` (phases from the ROI centre) of each quadrant, shape (2, 2): one
    complex product pass and two block reductions."""
    rows, cols = resid.shape
    y, x = _centred_grid((rows, cols))
    ex = np.exp(-2j * math.pi * kx * x)
    ey = np.exp(-2j * math.pi * ky * y)
    halves = np.add.reduceat(resid * ex[None, :], [0, cols // 2], axis=1)  # (rows, 2)
    halves *= ey[:, None]
    return np.add.reduceat(halves, [0, rows // 2], axis=0)


def _coarse_drift_step(resid: FloatArray, kx: float, ky: float) -> tuple[float, float]:
    """One phase-drift step between neighbouring quarters of the ROI (a baseline of a quarter
    of its size: twice the unambiguous range of the halves, for a start further off)."""
    rows, cols = resid.shape
    y, x = _centred_grid((rows, cols))
    ex = np.exp(-2j * math.pi * kx * x)
    ey = np.exp(-2j * math.pi * ky * y)
    col_edges = [round(i * cols / 4) for i in range(4)]
    row_edges = [round(i * rows / 4) for i in range(4)]
    blocks = np.add.reduceat(resid * ex[None, :], col_edges, axis=1)  # (rows, 4)
    blocks *= ey[:, None]
    z = np.add.reduceat(blocks, row_edges, axis=0)  # (4, 4)
    across = complex((z[:, 1:] * np.conj(z[:, :-1])).sum())
    down = complex((z[1:, :] * np.conj(z[:-1, :])).sum())
    return (kx + cmath.phase(across) / (2 * math.pi * cols / 4),
            ky + cmath.phase(down) / (2 * math.pi * rows / 4))


def _drift_refine(
    resid: FloatArray, kx: float, ky: float, settled_cycles: float, max_passes: int
) -> tuple[float, float, complex] | None:
    """Refine the frequency vector ``(kx, ky)`` from the phase drift of the DFT at it between
    the ROI's halves: a phase moving ``d`` cycles from one half to the other (their centres are
    ``cols / 2`` or ``rows / 2`` apart) means ``k`` is off by ``d / (size / 2)``.

    Returns the refined ``(kx, ky)`` and the whole ROI's DFT at the last ``k`` evaluated (the
    centre phase changes only to second order with the last step), once a step moves the
    phase at the ROI's edges by less than ``settled_cycles``; ``None`` if that takes more than
    ``max_passes`` passes over the pixels (a poor start: weak or unclear bars)."""
    rows, cols = resid.shape
    for _ in range(max_passes):
        (q00, q01), (q10, q11) = _quadrant_sums(resid, kx, ky).tolist()  # Python complexes
        dkx = cmath.phase(q01 * q00.conjugate() + q11 * q10.conjugate()) / (math.pi * cols)
        dky = cmath.phase(q10 * q00.conjugate() + q11 * q01.conjugate()) / (math.pi * rows)
        kx, ky = kx + dkx, ky + dky
        if abs(dkx) * cols / 2 + abs(dky) * rows / 2 < settled_cycles:
            return kx, ky, q00 + q01 + q10 + q11
    return None


def _centred_crop(img: FloatArray, max_px: int) -> FloatArray:
    """The central at most ``max_px`` x ``max_px`` of ``img`` with exactly the same centre
    (each side keeps its parity), so phases measured from the centre are unchanged; ``img``
    itself when it fits."""
    rows, cols = img.shape
    if rows <= max_px and cols <= max_px:
        return img
    crop_r = rows if rows <= max_px else max_px - (rows - max_px) % 2
    crop_c = cols if cols <= max_px else max_px - (cols - max_px) % 2
    r0, c0 = (rows - crop_r) // 2, (cols - crop_c) // 2
    return img[r0 : r0 + crop_r, c0 : c0 + crop_c]


def _uncertainties(
    shape: tuple[int, int], theta: float, f: float, amplitude: float, noise_sigma: float
) -> tuple[float, float, float]:
    """Cramer-Rao-like spreads ``(theta_sd, freq_sd, phase_sd)`` for one sinusoid in white
    noise."""
    rows, cols = shape
    n = rows * cols
    snr = amplitude / max(noise_sigma, 1e-12)
    # Mean squares of the centred coordinates: (n^2 - 1) / 12.
    mx, my = (cols * cols - 1) / 12.0, (rows * rows - 1) / 12.0
    c2, s2 = math.cos(theta) ** 2, math.sin(theta) ** 2
    s_u = math.sqrt(mx * c2 + my * s2)
    s_v = math.sqrt(mx * s2 + my * c2)
    base = 1.0 / (math.pi * max(snr, 1e-12) * math.sqrt(2.0 * n))
    return base / max(s_v, 0.5) / f, base / max(s_u, 0.5), base * math.sqrt(2.0) / 2.0


class Fundamental(NamedTuple):
    """The bars' fundamental as :func:`quick_fundamental` measures it."""

    theta_rad: float  #: direction in which the intensity varies, in (-pi/2, pi/2]
    freq_cycles_per_px: float
    value: complex  #: the DFT at ``f (cos t, sin t)``, phases from the centre
    amplitude: float  #: gray units
    shape: tuple[int, int]  #: the shape measured (a centred crop of large ROIs)
    power: float  #: mean square of the measured pixels about their plane (gray^2)

    @property
    def phase_cycles(self) -> float:
        return math.atan2(self.value.imag, self.value.real) / (2 * math.pi)


def quick_geometry(
    img: FloatArray, noise_sigma: float, freq_prior: float, resid: FloatArray | None = None,
    sums: tuple[FloatArray, FloatArray] | None = None,
) -> BarGeometry | None:
    """Straight-bar geometry near a known frequency in a few passes over the pixels, or
    ``None`` when it cannot be trusted (then use :func:`measure_geometry`).

    The direction comes from the gradient structure tensor (corrected for the 2 x 2-cell
    gradients' anisotropy at ``freq_prior``); the frequency vector ``f (cos t, sin t)`` is then
    refined from the phase differences of the DFT at it between the ROI's halves (a phase
    that drifts by ``d`` cycles over half the ROI means ``k`` is off by ``d / half``), once or
    twice; the phase and amplitude are those of the whole ROI's DFT. No 2-D spectrum, no
    search: what the bar-centre selection of the histogram method needs, at a fraction of the
    cost. It declines ROIs under ``QUICK_MIN_PIXELS`` or ``QUICK_MIN_PERIODS`` periods, a
    refinement that does not settle, a frequency outside the prior's band, and a fundamental
    that is not clear of the noise (:func:`fundamental_is_clear`).

    Parameters
    ----------
    img : ndarray, shape (rows, cols)
        The ROI in gray units.
    noise_sigma : float
        Per-pixel noise (for the uncertainties and the significance test).
    freq_prior : float
        Expected frequency (cycles/px, below Nyquist).
    resid : ndarray, optional
        ``detrend(img)`` if already computed (then used whole; otherwise ROIs larger than
        ``QUICK_CROP_PX`` are measured on a centred crop).
    sums : (ndarray, ndarray), optional
        ``(img.sum(axis=0), img.sum(axis=1))`` if already known (used when not cropped).

    Returns
    -------
    BarGeometry or None
        Straight bars (zero curvature).
    """
    found = quick_fundamental(img, noise_sigma, freq_prior, resid, sums)
    if found is None:
        return None
    theta_sd, freq_sd, phase_sd = _uncertainties(
        found.shape, found.theta_rad, found.freq_cycles_per_px, found.amplitude, noise_sigma)
    return BarGeometry(found.theta_rad, found.freq_cycles_per_px, found.phase_cycles,
                       found.amplitude, theta_sd, freq_sd, phase_sd)


def fundamental_is_clear(found: Fundamental, noise_sigma: float) -> bool:
    """Whether a fundamental from :func:`quick_fundamental` stands clear of the noise: at
    least ``QUICK_MIN_Z`` standard errors, and at least ``QUICK_MIN_POWER_SHARE`` of the power
    above the noise (a fundamental holds >= 3/4 of a square wave's, a side lobe or a harmonic
    of the bars much less).

    Parameters
    ----------
    found : Fundamental
        From :func:`quick_fundamental`.
    noise_sigma : float
        Per-pixel noise (gray units).

    Returns
    -------
    bool
    """
    n = found.shape[0] * found.shape[1]
    if found.amplitude < QUICK_MIN_Z * max(noise_sigma, 1e-12) * math.sqrt(2.0 / n):
        return False
    above_noise = found.power - noise_sigma**2
    return found.amplitude * found.amplitude / 2.0 >= QUICK_MIN_POWER_SHARE * above_noise


def quick_fundamental(
    img: FloatArray, noise_sigma: float | None, freq_prior: float, resid: FloatArray | None,
    sums: tuple[FloatArray, FloatArray] | None,
) -> Fundamental | None:
    """:func:`quick_geometry` without its uncertainties (which :func:`measure_geometry`'s
    start and the histogram method's bin phases do not need).

    Parameters
    ----------
    img, freq_prior, resid, sums
        As :func:`quick_geometry`.
    noise_sigma : float or None
        As :func:`quick_geometry`; ``None`` leaves :func:`fundamental_is_clear` to the caller
        (the histogram method measures the noise about the bars' profile afterwards).

    Returns
    -------
    Fundamental or None
        ``None`` where :func:`quick_geometry` declines.
    """
    rows, cols = img.shape
    n = rows * cols
    if not freq_prior or not 0 < freq_prior <= 0.5 or n < QUICK_MIN_PIXELS or min(rows, cols) < 8:
        return None
    if resid is None:
        # Straight bars: a centred crop (same centre, so the same phase) measures them as well
        # as the whole ROI, at a fixed cost.
        # Row-major (a copy of a Fortran-order crop): summed in the same order whatever the
        # ROI's memory layout.
        crop = row_major(_centred_crop(img, QUICK_CROP_PX))
        rows, cols = crop.shape
        n = rows * cols
        resid = detrend(crop, sums if crop is img else None)
    theta_cells, _ = structure_tensor_direction(resid)
    theta = theta_cells
    for _ in range(3):  # invert the cell gradients' anisotropy (a near-identity map)
        theta += theta_cells - _cell_gradient_direction(theta, freq_prior)
    # Periods across the ROI along the bars' normal (each half needs a few).
    if freq_prior * (abs(math.cos(theta)) * cols + abs(math.sin(theta)) * rows) < (
            QUICK_MIN_PERIODS):
        return None
    kx, ky = freq_prior * math.cos(theta), freq_prior * math.sin(theta)
    refined = _drift_refine(resid, kx, ky, QUICK_SETTLED_CYCLES, QUICK_ITERATIONS)
    if refined is None and min(rows, cols) >= QUICK_COARSE_MIN_PX:
        # The prior's magnitude may be a few % off (a nominal magnification): over half a
        # large ROI that wraps the phase; quarters first.
        kx, ky = _coarse_drift_step(resid, kx, ky)
        refined = _drift_refine(resid, kx, ky, QUICK_SETTLED_CYCLES, QUICK_ITERATIONS)
    if refined is None:
        return None  # still moving: a poor start (weak or unclear bars)
    kx, ky, value = refined
    power = float(np.einsum("ij,ij->", resid, resid)) / n
    return _found(kx, ky, value, freq_prior, (rows, cols), power, noise_sigma)


def _found(
    kx: float, ky: float, value: complex, freq_prior: float, shape: tuple[int, int],
    power: float, noise_sigma: float | None,
) -> Fundamental | None:
    """:func:`quick_fundamental`'s verdict on a settled refinement: the :class:`Fundamental`
    at ``(kx, ky)`` (DFT ``value``, mean square about the plane ``power``) when within the
    prior's band and clear of the noise, else ``None``."""
    f = math.hypot(kx, ky)
    if not PRIOR_BAND[0] * freq_prior <= f <= min(PRIOR_BAND[1] * freq_prior, 0.5):
        return None
    theta = math.atan2(ky, kx)
    if theta <= -math.pi / 2 + 1e-12 or theta > math.pi / 2:
        # The opposite k describes the same bars: its DFT is the conjugate.
        theta = theta + math.pi if theta <= 0 else theta - math.pi
        value = value.conjugate()
    n = shape[0] * shape[1]
    found = Fundamental(theta, f, value, 2.0 * abs(value) / n, shape, power)
    if noise_sigma is not None and not fundamental_is_clear(found, noise_sigma):
        return None
    return found


def _spectral_peak(
    resid: FloatArray, freq_prior: float | None, f_lo: float, f_hi: float
) -> tuple[float, float, float] | None:
    """The fundamental ``(kx, ky, magnitude)`` from the 2-D spectrum: the strongest peak in
    ``[f_lo, f_hi]``, or outside it when much stronger (see :func:`measure_geometry`)."""
    rows, cols = resid.shape
    spec = _spectrum(resid)
    peak = _fft_peak(spec, f_lo, f_hi)
    if freq_prior:
        # The prior is a cross-check, not a cage: a fundamental several times stronger than
        # anything in the band (a wrong magnification puts a harmonic there) wins, and the
        # disagreement is reported by the caller.
        wide = _fft_peak(spec, 0.7 / max(rows, cols), 0.5 * math.sqrt(2))
        # A band maximum on the band's edge is the skirt of a peak outside it.
        on_edge = peak is not None and min(
            abs(math.hypot(peak[0], peak[1]) - f_lo), abs(math.hypot(peak[0], peak[1]) - f_hi)
        ) < 1.0 / max(rows, cols)
        if wide is not None and (
            peak is None or wide[2] > WIDE_PEAK_RATIO * peak[2] or (on_edge and wide[2] > peak[2])
        ):
            peak = wide
    return peak


def measure_geometry(
    img: FloatArray,
    noise_sigma: float,
    freq_prior: float | None = None,
    curvature: bool = True,
    quick_start: bool = False,
    sums: tuple[FloatArray, FloatArray] | None = None,
) -> BarGeometry | None:
    """Direction, frequency and phase of the bars in ``img`` (see the module docstring).

    Parameters
    ----------
    img : ndarray, shape (rows, cols)
        The ROI in gray units.
    noise_sigma : float
        Per-pixel noise (for the uncertainties).
    freq_prior : float, optional
        Expected frequency (cycles/px, below Nyquist): the search band is 0.6-1.6 times it.
    curvature : bool
        Also measure the phase curvature of spokes or rings.
    quick_start : bool
        With ``freq_prior``: start from :func:`quick_geometry` (on a centred crop) when it
        accepts the ROI, instead of the 2-D spectrum's peak; the same refinement, phase and
        curvature follow. It accepts only a fundamental carrying at least
        ``QUICK_MIN_POWER_SHARE`` of the power, so no peak outside the prior's band can be
        ``WIDE_PEAK_RATIO`` times stronger: the spectral search would start there too.
    sums : (ndarray, ndarray), optional
        ``(img.sum(axis=0), img.sum(axis=1))`` if already known.

    Returns
    -------
    BarGeometry or None
        ``None`` when the ROI is too small for any spectral peak.
    """
    rows, cols = img.shape
    if rows * cols < 4:
        return None
    resid = detrend(img, sums)
    extent = math.hypot(rows, cols)
    if freq_prior:
        f_lo, f_hi = PRIOR_BAND[0] * freq_prior, min(PRIOR_BAND[1] * freq_prior, 0.5 * math.sqrt(2))
    else:
        f_lo, f_hi = 0.7 / max(rows, cols), 0.5 * math.sqrt(2)
    start = None
    if quick_start and freq_prior:
        start = quick_fundamental(_centred_crop(img, QUICK_CROP_PX), noise_sigma, freq_prior,
                         _centred_crop(resid, QUICK_CROP_PX), None)
    if start is not None:
        # As BarGeometry.k_xy of quick_geometry's result.
        q_theta, q_f = start.theta_rad, start.freq_cycles_per_px
        peak: tuple[float, float, float] | None = (
            q_f * math.cos(q_theta), q_f * math.sin(q_theta), start.amplitude)
    else:
        peak = _spectral_peak(resid, freq_prior, f_lo, f_hi)
    if peak is None:
        if not freq_prior:
            return None
        peak = (freq_prior, 0.0, 0.0) if cols >= rows else (0.0, freq_prior, 0.0)
    # The frequency vector and phase at the centre from a centred crop of large ROIs (the
    # curvature below sees the whole ROI).
    full_resid = resid
    resid = _centred_crop(resid, REFINE_CROP_PX)
    rows, cols = resid.shape
    step = 0.5 / max(rows, cols)
    refined = None
    if (min(rows, cols) >= 8 and rows * cols >= QUICK_MIN_PIXELS
            and abs(peak[0]) * cols + abs(peak[1]) * rows >= QUICK_MIN_PERIODS):
        # Enough periods in each half for the phase-drift refinement (a few passes); else the
        # DFT magnitude's maximum on grids of frequencies around the peak.
        refined = _drift_refine(resid, peak[0], peak[1], DRIFT_SETTLED_CYCLES, DRIFT_PASSES)
    if refined is None:
        kx, ky = refine_peak(resid, peak[0], peak[1], step)
    else:
        kx, ky = refined[0], refined[1]
    f = math.hypot(kx, ky)
    if freq_prior and not (f_lo <= f <= f_hi) and f_lo <= math.hypot(peak[0], peak[1]) <= f_hi:
        # The refinement walked out of the band (noise): keep the prior's magnitude.
        scale = freq_prior / max(f, 1e-12)
        kx, ky, f = kx * scale, ky * scale, freq_prior
        refined = None  # its DFT belongs to the frequency walked out of the band
    if f <= 0:
        return None
    theta = math.atan2(ky, kx)
    if theta <= -math.pi / 2 + 1e-12:
        theta += math.pi
    elif theta > math.pi / 2:
        theta -= math.pi
    # The phase belongs to the normalised direction (the opposite k is the conjugate peak).
    kx_found, ky_found = kx, ky
    kx, ky = f * math.cos(theta), f * math.sin(theta)
    if refined is not None:
        # The phase-drift refinement's last pass already summed the DFT at (nearly) this k:
        # the centre phase moves only to second order with its last, settled step.
        value = refined[2]
        if kx * kx_found + ky * ky_found < 0:  # the opposite k: the conjugate
            value = value.conjugate()
    else:
        value = dft_at(resid, kx, ky)
    n = rows * cols
    amplitude = 2.0 * abs(value) / n
    # F ~ (A n / 2) e^{i psi} for A cos(2 pi k.r + psi): bright-bar centres where k.r + psi/2pi
    # is an integer.
    phase = math.atan2(value.imag, value.real) / (2 * math.pi)
    theta_sd, freq_sd, phase_sd = _uncertainties((rows, cols), theta, f, amplitude, noise_sigma)
    hess = (0.0, 0.0, 0.0)
    geom = BarGeometry(theta, f, phase, amplitude, theta_sd, freq_sd, phase_sd, hess)
    resid = full_resid
    rows, cols = resid.shape
    if curvature and min(rows, cols) >= 16 and f * extent >= 10:
        hess = _curvature(resid, kx, ky, 0.5 / max(rows, cols))
        if any(hess):
            # Kept only when the pixels then fold onto one period more sharply (noise does
            # not make a consistent curvature).
            n_bins = int(min(32, max(8, resid.size // 8)))
            curved = replace(geom, hessian=hess)
            if _fold_contrast(resid, curved, n_bins) > 1.001 * _fold_contrast(resid, geom, n_bins):
                geom = curved
    return geom


def _curvature(resid: FloatArray, kx: float, ky: float, step: float) -> tuple[float, float, float]:
    """Phase curvature from the frequency vectors of the four quadrants (see module doc)."""
    rows, cols = resid.shape
    hr, hc = rows // 2, cols // 2
    quads = {}
    for qr, (r0, r1) in enumerate(((0, hr), (rows - hr, rows))):
        for qc, (c0, c1) in enumerate(((0, hc), (cols - hc, cols))):
            # Each quadrant's local frequency from its centred crop (the same centre).
            sub = _centred_crop(resid[r0:r1, c0:c1], QUICK_CROP_PX)
            drift = _drift_refine(sub, kx, ky, DRIFT_SETTLED_CYCLES, DRIFT_PASSES)
            qkx, qky = ((drift[0], drift[1]) if drift is not None
                        else refine_peak(sub, kx, ky, 2 * step, iterations=3))
            centre = ((r0 + r1 - 1) / 2 - (rows - 1) / 2, (c0 + c1 - 1) / 2 - (cols - 1) / 2)
            quads[(qr, qc)] = (centre, qkx, qky)
    dy = quads[(1, 0)][0][0] - quads[(0, 0)][0][0]
    dx = quads[(0, 1)][0][1] - quads[(0, 0)][0][1]
    if dx <= 0 or dy <= 0:
        return (0.0, 0.0, 0.0)
    # Gradients of kx and ky along x and y, averaged over the two pairs of quadrants.
    dkx_dx = ((quads[(0, 1)][1] - quads[(0, 0)][1]) + (quads[(1, 1)][1] - quads[(1, 0)][1])) / (
        2 * dx
    )
    dky_dy = ((quads[(1, 0)][2] - quads[(0, 0)][2]) + (quads[(1, 1)][2] - quads[(0, 1)][2])) / (
        2 * dy
    )
    dkx_dy = ((quads[(1, 0)][1] - quads[(0, 0)][1]) + (quads[(1, 1)][1] - quads[(0, 1)][1])) / (
        2 * dy
    )
    dky_dx = ((quads[(0, 1)][2] - quads[(0, 0)][2]) + (quads[(1, 1)][2] - quads[(1, 0)][2])) / (
        2 * dx
    )
    hxy = 0.5 * (dkx_dy + dky_dx)
    corner = (cols / 2.0, rows / 2.0)
    worst = 0.0
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * corner[0], sy * corner[1]
            worst = max(worst, abs(0.5 * (dkx_dx * x * x + 2 * hxy * x * y + dky_dy * y * y)))
    if worst < CURVATURE_MIN_CYCLES:
        return (0.0, 0.0, 0.0)
    return (dkx_dx, hxy, dky_dy)


def _fold_contrast(img: FloatArray, geom: BarGeometry, n_bins: int) -> float:
    """How sharply the pixels fold onto one period: the variance of the phase-binned means
    weighted by their counts (largest at the right direction and frequency)."""
    phi = phase_map((img.shape[0], img.shape[1]), geom)
    idx = ((phi - np.floor(phi)) * n_bins).astype(np.intp) % n_bins
    flat = img.ravel()
    count = np.bincount(idx.ravel(), minlength=n_bins)
    sums = np.bincount(idx.ravel(), weights=flat, minlength=n_bins)
    ok = count > 0
    return float((sums[ok] ** 2 / count[ok]).sum())


def refine_by_folding(img: FloatArray, geom: BarGeometry, fix_freq: bool) -> BarGeometry:
    """Refine the direction (and the frequency unless ``fix_freq``) so that the pixels fold
    most sharply onto one bar period. On small ROIs and few periods the spectral peak is pulled
    by its own side lobes and by the opposite peak; folding uses the bar edges themselves."""
    n_bins = int(min(32, max(8, img.size // 8)))
    resid = img - float(img.mean())
    start = geom
    f = geom.freq_cycles_per_px
    h_theta = min(max(2.0 * geom.theta_sd_rad, math.radians(0.2)), math.radians(2.0))
    steps: list[tuple[str, float]] = [("theta", h_theta)]
    if not fix_freq:
        steps.append(("freq", min(max(2.0 * geom.freq_sd, 0.003 * f), 0.02 * f)))
    for _ in range(2):
        for name, h in steps:
            base = getattr(geom, "theta_rad" if name == "theta" else "freq_cycles_per_px")
            vals = []
            for j in range(-2, 3):
                trial = replace(geom, **{("theta_rad" if name == "theta" else
                                          "freq_cycles_per_px"): base + j * h})
                vals.append(_fold_contrast(resid, trial, n_bins))
            best = int(np.argmax(vals))
            offset = 0.0
            if 0 < best < 4:
                offset = _parabola_offset(np.asarray(vals[best - 1 : best + 2]))
            new = base + (best - 2 + offset) * h
            geom = replace(geom, **{("theta_rad" if name == "theta" else
                                     "freq_cycles_per_px"): new})
    if _fold_contrast(resid, geom, n_bins) <= 1.001 * _fold_contrast(resid, start, n_bins):
        return start  # no clear gain: the spectral estimate stands
    # The phase at the centre for the refined direction and frequency.
    kx, ky = geom.k_xy
    value = dft_at(detrend(img), kx, ky)
    return replace(geom, phase_cycles=math.atan2(value.imag, value.real) / (2 * math.pi))


def phase_map(shape: tuple[int, int], geom: BarGeometry) -> FloatArray:
    """Fundamental phase (cycles) of every pixel: ``k . r + 1/2 r^T H r + phase``; the bright
    bar centres sit at integers."""
    from benchlab.analysis.bars.projection import across_coordinate

    u = across_coordinate(shape, geom.theta_rad)
    phi = geom.freq_cycles_per_px * u + geom.phase_cycles
    hxx, hxy, hyy = geom.hessian
    if hxx or hxy or hyy:
        y, x = _centred_grid(shape)
        phi = phi + 0.5 * (hxx * (x * x)[None, :] + 2 * hxy * np.outer(y, x)
                           + hyy * (y * y)[:, None])
    return phi


def frequency_disagreement(geom: BarGeometry, freq_prior: float | None) -> str | None:
    """A warning when the measured frequency is off the prior beyond 3 sigma and 3 %."""
    if not freq_prior:
        return None
    f = geom.freq_cycles_per_px
    if abs(f - freq_prior) > 3.0 * geom.freq_sd + FREQ_TOLERANCE * freq_prior:
        return (
            f"measured period {1 / f:.2f} px (+-{geom.freq_sd / f**2:.2f}) disagrees with the "
            f"given frequency ({1 / freq_prior:.2f} px per period); the measured one is used"
        )
    return None
