"""Radial view: a rolled single-frequency bar pattern imaged into the annulus, through the
ray-trace table.

The pattern lies on an object cylinder around the axis (default 19.88 mm from it, depth 6 mm:
the thesis's radial set-up, section 5.2.2). Every annulus pixel is an object point: its image
radius gives the axial position through the same ray-trace table that view synthesis uses
(:func:`benchlab.analysis.views.synthesis.cylinder_map`, default the shipped modelled table) and its
image azimuth is the object azimuth. So what the simulated camera sees and what ``unwrap``
undoes agree by construction.

Orientation (fig. 4.9; :mod:`benchlab.analysis.chart.layout`):

- **sagittal** - the paper is rolled so its bars run along the endoscope axis: *spokes*, the
  intensity varies around the circle. The object period is along the arc of the cylinder, so
  on the sensor it is ``period x image radius / object radius`` (rotational symmetry), exact
  along the arc through the reference point (the radial ROI's centroid). The roll's seam sits
  diametrically opposite the reference point.
- **tangential** - rolled the other way: bars around the cylinder, imaged as *rings*; the
  intensity varies along the radius with the table's axial magnification, which is Eq. 4.1's
  17.5 at the reference point (:data:`~benchlab.analysis.views.raytrace.EQ41_RADIAL_MAGNIFICATION`).

The thesis applies Eq. 4.1's 17.5 to both roll directions; around the circle the geometry
gives ``object radius / image radius`` (19.88 / 2.48 = 8.0 at the radial ROI) instead, so
:attr:`RadialScene.image_lp_per_mm` of a sagittal pattern is that geometric value, which is
what the camera sees. The pattern is back-lit paper: bright spaces, dark bars, 50 % duty. Each
pixel is the pattern blurred across its bars by the radial
:class:`~benchlab.scenes.optics.BlurProfile` at its own radius plus the pixel aperture
(Gaussian of variance 1/12 px^2), converted to object mm through the local scale, in closed
form, so the blur varies continuously with image height and needs no resampling.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.special import ndtr

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars.result import eq29_modulation
from benchlab.analysis.chart.layout import RADIAL_ROI_BOX, Orientation, RadialLayout, box_centroid
from benchlab.analysis.views.raytrace import (
    REFERENCE_OBJECT_RADIUS_MM,
    RayTraceTable,
    read_raytrace_table,
)
from benchlab.analysis.views.synthesis import CylinderMap, cylinder_map
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes.optics import (
    PIXEL_APERTURE_VAR_PX2,
    RADIAL_BLUR,
    BlurProfile,
    blurred_square_wave,
)
from benchlab.scenes.printed import TwoLevelPrint

#: The object frequencies of the thesis's printed radial targets (Table 4.12), lp/mm.
RADIAL_TARGETS_LP_PER_MM = (0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0)


@functools.cache
def default_table() -> RayTraceTable:
    """The shipped modelled ray-trace table (read once)."""
    return read_raytrace_table(None)


@dataclass(frozen=True)
class CylinderPixels:
    """Annulus pixels as points on an object cylinder (read-only arrays, one per pixel).

    ``index`` are flat pixel indices; ``rho_px`` image radius; ``dtheta`` azimuth from the
    reference direction in [-pi, pi); ``z_mm`` axial position; ``arc_mm`` arc length from the
    reference azimuth on the cylinder; ``axial_mm_per_px`` and ``arc_mm_per_px`` the local
    object mm per image pixel along the radius and around the circle; ``envelope`` the soft
    edges of the annulus.
    """

    index: npt.NDArray[np.intp]
    rho_px: FloatArray
    dtheta: FloatArray
    z_mm: FloatArray
    arc_mm: FloatArray
    axial_mm_per_px: FloatArray
    arc_mm_per_px: FloatArray
    envelope: FloatArray


@functools.lru_cache(maxsize=8)
def cylinder_pixels(
    circles: RadialLayout,
    edge_sigma_px: float,
    height: int,
    width: int,
    table: RayTraceTable,
    object_radius_mm: float,
    theta_ref: float,
) -> CylinderPixels:
    """Where each annulus pixel looks on the object cylinder, through the ray-trace table."""
    index, r, theta, envelope = _annulus(circles, edge_sigma_px, height, width)
    cyl = cylinder_map(table, object_radius_mm)
    pitch_mm = circles.pixel_pitch_um / 1000.0
    rho_mm = r * pitch_mm
    slope = np.gradient(cyl.z_mm, cyl.rho_mm)
    dtheta = np.mod(theta - theta_ref + np.pi, 2.0 * np.pi) - np.pi
    parts = CylinderPixels(
        index=index,
        rho_px=r,
        dtheta=dtheta,
        z_mm=cyl.axial_mm(rho_mm),
        arc_mm=object_radius_mm * dtheta,
        axial_mm_per_px=np.abs(np.interp(rho_mm, cyl.rho_mm, slope)) * pitch_mm,
        arc_mm_per_px=object_radius_mm / np.maximum(r, 1.0),
        envelope=envelope,
    )
    for f in dataclasses.fields(parts):
        getattr(parts, f.name).setflags(write=False)
    return parts


@dataclass(frozen=True)
class RadialScene(TwoLevelPrint):
    """A rolled bar pattern seen by the radial view.

    Parameters
    ----------
    object_lp_per_mm
        Printed frequency of the pattern.
    orientation
        ``"sagittal"`` (spokes) or ``"tangential"`` (rings).
    circles
        Centre and annulus radii.
    reference_rc
        Point where the period is exact and the truth is quoted (default: radial ROI centroid).
    object_radius_mm
        Radius of the cylinder the pattern is rolled on, mm from the axis.
    table
        Ray-trace table the image is formed through (None: the shipped modelled table).
    blur
        Radial-view blur over image height (sagittal = around the circle, tangential = radial).
    dark_dn8, bright_dn8
        Noise-free 8-bit levels of a wide bar and of the paper at the reference acquisition.
    reference_exposure_ms, reference_gain
        The acquisition those levels refer to.
    edge_sigma_px
        Softness of the annulus edges.
    phase_cycles
        Shift of the pattern; 0 centres a dark bar on the reference point.
    """

    object_lp_per_mm: float
    orientation: Orientation
    circles: RadialLayout = field(default_factory=RadialLayout)
    reference_rc: tuple[float, float] = box_centroid(RADIAL_ROI_BOX)
    object_radius_mm: float = REFERENCE_OBJECT_RADIUS_MM
    table: RayTraceTable | None = None
    blur: BlurProfile = RADIAL_BLUR
    dark_dn8: float = 20.0
    bright_dn8: float = 190.0
    reference_exposure_ms: float = 300.0
    reference_gain: float = 1.0
    edge_sigma_px: float = 1.5
    phase_cycles: float = 0.0

    def __post_init__(self) -> None:
        if self.orientation not in ("sagittal", "tangential"):
            raise ValueError(
                f"orientation must be 'sagittal' or 'tangential', got {self.orientation!r}"
            )
        if not self.object_lp_per_mm > 0:
            raise ValueError(f"object frequency must be > 0 lp/mm, got {self.object_lp_per_mm}")
        cylinder_map(self.ray_table, self.object_radius_mm)  # refuses a cylinder off the table

    @property
    def ray_table(self) -> RayTraceTable:
        """The ray-trace table in use."""
        return self.table if self.table is not None else default_table()

    @property
    def pixel_pitch_um(self) -> float:
        return self.circles.pixel_pitch_um

    def _cylinder(self) -> CylinderMap:
        return cylinder_map(self.ray_table, self.object_radius_mm)

    @property
    def reference_radius_px(self) -> float:
        return self.circles.radius_px(self.reference_rc)

    @property
    def reference_z_mm(self) -> float:
        """Axial position of the object point imaged at the reference point."""
        rho_mm = self.reference_radius_px * self.pixel_pitch_um / 1000.0
        return float(self._cylinder().axial_mm(rho_mm))

    def object_mm_per_px(self) -> float:
        """Object mm per image pixel across the bars at the reference point."""
        if self.orientation == "sagittal":
            return self.object_radius_mm / self.reference_radius_px
        rho_mm = self.reference_radius_px * self.pixel_pitch_um / 1000.0
        return self._cylinder().axial_magnification(rho_mm) * self.pixel_pitch_um / 1000.0

    @property
    def magnification(self) -> float:
        """Object-to-image frequency factor across the bars at the reference point (the
        table's axial magnification for rings, object / image radius for spokes)."""
        return self.object_mm_per_px() * 1000.0 / self.pixel_pitch_um

    @property
    def image_lp_per_mm(self) -> float:
        """Image-plane frequency at the reference point."""
        return self.object_lp_per_mm * self.magnification

    @property
    def px_per_period(self) -> float:
        """Pattern period at the reference point, px."""
        return 1.0 / (self.object_lp_per_mm * self.object_mm_per_px())


    def across_bar_sigma_px(self, radius_px: float | FloatArray) -> FloatArray:
        """Optical blur across the bars at a radius, px (without the pixel aperture)."""
        h_mm = np.asarray(radius_px, dtype=np.float64) * self.pixel_pitch_um / 1000.0
        if self.orientation == "sagittal":
            return self.blur.sagittal_px(h_mm)
        return self.blur.tangential_px(h_mm)

    def _pattern_object(self, u_mm: FloatArray, sigma_mm: FloatArray) -> FloatArray:
        """Bright fraction of the blurred pattern at ``u_mm`` across the bars from the
        reference point (object mm)."""
        period = 1.0 / self.object_lp_per_mm
        # Square wave is bright on [0, p/2): shift so a dark bar is centred at u = 0.
        return blurred_square_wave(u_mm + (0.75 + self.phase_cycles) * period, period, sigma_mm)

    def _theta_ref(self) -> float:
        cr, cc = self.circles.centre_rc
        return math.atan2(self.reference_rc[0] - cr, self.reference_rc[1] - cc)

    def pixels(self, height: int, width: int) -> CylinderPixels:
        """The annulus pixels as points on this scene's cylinder (cached)."""
        return cylinder_pixels(self.circles, self.edge_sigma_px, height, width, self.ray_table,
                               self.object_radius_mm, self._theta_ref())

    def _bright_fraction(self, pix: CylinderPixels) -> FloatArray:
        sigma_px = np.sqrt(self.across_bar_sigma_px(pix.rho_px) ** 2 + PIXEL_APERTURE_VAR_PX2)
        if self.orientation == "sagittal":
            return self._pattern_object(pix.arc_mm, sigma_px * pix.arc_mm_per_px)
        return self._pattern_object(pix.z_mm - self.reference_z_mm,
                                    sigma_px * pix.axial_mm_per_px)

    def truth_levels(self, point_rc: tuple[float, float] | None = None) -> tuple[float, float]:
        """Noise-free ``(dark, bright)`` rates (e-/ms) at the centre of a bar and of a space
        at ``point_rc``'s radius (default the reference point), with the blur there."""
        radius = self.reference_radius_px if point_rc is None else self.circles.radius_px(point_rc)
        sigma_px = math.sqrt(float(self.across_bar_sigma_px(radius)) ** 2 + PIXEL_APERTURE_VAR_PX2)
        sigma_mm = np.array([sigma_px * self.object_mm_per_px()])
        half = 0.5 / self.object_lp_per_mm
        bar = float(self._pattern_object(np.array([0.0]), sigma_mm)[0])
        space = float(self._pattern_object(np.array([half]), sigma_mm)[0])
        depth = self.bright_rate - self.dark_rate
        return self.dark_rate + depth * bar, self.dark_rate + depth * space

    def truth_levels_dn8(self, point_rc: tuple[float, float] | None = None) -> tuple[float, float]:
        """:meth:`truth_levels` as 8-bit codes at the reference exposure and gain."""
        scale = 1.0 / float(rate_for_dn8(1.0, self.reference_exposure_ms, self.reference_gain))
        dark, bright = self.truth_levels(point_rc)
        return dark * scale, bright * scale

    def truth_modulation(self, point_rc: tuple[float, float] | None = None) -> float:
        """Eq. 2.9 modulation of the noise-free imaged pattern at ``point_rc`` (default the
        reference point, i.e. the radial ROI centroid)."""
        dark, bright = self.truth_levels(point_rc)
        return eq29_modulation(dark, bright)

    def __call__(self, state: AcquisitionState) -> FloatArray:
        """Electron-rate image (e-/ms) for the camera simulator (a fresh copy each call)."""
        return _render(self, state.height, state.width).copy()

    def render(self, height: int, width: int) -> FloatArray:
        """The cached, read-only electron-rate image."""
        return _render(self, height, width)


def radial_truth_table(
    template: RadialScene | None = None,
    frequencies_lp_per_mm: tuple[float, ...] = RADIAL_TARGETS_LP_PER_MM,
) -> list[dict[str, object]]:
    """Noise-free truth at the reference point for every pattern (Table 4.12 layout)."""
    base = template if template is not None else RadialScene(1.0, "sagittal")
    rows: list[dict[str, object]] = []
    for orientation in ("sagittal", "tangential"):
        for lp in frequencies_lp_per_mm:
            scene = dataclasses.replace(base, object_lp_per_mm=lp, orientation=orientation)
            dark, bright = scene.truth_levels_dn8()
            rows.append(
                {
                    "orientation": orientation,
                    "object_lp_per_mm": lp,
                    "image_lp_per_mm": scene.image_lp_per_mm,
                    "px_per_period": scene.px_per_period,
                    "dark_dn8": dark,
                    "bright_dn8": bright,
                    "modulation": eq29_modulation(dark, bright),
                }
            )
    return rows


@functools.lru_cache(maxsize=4)
def _annulus(
    circles: RadialLayout, edge_sigma_px: float, height: int, width: int
) -> tuple[npt.NDArray[np.intp], FloatArray, FloatArray, FloatArray]:
    """Flat indices, radius, angle and edge envelope of the pixels the annulus can light."""
    cr, cc = circles.centre_rc
    rows = np.arange(height, dtype=np.float64)[:, None] - cr
    cols = np.arange(width, dtype=np.float64)[None, :] - cc
    radius = np.hypot(rows, cols)
    reach = 6.0 * edge_sigma_px
    inside = (radius > circles.annulus_inner_radius_px - reach) & (
        radius < circles.annulus_outer_radius_px + reach
    )
    index = np.flatnonzero(inside)
    r = radius.ravel()[index]
    theta = np.arctan2(np.broadcast_to(rows, radius.shape), np.broadcast_to(cols, radius.shape))
    envelope = ndtr((r - circles.annulus_inner_radius_px) / edge_sigma_px) * ndtr(
        (circles.annulus_outer_radius_px - r) / edge_sigma_px
    )
    parts = (index, r, theta.ravel()[index], envelope)
    for part in parts:
        part.setflags(write=False)
    return parts


@functools.lru_cache(maxsize=16)
def _render(scene: RadialScene, height: int, width: int) -> FloatArray:
    pix = scene.pixels(height, width)
    bright_fraction = scene._bright_fraction(pix)
    depth = scene.bright_rate - scene.dark_rate
    flat = np.zeros(height * width)
    flat[pix.index] = pix.envelope * (scene.dark_rate + depth * bright_fraction)
    img: FloatArray = flat.reshape(height, width)
    img.setflags(write=False)
    return img
