"""Through focus: the forward view's blur and magnification as the chart moves along the axis.

Only what a depth-of-field measurement needs, in closed form (no ray tracing):

* a thin lens of focal length ``f`` and pupil diameter ``D`` whose sensor sits at the image
  distance ``v = 1 / (1/f - u0)`` of the on-axis best-focus object vergence ``u0 = 1/z0``
  (vergence ``u = 1/z``, 1/mm). The back focus never moves, so ``v`` is fixed for the run;
* the best-focus vergence of a field point depends on its image position and orientation
  (sagittal S, tangential T): ``u_b = u0 + (k +- a/2) h^2 +- a0/2 + t x`` with field curvature
  ``k``, astigmatism ``a`` growing with the image height ``h`` squared, an on-axis astigmatism
  ``a0`` (decentre) and an image-plane tilt ``t`` along the image x (columns); + for S, - for T;
* an object at ``z`` focuses off the sensor and a point spreads over the geometric blur disc of
  diameter ``c = D v |1/z - u_b|`` (exact for a thin lens with the sensor at ``v``); the render
  represents that disc by the Gaussian of the same variance, ``sigma = c / 4`` (the renders are
  Gaussian closed forms), added in quadrature to the lens's own blur table at that height;
* the chart's image scales as ``v / z`` (chief rays through the pupil centre): the scenes get a
  pose of scale ``z_ref / z`` about the optical centre, ``z_ref = M v`` being the distance at
  which the layout's Eq. 4.1 magnification ``M`` (16.3, object size / image size) holds.

The truth of a simulated run is these formulas evaluated for the scenes actually rendered:
:meth:`DefocusedEdgeScene.truth_mtf` is the analytic MTF of what the camera saw.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.chart.layout import IMAGE_CENTRE_RC, BarGroup
from benchlab.analysis.chart.pose import ChartPose, PosedBarSet
from benchlab.analysis.sfr.target import SlantedSquare, edge_spec, scaled_squares
from benchlab.drivers.sensor import PIXEL_PITCH_UM
from benchlab.scenes.edge import EdgeScene
from benchlab.scenes.optics import BlurProfile
from benchlab.scenes.radial import RadialScene
from benchlab.scenes.usaf import UsafScene
from benchlab.synthetic.edges import edge_truth_mtf

#: Sign of the astigmatic terms per orientation.
_SIGN = {"sagittal": 1.0, "tangential": -1.0}


@dataclass(frozen=True)
class ThroughFocusLens:
    """The simulated prototype's focus behaviour (see the module docstring).

    Parameters
    ----------
    focal_length_mm
        Effective focal length (Table 4.4 forward view: 2.8 mm).
    pupil_diameter_mm
        Entrance pupil diameter (Table 4.4 forward view: radius 0.67 mm).
    best_focus_mm
        On-axis best-focus object distance ``z0`` (mean of S and T), mm.
    reference_magnification
        Eq. 4.1 magnification (object size / image size) of the chart layout (16.3).
    field_curvature_per_mm2
        Change of best-focus vergence (1/mm) per squared image height (mm^2).
    astigmatism_per_mm2
        S minus T best-focus vergence (1/mm) per squared image height (mm^2).
    axial_astigmatism_per_mm
        S minus T best-focus vergence on axis (1/mm).
    tilt_per_mm2
        Best-focus vergence gradient (1/mm per mm) along the image x (columns) from the centre.
    lens_blur_scale
        Factor on the lens's own blur table (the scene's ``blur``) at best focus: < 1 a
        sharper lens.
    """

    focal_length_mm: float = 2.8
    pupil_diameter_mm: float = 1.34
    best_focus_mm: float = 60.0
    reference_magnification: float = 16.3
    field_curvature_per_mm2: float = 0.0
    astigmatism_per_mm2: float = 0.0
    axial_astigmatism_per_mm: float = 0.0
    tilt_per_mm2: float = 0.0
    lens_blur_scale: float = 1.0

    def __post_init__(self) -> None:
        for name in ("focal_length_mm", "pupil_diameter_mm", "best_focus_mm",
                     "reference_magnification", "lens_blur_scale"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if self.best_focus_mm <= self.focal_length_mm:
            raise ValueError(f"best_focus_mm {self.best_focus_mm} must exceed the focal length "
                             f"{self.focal_length_mm} (a real image)")

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> ThroughFocusLens:
        """From a parameter table (unknown keys refused by the caller)."""
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: float(v) for k, v in data.items() if k in names})

    def to_dict(self) -> dict[str, float]:
        return {f.name: float(getattr(self, f.name)) for f in dataclasses.fields(self)}

    @property
    def sensor_distance_mm(self) -> float:
        """Image distance of the sensor (fixed: the back focus is never touched)."""
        return 1.0 / (1.0 / self.focal_length_mm - 1.0 / self.best_focus_mm)

    @property
    def reference_distance_mm(self) -> float:
        """Object distance where the image scale is the layout's (scale 1)."""
        return self.reference_magnification * self.sensor_distance_mm

    def scale_at(self, distance_mm: float) -> float:
        """Image scale relative to the layout's at object distance ``distance_mm``."""
        return self.reference_distance_mm / float(distance_mm)

    def best_vergence_per_mm(self, x_mm: float, y_mm: float, orientation: str) -> float:
        """Best-focus object vergence (1/mm) at image position (x right, y down) from the
        optical centre, mm."""
        s = _SIGN[orientation]
        h2 = x_mm * x_mm + y_mm * y_mm
        return (1.0 / self.best_focus_mm
                + (self.field_curvature_per_mm2 + s * self.astigmatism_per_mm2 / 2.0) * h2
                + s * self.axial_astigmatism_per_mm / 2.0 + self.tilt_per_mm2 * x_mm)

    def defocus_sigma_px(self, distance_mm: float, x_mm: float, y_mm: float,
                         orientation: str) -> float:
        """Gaussian width (px) of the geometric defocus blur at that image point."""
        du = abs(1.0 / float(distance_mm) - self.best_vergence_per_mm(x_mm, y_mm, orientation))
        diameter_mm = self.pupil_diameter_mm * self.sensor_distance_mm * du
        return diameter_mm / 4.0 * 1000.0 / PIXEL_PITCH_UM


