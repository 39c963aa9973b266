"""A flat printed card rolled onto an object cylinder, seen by the radial view.

For judging synthesized views (thesis fig. 5.8 / 5.11 used a business card): a card printed
with a square grid of straight lines and rows of text-like blocks in its cells, rolled around
the inside of the back-lit paper tube at a chosen distance from the axis. The card's x runs
around the cylinder (arc length), its y along the axis (towards +z), so its flat truth is
known exactly: line ``k`` of the grid is at ``x = k * grid_pitch_mm`` and the unwrapped view of
the card at the right depth must show straight, evenly spaced lines.

The image is formed through the same ray-trace table as :class:`~benchlab.scenes.radial.
RadialScene` (:func:`~benchlab.scenes.radial.cylinder_pixels`), with the radial view's blur
converted to object mm per direction (sagittal around the circle, tangential along the axis)
and the pixel aperture; every printed feature is a rectangle, so the blurred card is a sum of
separable error-function products in closed form. Outside the card the tube is blank paper.
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
from benchlab.analysis.views.raytrace import REFERENCE_OBJECT_RADIUS_MM, RayTraceTable
from benchlab.analysis.views.synthesis import cylinder_map
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes.optics import PIXEL_APERTURE_VAR_PX2, RADIAL_BLUR, BlurProfile
from benchlab.scenes.radial import CylinderPixels, cylinder_pixels, default_table

Rect = tuple[float, float, float, float]  # x0, x1, y0, y1 on the card, mm


@dataclass(frozen=True)
class CardScene:
    """A grid-and-text card rolled onto the cylinder of radius ``object_radius_mm``.

    Parameters
    ----------
    object_radius_mm
        Distance of the card from the axis, mm (19.88: the thesis's radial set-up).
    card_width_mm, card_height_mm
        Card size around the cylinder and along the axis.
    centre_z_mm
        Axial position of the card's centre (None: middle of the imaged field).
    grid_pitch_mm, line_width_mm
        The printed grid (lines on the card's edges too).
    text_seed
        Seed of the text-like blocks' layout.
    circles, reference_rc
        Image circles; the card is centred on the reference point's azimuth.
    table
        Ray-trace table (None: the shipped modelled one).
    blur
        Radial-view blur over image height.
    ink_dn8, paper_dn8
        Noise-free 8-bit levels of wide ink and of paper at the reference acquisition.
    """

    object_radius_mm: float = REFERENCE_OBJECT_RADIUS_MM
    card_width_mm: float = 90.0
    card_height_mm: float = 30.0
    centre_z_mm: float | None = None
    grid_pitch_mm: float = 5.0
    line_width_mm: float = 0.3
    text_seed: int = 12
    circles: RadialLayout = field(default_factory=RadialLayout)
    reference_rc: tuple[float, float] = box_centroid(RADIAL_ROI_BOX)
    table: RayTraceTable | None = None
    blur: BlurProfile = RADIAL_BLUR
    ink_dn8: float = 20.0
    paper_dn8: float = 190.0
    reference_exposure_ms: float = 300.0
    reference_gain: float = 1.0
    edge_sigma_px: float = 1.5

    def __post_init__(self) -> None:
        if not (self.grid_pitch_mm > 4 * self.line_width_mm > 0):
            raise ValueError("grid pitch must exceed 4 line widths, both > 0")
        circumference = 2 * math.pi * self.object_radius_mm
        if not (0 < self.card_width_mm < circumference and self.card_height_mm > 0):
            raise ValueError(
                f"card width must be in (0, {circumference:.1f}) mm around this cylinder"
            )
        cylinder_map(self.ray_table, self.object_radius_mm)  # refuses a cylinder off the table

    @property
    def ray_table(self) -> RayTraceTable:
        return self.table if self.table is not None else default_table()

    @property
    def card_centre_z_mm(self) -> float:
        """Axial position of the card's centre."""
        if self.centre_z_mm is not None:
            return self.centre_z_mm
        cyl = cylinder_map(self.ray_table, self.object_radius_mm)
        pitch_mm = self.circles.pixel_pitch_um / 1000.0
        ends = cyl.axial_mm(np.array([self.circles.annulus_inner_radius_px,
                                      self.circles.annulus_outer_radius_px]) * pitch_mm)
        return float(ends.mean())

    @property
    def centre_azimuth_rad(self) -> float:
        """Image azimuth of the card's centre (the reference point's)."""
        cr, cc = self.circles.centre_rc
        return math.atan2(self.reference_rc[0] - cr, self.reference_rc[1] - cc)

    def grid_lines_mm(self) -> tuple[FloatArray, FloatArray]:
        """Flat truth: x of the lines along the axis and y of the lines around, card mm."""
        nx = int(math.floor(self.card_width_mm / self.grid_pitch_mm + 1e-9))
        ny = int(math.floor(self.card_height_mm / self.grid_pitch_mm + 1e-9))
        pitch = self.grid_pitch_mm
        return (np.arange(nx + 1, dtype=np.float64) * pitch,
                np.arange(ny + 1, dtype=np.float64) * pitch)

    def card_to_object(self, x_mm: npt.ArrayLike, y_mm: npt.ArrayLike) -> tuple[
        FloatArray, FloatArray
    ]:
        """Card coordinates -> (image azimuth rad, axial z mm) on the cylinder."""
        x = np.asarray(x_mm, dtype=np.float64)
        y = np.asarray(y_mm, dtype=np.float64)
        phi: FloatArray = self.centre_azimuth_rad + (x - self.card_width_mm / 2.0) / (
            self.object_radius_mm)
        z: FloatArray = self.card_centre_z_mm + (y - self.card_height_mm / 2.0)
        return phi, z

    def text_blocks(self) -> tuple[Rect, ...]:
        """The text-like blocks: rows of 'words' inside the grid cells, clear of the lines."""
        return _text_blocks(self.card_width_mm, self.card_height_mm, self.grid_pitch_mm,
                            self.text_seed)

    @property
    def ink_rate(self) -> float:
        return float(rate_for_dn8(self.ink_dn8, self.reference_exposure_ms, self.reference_gain))

    @property
    def paper_rate(self) -> float:
        return float(rate_for_dn8(self.paper_dn8, self.reference_exposure_ms, self.reference_gain))

    def pixels(self, height: int, width: int) -> CylinderPixels:
        return cylinder_pixels(self.circles, self.edge_sigma_px, height, width, self.ray_table,
                               self.object_radius_mm, self.centre_azimuth_rad)

    def __call__(self, state: AcquisitionState) -> FloatArray:
        """Electron-rate image (e-/ms) for the camera simulator (a fresh copy each call)."""
        return _render(self, state.height, state.width).copy()

    def render(self, height: int, width: int) -> FloatArray:
        """The cached, read-only electron-rate image."""
        return _render(self, height, width)


@functools.lru_cache(maxsize=8)
def _text_blocks(width: float, height: float, pitch: float, seed: int) -> tuple[Rect, ...]:
    rng = np.random.default_rng(seed)
    margin, text_h, gap = 0.8, 0.9, 0.45
    blocks: list[Rect] = []
    for i in range(int(width // pitch)):
        for j in range(int(height // pitch)):
            if rng.random() < 0.25:
                continue  # some cells left blank
            x_start, x_stop = i * pitch + margin, (i + 1) * pitch - margin
            for y0 in (j * pitch + margin, j * pitch + margin + text_h + 0.8):
                if y0 + text_h > (j + 1) * pitch - margin:
                    break
                x = x_start
                while True:
                    w = float(rng.uniform(0.4, 1.5))
                    if x + w > x_stop:
                        break
                    blocks.append((x, x + w, y0, y0 + text_h))
                    x += w + gap
    return tuple(blocks)


def _box(u: FloatArray, a: float, b: float, sigma: FloatArray) -> FloatArray:
    """Indicator of [a, b] blurred by a Gaussian of width sigma (per sample)."""
    return np.asarray(ndtr((u - a) / sigma) - ndtr((u - b) / sigma))


def _lines(u: FloatArray, pitch: float, n: int, width: float, sigma: FloatArray) -> FloatArray:
    """Ink of lines of ``width`` at 0, pitch, ..., n pitch (nearest line only: pitch >> sigma)."""
    k = np.clip(np.round(u / pitch), 0, n)
    d = u - k * pitch
    return _box(d, -width / 2.0, width / 2.0, sigma)


@functools.lru_cache(maxsize=8)
def _render(scene: CardScene, height: int, width: int) -> FloatArray:
    pix = scene.pixels(height, width)
    h_mm = pix.rho_px * scene.circles.pixel_pitch_um / 1000.0
    sig_arc = np.sqrt(scene.blur.sagittal_px(h_mm) ** 2 + PIXEL_APERTURE_VAR_PX2)
    sig_ax = np.sqrt(scene.blur.tangential_px(h_mm) ** 2 + PIXEL_APERTURE_VAR_PX2)
    sx = sig_arc * pix.arc_mm_per_px
    sy = sig_ax * pix.axial_mm_per_px
    x = pix.arc_mm + scene.card_width_mm / 2.0
    y = pix.z_mm - scene.card_centre_z_mm + scene.card_height_mm / 2.0
    xs, ys = scene.grid_lines_mm()
    lw = scene.line_width_mm
    half = lw / 2.0
    # Grid lines run across the card between its printed edge lines.
    along = _lines(x, scene.grid_pitch_mm, xs.size - 1, lw, sx) * _box(
        y, ys[0] - half, ys[-1] + half, sy)
    around = _lines(y, scene.grid_pitch_mm, ys.size - 1, lw, sy) * _box(
        x, xs[0] - half, xs[-1] + half, sx)
    text = np.zeros_like(x)
    pitch = scene.grid_pitch_mm
    cell = np.floor(x / pitch) * 10_000 + np.floor(y / pitch)
    order = np.argsort(cell, kind="stable")
    keys, starts = np.unique(cell[order], return_index=True)
    bounds = dict(zip(keys.tolist(), zip(starts, [*starts[1:], order.size], strict=True),
                      strict=True))
    for x0, x1, y0, y1 in scene.text_blocks():
        key = math.floor(x0 / pitch) * 10_000 + math.floor(y0 / pitch)
        if key not in bounds:
            continue
        lo, hi = bounds[key]
        idx = order[lo:hi]
        text[idx] += _box(x[idx], x0, x1, sx[idx]) * _box(y[idx], y0, y1, sy[idx])
    transmission = (1.0 - along) * (1.0 - around) * (1.0 - np.clip(text, 0.0, 1.0))
    depth = scene.paper_rate - scene.ink_rate
    flat = np.zeros(height * width)
    flat[pix.index] = pix.envelope * (scene.ink_rate + depth * transmission)
    img: FloatArray = flat.reshape(height, width)
    img.setflags(write=False)
    return img
