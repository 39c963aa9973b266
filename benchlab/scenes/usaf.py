"""Forward view: the USAF 1951 chart, back-lit, imaged into the central disc.

A positive chart (chrome bars on clear glass) lit from behind: the disc is bright, the bars dark.
Each bar set is three rectangles from :mod:`benchlab.analysis.chart.layout`, blurred by the forward
:class:`~benchlab.scenes.optics.BlurProfile` at that set's image height and integrated over the
pixel aperture, all in closed form. The image is linear in the bars, so the render is the bright
disc minus each blurred bar; the truth values use the same formulas.

Pose knobs (:class:`~benchlab.analysis.chart.pose.ChartPose`): the chart may be imaged offset,
scaled and rotated. Bars parallel to the pixel axes use the exact separable form above. A
rotated bar is the product of two slabs, along and across it, each blurred by the Gaussian
projected on that direction and by the pixel aperture projected on it (a trapezoid: two boxes
of widths ``|cos t|`` and ``|sin t|``), in closed form. That is exact along the bar edges and
approximate only at the bar corners (the aperture and an anisotropic blur are not separable
along rotated axes), which the measurement ROIs keep off. ``negative`` renders a negative target
(clear bars on chrome: bright bars on a dark ground); ``vignetting`` dims the disc
multiplicatively by ``1 - vignetting (rho / disc radius)^2``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars.result import eq29_modulation
from benchlab.analysis.chart.layout import (
    BarGroup,
    ChartLayout,
    Orientation,
    RadialLayout,
    usaf_bar_group,
)
from benchlab.analysis.chart.pose import ChartPose, PosedBarSet, posed_bar_set
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes.optics import FORWARD_BLUR, BlurProfile, box_blurred_rect, saturated_ndtr
from benchlab.scenes.printed import TwoLevelPrint


@dataclass(frozen=True)
class UsafScene(TwoLevelPrint):
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
    pose
        Offset, scale and rotation of the imaged chart about its layout origin.
    negative
        A negative target: bright bars (``bright_dn8``) on a dark ground (``dark_dn8``).
    vignetting
        Fractional fall-off of the lit disc at its edge (0 = flat), quadratic in radius.
    full_field
        Light the whole frame, not the forward disc: a microscope's or a lab camera's view
        (with the whole chart as ``layout``, ``usaf:whole=M``).
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
    pose: ChartPose = field(default_factory=ChartPose)
    negative: bool = False
    vignetting: float = 0.0
    full_field: bool = False

    def __post_init__(self) -> None:
        if not 0.0 <= self.vignetting < 1.0:
            raise ValueError(f"vignetting must be in [0, 1), got {self.vignetting}")

    @property
    def nominal(self) -> bool:
        """True when the chart sits at its layout's place, positive, without vignetting: the
        original closed forms apply unchanged."""
        return self.pose.is_identity and not self.negative and self.vignetting == 0.0


    def bar_group(self, group: int, element: int, orientation: Orientation) -> BarGroup:
        """Geometry of one bar set (see :func:`benchlab.analysis.chart.layout.usaf_bar_group`)."""
        return usaf_bar_group(self.layout, group, element, orientation)

    def bar_set(self, group: int, element: int, orientation: Orientation) -> PosedBarSet:
        """Geometry of one bar set as imaged at the scene's pose."""
        return posed_bar_set(self.layout, self.pose, group, element, orientation)

    def sigmas_px(self, bars: BarGroup | PosedBarSet) -> tuple[float, float]:
        """Blur widths ``(along rows, along columns)`` applied to a bar set, px."""
        h = bars.image_height_mm
        extra = self.defocus_px**2
        return (
            math.sqrt(float(self.blur.tangential_px(h)) ** 2 + extra),
            math.sqrt(float(self.blur.sagittal_px(h)) ** 2 + extra),
        )

    def __call__(self, state: AcquisitionState) -> FloatArray:
        """Electron-rate image (e-/ms) for the camera simulator (a fresh copy each call)."""
        return self.rendered(state).copy()

    def rendered(self, state: AcquisitionState) -> FloatArray:
        """:meth:`__call__`'s image, cached and read-only (for a caller that composes it into
        a new array anyway)."""
        scene = self
        defocus = (state.bench or {}).get("defocus_px")
        if defocus is not None and float(defocus) != self.defocus_px:
            scene = dataclasses.replace(self, defocus_px=abs(float(defocus)))
        return _render(scene, state.height, state.width)

    def render(self, height: int, width: int) -> FloatArray:
        """The cached, read-only electron-rate image of a ``height x width`` frame."""
        return _render(self, height, width)

    def _profile_values(self, bars: BarGroup, rows: FloatArray, cols: FloatArray
                        ) -> FloatArray:
        """The noise-free value (e-/ms) of a nominal chart at several pixel centres (``rows``,
        ``cols``: 1-D) at once: each point's value by the same operations in the same order
        (elementwise over points, and over the bars for their blurred profiles), in a few
        array calls instead of a dozen per point."""
        sig_r, sig_c = self.sigmas_px(bars)
        value = self.bright_rate * self._disc(rows, cols)
        top, left, bottom, right = (np.array(v, dtype=np.float64)[:, None]
                                    for v in zip(*bars.bars, strict=True))
        fy = box_blurred_rect(rows[None, :], top, bottom, sig_r)  # bars x points
        fx = box_blurred_rect(cols[None, :], left, right, sig_c)
        for k in range(len(bars.bars)):
            value -= (self.bright_rate - self.dark_rate) * fy[k] * fx[k]
        return np.asarray(value, dtype=np.float64)

    def _compose(self, bar_sum: FloatArray, rows: FloatArray, cols: FloatArray,
                 lit: FloatArray | None = None) -> FloatArray:
        """Pixel values from the summed blurred bars (the general, posed form). ``lit``: the
        lit disc times ``bright_rate`` at (rows, cols), when known; a positive chart then
        overwrites ``bar_sum`` (it becomes the image, with no full-frame temporaries)."""
        depth = self.bright_rate - self.dark_rate
        if lit is not None and not self.negative:
            img = np.multiply(bar_sum, depth, out=bar_sum)
            np.subtract(lit, img, out=img)
        else:
            disc = self._disc(rows, cols)
            if self.negative:
                img = disc * (self.dark_rate + depth * bar_sum)
            else:
                img = self.bright_rate * disc - depth * bar_sum
        if self.vignetting:
            cr, cc = self.circles.centre_rc
            rho2 = ((rows - cr) ** 2 + (cols - cc) ** 2) / self.circles.disc_radius_px**2
            img = img * np.clip(1.0 - self.vignetting * rho2, 0.0, None)
        return np.asarray(img, dtype=np.float64)

    def _set_sum(self, posed: PosedBarSet, rows: FloatArray, cols: FloatArray) -> FloatArray:
        """Sum of the set's three blurred, pixel-integrated bars at pixel centres (rows, cols)."""
        sig_r, sig_c = self.sigmas_px(posed)
        out = np.zeros(np.broadcast(rows, cols).shape)
        for centre, half_len, half_w in posed.bars():
            out += _rotated_bar(rows, cols, centre, half_len, half_w, posed.theta_deg, sig_r, sig_c)
        return out

    def truth_centre_levels(self, posed: PosedBarSet) -> tuple[float, float]:
        """Noise-free ``(bar, space)`` rates at the centre bar and the spaces beside it."""
        t = math.radians(posed.theta_deg)
        w = posed.bar_width_px
        pts = [(posed.centre_rc[0] + k * w * math.sin(t), posed.centre_rc[1] + k * w * math.cos(t))
               for k in (0, -1, 1)]
        r = np.array([[p[0] for p in pts]])
        c = np.array([[p[1] for p in pts]])
        vals = self._compose(self._set_sum(posed, r, c), r, c)[0]
        return float(vals[0]), float(0.5 * (vals[1] + vals[2]))

    def truth_levels(
        self, group: int, element: int, orientation: Orientation
    ) -> tuple[float, float]:
        """Noise-free ``(dark, bright)`` rates (e-/ms) of a bar set as imaged.

        Dark = the blurred, pixel-integrated profile at the centre of the middle bar; bright =
        at the centre of the spaces either side of it, both at mid bar length. That is the
        best sampling phase (a pixel centred on the bar and on the spaces): the pre-sampling
        bar contrast. A frame at a non-integer period samples other phases; near Nyquist its
        reading depends on that phase (the estimators flag it), and a measurement ROI must keep
        off the bar ends (:func:`benchlab.analysis.chart.layout.bar_set_roi`).
        """
        if not self.nominal:
            bar, space = self.truth_centre_levels(self.bar_set(group, element, orientation))
            return (space, bar) if self.negative else (bar, space)
        bars = self.bar_group(group, element, orientation)
        cr, cc = bars.centre_rc
        w = bars.bar_width_px
        # the centre, then the spaces either side, in one call
        if orientation == "sagittal":
            rows, cols = [cr, cr, cr], [cc, cc - w, cc + w]
        else:
            rows, cols = [cr, cr - w, cr + w], [cc, cc, cc]
        v = self._profile_values(bars, np.array(rows, dtype=np.float64),
                                 np.array(cols, dtype=np.float64))
        dark = float(v[0])
        bright = 0.5 * (float(v[1]) + float(v[2]))
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
                posed = self.bar_set(g, e, orientation)  # type: ignore[arg-type]
                dark, bright = self.truth_levels_dn8(g, e, orientation)  # type: ignore[arg-type]
                rows.append(
                    {
                        "label": bars.label,
                        "group": g,
                        "element": e,
                        "orientation": orientation,
                        "image_lp_per_mm": posed.image_lp_per_mm,
                        "image_height_mm": posed.image_height_mm,
                        "centre_rc": posed.centre_rc,
                        "bar_width_px": posed.bar_width_px,
                        "box": bars.box if self.nominal else posed.roi,
                        "dark_dn8": dark,
                        "bright_dn8": bright,
                        "modulation": eq29_modulation(dark, bright),
                    }
                )
        return rows

    def _disc(self, rows: FloatArray, cols: FloatArray) -> FloatArray:
        if self.full_field:
            return np.ones(np.broadcast_shapes(rows.shape, cols.shape))
        cr, cc = self.circles.centre_rc
        radius = np.hypot(rows - cr, cols - cc)
        edge = math.hypot(self.disc_edge_sigma_px, self.defocus_px)
        return saturated_ndtr((self.circles.disc_radius_px - radius) / edge)