def _image_xy_mm(point_rc: tuple[float, float]) -> tuple[float, float]:
    r, c = point_rc
    k = PIXEL_PITCH_UM / 1000.0
    return (c - IMAGE_CENTRE_RC[1]) * k, (r - IMAGE_CENTRE_RC[0]) * k


@dataclass(frozen=True)
class DefocusedUsafScene(UsafScene):
    """The USAF chart at object distance ``distance_mm`` through ``lens``."""

    lens: ThroughFocusLens = ThroughFocusLens()
    distance_mm: float = 60.0

    def sigmas_px(self, bars: BarGroup | PosedBarSet) -> tuple[float, float]:
        sig_r, sig_c = super().sigmas_px(bars)
        sig_r, sig_c = sig_r * self.lens.lens_blur_scale, sig_c * self.lens.lens_blur_scale
        x, y = _image_xy_mm(bars.centre_rc)
        d_t = self.lens.defocus_sigma_px(self.distance_mm, x, y, "tangential")
        d_s = self.lens.defocus_sigma_px(self.distance_mm, x, y, "sagittal")
        return math.hypot(sig_r, d_t), math.hypot(sig_c, d_s)


@dataclass(frozen=True)
class DefocusedEdgeScene(EdgeScene):
    """The slanted-edge target at object distance ``distance_mm`` through ``lens``."""

    lens: ThroughFocusLens = ThroughFocusLens()
    distance_mm: float = 60.0

    def side_sigma_px(self, square: SlantedSquare, theta_rad: float) -> float:
        base = super().side_sigma_px(square, theta_rad) * self.lens.lens_blur_scale
        half = square.side_px / 2.0
        mid = (square.centre_rc[0] + half * math.sin(theta_rad),
               square.centre_rc[1] + half * math.cos(theta_rad))
        x, y = _image_xy_mm(mid)
        d_s = self.lens.defocus_sigma_px(self.distance_mm, x, y, "sagittal")
        d_t = self.lens.defocus_sigma_px(self.distance_mm, x, y, "tangential")
        c, s = math.cos(theta_rad), math.sin(theta_rad)
        return math.sqrt(base * base + d_s * d_s * c * c + d_t * d_t * s * s)

    def truth_mtf_at(self, label: str, freqs_cycles_per_px: npt.ArrayLike) -> FloatArray:
        """Analytic MTF of the edge ``label`` (e.g. ``"E0L"``) of this scene."""
        try:
            edge = edge_spec(label, self.squares)  # that edge alone, not all of them
        except KeyError:
            raise KeyError(f"no edge {label!r} on the target") from None
        sigma = self.side_sigma_px(edge.square, edge.normal_theta_rad)
        return edge_truth_mtf(freqs_cycles_per_px, sigma, edge.normal_theta_rad)


