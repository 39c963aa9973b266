"""Relative radiometry (section 4.4): one LED seen by the radial view, moved along the field.

The LED (2 mm x 3 mm emitter) sits against the side wall; the stage moves it along the endoscope
axis, which the radial view images along the image radius. The spot is a flat-topped ellipse
(its 3 mm side along the radius, 2 mm around) with soft edges, at a radius that is linear in the
stage position and on a fixed azimuth (default: the radial ROI's direction). Its plateau
brightness is ``peak x falloff(position) x current / reference current`` - linear in LED current
and in the fall-off table, which is data so a test can set a known truth. The default table is
the thesis's measured, normalised fall-off (Table 4.16): 0.78, 1.00, 0.92, 0.77, 0.50.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.special import ndtr

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.chart.layout import RADIAL_ROI_BOX, RadialLayout, box_centroid
from benchlab.analysis.mtf.frequency import RADIAL_MAGNIFICATION
from benchlab.drivers.sensor import PIXEL_PITCH_UM, AcquisitionState, rate_for_dn8

BoolArray = npt.NDArray[np.bool_]


def _roi_azimuth_deg() -> float:
    cr, cc = RadialLayout().centre_rc
    r, c = box_centroid(RADIAL_ROI_BOX)
    return math.degrees(math.atan2(r - cr, c - cc))


@dataclass(frozen=True)
class LedFalloff:
    """Relative LED brightness against stage position (linear between rows, flat beyond)."""

    position_mm: tuple[float, ...] = (15.0, 18.0, 20.0, 25.0, 32.0)
    relative_brightness: tuple[float, ...] = (0.78, 1.00, 0.92, 0.77, 0.50)

    def __post_init__(self) -> None:
        if len(self.position_mm) != len(self.relative_brightness) or not self.position_mm:
            raise ValueError("LedFalloff needs equally long, non-empty tables")
        pairs = zip(self.position_mm, self.position_mm[1:], strict=False)
        if any(b <= a for a, b in pairs):
            raise ValueError("LedFalloff positions must increase")
        if min(self.relative_brightness) < 0:
            raise ValueError("relative brightness must be >= 0")

    def at(self, position_mm: float) -> float:
        """Relative brightness at a stage position."""
        return float(np.interp(position_mm, self.position_mm, self.relative_brightness))


@dataclass(frozen=True)
class LedScene:
    """The radiometry LED spot.

    Parameters
    ----------
    falloff
        Relative brightness against stage position.
    peak_dn8
        Plateau 8-bit level at relative brightness 1, the reference current, exposure and gain.
    reference_current_ma, reference_exposure_ms, reference_gain
        The conditions ``peak_dn8`` refers to (the thesis: 375 ms, unity gain).
    position_range_mm, radius_range_px
        Stage positions and the image radii of the spot centre there (linear in between).
    azimuth_deg
        Direction of the spot from the optical centre (atan2(row, col)), degrees.
    size_mm
        LED emitter ``(along the axis, around)``; imaged at 1 / ``magnification``.
    edge_sigma_px
        Softness of the spot's edge (blur of the radial view). The room is dark: no background.
    """

    falloff: LedFalloff = field(default_factory=LedFalloff)
    circles: RadialLayout = field(default_factory=RadialLayout)
    peak_dn8: float = 110.0
    reference_current_ma: float = 20.0
    reference_exposure_ms: float = 375.0
    reference_gain: float = 1.0
    position_range_mm: tuple[float, float] = (15.0, 32.0)
    radius_range_px: tuple[float, float] = (505.0, 335.0)
    azimuth_deg: float = field(default_factory=_roi_azimuth_deg)
    size_mm: tuple[float, float] = (3.0, 2.0)
    magnification: float = RADIAL_MAGNIFICATION
    pixel_pitch_um: float = PIXEL_PITCH_UM
    edge_sigma_px: float = 1.5

    def radius_px(self, position_mm: float) -> float:
        """Image radius of the spot centre at a stage position (linear map)."""
        (p0, p1), (r0, r1) = self.position_range_mm, self.radius_range_px
        return r0 + (position_mm - p0) * (r1 - r0) / (p1 - p0)

    def centre_rc(self, position_mm: float) -> tuple[float, float]:
        """Image position (row, col) of the spot centre."""
        a = math.radians(self.azimuth_deg)
        rad = self.radius_px(position_mm)
        cr, cc = self.circles.centre_rc
        return (cr + rad * math.sin(a), cc + rad * math.cos(a))

    @property
    def semi_axes_px(self) -> tuple[float, float]:
        """Spot semi-axes ``(radial, tangential)`` in px."""
        scale = 1000.0 / (self.magnification * self.pixel_pitch_um)
        return (self.size_mm[0] * scale / 2.0, self.size_mm[1] * scale / 2.0)

    def plateau_rate(self, position_mm: float, current_ma: float) -> float:
        """Electron rate (e-/ms) in the flat centre of the spot."""
        if current_ma <= 0:
            return 0.0
        peak = float(rate_for_dn8(self.peak_dn8, self.reference_exposure_ms, self.reference_gain))
        return peak * self.falloff.at(position_mm) * current_ma / self.reference_current_ma

    def expected_plateau_dn8(
        self, position_mm: float, current_ma: float, exposure_ms: float, gain: float = 1.0
    ) -> float:
        """Noise-free 8-bit level in the spot's centre (before clipping at 255)."""
        per_dn8 = float(rate_for_dn8(1.0, exposure_ms, gain))
        return self.plateau_rate(position_mm, current_ma) / per_dn8

    def expected_mean_dn8(
        self,
        mask: BoolArray,
        position_mm: float,
        current_ma: float,
        exposure_ms: float,
        gain: float = 1.0,
    ) -> float:
        """Noise-free mean 8-bit level inside ``mask`` (clipped at 255 per pixel, as the camera
        would), i.e. what the section 4.4 reading should be for that mask.
        """
        m = np.asarray(mask, dtype=bool)
        if not m.any():
            raise ValueError("mask selects no pixels")
        img = _render(self, position_mm, current_ma, m.shape[0], m.shape[1])
        per_dn8 = float(rate_for_dn8(1.0, exposure_ms, gain))
        return float(np.minimum(img[m] / per_dn8, 255.0).mean())

    def render(self, position_mm: float, current_ma: float, height: int, width: int) -> FloatArray:
        """Cached, read-only electron-rate image."""
        return _render(self, position_mm, current_ma, height, width)

    def __call__(self, state: AcquisitionState) -> FloatArray:
        """Scene for the camera: reads ``stage_position_mm`` and ``led_current_ma`` from
        ``state.bench`` (LED off and mid-range position when absent)."""
        bench = state.bench
        position = float(bench.get("stage_position_mm", sum(self.position_range_mm) / 2.0))
        current = float(bench.get("led_current_ma", 0.0))
        return _render(self, position, current, state.height, state.width).copy()


