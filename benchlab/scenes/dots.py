"""Forward view: the dot-grid chart of ``benchlab run fov``, imaged through a mapping the
simulator knows exactly.

The chart (docs/procedures/fov.md): dark chrome dots of side ``dot_mm`` on clear glass, on a
square grid of pitch ``pitch_mm``, ``2 half_count + 1`` dots a side, the centre dot (grid
index ``(0, 0)``) ``fiducial_scale`` times larger; back-lit, so the forward disc is bright
and the dots dark. It rides on the stage carriage at object distance ``D`` (the bench state's
``object_offset_mm`` + stage position).

The lens (:class:`FovLens`): the mapping ``h = f ((1 - b) tan theta + b theta)``
(:func:`benchlab.analysis.fov.model.blend_height_mm`), the entrance pupil ``e`` mm behind the
front reference, the optical axis tilted by ``tilt_deg`` (rotation about the direction
``tilt_azimuth_deg`` in the image plane, about the pupil), the chart mounted with a roll and a
lateral offset. Each dot's centre is imaged exactly (:func:`benchlab.analysis.fov.model.project`);
its image is a rectangle of the local scale centred there, blurred by the forward blur
(:data:`benchlab.scenes.optics.FORWARD_BLUR`) and integrated over the pixel in closed form
(:func:`benchlab.scenes.optics.box_blurred_rect`). That is a simplification: a real dot's image
is a slightly distorted ellipse whose centroid sits ~``r^2 / R`` (~0.02 px here) off its
centre's image. The disc (the field stop, centred on the optical axis in the image) is lit
with a soft edge; the camera adds shot and read noise and clips.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.chart.layout import RadialLayout
from benchlab.analysis.fov.model import (
    PIXEL_MM,
    HeightFn,
    Pose,
    blend_height_mm,
    chart_points_mm,
    field_angles,
    project,
)
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes.optics import FORWARD_BLUR, BlurProfile, box_blurred_rect


@dataclass(frozen=True)
class DotChart:
    """The grid chart's drawing (module docstring)."""

    pitch_mm: float = 1.0
    dot_mm: float = 0.3
    fiducial_scale: float = 2.0
    half_count: int = 25

    @property
    def half_width_mm(self) -> float:
        return self.half_count * self.pitch_mm

    def indices(self) -> FloatArray:
        k = np.arange(-self.half_count, self.half_count + 1, dtype=np.float64)
        i, j = np.meshgrid(k, k)
        return np.stack([i.ravel(), j.ravel()], axis=1)


