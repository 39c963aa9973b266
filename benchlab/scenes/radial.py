"""Radial view: a rolled single-frequency bar pattern imaged into the annulus.

Orientation (fig. 4.9; :mod:`benchlab.analysis.chart`):

- **sagittal** - the paper is rolled so its bars run along the endoscope axis. The radial view
  images the axis direction along the image radius, so the bars are *spokes*; intensity varies
  around the circle. The pattern's period is exact (``px_per_period``) along the arc through the
  reference point (the radial ROI's centroid) and scales with radius elsewhere, as an object
  period on a cylinder does. The roll's seam sits diametrically opposite the reference point.
- **tangential** - rolled the other way: bars around the cylinder, imaged as *rings*; intensity
  varies along the radius with a constant period.

Image frequency = object lp/mm x :data:`~benchlab.analysis.frequency.RADIAL_MAGNIFICATION`
(Eq. 4.1). The pattern is back-lit paper: bright spaces, dark bars, 50 % duty. Each pixel is the
pattern blurred across its bars by the radial :class:`~benchlab.scenes.optics.BlurProfile` at its
own radius plus the pixel aperture (Gaussian of variance 1/12 px^2), in closed form, so the blur
varies continuously with image height and needs no resampling.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.special import ndtr

from benchlab.analysis.chart import RADIAL_ROI_BOX, Orientation, RadialLayout, box_centroid
from benchlab.analysis.frequency import (
    RADIAL_MAGNIFICATION,
    image_frequency_lp_per_mm,
    px_per_period,
)
from benchlab.analysis.result import eq29_modulation
from benchlab.drivers.sensor import PIXEL_PITCH_UM, AcquisitionState, rate_for_dn8
from benchlab.scenes.optics import (
    PIXEL_APERTURE_VAR_PX2,
    RADIAL_BLUR,
    BlurProfile,
    blurred_square_wave,
)

FloatArray = npt.NDArray[np.float64]
#: The object frequencies of the thesis's printed radial targets (Table 4.12), lp/mm.
RADIAL_TARGETS_LP_PER_MM = (0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0)


@dataclass(frozen=True)
class RadialScene:
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
    magnification
        Object-to-image frequency factor.
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
    magnification: float = RADIAL_MAGNIFICATION
    pixel_pitch_um: float = PIXEL_PITCH_UM
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

    @property
    def image_lp_per_mm(self) -> float:
        """Image-plane frequency at the reference point."""
        return image_frequency_lp_per_mm(self.object_lp_per_mm, self.magnification)

    @property
    def px_per_period(self) -> float:
        """Pattern period at the reference point, px."""
        return px_per_period(self.image_lp_per_mm, self.pixel_pitch_um)

    @property
    def reference_radius_px(self) -> float:
        return self.circles.radius_px(self.reference_rc)

    @property
    def dark_rate(self) -> float:
        return float(rate_for_dn8(self.dark_dn8, self.reference_exposure_ms, self.reference_gain))

    @property
    def bright_rate(self) -> float:
        return float(rate_for_dn8(self.bright_dn8, self.reference_exposure_ms, self.reference_gain))

    def across_bar_sigma_px(self, radius_px: float | FloatArray) -> FloatArray:
        """Optical blur across the bars at a radius, px (without the pixel aperture)."""
        h_mm = np.asarray(radius_px, dtype=np.float64) * self.pixel_pitch_um / 1000.0
        if self.orientation == "sagittal":
            return self.blur.sagittal_px(h_mm)
        return self.blur.tangential_px(h_mm)

    def _pattern(self, radius_px: FloatArray, dtheta: FloatArray) -> FloatArray:
        """Bright fraction (0..1) of the blurred pattern at polar coordinates about the centre."""
        period = self.px_per_period
        r_ref = self.reference_radius_px
        sigma = np.sqrt(self.across_bar_sigma_px(radius_px) ** 2 + PIXEL_APERTURE_VAR_PX2)
        if self.orientation == "sagittal":
            u = dtheta * r_ref  # arc length at the reference radius
            sigma = sigma * r_ref / np.maximum(radius_px, 1.0)
        else:
            u = radius_px - r_ref
        # Square wave is bright on [0, p/2): shift so a dark bar is centred at u = 0.
        return blurred_square_wave(u + (0.75 + self.phase_cycles) * period, period, sigma)

    def _theta_ref(self) -> float:
        cr, cc = self.circles.centre_rc
        return math.atan2(self.reference_rc[0] - cr, self.reference_rc[1] - cc)

    def truth_levels(self, point_rc: tuple[float, float] | None = None) -> tuple[float, float]:
        """Noise-free ``(dark, bright)`` rates (e-/ms) at the centre of a bar and of a space
        next to ``point_rc``'s radius (default the reference point)."""
        radius = self.reference_radius_px if point_rc is None else self.circles.radius_px(point_rc)
        r = np.array([radius])
        period = self.px_per_period
        if self.orientation == "sagittal":
            half_period_rad = period / (2.0 * self.reference_radius_px)
            bar = self._pattern(r, np.array([0.0]))[0]
            space = self._pattern(r, np.array([half_period_rad]))[0]
        else:
            bar = self._pattern(r, np.array([0.0]))[0]
            space = self._pattern(r + period / 2.0, np.array([0.0]))[0]
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
    index, r, theta, envelope = _annulus(scene.circles, scene.edge_sigma_px, height, width)
    # Angle from the reference direction in [-pi, pi): the roll's seam is opposite the ROI.
    dtheta = np.mod(theta - scene._theta_ref() + np.pi, 2.0 * np.pi) - np.pi
    bright_fraction = scene._pattern(r, dtheta)
    depth = scene.bright_rate - scene.dark_rate
    flat = np.zeros(height * width)
    flat[index] = envelope * (scene.dark_rate + depth * bright_fraction)
    img: FloatArray = flat.reshape(height, width)
    img.setflags(write=False)
    return img
