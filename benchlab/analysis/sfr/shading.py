"""Illumination non-uniformity (shading) under a slanted edge, and its removal.

A vignetted or unevenly lit edge ROI is ``I = b + L S(u)``: the step response ``S`` across the
edge under a smooth illumination ``L`` and background ``b``. The slanted-edge SFR assumes
``L`` and ``b`` constant; a gradient of a few per cent across a 100 px ROI (a field edge of the
endoscope's view) tilts the plateaus, and the LSF window's derivative of the tilt adds a
low-frequency lobe: the MTF reads 0.02-0.04 low from ~0.05 cycles/px on (``benchlab
benchmark sfr``, shading rows). Along the edge it also makes the pixels of one ESF position
disagree, which reads as "other structure".

Both plateaus show the illumination: the dark one ``b + L s_d``, the bright one ``b + L s_b``.
Planes fitted to each plateau far from the edge (beyond the LSF's support, where the ESF no
longer departs from its plateaus) give ``D`` and ``B`` at every pixel, and::

    (I - D) / (B - D) = (S(u) - s_d) / (s_b - s_d)

whatever the planes of ``L`` and ``b`` (a multiplicative falloff, an additive stray-light
gradient, or both). The ROI is mapped back to its levels at the edge centre, so everything
downstream keeps its units. A plane is used only where it is significant against a constant
(its two slopes' chi-square drop beyond :data:`SHADING_CHI2`): a uniform ROI is left exactly
as it was.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.noise import MAD_TO_SIGMA

#: Chi-square drop (2 degrees of freedom: the two slopes) above which a plateau's plane is
#: taken as shading rather than noise: p = exp(-20 / 2) = 4.5e-5 per plateau.
SHADING_CHI2 = 20.0
#: ... and the plateaus change by at least this fraction of the step across the ROI: a
#: noise-free ROI's rounding makes a plane of a 0.06 % ESF tail "significant"; a change below
#: 0.5 % moves the MTF by < 0.002 (the LSF window sees a fraction of it).
MIN_CHANGE = 0.005
#: Fits of the planes: the first beyond the support read off the shaded ROI (a tilted plateau
#: widens it), the second beyond the support of the flattened one (nearer the edge: more
#: pixels, a better plane).
SHADING_PASSES = 2
#: Plateau pixels further than this many noise sigmas from the first plane are left out of
#: the second (as the SFR clips its outliers).
OUTLIER_SIGMAS = 5.0
#: Each plateau needs at least this many pixels for its plane.
MIN_PLATEAU_PIXELS = 100
#: Plateau pixels start this far (px) beyond the LSF's support from the edge.
PLATEAU_MARGIN_PX = 2.0
#: No flattening where the step ``B - D`` falls below this fraction of its value at the edge
#: centre anywhere in the ROI (a plane extrapolated that far is not the illumination).
MIN_STEP_FRACTION = 0.25


@dataclass(frozen=True)
class Plane:
    """A level ``c0 + c_row (row - row0) + c_col (col - col0)`` (ROI units, per px)."""

    c0: float
    c_row: float
    c_col: float
    chi2_drop: float  # its two slopes' drop of the chi-square against a constant

    def at(self, drow: FloatArray | float, dcol: FloatArray | float) -> FloatArray:
        return np.asarray(self.c0 + self.c_row * drow + self.c_col * dcol, dtype=np.float64)


@dataclass(frozen=True)
class Shading:
    """The two plateaus' planes, about the edge centre ``(row0, col0)`` of the work frame."""

    dark: Plane
    bright: Plane
    row0: float
    col0: float
    beyond_px: float  # plateau pixels: further than this from the edge
    max_change: float  # largest |plane - its value at the edge centre| over the ROI / step
    min_step_fraction: float  # smallest (B - D) over the ROI / (B - D) at the edge centre

    @property
    def significant(self) -> bool:
        """Whether either plateau is a plane rather than a constant (see SHADING_CHI2), by
        enough to matter (MIN_CHANGE)."""
        return (max(self.dark.chi2_drop, self.bright.chi2_drop) > SHADING_CHI2
                and self.max_change >= MIN_CHANGE)

    @property
    def correctable(self) -> bool:
        """Whether the step stays wide enough everywhere to divide by."""
        return self.min_step_fraction >= MIN_STEP_FRACTION

    def describe(self) -> str:
        """One line for the warnings."""
        return (f"illumination not uniform: the plateaus change by up to "
                f"{100 * self.max_change:.1f} % of the step across the ROI (fitted as planes "
                f"beyond {self.beyond_px:.1f} px of the edge)")


