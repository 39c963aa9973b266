"""Radial view: the ring tube of ``benchlab run fov``, imaged through the ray-trace table.

The target (docs/procedures/fov.md): a back-lit translucent tube of inner radius
``radius_mm`` around the endoscope axis, with dark rings of axial width ``ring_mm`` every
``pitch_mm`` along it, ``2 half_count + 1`` of them; the ring of index 0 (the fiducial) is
``fiducial_scale`` times wider. It rides on the stage carriage: ring ``k`` sits at axial
position ``z0 + k pitch_mm`` in the thesis's coordinates (the effective viewpoint at
``z = -6.4 mm``, the radial field at larger ``z``), with ``z0`` the bench state's
``object_offset_mm`` + the stage position.

Every annulus pixel is a point on the wall: its image radius gives the axial position through
the same ray-trace table as the radial bar scenes and view synthesis
(:func:`benchlab.scenes.radial.cylinder_pixels`, default the shipped modelled table), so the
simulator knows the mapping from wall position (and field angle from the viewpoint) to image
height exactly: :meth:`RingTubeScene.image_radius_mm`. A ring's edge is blurred along the
radius by the radial view's tangential blur plus the pixel aperture, converted to wall mm
with the local axial scale, in closed form. The tube's far end is capped: the forward disc is
dark.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.chart.layout import RadialLayout
from benchlab.analysis.views.raytrace import REFERENCE_OBJECT_RADIUS_MM, RayTraceTable
from benchlab.analysis.views.synthesis import CylinderMap, cylinder_map
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes.optics import PIXEL_APERTURE_VAR_PX2, RADIAL_BLUR, BlurProfile
from benchlab.scenes.radial import cylinder_pixels, default_table


@dataclass(frozen=True)
class RingTube:
    """The ring tube's drawing (module docstring)."""

    radius_mm: float = REFERENCE_OBJECT_RADIUS_MM
    pitch_mm: float = 4.0
    ring_mm: float = 0.3
    fiducial_scale: float = 3.0
    half_count: int = 6

    def __post_init__(self) -> None:
        if not 0 < self.ring_mm * self.fiducial_scale < self.pitch_mm - self.ring_mm:
            raise ValueError(f"rings of {self.ring_mm:g} mm (fiducial x{self.fiducial_scale:g})"
                             f" touch on a {self.pitch_mm:g} mm pitch")

    def ring_z_mm(self, z0_mm: float) -> tuple[FloatArray, FloatArray]:
        """Ring indices and axial centres with ring 0 at ``z0_mm``."""
        k = np.arange(-self.half_count, self.half_count + 1, dtype=np.float64)
        return k, z0_mm + k * self.pitch_mm


@dataclass(frozen=True)
class RingTubeScene:
    """The ring tube seen by the radial view (module docstring)."""

    tube: RingTube = field(default_factory=RingTube)
    table: RayTraceTable | None = None
    circles: RadialLayout = field(default_factory=RadialLayout)
    blur: BlurProfile = RADIAL_BLUR
    dark_dn8: float = 20.0
    bright_dn8: float = 190.0
    reference_exposure_ms: float = 300.0
    reference_gain: float = 1.0
    edge_sigma_px: float = 1.5
    default_offset_mm: float = 12.0

    def __post_init__(self) -> None:
        cylinder_map(self.ray_table, self.tube.radius_mm)  # refuses a tube off the table

    @property
    def ray_table(self) -> RayTraceTable:
        return self.table if self.table is not None else default_table()

    def cylinder(self) -> CylinderMap:
        return cylinder_map(self.ray_table, self.tube.radius_mm)

    def image_radius_mm(self, z_mm: FloatArray) -> FloatArray:
        """The exact image radius of wall positions (NaN off the table)."""
        return self.cylinder().image_radius_mm(z_mm)

    def field_ends_mm(self) -> tuple[float, float]:
        """Axial positions imaged on the annulus's outer and inner edges: the radial field's
        start and end on this wall."""
        pitch = self.circles.pixel_pitch_um / 1000.0
        cyl = self.cylinder()
        return (float(cyl.axial_mm(self.circles.annulus_outer_radius_px * pitch)),
                float(cyl.axial_mm(self.circles.annulus_inner_radius_px * pitch)))

    def render(self, z0_mm: float, height: int, width: int) -> FloatArray:
        """Cached, read-only electron-rate image with ring 0 at ``z0_mm``."""
        return _render(self, float(z0_mm), height, width)

    def __call__(self, state: AcquisitionState) -> FloatArray:
        offset = state.bench.get("object_offset_mm")
        z0 = (self.default_offset_mm if offset is None
              else float(offset) + float(state.bench.get("stage_position_mm") or 0.0))
        return _render(self, z0, state.height, state.width).copy()


@functools.lru_cache(maxsize=4)
def _render(scene: RingTubeScene, z0_mm: float, height: int, width: int) -> FloatArray:
    pix = cylinder_pixels(scene.circles, scene.edge_sigma_px, height, width, scene.ray_table,
                          scene.tube.radius_mm, 0.0)
    bright = float(rate_for_dn8(scene.bright_dn8, scene.reference_exposure_ms,
                                scene.reference_gain))
    depth = 1.0 - scene.dark_dn8 / scene.bright_dn8
    h_mm = pix.rho_px * scene.circles.pixel_pitch_um / 1000.0
    sigma_mm = np.sqrt(scene.blur.tangential_px(h_mm) ** 2 + PIXEL_APERTURE_VAR_PX2) \
        * pix.axial_mm_per_px
    tube = scene.tube
    # the two rings nearest each pixel's wall position are the only ones its blur reaches
    nearest = np.rint((pix.z_mm - z0_mm) / tube.pitch_mm)
    dark = np.zeros_like(pix.z_mm)
    for shift in (-1.0, 0.0, 1.0):
        k = nearest + shift
        valid = np.abs(k) <= tube.half_count
        half = np.where(k == 0, tube.ring_mm * tube.fiducial_scale, tube.ring_mm) / 2.0
        u = pix.z_mm - (z0_mm + k * tube.pitch_mm)
        dark += np.where(valid, ndtr((u + half) / sigma_mm) - ndtr((u - half) / sigma_mm), 0.0)
    flat = np.zeros(height * width)
    flat[pix.index] = bright * pix.envelope * (1.0 - depth * np.clip(dark, 0.0, 1.0))
    img: FloatArray = flat.reshape(height, width)
    img.setflags(write=False)
    return img
