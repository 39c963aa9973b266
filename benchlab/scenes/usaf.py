"""Forward view: the USAF 1951 chart, back-lit, imaged into the central disc.

A positive chart (chrome bars on clear glass) lit from behind: the disc is bright, the bars dark.
Each bar set is three rectangles from :mod:`benchlab.analysis.chart`, blurred by the forward
:class:`~benchlab.scenes.optics.BlurProfile` at that set's image height and integrated over the
pixel aperture, all in closed form. The image is linear in the bars, so the render is the bright
disc minus each blurred bar; the truth values use the same formulas.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.special import ndtr

from benchlab.analysis.chart import BarGroup, ChartLayout, Orientation, RadialLayout, usaf_bar_group
from benchlab.analysis.result import eq29_modulation
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes.optics import FORWARD_BLUR, BlurProfile, box_blurred_rect

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class UsafScene:
    """The forward-view USAF 1951 scene.

    Parameters
    ----------
    layout
        Where the chart's elements are imaged.
    circles
        Dual-view circles; only the forward disc (centre and radius) is lit.
    blur
        Forward-view blur widths over image height (sagittal = along x, tangential = along y).
    dark_dn8, bright_dn8
        Noise-free 8-bit levels of a wide bar and of the clear glass at the reference exposure
        and gain (the thesis's ~20 and ~190 at 300 ms, unity gain).
    reference_exposure_ms, reference_gain
        The acquisition those levels refer to; the scene returns rates, so other settings scale.
    disc_edge_sigma_px
        Softness of the disc edge.
    defocus_px
        Extra isotropic Gaussian blur (added in quadrature) for a back focus away from best;
        ``state.bench["defocus_px"]`` overrides it per exposure, so the focus step (Table 4.10,
        step 3) has something to maximise on the simulated bench.
    """

    layout: ChartLayout = field(default_factory=ChartLayout)
    circles: RadialLayout = field(default_factory=RadialLayout)
    blur: BlurProfile = FORWARD_BLUR
    dark_dn8: float = 20.0
    bright_dn8: float = 190.0
    reference_exposure_ms: float = 300.0
    reference_gain: float = 1.0
    disc_edge_sigma_px: float = 1.5
    defocus_px: float = 0.0

    @property
    def dark_rate(self) -> float:
        """Electron rate (e-/ms) of a wide dark bar."""
        return float(rate_for_dn8(self.dark_dn8, self.reference_exposure_ms, self.reference_gain))

    @property
    def bright_rate(self) -> float:
        """Electron rate (e-/ms) of the clear glass."""
        return float(rate_for_dn8(self.bright_dn8, self.reference_exposure_ms, self.reference_gain))

    def bar_group(self, group: int, element: int, orientation: Orientation) -> BarGroup:
        """Geometry of one bar set (see :func:`benchlab.analysis.chart.usaf_bar_group`)."""
        return usaf_bar_group(self.layout, group, element, orientation)

    def sigmas_px(self, bars: BarGroup) -> tuple[float, float]:
        """Blur widths ``(along rows, along columns)`` applied to a bar set, px."""
        h = bars.image_height_mm
        extra = self.defocus_px**2
        return (
            math.sqrt(float(self.blur.tangential_px(h)) ** 2 + extra),
            math.sqrt(float(self.blur.sagittal_px(h)) ** 2 + extra),
        )

    def __call__(self, state: AcquisitionState) -> FloatArray:
        """Electron-rate image (e-/ms) for the camera simulator (a fresh copy each call)."""
        scene = self
        defocus = (state.bench or {}).get("defocus_px")
        if defocus is not None and float(defocus) != self.defocus_px:
            scene = dataclasses.replace(self, defocus_px=abs(float(defocus)))
        return _render(scene, state.height, state.width).copy()

    def render(self, height: int, width: int) -> FloatArray:
        """The cached, read-only electron-rate image of a ``height x width`` frame."""
        return _render(self, height, width)

    def _profile_value(self, bars: BarGroup, row: float, col: float) -> float:
        """Noise-free pixel value (e-/ms) a pixel centred at (row, col) would read."""
        sig_r, sig_c = self.sigmas_px(bars)
        disc = self._disc(np.array([row]), np.array([col]))[0]
        value = self.bright_rate * disc
        r = np.array([row])
        c = np.array([col])
        for top, left, bottom, right in bars.bars:
            fy = box_blurred_rect(r, top, bottom, sig_r)[0]
            fx = box_blurred_rect(c, left, right, sig_c)[0]
            value -= (self.bright_rate - self.dark_rate) * fy * fx
        return float(value)

    def truth_levels(
        self, group: int, element: int, orientation: Orientation
    ) -> tuple[float, float]:
        """Noise-free ``(dark, bright)`` rates (e-/ms) of a bar set as imaged.

        Dark = the blurred, pixel-integrated profile at the centre of the middle bar; bright =
        at the centre of the spaces either side of it, both at mid bar length. That is the
        best sampling phase (a pixel centred on the bar and on the spaces): the pre-sampling
        bar contrast. A frame at a non-integer period samples other phases; near Nyquist its
        reading depends on that phase (the estimators flag it), and a measurement ROI must keep
        off the bar ends (:func:`benchlab.analysis.chart.bar_set_roi`).
        """
        bars = self.bar_group(group, element, orientation)
        cr, cc = bars.centre_rc
        w = bars.bar_width_px
        dark = self._profile_value(bars, cr, cc)
        if orientation == "sagittal":
            bright = 0.5 * (
                self._profile_value(bars, cr, cc - w) + self._profile_value(bars, cr, cc + w)
            )
        else:
            bright = 0.5 * (
                self._profile_value(bars, cr - w, cc) + self._profile_value(bars, cr + w, cc)
            )
        return dark, bright

    def truth_levels_dn8(
        self, group: int, element: int, orientation: Orientation
    ) -> tuple[float, float]:
        """:meth:`truth_levels` as 8-bit codes at the reference exposure and gain."""
        dark, bright = self.truth_levels(group, element, orientation)
        scale = 1.0 / float(rate_for_dn8(1.0, self.reference_exposure_ms, self.reference_gain))
        return dark * scale, bright * scale

    def truth_modulation(self, group: int, element: int, orientation: Orientation) -> float:
        """Eq. 2.9 modulation ``(bright - dark) / (bright + dark)`` of the noise-free imaged set."""
        dark, bright = self.truth_levels(group, element, orientation)
        return eq29_modulation(dark, bright)

    def truth_table(self) -> list[dict[str, object]]:
        """Noise-free truth of every bar set on the chart (Table 4.11 layout), coarse to fine."""
        rows: list[dict[str, object]] = []
        for g, e in self.layout.elements:
            for orientation in ("sagittal", "tangential"):
                bars = self.bar_group(g, e, orientation)  # type: ignore[arg-type]
                dark, bright = self.truth_levels_dn8(g, e, orientation)  # type: ignore[arg-type]
                rows.append(
                    {
                        "label": bars.label,
                        "group": g,
                        "element": e,
                        "orientation": orientation,
                        "image_lp_per_mm": bars.image_lp_per_mm,
                        "image_height_mm": bars.image_height_mm,
                        "box": bars.box,
                        "dark_dn8": dark,
                        "bright_dn8": bright,
                        "modulation": eq29_modulation(dark, bright),
                    }
                )
        return rows

    def _disc(self, rows: FloatArray, cols: FloatArray) -> FloatArray:
        cr, cc = self.circles.centre_rc
        radius = np.hypot(rows - cr, cols - cc)
        edge = math.hypot(self.disc_edge_sigma_px, self.defocus_px)
        return ndtr((self.circles.disc_radius_px - radius) / edge)


@functools.lru_cache(maxsize=8)
def _render(scene: UsafScene, height: int, width: int) -> FloatArray:
    rows = np.arange(height, dtype=np.float64)[:, None]
    cols = np.arange(width, dtype=np.float64)[None, :]
    img = scene.bright_rate * scene._disc(rows, cols)
    depth = scene.bright_rate - scene.dark_rate
    for g, e in scene.layout.elements:
        for orientation in ("sagittal", "tangential"):
            bars = scene.bar_group(g, e, orientation)  # type: ignore[arg-type]
            sig_r, sig_c = scene.sigmas_px(bars)
            for top, left, bottom, right in bars.bars:
                # Only the patch the blurred bar can reach (6 sigma plus the pixel aperture).
                r0 = max(int(np.floor(top - 6 * sig_r - 1)), 0)
                r1 = min(int(np.ceil(bottom + 6 * sig_r + 2)), height)
                c0 = max(int(np.floor(left - 6 * sig_c - 1)), 0)
                c1 = min(int(np.ceil(right + 6 * sig_c + 2)), width)
                if r0 >= r1 or c0 >= c1:
                    continue
                fy = box_blurred_rect(np.arange(r0, r1, dtype=np.float64), top, bottom, sig_r)
                fx = box_blurred_rect(np.arange(c0, c1, dtype=np.float64), left, right, sig_c)
                img[r0:r1, c0:c1] -= depth * np.outer(fy, fx)
    np.maximum(img, 0.0, out=img)
    img.setflags(write=False)
    return img