def _plane_of_sums(
    r: FloatArray, c: FloatArray, mask: npt.NDArray[np.bool_], work: FloatArray, var: float
) -> Plane | None:
    """Least-squares plane through ``work`` where ``mask`` holds, at row offsets ``r`` and
    column offsets ``c``, from row and column sums (no pixel gathered: the common, uniform
    case costs a few passes over the ROI); None with fewer than MIN_PLATEAU_PIXELS."""
    m = mask.astype(np.float64)
    mz = m * work
    m_rows, m_cols = m.sum(axis=1), m.sum(axis=0)
    n = float(m_rows.sum())
    if n < MIN_PLATEAU_PIXELS:
        return None
    z_rows, z_cols = mz.sum(axis=1), mz.sum(axis=0)
    mr, mc, mz_mean = float(r @ m_rows) / n, float(c @ m_cols) / n, float(z_rows.sum()) / n
    srr = float((r * r) @ m_rows) - n * mr * mr
    scc = float((c * c) @ m_cols) - n * mc * mc
    src = float(r @ (m @ c)) - n * mr * mc
    srz = float(r @ z_rows) - n * mr * mz_mean
    scz = float(c @ z_cols) - n * mc * mz_mean
    return _solve_plane(n, mr, mc, mz_mean, srr, scc, src, srz, scz, var)


def _solve_plane(n: float, mr: float, mc: float, mz: float, srr: float, scc: float,
                 src: float, srz: float, scz: float, var: float) -> Plane:
    """The plane from its centred sums (see :func:`_plane_lsq`)."""
    det = srr * scc - src * src
    if n < 3 or det <= 1e-12 * max(srr * scc, 1e-300):
        return Plane(mz, 0.0, 0.0, 0.0)  # the pixels lie on a line: only the mean is known
    b_r = (scc * srz - src * scz) / det
    b_c = (srr * scz - src * srz) / det
    drop = (b_r * srz + b_c * scz) / max(var, 1e-300)
    return Plane(mz - b_r * mr - b_c * mc, b_r, b_c, float(drop))


def _plane(drow: FloatArray, dcol: FloatArray, z: FloatArray, var: float) -> Plane:
    """:func:`_plane_lsq`, then again without the pixels more than OUTLIER_SIGMAS noise
    sigmas off it (hot or dead pixels, dust: one hot pixel pulls a least-squares plane far
    enough to read as shading on a clean edge)."""
    plane = _plane_lsq(drow, dcol, z, var)
    for i in range(3):
        res = z - plane.at(drow, dcol)
        limit = OUTLIER_SIGMAS * np.sqrt(var)
        if i == 0:  # the first plane leans towards the outliers: the clean pixels' spread
            limit = max(limit, OUTLIER_SIGMAS * MAD_TO_SIGMA * float(np.median(np.abs(res))))
        keep = np.abs(res) <= limit
        if bool(keep.all()) or int(np.count_nonzero(keep)) < MIN_PLATEAU_PIXELS:
            break
        drow, dcol, z = drow[keep], dcol[keep], z[keep]
        plane = _plane_lsq(drow, dcol, z, var)
    return plane