@functools.lru_cache(maxsize=8)
def _render(scene: UsafScene, height: int, width: int) -> FloatArray:
    if not scene.nominal:
        return _render_posed(scene, height, width)
    img = _frame_lit(scene, height, width).copy()
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


def _frame_lit(scene: UsafScene, height: int, width: int) -> FloatArray:
    """``bright_rate`` times the lit disc over a whole frame, read-only: the same for every
    chart pose and defocus of a sweep (only the disc's own geometry and edge enter), so
    computed once."""
    return _frame_lit_of(scene.circles, scene.disc_edge_sigma_px, scene.defocus_px,
                         scene.full_field, scene.bright_rate, height, width)


@functools.lru_cache(maxsize=4)
def _frame_lit_of(circles: RadialLayout, disc_edge_sigma_px: float, defocus_px: float,
                  full_field: bool, bright_rate: float, height: int, width: int) -> FloatArray:
    probe = UsafScene(circles=circles, disc_edge_sigma_px=disc_edge_sigma_px,
                      defocus_px=defocus_px, full_field=full_field)
    rows = np.arange(height, dtype=np.float64)[:, None]
    cols = np.arange(width, dtype=np.float64)[None, :]
    lit = np.asarray(bright_rate * probe._disc(rows, cols), dtype=np.float64)
    lit.setflags(write=False)
    return lit