def scenes_at(lens: ThroughFocusLens, distance_mm: float, usaf: UsafScene,
              edges: EdgeScene) -> tuple[DefocusedUsafScene, DefocusedEdgeScene]:
    """The forward view's chart and edge target with the chart at ``distance_mm``."""
    scale = lens.scale_at(distance_mm)
    fields_u = {f.name: getattr(usaf, f.name) for f in dataclasses.fields(UsafScene)}
    fields_u["pose"] = ChartPose(scale=scale)
    return (DefocusedUsafScene(**fields_u, lens=lens, distance_mm=float(distance_mm)),
            edges_at(lens, distance_mm, edges))


def edges_at(lens: ThroughFocusLens, distance_mm: float, edges: EdgeScene
             ) -> DefocusedEdgeScene:
    """:func:`scenes_at`'s edge target alone (the simulator's truth needs no chart)."""
    fields_e = {f.name: getattr(edges, f.name) for f in dataclasses.fields(EdgeScene)}
    fields_e["squares"] = scaled_squares(lens.scale_at(distance_mm), edges.squares)
    return DefocusedEdgeScene(**fields_e, lens=lens, distance_mm=float(distance_mm))


#: The radial view's lens (Table 4.4: EFL 3.52 mm, entrance pupil radius 0.84 mm; best focus
#: on the thesis's object cylinder, 19.88 mm from the axis). The thin-lens model folds the
#: mirrors' path into "object distance = object radius"; the ray-trace table gives the
#: magnification at each radius (15.88-24.88 mm: 2-11 mm from the side wall).
RADIAL_LENS = {"focal_length_mm": 3.52, "pupil_diameter_mm": 1.68, "best_focus_mm": 19.88,
               "reference_magnification": 17.5}


#: Image-height step (mm) of the defocused radial blur table: the defocus (with field curvature
#: ``k h^2``) is evaluated at every step, so the render follows it between the lens table's rows.
RADIAL_DEFOCUS_STEP_MM = 0.05


def defocused_radial(scene: RadialScene, lens: ThroughFocusLens, radius_mm: float
                     ) -> RadialScene:
    """The rolled pattern on a cylinder ``radius_mm`` from the axis through ``lens``: the
    ray-trace table images it at that radius (its magnification), and the defocus blur at each
    image height (every :data:`RADIAL_DEFOCUS_STEP_MM` over the radial blur table's range, and
    its rows) is added in quadrature to the radial blur table there."""
    base = scene.blur
    lo, hi = min(base.image_height_mm), max(base.image_height_mm)
    n = max(2, int(round((hi - lo) / RADIAL_DEFOCUS_STEP_MM)) + 1)
    h = np.union1d(np.linspace(lo, hi, n), base.image_height_mm)
    scale = lens.lens_blur_scale
    sag_base = base.sagittal_px(h) * scale
    tan_base = base.tangential_px(h) * scale
    sag = tuple(float(np.hypot(s, lens.defocus_sigma_px(radius_mm, x, 0.0, "sagittal")))
                for x, s in zip(h, sag_base, strict=True))
    tan = tuple(float(np.hypot(t, lens.defocus_sigma_px(radius_mm, x, 0.0, "tangential")))
                for x, t in zip(h, tan_base, strict=True))
    return dataclasses.replace(scene, object_radius_mm=float(radius_mm),
                               blur=BlurProfile(tuple(float(x) for x in h), sag, tan))
