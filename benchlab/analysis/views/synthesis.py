"""View synthesis of the radial view (thesis chapter 5): viewpoint, unwrapped and perspective maps.

Every output pixel is one point on an object cylinder around the endoscope axis; the ray-trace
table (:mod:`benchlab.analysis.views.raytrace`) gives the image radius of that point and the azimuth
passes through, so each output pixel maps to one raw-image position. The maps are built once
(:func:`unwrap_maps`, :func:`perspective_maps`) and applied with ``cv2.remap``
(:func:`apply_maps`), fast enough to show live.

Coordinates
-----------
Raw image: numpy ``(row, col)``, 0-based, pixel centres at integers. Image azimuth ``phi`` is
measured about the optical centre from ``+col`` towards ``+row`` (``atan2(drow, dcol)``); the
object point at azimuth ``phi`` images at image azimuth ``phi``. Object space: ``z`` along the
axis (the thesis's: viewpoint at -6.4 mm, field of view at larger ``z``), ``R`` the cylinder
radius from the axis (``--depth-mm`` on the command line; the table's ``depth_mm`` is measured
from the side wall, ``R = 13.88 + depth``).

Unwrapped ("estimated orthographic") view, thesis 5.2: column ``j`` is arc length
``R (phi0 + j / (R px_per_mm))``, row ``i`` axial position ``z_max - i / px_per_mm`` (row 0 is
the far end of the field, which the radial view images innermost). Output pixels whose raw
position falls outside the frame (a clipped annulus) or outside the table are *invalid*: their
value is 0 and :attr:`ViewMaps.valid` is False - never invented.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.views.raytrace import (
    OPERATIONAL_IMAGE_RADIUS_MM,
    SVP_TOLERANCE_MM,
    RayTraceError,
    RayTraceTable,
)

BoolArray = npt.NDArray[np.bool_]
#: ``--interpolation`` names and the OpenCV flags they select.
INTERPOLATIONS = ("nearest", "linear", "cubic", "lanczos")
#: Raw-image position given to invalid output pixels (outside every frame: remap writes 0).
_OUTSIDE = -16.0


# --------------------------------------------------------------------------- object <-> image
@dataclass(frozen=True)
class CylinderMap:
    """The table at one object cylinder: axial position over the uniform image-radius grid.

    Attributes
    ----------
    object_radius_mm : float
        Cylinder radius from the axis.
    rho_mm, z_mm : ndarray
        Image radius grid and the axial position imaged at each radius (monotonic).
    extrapolated : bool
        True when the radius lies outside the table's depths and was extrapolated on request.
    """

    object_radius_mm: float
    rho_mm: FloatArray
    z_mm: FloatArray
    extrapolated: bool

    @property
    def z_range_mm(self) -> tuple[float, float]:
        return float(self.z_mm.min()), float(self.z_mm.max())

    def image_radius_mm(self, z_mm: npt.ArrayLike) -> FloatArray:
        """Image radius of axial positions on this cylinder; NaN outside the table."""
        z = np.asarray(z_mm, dtype=np.float64)
        zs, rhos = (self.z_mm, self.rho_mm) if self.z_mm[-1] > self.z_mm[0] else (
            self.z_mm[::-1], self.rho_mm[::-1])
        out = np.interp(z, zs, rhos)
        return np.where((z < zs[0]) | (z > zs[-1]), np.nan, out)

    def axial_mm(self, rho_mm: npt.ArrayLike) -> FloatArray:
        """Axial position imaged at image radii (clamped at the ends of the table)."""
        return np.interp(np.asarray(rho_mm, dtype=np.float64), self.rho_mm, self.z_mm)

    def axial_magnification(self, rho_mm: float) -> float:
        """|dz / d(image radius)| at an image radius: object mm per image mm along the axis."""
        slope = np.gradient(self.z_mm, self.rho_mm)
        return float(abs(np.interp(rho_mm, self.rho_mm, slope)))


@functools.lru_cache(maxsize=32)
def cylinder_map(
    table: RayTraceTable, object_radius_mm: float, *, allow_extrapolation: bool = False
) -> CylinderMap:
    """The table at a cylinder of radius ``object_radius_mm`` (mm from the axis).

    Between the table's depths each equal-image-radius group (one line of sight) is
    interpolated over object radius with a cubic spline: exact for the straight lines of a
    single viewpoint, and it follows curved lines of sight where the viewpoint spreads (the
    thesis's fig. 5.4b fallback); with fewer than four depths, linearly. Outside the table's
    depths the two nearest depths are extrapolated linearly only when ``allow_extrapolation``
    (and the result says so). A table with one depth can only be used at that depth.

    Raises
    ------
    RayTraceError
        Radius outside the table (without ``allow_extrapolation``), a one-depth table asked
        for another radius, or a map that is not monotonic there.
    """
    res = table.resampled
    radii = res.object_radius_mm
    r = float(object_radius_mm)
    if not (math.isfinite(r) and r > 0):
        raise RayTraceError(f"object radius must be > 0 mm, got {object_radius_mm!r}")
    lo, hi = float(radii[0]), float(radii[-1])
    extrapolated = False
    if radii.size == 1:
        if not math.isclose(r, lo, rel_tol=0.0, abs_tol=1e-6):
            raise RayTraceError(
                f"{table.source}: the table has one depth (object radius {lo:g} mm); it can only "
                f"map that cylinder, not {r:g} mm"
            )
        z = res.z_mm[0].copy()
    else:
        if not lo - 1e-9 <= r <= hi + 1e-9:
            if not allow_extrapolation:
                raise RayTraceError(
                    f"object radius {r:g} mm is outside the table's {lo:g}-{hi:g} mm "
                    f"({table.source}); allow extrapolation to use it anyway"
                )
            extrapolated = True
        if extrapolated or radii.size < 4:
            k = int(np.clip(np.searchsorted(radii, r) - 1, 0, radii.size - 2))
            w = (r - radii[k]) / (radii[k + 1] - radii[k])
            z = (1.0 - w) * res.z_mm[k] + w * res.z_mm[k + 1]
        else:  # follows curved lines of sight; exact (not-a-knot) for straight ones
            # here: scipy.interpolate costs 0.2-0.5 s CPU to import, and the scenes import
            # this module for every simulated run and depth re-analysis
            from scipy.interpolate import CubicSpline

            z = np.asarray(CubicSpline(radii, res.z_mm, axis=0)(r), dtype=np.float64)
    steps = np.diff(z)
    if not (np.all(steps > 0) or np.all(steps < 0)):
        raise RayTraceError(
            f"{table.source}: axial position is not monotonic in image radius at {r:g} mm"
        )
    z.setflags(write=False)
    return CylinderMap(r, res.rho_mm, z, extrapolated)


# --------------------------------------------------------------------------- viewpoint
@dataclass(frozen=True)
class ViewpointResult:
    """Back-projection of each equal-image-radius group to the axis (thesis 5.1.2).

    Attributes
    ----------
    rho_mm : ndarray
        Image radii (mm) at which the groups were taken.
    viewpoint_z_mm : ndarray
        Where the straight line fitted through each group meets the axis.
    spread_um : ndarray
        Distance of each group's viewpoint from the effective viewpoint, um.
    line_residual_um : ndarray
        RMS distance of the group's points from its straight line (a curved line of sight).
    curved : ndarray of bool
        Groups beyond ``tolerance_mm`` either way: not single-viewpoint; use the table at the
        object cylinder itself (a curved line of sight) there, which the maps always do.
    effective_viewpoint_z_mm : float
        Median viewpoint over the operational image radii (all radii if none is operational).
    svp_spread_um : float
        Peak-to-peak of the viewpoints over the operational radii (thesis: within 20 um).
    operational_mm : (float, float)
        The radii used for the effective viewpoint.
    """

    rho_mm: FloatArray
    viewpoint_z_mm: FloatArray
    spread_um: FloatArray
    line_residual_um: FloatArray
    curved: BoolArray
    effective_viewpoint_z_mm: float
    svp_spread_um: float
    operational_mm: tuple[float, float]
    tolerance_mm: float

    def rows(self) -> list[dict[str, float | bool]]:
        """One dict per image radius (for tables and JSON)."""
        return [
            {
                "image_radius_mm": float(r),
                "viewpoint_z_mm": float(v),
                "spread_um": float(s),
                "line_residual_um": float(q),
                "curved": bool(c),
            }
            for r, v, s, q, c in zip(
                self.rho_mm, self.viewpoint_z_mm, self.spread_um, self.line_residual_um,
                self.curved, strict=True,
            )
        ]


def viewpoint(
    table: RayTraceTable,
    *,
    step_mm: float = 0.02,
    operational_mm: tuple[float, float] = OPERATIONAL_IMAGE_RADIUS_MM,
    tolerance_mm: float = SVP_TOLERANCE_MM,
) -> ViewpointResult:
    """Effective viewpoint and its spread over image radius, from the table's depths.

    For each image radius (every ``step_mm``) the object points imaged there at the table's
    depths are fitted with a straight line ``z = a + b R``; ``a`` is that group's viewpoint on
    the axis. The effective viewpoint is their median over the operational radii.

    Raises
    ------
    RayTraceError
        With fewer than two depths (one point per group fixes no line).
    """
    res = table.resampled
    if res.object_radius_mm.size < 2:
        raise RayTraceError(
            f"{table.source}: one depth only; the viewpoint needs at least two depths"
        )
    stride = max(1, int(round(step_mm / float(res.rho_mm[1] - res.rho_mm[0]))))
    idx = np.arange(0, res.rho_mm.size, stride)
    rho = res.rho_mm[idx]
    z = res.z_mm[:, idx]  # (depths, radii)
    radii = res.object_radius_mm
    design = np.stack([np.ones_like(radii), radii], axis=1)
    coeffs, *_ = np.linalg.lstsq(design, z, rcond=None)
    fitted = design @ coeffs
    # Distance from the line measured along z, converted to the perpendicular distance.
    slope = coeffs[1]
    residual = np.sqrt(np.mean((z - fitted) ** 2, axis=0)) / np.sqrt(1.0 + slope**2)
    vp = coeffs[0]
    band = (rho >= operational_mm[0]) & (rho <= operational_mm[1])
    used = band if band.any() else np.ones_like(band)
    eff = float(np.median(vp[used]))
    spread = np.abs(vp - eff) * 1e3
    return ViewpointResult(
        rho_mm=rho,
        viewpoint_z_mm=vp,
        spread_um=spread,
        line_residual_um=residual * 1e3,
        curved=(spread > tolerance_mm * 1e3) | (residual > tolerance_mm),
        effective_viewpoint_z_mm=eff,
        svp_spread_um=float(np.ptp(vp[used]) * 1e3),
        operational_mm=(float(rho[used].min()), float(rho[used].max())),
        tolerance_mm=tolerance_mm,
    )


# --------------------------------------------------------------------------- maps
@dataclass
class ViewMaps:
    """Output pixel -> raw-image position, built once and applied to many frames.

    Attributes
    ----------
    map_col, map_row : ndarray float32 (height, width)
        Raw-image column and row of each output pixel (invalid pixels point outside).
    valid : ndarray bool
        Output pixels whose raw position is inside the frame and the table.
    meta : dict
        The mapping for the output file's metadata (kind, table hash, centre, radius, scale).
    """

    map_col: npt.NDArray[np.float32]
    map_row: npt.NDArray[np.float32]
    valid: BoolArray
    meta: dict[str, Any]

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.map_col.shape[0]), int(self.map_col.shape[1]))

    @property
    def valid_fraction(self) -> float:
        return float(self.valid.mean()) if self.valid.size else 0.0


def _finish(
    col: FloatArray, row: FloatArray, frame_shape: tuple[int, int], meta: dict[str, Any]
) -> ViewMaps:
    h, w = int(frame_shape[0]), int(frame_shape[1])
    # Bilinear reads the 2x2 pixels around a position: keep it wholly inside the frame.
    valid = np.isfinite(col) & np.isfinite(row)
    valid &= (col >= 0) & (col <= w - 1) & (row >= 0) & (row <= h - 1)
    map_col = np.where(valid, col, _OUTSIDE).astype(np.float32)
    map_row = np.where(valid, row, _OUTSIDE).astype(np.float32)
    meta = {**meta, "frame_shape": [h, w], "valid_fraction": float(valid.mean())}
    return ViewMaps(map_col, map_row, valid, meta)


def _check_common(frame_shape: tuple[int, ...], centre_rc: tuple[float, float],
                  pixel_pitch_um: float) -> None:
    if len(frame_shape) < 2 or frame_shape[0] < 1 or frame_shape[1] < 1:
        raise ValueError(f"frame shape must be (rows, cols), got {frame_shape!r}")
    if not all(math.isfinite(v) for v in centre_rc):
        raise ValueError(f"centre must be finite, got {centre_rc!r}")
    if not pixel_pitch_um > 0:
        raise ValueError(f"pixel pitch must be > 0 um, got {pixel_pitch_um}")


def unwrap_maps(
    table: RayTraceTable,
    frame_shape: tuple[int, ...],
    centre_rc: tuple[float, float],
    *,
    object_radius_mm: float,
    azimuth_deg: tuple[float, float] = (0.0, 360.0),
    px_per_mm: float = 20.0,
    pixel_pitch_um: float = 5.2,
    allow_extrapolation: bool = False,
) -> ViewMaps:
    """Maps of the estimated orthographic (unwrapped) view at an assumed object radius.

    Parameters
    ----------
    table : RayTraceTable
        The radial view's ray-trace table.
    frame_shape : (rows, cols)
        Raw frame size.
    centre_rc : (float, float)
        Optical centre in the raw frame (row, col).
    object_radius_mm : float
        Assumed distance of the object from the axis (thesis: 19.88 mm).
    azimuth_deg : (start, end)
        Azimuth range shown, degrees (end > start, at most 360 apart).
    px_per_mm : float
        Output scale, pixels per object mm, both directions.
    pixel_pitch_um : float
        Raw sensor pixel pitch.
    allow_extrapolation : bool
        Accept a radius outside the table (flagged in ``meta["extrapolated"]``).

    Raises
    ------
    ValueError
        Bad scale, azimuth range or frame shape; :class:`RayTraceError` for the radius.
    """
    _check_common(frame_shape, centre_rc, pixel_pitch_um)
    a0, a1 = (float(a) for a in azimuth_deg)
    if not (math.isfinite(a0) and math.isfinite(a1) and 0 < a1 - a0 <= 360.0 + 1e-9):
        raise ValueError(f"azimuth range must be START:END with 0 < END-START <= 360, got "
                         f"{a0:g}:{a1:g}")
    if not (math.isfinite(px_per_mm) and 0 < px_per_mm <= 1000):
        raise ValueError(f"px per mm must be in (0, 1000], got {px_per_mm}")
    cyl = cylinder_map(table, object_radius_mm, allow_extrapolation=allow_extrapolation)
    r = cyl.object_radius_mm
    z_lo, z_hi = cyl.z_range_mm
    n_rows = int(math.floor((z_hi - z_lo) * px_per_mm)) + 1
    n_cols = max(1, int(round(r * math.radians(a1 - a0) * px_per_mm)))
    if n_rows * n_cols > 40_000_000:
        raise ValueError(f"output of {n_rows} x {n_cols} px is too large; lower --px-per-mm")
    z = z_hi - np.arange(n_rows) / px_per_mm
    rho_px = cyl.image_radius_mm(z) * 1e3 / pixel_pitch_um
    phi = math.radians(a0) + np.arange(n_cols) / (r * px_per_mm)
    row = centre_rc[0] + rho_px[:, None] * np.sin(phi)[None, :]
    col = centre_rc[1] + rho_px[:, None] * np.cos(phi)[None, :]
    meta = {
        "view": "unwrap",
        "table_sha256": table.sha256,
        "table_source": table.source,
        "centre_rc": [float(centre_rc[0]), float(centre_rc[1])],
        "object_radius_mm": r,
        "extrapolated": cyl.extrapolated,
        "px_per_mm": float(px_per_mm),
        "azimuth_deg": [a0, a1],
        "z_top_mm": float(z_hi),
        "z_step_mm_per_row": -1.0 / px_per_mm,
        "arc_start_mm": r * math.radians(a0),
        "pixel_pitch_um": float(pixel_pitch_um),
    }
    return _finish(col, row, (int(frame_shape[0]), int(frame_shape[1])), meta)


def perspective_maps(
    table: RayTraceTable,
    frame_shape: tuple[int, ...],
    centre_rc: tuple[float, float],
    *,
    object_radius_mm: float,
    yaw_deg: float,
    pitch_deg: float,
    fov_deg: float,
    size_wh: tuple[int, int],
    viewpoint_z_mm: float | None = None,
    pixel_pitch_um: float = 5.2,
    allow_extrapolation: bool = False,
) -> ViewMaps:
    """Maps of a perspective view through the effective viewpoint (thesis 5.1.3-5.1.5).

    A pinhole at ``(0, 0, viewpoint_z_mm)`` on the axis looks along azimuth ``yaw_deg`` with
    elevation ``pitch_deg`` towards ``+z``; ``fov_deg`` is the horizontal field of view and
    ``size_wh`` the output size. Each pixel's ray meets the object cylinder (radius
    ``object_radius_mm``) at one point, which the table maps to the raw image. Rays along the
    axis never meet the cylinder and are invalid.

    Raises
    ------
    ValueError
        Bad size or field of view; :class:`RayTraceError` for the table or radius.
    """
    _check_common(frame_shape, centre_rc, pixel_pitch_um)
    w_out, h_out = (int(v) for v in size_wh)
    if not (1 <= w_out <= 8192 and 1 <= h_out <= 8192):
        raise ValueError(f"size must be WxH between 1 and 8192, got {size_wh!r}")
    if not (math.isfinite(fov_deg) and 0 < fov_deg < 179):
        raise ValueError(f"field of view must be in (0, 179) deg, got {fov_deg}")
    if not (math.isfinite(yaw_deg) and math.isfinite(pitch_deg) and abs(pitch_deg) <= 90):
        raise ValueError(f"yaw must be finite and |pitch| <= 90 deg, got {yaw_deg}, {pitch_deg}")
    cyl = cylinder_map(table, object_radius_mm, allow_extrapolation=allow_extrapolation)
    vp_z = viewpoint(table).effective_viewpoint_z_mm if viewpoint_z_mm is None else viewpoint_z_mm
    yaw, pitch = math.radians(yaw_deg), math.radians(pitch_deg)
    fwd = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                    math.sin(pitch)])
    right = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    up = np.cross(fwd, right)  # +z at zero pitch; columns follow increasing azimuth
    focal = (w_out / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    u = np.arange(w_out) - (w_out - 1) / 2.0
    v = np.arange(h_out) - (h_out - 1) / 2.0
    d = (focal * fwd[:, None, None] + u[None, None, :] * right[:, None, None]
         - v[None, :, None] * up[:, None, None])
    dxy = np.hypot(d[0], d[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(dxy > 1e-9 * focal, cyl.object_radius_mm / dxy, np.nan)
    z = vp_z + lam * d[2]
    phi = np.arctan2(d[1], d[0])
    rho_px = cyl.image_radius_mm(z) * 1e3 / pixel_pitch_um
    row = centre_rc[0] + rho_px * np.sin(phi)
    col = centre_rc[1] + rho_px * np.cos(phi)
    meta = {
        "view": "perspective",
        "table_sha256": table.sha256,
        "table_source": table.source,
        "centre_rc": [float(centre_rc[0]), float(centre_rc[1])],
        "object_radius_mm": cyl.object_radius_mm,
        "extrapolated": cyl.extrapolated,
        "viewpoint_z_mm": float(vp_z),
        "yaw_deg": float(yaw_deg),
        "pitch_deg": float(pitch_deg),
        "fov_deg": float(fov_deg),
        "size_wh": [w_out, h_out],
        "focal_px": focal,
        "pixel_pitch_um": float(pixel_pitch_um),
    }
    return _finish(col, row, (int(frame_shape[0]), int(frame_shape[1])), meta)


def apply_maps(
    frame: npt.NDArray[Any], maps: ViewMaps, interpolation: str = "linear"
) -> npt.NDArray[Any]:
    """Resample a raw frame through prebuilt maps with ``cv2.remap``.

    Same dtype out as in; invalid output pixels are 0 (see ``maps.valid``).

    Raises
    ------
    ValueError
        Frame shape other than the maps were built for, or an unknown interpolation.
    """
    import cv2

    flags = {"nearest": cv2.INTER_NEAREST, "linear": cv2.INTER_LINEAR,
             "cubic": cv2.INTER_CUBIC, "lanczos": cv2.INTER_LANCZOS4}
    if interpolation not in flags:
        raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
    arr = np.asarray(frame)
    expected = tuple(maps.meta["frame_shape"])
    if arr.ndim != 2 or arr.shape != expected:
        raise ValueError(f"frame shape {arr.shape} differs from the maps' {expected}")
    if arr.dtype not in (np.uint8, np.uint16, np.float32):
        arr = arr.astype(np.float32)
    # Float maps: measured faster here than OpenCV's fixed-point CV_16SC2 form (and exact).
    out = cv2.remap(arr, maps.map_col, maps.map_row, flags[interpolation],
                    borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    if interpolation in ("cubic", "lanczos"):  # wider kernels reach past the valid edge
        out[~maps.valid] = 0
    return np.asarray(out)


def fov_centre_of_frame(frame: npt.NDArray[Any], threshold: float | None = None) -> tuple[
    tuple[float, float], str
]:
    """Optical centre from a radial frame's lit field of view (section 4.3.3).

    The lit annulus, holes filled, is the field-of-view disc; its centroid, or a circle fit
    when the frame clips it (:func:`benchlab.analysis.geometry.fov_centre`).
    ``threshold`` defaults to 5 % of the frame's 99.9th percentile.

    Raises
    ------
    ValueError
        When nothing is lit or the circle cannot be fitted.
    """
    from scipy import ndimage

    from benchlab.analysis.geometry import fov_centre

    arr = np.asarray(frame, dtype=np.float64)
    if arr.ndim != 2:
        raise ValueError(f"frame must be 2-D, got shape {arr.shape}")
    level = 0.05 * float(np.percentile(arr, 99.9)) if threshold is None else float(threshold)
    mask = ndimage.binary_fill_holes(ndimage.binary_opening(arr > level, iterations=2))
    circle = fov_centre(mask)
    return circle.centre_rc, circle.method