def _render_posed(scene: UsafScene, height: int, width: int) -> FloatArray:
    """Render at any pose / polarity / vignetting: sum the blurred bars, then compose."""
    bar_sum = np.zeros((height, width))
    for g, e in scene.layout.elements:
        for orientation in ("sagittal", "tangential"):
            posed = scene.bar_set(g, e, orientation)  # type: ignore[arg-type]
            sig_r, sig_c = scene.sigmas_px(posed)
            _add_bars(bar_sum, posed, sig_r, sig_c)
    rows = np.arange(height, dtype=np.float64)[:, None]
    cols = np.arange(width, dtype=np.float64)[None, :]
    img = scene._compose(bar_sum, rows, cols, _frame_lit(scene, height, width))
    np.maximum(img, 0.0, out=img)
    img.setflags(write=False)
    return img


def _f2(z: FloatArray) -> FloatArray:
    """Second antiderivative of the Gaussian CDF: ``((z^2 + 1) Phi(z) + z phi(z)) / 2``."""
    return 0.5 * ((z * z + 1.0) * ndtr(z) + z * np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi))


def _f1(z: FloatArray) -> FloatArray:
    """Antiderivative of the Gaussian CDF: ``z Phi(z) + phi(z)``."""
    return z * ndtr(z) + np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)