# Small caches: each entry is a full frame (10 MB); a re-render costs ~25 ms.
@functools.lru_cache(maxsize=6)
def _shape(scene: LedScene, position_mm: float, height: int, width: int) -> FloatArray:
    out = np.zeros((height, width))
    cr, cc = scene.centre_rc(position_mm)
    a_rad, a_tan = scene.semi_axes_px
    reach = max(a_rad, a_tan) + 6.0 * scene.edge_sigma_px + 2.0
    r0, r1 = max(int(cr - reach), 0), min(int(cr + reach) + 1, height)
    c0, c1 = max(int(cc - reach), 0), min(int(cc + reach) + 1, width)
    if r0 < r1 and c0 < c1:
        rows = np.arange(r0, r1, dtype=np.float64)[:, None] - cr
        cols = np.arange(c0, c1, dtype=np.float64)[None, :] - cc
        az = math.radians(scene.azimuth_deg)
        along = rows * math.sin(az) + cols * math.cos(az)  # radial direction
        across = -rows * math.cos(az) + cols * math.sin(az)
        # Signed distance (px, approximately) outside the ellipse boundary.
        rho = np.hypot(along / a_rad, across / a_tan)
        dist = (rho - 1.0) * min(a_rad, a_tan)
        out[r0:r1, c0:c1] = ndtr(-dist / scene.edge_sigma_px)
    # Parts of the spot outside the radial field of view are not imaged.
    circ = scene.circles
    radius = np.hypot(
        np.arange(height)[:, None] - circ.centre_rc[0],
        np.arange(width)[None, :] - circ.centre_rc[1],
    )
    inside = (radius >= circ.annulus_inner_radius_px) & (radius <= circ.annulus_outer_radius_px)
    out *= inside
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=6)
def _render(
    scene: LedScene, position_mm: float, current_ma: float, height: int, width: int
) -> FloatArray:
    img = _shape(scene, position_mm, height, width) * scene.plateau_rate(position_mm, current_ma)
    img.setflags(write=False)
    return img
