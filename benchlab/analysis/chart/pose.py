"""A USAF 1951 chart at any pose: offset, scale and rotation of its image, and the bar sets there.

The nominal geometry is :class:`benchlab.analysis.chart.layout.ChartLayout` (the configured
magnification, the chart origin at its configured place, bars parallel to the pixel axes). A
:class:`ChartPose` moves that image: every nominal point ``p`` goes to

    p' = origin + offset + scale * R(rotation) (p - origin)

with ``R`` a rotation in (x = column, y = row) coordinates by ``rotation_deg`` from the column axis
towards the row axis - clockwise on a displayed image, the same sense as the angle of
:mod:`benchlab.analysis.bars.projection`. ``scale`` > 1 is a larger image (magnification / scale in
the Eq. 4.1 sense: image frequency = object frequency x magnification / scale).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.chart.layout import (
    ROI_END_MARGIN_PX,
    Box,
    ChartLayout,
    Orientation,
    image_height_mm,
    usaf_bar_group,
)
from benchlab.analysis.mtf.frequency import px_per_period

Point = tuple[float, float]

#: Half width across the bars, in bar widths, of the measurement ROI: the set (``2.5``) plus half
#: a space each side, so the ROI holds exactly three whole periods of the bar pattern (the
#: ground beside the outer bars reads as the space that would follow them). A ROI of 2.5
#: periods leaves the estimators an unbalanced pattern: on the benchmark's 3-5 px periods it
#: misread the modulation by more than 0.03 in twice as many sets.
WHOLE_PERIODS_HALF_WIDTHS = 3.0
#: Bars within this many degrees of a pixel axis count as axis-aligned: every line across them
#: then samples the same phases, and the estimators may take the axis as the bar direction.
#: Beyond it the direction must be measured (the estimators take an axis, not an angle, as a
#: prior: a set at 2-15 deg measured as if on the axis read up to 0.2 off on a small ROI).
AXIS_TOLERANCE_DEG = 0.5


@dataclass(frozen=True)
class ChartPose:
    """Offset (px), scale and rotation (deg, clockwise on screen) of the imaged chart.

    ``offset_rc`` moves the chart origin (row, col); scale and rotation act about the origin.
    """

    offset_rc: Point = (0.0, 0.0)
    scale: float = 1.0
    rotation_deg: float = 0.0

    def __post_init__(self) -> None:
        if not (self.scale > 0 and math.isfinite(self.scale)):
            raise ValueError(f"chart scale must be a positive number, got {self.scale}")
        if not all(math.isfinite(v) for v in (*self.offset_rc, self.rotation_deg)):
            raise ValueError("chart offset and rotation must be finite")

    @property
    def is_identity(self) -> bool:
        """True for the nominal pose (no offset, unit scale, no rotation)."""
        return self.offset_rc == (0.0, 0.0) and self.scale == 1.0 and self.rotation_deg == 0.0

    def apply(self, point_rc: Point, origin_rc: Point) -> Point:
        """Image position of the nominal point ``point_rc`` of a chart with origin ``origin_rc``."""
        phi = math.radians(self.rotation_deg)
        dy, dx = point_rc[0] - origin_rc[0], point_rc[1] - origin_rc[1]
        x = self.scale * (dx * math.cos(phi) - dy * math.sin(phi))
        y = self.scale * (dx * math.sin(phi) + dy * math.cos(phi))
        return (origin_rc[0] + self.offset_rc[0] + y, origin_rc[1] + self.offset_rc[1] + x)


@dataclass(frozen=True)
class PosedBarSet:
    """One three-bar set of the chart as imaged at a pose.

    ``theta_deg`` is the direction in which the intensity varies (across the bars), from the
    column axis towards the row axis: ``rotation`` for a sagittal (vertical-bar) set,
    ``90 + rotation`` for a tangential one. The bars are ``5 w`` long and ``w`` wide, dark bars
    centred at ``-2w, 0, +2w`` along that direction.
    """

    group: int
    element: int
    orientation: Orientation
    centre_rc: Point
    bar_width_px: float
    theta_deg: float
    object_lp_per_mm: float
    image_lp_per_mm: float
    px_per_period: float
    image_height_mm: float

    @property
    def label(self) -> str:
        """Thesis label, e.g. ``G2E4S``."""
        return f"G{self.group}E{self.element}{self.orientation[0].upper()}"

    @property
    def half_size_px(self) -> float:
        """Half the side of the 5 x 5 bar-width square the set fills."""
        return 2.5 * self.bar_width_px

    def bars(self) -> list[tuple[Point, float, float]]:
        """Dark bars as ``(centre_rc, half_length, half_width)``, long axis at ``theta + 90``."""
        t = math.radians(self.theta_deg)
        w = self.bar_width_px
        cr, cc = self.centre_rc
        return [
            ((cr + k * 2 * w * math.sin(t), cc + k * 2 * w * math.cos(t)), 2.5 * w, 0.5 * w)
            for k in (-1, 0, 1)
        ]

    def corners(self) -> list[Point]:
        """The four corners (row, col) of the set's square, in drawing order."""
        t = math.radians(self.theta_deg)
        h = self.half_size_px
        ux, uy = math.cos(t), math.sin(t)  # across the bars
        vx, vy = -uy, ux  # along the bars
        out = []
        for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            out.append((self.centre_rc[0] + h * (su * uy + sv * vy),
                        self.centre_rc[1] + h * (su * ux + sv * vx)))
        return out

    @property
    def roi(self) -> Box:
        """The bar-set ROI: :func:`posed_bar_set_roi` of this set (across: the set only)."""
        return posed_bar_set_roi(self.centre_rc, self.bar_width_px, self.theta_deg)

    @property
    def whole_period_roi(self) -> Box:
        """The set's ROI over three whole periods across the bars (half a space beyond each
        outer bar, :data:`WHOLE_PERIODS_HALF_WIDTHS`), bar ends trimmed as in :attr:`roi`."""
        return posed_bar_set_roi(self.centre_rc, self.bar_width_px, self.theta_deg,
                                 half_across_widths=WHOLE_PERIODS_HALF_WIDTHS)

    @property
    def axis_aligned(self) -> bool:
        """True when the bars lie along a pixel axis within :data:`AXIS_TOLERANCE_DEG`."""
        return abs((self.theta_deg + 45.0) % 90.0 - 45.0) <= AXIS_TOLERANCE_DEG


