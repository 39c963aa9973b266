"""Self-calibration of the radial view without a ray tracer (beyond the thesis).

A tangential ring target (bars around the cylinder) of known object frequency ``f`` at a known
distance ``R`` from the axis images as concentric rings. Consecutive dark rings are one object
period (``1 / f`` mm) apart along the axis, so the radii of the ring centres give axial
position against image radius at that depth - a one-depth ray-trace table that ``unwrap``
accepts at that depth.

Two things rings cannot tell: where ``z = 0`` is (the table's axial origin is put at the
innermost ring found) and which way ``z`` runs (``axial_increases_inward``, default as in the
shipped table). :func:`compare_tables` reports how far a calibration is from another table
after the best axial shift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage, signal

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.views.raytrace import (
    ENDOSCOPE_RADIUS_MM,
    MIN_POINTS_PER_DEPTH,
    RayTraceError,
    RayTraceTable,
)
from benchlab.analysis.views.synthesis import cylinder_map

#: Radial sampling step of the ring profile, px.
_STEP_PX = 0.25
#: Points written per depth (as the thesis's database).
CALIBRATION_POINTS = 36


@dataclass(frozen=True)
class RingCalibration:
    """Result of :func:`calibrate_from_rings`.

    Attributes
    ----------
    table : RayTraceTable
        One-depth table: 36 points of the fitted axial position over image radius.
    ring_radius_mm, ring_z_mm : ndarray
        The dark rings found (image radius) and their axial positions.
    fit_residual_um : float
        RMS axial residual of the rings about the fitted polynomial.
    period_px : float
        Median ring spacing, px.
    """

    table: RayTraceTable
    ring_radius_mm: FloatArray
    ring_z_mm: FloatArray
    fit_residual_um: float
    period_px: float


def _radial_profile(
    frame: npt.NDArray[Any], centre_rc: tuple[float, float], r_max_px: float, n_azimuth: int
) -> tuple[FloatArray, FloatArray]:
    """Mean over azimuth of the frame along radii, ignoring samples outside the frame."""
    arr = np.asarray(frame, dtype=np.float64)
    radii = np.arange(0.0, r_max_px, _STEP_PX)
    phi = np.linspace(0.0, 2.0 * np.pi, n_azimuth, endpoint=False)
    rows = centre_rc[0] + radii[:, None] * np.sin(phi)[None, :]
    cols = centre_rc[1] + radii[:, None] * np.cos(phi)[None, :]
    h, w = arr.shape
    inside = (rows >= 0) & (rows <= h - 1) & (cols >= 0) & (cols <= w - 1)
    values = ndimage.map_coordinates(arr, [rows, cols], order=1, mode="nearest")
    count = inside.sum(axis=1)
    total = np.where(inside, values, 0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        profile = np.where(count > n_azimuth // 8, total / np.maximum(count, 1), np.nan)
    return radii, profile


def calibrate_from_rings(
    frame: npt.NDArray[Any],
    *,
    object_lp_per_mm: float,
    object_radius_mm: float,
    centre_rc: tuple[float, float],
    pixel_pitch_um: float = 5.2,
    axial_increases_inward: bool = True,
    degree: int = 3,
    source: str = "<calibration>",
) -> RingCalibration:
    """Fit axial position against image radius from a tangential ring frame.

    Parameters
    ----------
    frame : ndarray
        Raw radial frame of a tangential (ring) target.
    object_lp_per_mm : float
        Printed frequency of the target.
    object_radius_mm : float
        Distance of the target from the axis, mm.
    centre_rc : (float, float)
        Optical centre in the frame.
    pixel_pitch_um : float
        Sensor pixel pitch.
    axial_increases_inward : bool
        Whether axial position grows towards the image centre (the shipped table's sense).
    degree : int
        Degree of the polynomial fitted through the rings.
    source : str
        Name recorded in the table.

    Raises
    ------
    ValueError
        Bad parameters, or fewer than ``degree + 2`` rings found.
    """
    if not (object_lp_per_mm > 0 and math.isfinite(object_lp_per_mm)):
        raise ValueError(f"object frequency must be > 0 lp/mm, got {object_lp_per_mm}")
    if not object_radius_mm > ENDOSCOPE_RADIUS_MM:
        raise ValueError(
            f"object radius must be beyond the side wall ({ENDOSCOPE_RADIUS_MM} mm), got "
            f"{object_radius_mm}"
        )
    arr = np.asarray(frame, dtype=np.float64)
    if arr.ndim != 2:
        raise ValueError(f"frame must be 2-D, got shape {arr.shape}")
    h, w = arr.shape
    corners = [math.hypot(r - centre_rc[0], c - centre_rc[1]) for r in (0, h) for c in (0, w)]
    radii, profile = _radial_profile(arr, centre_rc, max(corners), 720)
    level = 0.05 * float(np.nanpercentile(arr, 99.9))
    lit = np.nan_to_num(profile, nan=0.0) > level
    labels, n = ndimage.label(lit)
    if n == 0:
        raise ValueError("no lit annulus found in the frame")
    sizes = ndimage.sum(lit, labels, index=np.arange(1, n + 1))
    keep = np.flatnonzero(labels == int(np.argmax(sizes)) + 1)
    trim = int(round(4.0 / _STEP_PX))  # the annulus edges are soft: stay off them
    keep = keep[trim:-trim] if keep.size > 2 * trim + 8 else keep
    r_px, prof = radii[keep], profile[keep]
    detrended = prof - ndimage.uniform_filter1d(prof, size=max(9, int(60 / _STEP_PX)))
    spectrum = np.abs(np.fft.rfft(detrended * np.hanning(detrended.size), 8 * detrended.size))
    k = int(np.argmax(spectrum[1:])) + 1
    period_samples = 8 * detrended.size / k
    smooth = ndimage.gaussian_filter1d(detrended, max(1.0, period_samples / 12.0))
    minima, _ = signal.find_peaks(-smooth, distance=max(1, int(0.6 * period_samples)),
                                  prominence=0.2 * float(np.ptp(smooth)))
    minima = minima[(minima > 0) & (minima < smooth.size - 1)]
    if minima.size < max(degree + 2, MIN_POINTS_PER_DEPTH):
        raise ValueError(
            f"found {minima.size} dark rings; need at least {max(degree + 2, MIN_POINTS_PER_DEPTH)}"
            " (is it a tangential ring target, in focus, with the right centre?)"
        )
    # Parabolic sub-sample refinement of each minimum.
    a, b, c = smooth[minima - 1], smooth[minima], smooth[minima + 1]
    denom = a - 2 * b + c
    offset = np.where(np.abs(denom) > 1e-12, 0.5 * (a - c) / np.where(denom == 0, 1, denom), 0)
    ring_px = r_px[0] + (minima + np.clip(offset, -0.5, 0.5)) * _STEP_PX
    gaps = np.diff(ring_px)
    local = ndimage.median_filter(gaps, size=min(5, gaps.size), mode="nearest")
    steps = np.maximum(1, np.round(gaps / local)).astype(int)  # a missed ring counts twice
    index = np.concatenate([[0], np.cumsum(steps)])
    period_mm = 1.0 / object_lp_per_mm
    sign = 1.0 if axial_increases_inward else -1.0
    ring_mm = ring_px * pixel_pitch_um / 1000.0
    z = -sign * index * period_mm
    z = z - z[0]  # origin at the innermost ring
    coeffs = np.polyfit(ring_mm, z, degree)
    fit_residual_um = float(np.sqrt(np.mean((np.polyval(coeffs, ring_mm) - z) ** 2)) * 1e3)
    rho = np.linspace(ring_mm[0], ring_mm[-1], CALIBRATION_POINTS)
    z_fit = np.polyval(coeffs, rho)
    if not (np.all(np.diff(z_fit) > 0) or np.all(np.diff(z_fit) < 0)):
        raise ValueError("fitted axial position is not monotonic; lower the polynomial degree")
    table = RayTraceTable(
        depths_mm=np.array([object_radius_mm - ENDOSCOPE_RADIUS_MM]),
        object_radius_mm=np.array([float(object_radius_mm)]),
        object_z_mm=(np.asarray(z_fit, dtype=np.float64),),
        image_radius_mm=(np.asarray(rho, dtype=np.float64),),
        source=source,
    )
    return RingCalibration(table, ring_mm, z, fit_residual_um,
                           float(np.median(gaps)))


def compare_tables(
    calibrated: RayTraceTable, reference: RayTraceTable, object_radius_mm: float,
    reference_rho_mm: float | None = None,
) -> dict[str, float]:
    """How far a calibrated table is from a reference one at one cylinder.

    The axial origin of a ring calibration is arbitrary, so the best constant shift is removed
    first. Returns the shift, the RMS and maximum axial differences (um), the same as image
    radius differences (um, through the local magnification) and the relative difference of
    the axial magnification at ``reference_rho_mm`` (default mid-range), in %.

    Raises
    ------
    RayTraceError
        When either table cannot map that cylinder or they share no image radii.
    """
    cal = cylinder_map(calibrated, object_radius_mm)
    ref = cylinder_map(reference, object_radius_mm)
    lo = max(float(cal.rho_mm[0]), float(ref.rho_mm[0]))
    hi = min(float(cal.rho_mm[-1]), float(ref.rho_mm[-1]))
    if not hi > lo:
        raise RayTraceError("the two tables share no image radii at this cylinder")
    rho = np.linspace(lo, hi, 200)
    diff = cal.axial_mm(rho) - ref.axial_mm(rho)
    shift = float(np.mean(diff))
    diff -= shift
    mag = np.array([ref.axial_magnification(r) for r in rho])
    rho_ref = (lo + hi) / 2.0 if reference_rho_mm is None else reference_rho_mm
    m_cal, m_ref = cal.axial_magnification(rho_ref), ref.axial_magnification(rho_ref)
    return {
        "axial_shift_mm": shift,
        "rms_axial_um": float(np.sqrt(np.mean(diff**2)) * 1e3),
        "max_axial_um": float(np.max(np.abs(diff)) * 1e3),
        "rms_image_radius_um": float(np.sqrt(np.mean((diff / mag) ** 2)) * 1e3),
        "magnification_at_mm": float(rho_ref),
        "magnification_calibrated": m_cal,
        "magnification_reference": m_ref,
        "magnification_error_pct": 100.0 * (m_cal - m_ref) / m_ref,
        "image_radius_from_mm": lo,
        "image_radius_to_mm": hi,
    }