def _smoothed_step(t: FloatArray, sigma: float, p: float, q: float) -> FloatArray:
    """A unit step at 0 blurred by a Gaussian ``sigma`` and by boxes of widths ``p >= q``."""
    s = max(sigma, 1e-6)
    if q < 1e-6:
        return (s / p) * (_f1((t + p / 2) / s) - _f1((t - p / 2) / s))
    a, b = (p + q) / 2, (p - q) / 2
    return (s * s / (p * q)) * (
        _f2((t + a) / s) - _f2((t + b) / s) - _f2((t - b) / s) + _f2((t - a) / s)
    )


def _add_bars(bar_sum: FloatArray, posed: PosedBarSet, sig_r: float, sig_c: float) -> None:
    """Add a posed bar set's blurred bars (0..1 coverage) into ``bar_sum``, each only over
    the pixels its blur reaches."""
    height, width = bar_sum.shape
    for centre, half_len, half_w in posed.bars():
        reach = half_len + 6.0 * max(sig_r, sig_c) + 2.0
        r0 = max(int(np.floor(centre[0] - reach)), 0)
        r1 = min(int(np.ceil(centre[0] + reach)) + 1, height)
        c0 = max(int(np.floor(centre[1] - reach)), 0)
        c1 = min(int(np.ceil(centre[1] + reach)) + 1, width)
        if r0 >= r1 or c0 >= c1:
            continue
        rows = np.arange(r0, r1, dtype=np.float64)[:, None]
        cols = np.arange(c0, c1, dtype=np.float64)[None, :]
        bar_sum[r0:r1, c0:c1] += _rotated_bar(
            rows, cols, centre, half_len, half_w, posed.theta_deg, sig_r, sig_c)


def _rotated_bar(
    rows: FloatArray,
    cols: FloatArray,
    centre: tuple[float, float],
    half_len: float,
    half_w: float,
    theta_deg: float,
    sig_r: float,
    sig_c: float,
) -> FloatArray:
    """A bar (long axis at ``theta + 90``) blurred and pixel-integrated, at pixel centres.

    Product of the two slab responses (see the module docstring); at 0 / 90 degrees it is the
    exact separable form of :func:`benchlab.scenes.optics.box_blurred_rect`.
    """
    t = math.radians(theta_deg)
    ct, st = math.cos(t), math.sin(t)
    dy, dx = rows - centre[0], cols - centre[1]
    if ct == 1.0 and st == 0.0:
        # An unrotated bar: ``across`` is ``dx`` and ``along`` is ``dy`` (x * 1.0 is x; the
        # other axis times 0.0 can change only the sign of a zero, which the steps' shift by
        # the half width removes), so each factor is evaluated along its own axis and the
        # product broadcasts: the same values from a row and a column instead of a patch.
        across, along = dx, dy
    else:
        across = dx * ct + dy * st
        along = -dx * st + dy * ct
    sig_across = math.sqrt((sig_c * ct) ** 2 + (sig_r * st) ** 2)
    sig_along = math.sqrt((sig_c * st) ** 2 + (sig_r * ct) ** 2)
    p, q = max(abs(ct), abs(st)), min(abs(ct), abs(st))
    f_across = _smoothed_step(across + half_w, sig_across, p, q) - _smoothed_step(
        across - half_w, sig_across, p, q
    )
    f_along = _smoothed_step(along + half_len, sig_along, p, q) - _smoothed_step(
        along - half_len, sig_along, p, q
    )
    return np.asarray(f_across * f_along, dtype=np.float64)