def posed_bar_set(
    layout: ChartLayout, pose: ChartPose, group: int, element: int, orientation: Orientation
) -> PosedBarSet:
    """Geometry of one bar set of ``layout`` imaged at ``pose``.

    Raises
    ------
    KeyError
        If the element is not on the layout.
    ValueError
        For an unknown orientation.
    """
    nominal = usaf_bar_group(layout, group, element, orientation)
    centre = pose.apply(nominal.centre_rc, layout.origin_rc)
    img_f = nominal.image_lp_per_mm / pose.scale
    theta = pose.rotation_deg + (0.0 if orientation == "sagittal" else 90.0)
    return PosedBarSet(
        group=group,
        element=element,
        orientation=orientation,
        centre_rc=centre,
        bar_width_px=nominal.bar_width_px * pose.scale,
        theta_deg=theta,
        object_lp_per_mm=nominal.object_lp_per_mm,
        image_lp_per_mm=img_f,
        px_per_period=px_per_period(img_f, layout.pixel_pitch_um),
        image_height_mm=image_height_mm(centre, layout.optical_centre_rc, layout.pixel_pitch_um),
    )


def posed_bar_sets(layout: ChartLayout, pose: ChartPose) -> list[PosedBarSet]:
    """Every bar set of the layout at the pose, coarse to fine, sagittal before tangential."""
    return [
        posed_bar_set(layout, pose, g, e, o)
        for g, e in layout.elements
        for o in ("sagittal", "tangential")
    ]