@dataclass(frozen=True)
class FovLens:
    """The simulated forward lens and mounting (module docstring). Defaults: Table 4.14's
    forward field points (0.6 / 0.79 / 1.23 mm at 12 / 16 / 25 deg) are an equidistant
    ``f = 2.83 mm`` to 0.01 mm."""

    focal_length_mm: float = 2.83
    barrel: float = 1.0
    entrance_pupil_mm: float = 2.0
    tilt_deg: float = 0.0
    tilt_azimuth_deg: float = 0.0
    roll_deg: float = 0.3
    offset_x_mm: float = 0.2
    offset_y_mm: float = -0.15

    def __post_init__(self) -> None:
        if not self.focal_length_mm > 0:
            raise ValueError(f"focal_length_mm must be > 0, got {self.focal_length_mm}")
        if not -1.0 <= self.barrel <= 3.0:
            raise ValueError(f"barrel must be within -1..3, got {self.barrel}")
        if not 0.0 <= self.tilt_deg < 20.0:
            raise ValueError(f"tilt_deg must be within 0..20, got {self.tilt_deg}")

    def height_mm(self) -> HeightFn:
        return blend_height_mm(self.focal_length_mm, self.barrel)

    def pose(self, centre_rc: tuple[float, float]) -> Pose:
        t, a = math.radians(self.tilt_deg), math.radians(self.tilt_azimuth_deg)
        return Pose(centre_col=centre_rc[1], centre_row=centre_rc[0],
                    entrance_pupil_mm=self.entrance_pupil_mm, tilt_x_rad=t * math.cos(a),
                    tilt_y_rad=t * math.sin(a), roll_rad=math.radians(self.roll_deg),
                    offset_x_mm=self.offset_x_mm, offset_y_mm=self.offset_y_mm)

    def to_dict(self) -> dict[str, float]:
        return {k: float(getattr(self, k)) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class DotGridScene:
    """The chart through the lens at a distance (module docstring)."""

    chart: DotChart = field(default_factory=DotChart)
    lens: FovLens = field(default_factory=FovLens)
    circles: RadialLayout = field(default_factory=RadialLayout)
    blur: BlurProfile = FORWARD_BLUR
    dark_dn8: float = 20.0
    bright_dn8: float = 190.0
    reference_exposure_ms: float = 300.0
    reference_gain: float = 1.0
    disc_edge_sigma_px: float = 1.5
    default_distance_mm: float = 20.0

    @property
    def pose(self) -> Pose:
        return self.lens.pose(self.circles.centre_rc)

    def edge_angle_rad(self) -> float:
        """The field angle imaged onto the disc's edge (half the true field of view).

        Raises
        ------
        ValueError
            The mapping turns back before it reaches the edge (too strong a barrel).
        """
        from scipy.optimize import brentq

        h = self.lens.height_mm()
        target = self.circles.disc_radius_px * PIXEL_MM
        grid = np.linspace(0.0, 1.5, 1501)
        vals = h(grid)
        turn = np.nonzero(np.diff(vals) <= 0)[0]
        top = int(turn[0]) + 1 if len(turn) else len(grid)
        over = np.nonzero(vals[:top] >= target)[0]
        if len(over) == 0:
            raise ValueError(f"the mapping (f {self.lens.focal_length_mm:g} mm, barrel "
                             f"{self.lens.barrel:g}) never reaches the disc's edge")
        k = int(over[0])
        return float(brentq(lambda t: float(h(np.array([t]))[0]) - target, grid[k - 1],
                            grid[k], xtol=1e-13))

    def dot_centres(self, distance_mm: float) -> tuple[FloatArray, FloatArray]:
        """Grid indices ``(n, 2)`` and exact image centres ``(n, 2)`` ``(col, row)`` of every
        chart dot in front of the lens."""
        ij = self.chart.indices()
        pts = chart_points_mm(ij, self.chart.pitch_mm, np.float64(distance_mm), self.pose)
        # rays beyond the field stop never reach the sensor (and a barrel mapping turns back)
        theta, _ = field_angles(pts, self.pose)
        seen = theta <= self.edge_angle_rad() + 0.05
        return ij[seen], project(pts[seen], self.pose, self.lens.height_mm())

    def render(self, distance_mm: float, height: int, width: int) -> FloatArray:
        """Cached, read-only electron-rate image at an object distance."""
        return _render(self, float(distance_mm), height, width)

    def __call__(self, state: AcquisitionState) -> FloatArray:
        d = state.bench.get("object_distance_mm", self.default_distance_mm)
        return _render(self, float(d), state.height, state.width).copy()


@functools.lru_cache(maxsize=4)
def _render(scene: DotGridScene, distance_mm: float, height: int, width: int) -> FloatArray:
    bright = float(rate_for_dn8(scene.bright_dn8, scene.reference_exposure_ms,
                                scene.reference_gain))
    depth = bright * (1.0 - scene.dark_dn8 / scene.bright_dn8)
    cr, cc = scene.circles.centre_rc
    radius = scene.circles.disc_radius_px
    rows = np.arange(height, dtype=np.float64)[:, None]
    cols = np.arange(width, dtype=np.float64)[None, :]
    transmission = np.ones((height, width))
    ij, centres = scene.dot_centres(distance_mm)
    pose, hfn, pitch = scene.pose, scene.lens.height_mm(), scene.chart.pitch_mm
    half = scene.chart.dot_mm / 2.0
    rho = np.hypot(centres[:, 0] - cc, centres[:, 1] - cr)
    for k in np.nonzero(rho < radius + 15.0)[0]:
        grow = scene.chart.fiducial_scale if (ij[k] == 0).all() else 1.0
        step = half * grow / pitch
        ends = project(chart_points_mm(
            np.array([ij[k] + (step, 0.0), ij[k] - (step, 0.0), ij[k] + (0.0, step),
                      ij[k] - (0.0, step)]), pitch, np.float64(distance_mm), pose), pose, hfn)
        half_c = 0.5 * float(np.hypot(*(ends[0] - ends[1])))
        half_r = 0.5 * float(np.hypot(*(ends[2] - ends[3])))
        c, r = centres[k]
        h_mm = rho[k] * PIXEL_MM
        s_c, s_r = float(scene.blur.sagittal_px(h_mm)), float(scene.blur.tangential_px(h_mm))
        reach_c, reach_r = half_c + 6 * s_c + 2, half_r + 6 * s_r + 2
        r0, r1 = max(int(r - reach_r), 0), min(int(r + reach_r) + 2, height)
        c0, c1 = max(int(c - reach_c), 0), min(int(c + reach_c) + 2, width)
        if r0 >= r1 or c0 >= c1:
            continue
        prof_r = box_blurred_rect(np.arange(r0, r1, dtype=np.float64), r - half_r, r + half_r,
                                  s_r)
        prof_c = box_blurred_rect(np.arange(c0, c1, dtype=np.float64), c - half_c, c + half_c,
                                  s_c)
        transmission[r0:r1, c0:c1] -= (depth / bright) * prof_r[:, None] * prof_c[None, :]
    disc = ndtr((radius - np.hypot(rows - cr, cols - cc)) / scene.disc_edge_sigma_px)
    img = bright * disc * transmission
    img.setflags(write=False)
    return img