#: Knobs of a ``usaf:...`` scene spec (``snap --simulate --scene``) and what they set.
USAF_SPEC_KNOBS = {
    "dx": "chart offset along columns, px (right +)",
    "dy": "chart offset along rows, px (down +)",
    "scale": "image scale vs the nominal magnification (> 0)",
    "rot": "rotation, deg (clockwise on screen +)",
    "vignetting": "fractional fall-off at the disc edge, 0 <= v < 1",
    "negative": "1 = negative target (bright bars on a dark ground)",
    "whole": "M > 0: the whole chart (groups -2 to 7) at Eq. 4.1 magnification M over the whole "
             "frame (0.25: a microscope's groups 4-7); 0 = the forward view's chart",
}


def usaf_scene_from_spec(spec: str) -> UsafScene:
    """A posed USAF scene from ``usaf`` or ``usaf:dx=..,dy=..,scale=..,rot=..[,vignetting=..]
    [,negative=1]`` (every knob optional; see :data:`USAF_SPEC_KNOBS`).

    Raises
    ------
    ValueError
        Naming the knob that is unknown, not a number or out of range.
    """
    head, _, rest = spec.partition(":")
    if head != "usaf":
        raise ValueError(f"not a usaf scene spec: {spec!r}")
    values = {"dx": 0.0, "dy": 0.0, "scale": 1.0, "rot": 0.0, "vignetting": 0.0, "negative": 0.0,
              "whole": 0.0}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, text = item.partition("=")
        key = key.strip()
        if key not in USAF_SPEC_KNOBS:
            raise ValueError(f"usaf knob {key!r} unknown; use {', '.join(USAF_SPEC_KNOBS)}")
        if not eq:
            raise ValueError(f"usaf knob {key!r} needs a value ({key}=NUMBER)")
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"usaf knob {key}={text!r} is not a number") from None
        if not math.isfinite(value):
            raise ValueError(f"usaf knob {key}={text!r} is not finite")
        values[key] = value
    if values["scale"] <= 0:
        raise ValueError(f"usaf knob scale={values['scale']:g} must be > 0")
    if not 0.0 <= values["vignetting"] < 1.0:
        raise ValueError(f"usaf knob vignetting={values['vignetting']:g} must be in [0, 1)")
    if values["negative"] not in (0.0, 1.0):
        raise ValueError("usaf knob negative must be 0 or 1")
    if values["whole"] < 0:
        raise ValueError(f"usaf knob whole={values['whole']:g} must be >= 0")
    pose = ChartPose((values["dy"], values["dx"]), values["scale"], values["rot"])
    if values["whole"] > 0:
        from benchlab.analysis.chart.layout import IMAGE_CENTRE_RC
        from benchlab.analysis.chart.whole_layout import whole_chart_layout

        return UsafScene(layout=whole_chart_layout(values["whole"], origin_rc=IMAGE_CENTRE_RC),
                         pose=pose, vignetting=values["vignetting"],
                         negative=values["negative"] == 1.0, full_field=True)
    return UsafScene(pose=pose, vignetting=values["vignetting"], negative=values["negative"] == 1.0)


def render_chart_image(
    layout: ChartLayout,
    pose: ChartPose,
    height: int,
    width: int,
    *,
    blur_px: float = 0.7,
    dark: float = 0.1,
    bright: float = 0.9,
) -> FloatArray:
    """A chart of any layout (e.g. the whole chart,
    :func:`benchlab.analysis.chart.whole_layout.whole_chart_layout`) imaged at ``pose`` onto a
    uniformly lit ``height x width`` frame: levels as fractions of full scale, every bar blurred
    by an isotropic Gaussian ``blur_px`` and integrated over the pixel aperture
    (:func:`_rotated_bar`). No noise, no vignetting: the test frame of a microscope or a lab
    camera that sees part of the chart. Bars off the frame cost nothing.
    """
    bar_sum = np.zeros((height, width))
    for g, e in layout.elements:
        for orientation in ("sagittal", "tangential"):
            posed = posed_bar_set(layout, pose, g, e, orientation)  # type: ignore[arg-type]
            _add_bars(bar_sum, posed, blur_px, blur_px)
    return np.asarray(bright - (bright - dark) * np.clip(bar_sum, 0.0, 1.0), dtype=np.float64)