def posed_bar_set_roi(
    centre_rc: Point, bar_width_px: float, theta_deg: float, margin_px: float = ROI_END_MARGIN_PX,
    half_across_widths: float = 2.5,
) -> Box:
    """Largest axis-aligned pixel box inside a (possibly rotated) bar set, bar ends trimmed.

    The rule of :func:`~.layout.bar_set_roi`, at any angle: across the bars every
    pixel centre lies inside the set (the outer bars' edges are part of the pattern); along the
    bars every pixel's whole aperture lies ``margin_px`` inside the bar ends (a 1-px aperture
    at angle ``t`` reaches ``(|cos t| + |sin t|) / 2`` along any axis). The region is convex, so
    a box is inside when its four corner pixels are; among the boxes centred on the set the one
    with most pixels wins. At 0 or 90 degrees this is exactly ``bar_set_roi``. Never empty: the
    pixel holding the centre when nothing fits. ``half_across_widths`` (bar widths from the
    centre) widens the region across the bars (3 = three whole periods).
    """
    t = math.radians(theta_deg)
    cu, su = math.cos(t), math.sin(t)
    reach = 0.5 * (abs(cu) + abs(su))
    half_across = half_across_widths * bar_width_px + 1e-9
    half_along = 2.5 * bar_width_px - margin_px - reach + 1e-9
    cr, cc = centre_rc
    if half_along >= 0:
        # every candidate top row r0 with the bottom rows r1 that centre the box on the set
        extent = math.ceil(1.45 * max(half_across, half_along + reach)) + 1
        r_mid = math.floor(cr)
        r0 = np.repeat(np.arange(r_mid - extent, r_mid + 1, dtype=np.float64), 2)
        r1 = np.empty_like(r0)
        r1[0::2], r1[1::2] = np.floor(2 * cr - r0[0::2]), np.ceil(2 * cr - r0[1::2])
        lo, hi = _x_range(r0 - cr, r1 - cr, cu, su, half_across, half_along)
        c0, c1 = np.ceil(cc + lo - 1e-9), np.floor(cc + hi + 1e-9)
        n = np.where((r1 >= r0) & (c1 >= c0), (r1 - r0 + 1) * (c1 - c0 + 1), 0.0)
        i = int(np.argmax(n))  # the first of the largest, as the rows are scanned top down
        if n[i] > 0:
            return (int(r0[i]), int(c0[i]), int(r1[i]) + 1, int(c1[i]) + 1)
    r, c = round(cr), round(cc)
    return (r, c, r + 1, c + 1)


def _x_range(
    dy0: FloatArray, dy1: FloatArray, cu: float, su: float, half_across: float,
    half_along: float,
) -> tuple[FloatArray, FloatArray]:
    """Column offsets x for which (x, dy) lies in the rotated rectangle for both dy0 and dy1
    (arrays: one interval per pair; empty where ``lo > hi``).

    Across: ``|x cu + dy su| <= half_across``; along: ``|-x su + dy cu| <= half_along``. Each
    is an interval in x (or all or nothing when its coefficient vanishes).
    """
    lo = np.full(dy0.shape, -np.inf)
    hi = np.full(dy0.shape, np.inf)
    for dy in (dy0, dy1):
        for coef, const, half in ((cu, dy * su, half_across), (-su, dy * cu, half_along)):
            if abs(coef) < 1e-12:
                outside = np.abs(const) > half
                lo, hi = np.where(outside, 1.0, lo), np.where(outside, -1.0, hi)
                continue
            a, b = (-half - const) / coef, (half - const) / coef
            lo, hi = np.maximum(lo, np.minimum(a, b)), np.minimum(hi, np.maximum(a, b))
    return lo, hi