def _plane_lsq(drow: FloatArray, dcol: FloatArray, z: FloatArray, var: float) -> Plane:
    """Least-squares plane through ``z`` at ``(drow, dcol)``, centred sums (well conditioned
    for any ROI size), and its chi-square drop against the mean."""
    mr, mc, mz = float(drow.mean()), float(dcol.mean()), float(z.mean())
    r, c, e = drow - mr, dcol - mc, z - mz
    return _solve_plane(float(z.size), mr, mc, mz, float(r @ r), float(c @ c), float(r @ c),
                        float(r @ e), float(c @ e), var)


def fit_shading(
    work: FloatArray, u: FloatArray, row0: float, col0: float, beyond_px: float,
    var_dark: float, var_bright: float,
) -> Shading | None:
    """Planes through the dark (``u < -beyond_px``) and bright (``u > beyond_px``) plateaus.

    Parameters
    ----------
    work : ndarray, shape (rows, cols)
        The ROI in the SFR's work frame (the edge crossing the rows).
    u : ndarray, shape (rows, cols)
        Each pixel's signed distance from the fitted edge, px, positive on the bright side.
    row0, col0 : float
        The edge centre (the planes' origin).
    beyond_px : float
        Plateau pixels are further than this from the edge (the LSF's support and a margin).
    var_dark, var_bright : float
        Pixel noise variance on each plateau (the chi-square's unit).

    Returns
    -------
    Shading or None
        None when a plateau has fewer than :data:`MIN_PLATEAU_PIXELS` pixels.
    """
    rows, cols = work.shape
    r = np.arange(rows, dtype=np.float64) - row0
    c = np.arange(cols, dtype=np.float64) - col0
    masks = (u < -beyond_px, u > beyond_px)
    variances = (var_dark, var_bright)
    planes = []
    for mask, var in zip(masks, variances, strict=True):
        plane = _plane_of_sums(r, c, mask, work, var)
        if plane is None:
            return None
        planes.append(plane)
    if max(p.chi2_drop for p in planes) > SHADING_CHI2:
        # Shading to remove: the planes again without outliers (the sums above are quick
        # and plain; a hot pixel may have made them).
        drow = np.broadcast_to(r[:, None], work.shape)
        dcol = np.broadcast_to(c[None, :], work.shape)
        planes = [_plane(drow[m], dcol[m], work[m], v)
                  for m, v in zip(masks, variances, strict=True)]
    dark, bright = planes
    step0 = bright.c0 - dark.c0
    if not step0 > 0:
        return None
    # Extremes of a plane over the ROI are at its corners.
    corners_r = np.array([-row0, -row0, rows - 1 - row0, rows - 1 - row0])
    corners_c = np.array([-col0, cols - 1 - col0, -col0, cols - 1 - col0])
    d_c, b_c = dark.at(corners_r, corners_c), bright.at(corners_r, corners_c)
    change = max(float(np.max(np.abs(d_c - dark.c0))), float(np.max(np.abs(b_c - bright.c0))))
    return Shading(dark, bright, row0, col0, beyond_px, change / step0,
                   float(np.min(b_c - d_c)) / step0)


def flatten(work: FloatArray, shading: Shading) -> FloatArray:
    """The ROI as if lit uniformly at its edge centre: ``D0 + (B0 - D0) (I - D) / (B - D)``.

    Parameters
    ----------
    work : ndarray, shape (rows, cols)
    shading : Shading
        From :func:`fit_shading`, correctable.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
    """
    rows, cols = work.shape
    drow = (np.arange(rows, dtype=np.float64) - shading.row0)[:, None]
    dcol = (np.arange(cols, dtype=np.float64) - shading.col0)[None, :]
    d = shading.dark.at(drow, dcol)
    step = shading.bright.at(drow, dcol) - d
    d0, b0 = shading.dark.c0, shading.bright.c0
    return np.asarray(d0 + (b0 - d0) * (work - d) / step, dtype=np.float64)

