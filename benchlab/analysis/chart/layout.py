"""Where the test charts fall in the image: pure geometry shared by the scenes and the procedures.

The simulated bench draws its charts from these numbers and the MTF procedure places its ROIs
from the same numbers, so an ROI "located on the chart" is on the bars by construction.

Coordinates
-----------
numpy (row, col), 0-based; pixel ``(r, c)`` covers ``[r - 0.5, r + 0.5] x [c - 0.5, c + 0.5]``
so its centre sits at the integer coordinate. Boxes are ``(r0, c0, r1, c1)``, end-exclusive:
``frame[r0:r1, c0:c1]``.

The thesis's image centre
-------------------------
Section 4.3.3 prints the centre as "(r,c) = (647, 561.5)" against a nominal "(640, 512)". The
nominal value only makes sense as (x, y) = (col, row) for a 1280 x 1024 frame, and Table 4.13
confirms it: the radial ROI centroid (row 270.5, col 1025.5) is 477.43 px from
(row 561.5, col 647) - the thesis's 477.43 px / 2.48 mm - but 597 px from (row 647, col 561.5).
So the optical centre is 1-based row 561.5, col 647, i.e. 0-based :data:`IMAGE_CENTRE_RC`.

Orientation (same convention as :mod:`benchlab.analysis.bars.roi`)
-------------------------------------------------------------
``orientation`` names the testing direction, the direction in which intensity varies.
Forward view (Table 4.11 note, "sagittal is in the horizontal direction"): **sagittal = vertical
bars** (intensity varies along columns), **tangential = horizontal bars**. Radial view (fig. 4.9):
the sagittal target has its bars along the endoscope axis, which the radial view images along the
image radius, so the bars are spokes and intensity varies around the circle; the tangential target
has bars around the cylinder, imaged as concentric rings, intensity varying along the radius.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Literal

from benchlab.analysis.mtf.frequency import (
    FORWARD_MAGNIFICATION,
    image_frequency_lp_per_mm,
    px_per_period,
    usaf_bar_width_mm,
    usaf_frequency_lp_per_mm,
)
from benchlab.drivers.mightex.profile import PIXEL_PITCH_UM, SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX

Orientation = Literal["sagittal", "tangential"]
ORIENTATIONS: tuple[Orientation, Orientation] = ("sagittal", "tangential")
Box = tuple[int, int, int, int]

#: Optical centre (row, col), 0-based: the thesis's 1-based (row 561.5, col 647).
IMAGE_CENTRE_RC: tuple[float, float] = (560.5, 646.0)
#: Radius of the forward-view disc, px (holds the 25 deg field point at 1.23 mm = 237 px).
FORWARD_DISC_RADIUS_PX = 250.0
#: Inner and outer radius of the radial-view annulus, px (field points 1.72-2.66 mm = 331-512
#: px inside). The outer edge is the field-of-view circle; at this centre it runs off the bottom
#: of the frame (row 560.5 + 545 > 1023), the clipping the thesis zero-padded around.
ANNULUS_INNER_RADIUS_PX = 300.0
ANNULUS_OUTER_RADIUS_PX = 545.0
#: The common radial ROI: the thesis's rectangle with vertices rows 250/290, cols 1000/1050 is
#: 40 x 50 px with centroid (270.5, 1025.5) 1-based (Table 4.13), i.e. 0-based rows 250-289,
#: cols 1000-1049.
RADIAL_ROI_BOX: Box = (250, 1000, 290, 1050)
#: How far (px) the measurement ROI of a bar set keeps each pixel's aperture inside the ends of
#: the bars (see :func:`bar_set_roi`): the forward blur is 0.12-0.70 px, so a pixel flush with a
#: bar end still reads some of the bright ground beyond it.
ROI_END_MARGIN_PX = 0.25
#: Gap between an element's tangential and sagittal bar sets, in bar widths (centre to centre the
#: two sets are 9 bar widths apart, as the thesis's ROI centroids show).
SET_GAP_BAR_WIDTHS = 4.0

#: Centre of each element (midway between its two bar sets) relative to the chart origin, in
#: object mm, x to the right and y down. Derived from the thesis's ROI centroids (Table 4.13):
#: pixel offset from the image centre x 5.2 um x 16.3.
_PX_TO_OBJECT_MM = PIXEL_PITCH_UM / 1000.0 * FORWARD_MAGNIFICATION
THESIS_ELEMENT_CENTRES_MM: Mapping[tuple[int, int], tuple[float, float]] = {
    (g, e): (dc * _PX_TO_OBJECT_MM, dr * _PX_TO_OBJECT_MM)
    for (g, e), (dr, dc) in {
        (1, 5): (59.5, -110.0),
        (1, 6): (41.5, -112.75),
        (2, 1): (44.0, -52.5),
        (2, 2): (91.25, -17.0),
        (2, 3): (76.75, -16.0),
        (2, 4): (63.5, -16.0),
        (2, 5): (51.25, -16.0),
        (2, 6): (41.0, -15.5),
        (3, 1): (94.5, -56.5),
    }.items()
}
#: Elements whose sagittal set is left of the tangential one (the chart mirrors its groups;
#: Table 4.13's centroids show which); in the others the sagittal set is on the right.
THESIS_SAGITTAL_LEFT: frozenset[tuple[int, int]] = frozenset({(1, 5), (1, 6), (2, 1), (3, 1)})
#: The chart's coarser elements around the thesis's (the R3L3S1N chart has every group; the
#: thesis measured G1E5-G3E1 only): group 1 continues its column below G1E5, elements growing
#: downwards as in group 2; group 0 is a column of its own right of group 2, as far below the
#: slanted-edge squares (:mod:`benchlab.analysis.sfr.target`) as the thesis's elements. Centres
#: as (row, col) px offsets from the chart origin at the nominal magnification, like the
#: thesis's, consecutive elements 6.5-8 mean bar widths apart. Their 2-6 px bars (at 16.3x)
#: give the chart finder (:mod:`benchlab.analysis.chart.finder`) separable three-bar sets at
#: any pose.
COARSE_ELEMENT_CENTRES_MM: Mapping[tuple[int, int], tuple[float, float]] = {
    (g, e): (dc * _PX_TO_OBJECT_MM, dr * _PX_TO_OBJECT_MM)
    for (g, e), (dr, dc) in {
        (0, 1): (190.9, 55.0),
        (0, 2): (154.6, 55.0),
        (0, 3): (122.3, 55.0),
        (0, 4): (93.5, 55.0),
        (0, 5): (67.8, 55.0),
        (0, 6): (45.0, 55.0),
        (1, 1): (135.0, -110.0),
        (1, 2): (113.0, -110.0),
        (1, 3): (93.5, -110.0),
        (1, 4): (76.0, -110.0),
    }.items()
}
COARSE_SAGITTAL_LEFT: frozenset[tuple[int, int]] = frozenset({(1, 1), (1, 2), (1, 3), (1, 4)})


@dataclass(frozen=True)
class ChartLayout:
    """How the USAF 1951 chart is imaged by the forward view.

    Parameters
    ----------
    origin_rc
        Image position (row, col, px, 0-based) of the chart origin.
    optical_centre_rc
        Optical centre, used for image heights.
    magnification
        Object-to-image frequency factor (Eq. 4.1); image size = object size / magnification.
    pixel_pitch_um
        Sensor pixel pitch.
    element_centres_mm
        ``(group, element) -> (x_mm, y_mm)`` element centres on the chart, relative to the origin.
    sagittal_left
        Elements whose sagittal (vertical-bar) set is left of their tangential set.
    set_gap_bar_widths
        Gap between an element's two sets, in its bar widths (their centres are 5 + this
        apart).
    """

    origin_rc: tuple[float, float] = IMAGE_CENTRE_RC
    optical_centre_rc: tuple[float, float] = IMAGE_CENTRE_RC
    magnification: float = FORWARD_MAGNIFICATION
    pixel_pitch_um: float = PIXEL_PITCH_UM
    element_centres_mm: Mapping[tuple[int, int], tuple[float, float]] = field(
        default_factory=lambda: {**COARSE_ELEMENT_CENTRES_MM, **THESIS_ELEMENT_CENTRES_MM}
    )
    sagittal_left: frozenset[tuple[int, int]] = THESIS_SAGITTAL_LEFT | COARSE_SAGITTAL_LEFT
    set_gap_bar_widths: float = SET_GAP_BAR_WIDTHS

    def __hash__(self) -> int:  # the mapping field is not hashable by itself
        return hash(
            (
                self.origin_rc,
                self.optical_centre_rc,
                self.magnification,
                self.pixel_pitch_um,
                tuple(sorted(self.element_centres_mm.items())),
                self.sagittal_left,
                self.set_gap_bar_widths,
            )
        )

    def object_mm_to_px(self, length_mm: float) -> float:
        """Image length in pixels of an object length on the chart."""
        return length_mm / self.magnification * 1000.0 / self.pixel_pitch_um

    @property
    def elements(self) -> tuple[tuple[int, int], ...]:
        """The (group, element) pairs on the chart, coarse to fine."""
        return tuple(sorted(self.element_centres_mm))


@dataclass(frozen=True)
class BarGroup:
    """One set of three bars of a USAF element, as imaged.

    ``bars`` are the dark bars as continuous rectangles ``(top, left, bottom, right)`` in pixel
    coordinates; ``extent`` is the 5 x 5 bar-width square they fill; ``box`` is every pixel whose
    centre lies inside ``extent`` (at least one pixel); ``roi`` is the measurement ROI
    (:func:`bar_set_roi`): ``box`` without the pixels that straddle the ends of the bars.
    """

    group: int
    element: int
    orientation: Orientation
    object_lp_per_mm: float
    image_lp_per_mm: float
    px_per_period: float
    bar_width_px: float
    bar_length_px: float
    centre_rc: tuple[float, float]
    extent: tuple[float, float, float, float]
    bars: tuple[tuple[float, float, float, float], ...]
    box: Box
    image_height_mm: float

    @property
    def label(self) -> str:
        """Thesis label, e.g. ``G2E4S``."""
        return f"G{self.group}E{self.element}{self.orientation[0].upper()}"

    @property
    def roi(self) -> Box:
        """Measurement ROI of the set (:func:`bar_set_roi` of ``extent``)."""
        return bar_set_roi(self.extent, self.orientation)

    @property
    def varies_along_axis(self) -> int:
        """numpy axis along which intensity varies: 1 for sagittal, 0 for tangential."""
        return 1 if self.orientation == "sagittal" else 0


def pixel_box(extent: tuple[float, float, float, float]) -> Box:
    """Pixels whose centres lie inside a continuous ``(top, left, bottom, right)`` rectangle.

    Never empty: a rectangle smaller than a pixel gives the pixel holding its centre.
    """
    top, left, bottom, right = extent
    r0, c0 = math.ceil(top), math.ceil(left)
    r1, c1 = math.floor(bottom) + 1, math.floor(right) + 1
    if r1 <= r0:
        r0 = round((top + bottom) / 2)
        r1 = r0 + 1
    if c1 <= c0:
        c0 = round((left + right) / 2)
        c1 = c0 + 1
    return (r0, c0, r1, c1)


def bar_set_roi(
    extent: tuple[float, float, float, float],
    orientation: Orientation,
    margin_px: float = ROI_END_MARGIN_PX,
) -> Box:
    """Measurement ROI of a bar set filling the continuous ``extent`` (top, left, bottom, right).

    Across the bars (the direction the intensity varies): every pixel whose centre lies inside
    the extent, as :func:`pixel_box` - the outer bars' edges are part of the bar pattern. Along
    the bars: only pixels whose whole aperture lies at least ``margin_px`` inside the bar ends.
    A pixel that straddles a bar end reads bar and bright ground at once, lifting the dark
    level and lowering the bright one. On the forward view's 7-10 px bar sets one such row (or
    column) at each end is 2 of 7-10 lines of the averaged bar profile, and the modulation
    read from it falls by up to 0.12 (G2E2, 0.38 cycles/px). Never empty: a bar shorter than a
    pixel plus the margins keeps the line nearest its middle.
    """
    top, left, bottom, right = extent

    def inner(a: float, b: float) -> tuple[int, int]:
        lo, hi = math.ceil(a + margin_px + 0.5), math.floor(b - margin_px - 0.5)
        if hi < lo:
            lo = round((a + b) / 2)
            hi = lo
        return lo, hi + 1

    r0, c0, r1, c1 = pixel_box(extent)
    if orientation == "sagittal":  # vertical bars: along the bars = along rows
        r0, r1 = inner(top, bottom)
    else:
        c0, c1 = inner(left, right)
    return (r0, c0, r1, c1)


def box_centroid(box: Box) -> tuple[float, float]:
    """Centroid (row, col) of the pixel centres of a box."""
    r0, c0, r1, c1 = box
    return ((r0 + r1 - 1) / 2.0, (c0 + c1 - 1) / 2.0)


def image_height_mm(
    point_rc: tuple[float, float],
    centre_rc: tuple[float, float] = IMAGE_CENTRE_RC,
    pixel_pitch_um: float = PIXEL_PITCH_UM,
) -> float:
    """Distance from the optical centre to a point, in mm on the sensor (section 4.3.3)."""
    return math.hypot(point_rc[0] - centre_rc[0], point_rc[1] - centre_rc[1]) * pixel_pitch_um / 1e3


def usaf_bar_group(
    layout: ChartLayout, group: int, element: int, orientation: Orientation
) -> BarGroup:
    """Geometry of one bar set of a USAF element under ``layout``.

    The two sets sit side by side on the element's row, each 5 bar widths square, their centres
    9 bar widths apart; the sagittal (vertical-bar) set is on the right unless the element is in
    ``layout.sagittal_left``.

    Raises
    ------
    KeyError
        If the element is not on the chart layout.
    ValueError
        For an unknown orientation.
    """
    if orientation not in ORIENTATIONS:
        raise ValueError(f"orientation must be 'sagittal' or 'tangential', got {orientation!r}")
    if (group, element) not in layout.element_centres_mm:
        raise KeyError(f"G{group}E{element} is not on the chart (have {layout.elements})")
    x_mm, y_mm = layout.element_centres_mm[(group, element)]
    w = layout.object_mm_to_px(usaf_bar_width_mm(group, element))
    half_offset = (5.0 + layout.set_gap_bar_widths) * w / 2.0
    side = 1.0 if orientation == "sagittal" else -1.0
    if (group, element) in layout.sagittal_left:
        side = -side
    cr = layout.origin_rc[0] + layout.object_mm_to_px(y_mm)
    cc = layout.origin_rc[1] + layout.object_mm_to_px(x_mm) + side * half_offset
    top, left, bottom, right = cr - 2.5 * w, cc - 2.5 * w, cr + 2.5 * w, cc + 2.5 * w
    bars: list[tuple[float, float, float, float]] = []
    for k in (-1, 0, 1):  # dark bars at -2w, 0, +2w from the set centre
        if orientation == "sagittal":
            bars.append((top, cc + 2 * k * w - w / 2, bottom, cc + 2 * k * w + w / 2))
        else:
            bars.append((cr + 2 * k * w - w / 2, left, cr + 2 * k * w + w / 2, right))
    obj_f = usaf_frequency_lp_per_mm(group, element)
    img_f = image_frequency_lp_per_mm(obj_f, layout.magnification)
    return BarGroup(
        group=group,
        element=element,
        orientation=orientation,
        object_lp_per_mm=obj_f,
        image_lp_per_mm=img_f,
        px_per_period=px_per_period(img_f, layout.pixel_pitch_um),
        bar_width_px=w,
        bar_length_px=5.0 * w,
        centre_rc=(cr, cc),
        extent=(top, left, bottom, right),
        bars=tuple(bars),
        box=pixel_box((top, left, bottom, right)),
        image_height_mm=image_height_mm((cr, cc), layout.optical_centre_rc, layout.pixel_pitch_um),
    )


def usaf_bar_groups(
    layout: ChartLayout | None = None,
    elements: Iterable[tuple[int, int]] | None = None,
) -> list[BarGroup]:
    """Every bar set (sagittal and tangential) of the given elements (default: all on the chart)."""
    lay = layout if layout is not None else ChartLayout()
    chosen = lay.elements if elements is None else tuple(elements)
    return [usaf_bar_group(lay, g, e, o) for g, e in chosen for o in ORIENTATIONS]


@dataclass(frozen=True)
class RadialLayout:
    """The dual-view image's circles: forward disc and radial annulus (px, 0-based)."""

    centre_rc: tuple[float, float] = IMAGE_CENTRE_RC
    disc_radius_px: float = FORWARD_DISC_RADIUS_PX
    annulus_inner_radius_px: float = ANNULUS_INNER_RADIUS_PX
    annulus_outer_radius_px: float = ANNULUS_OUTER_RADIUS_PX
    pixel_pitch_um: float = PIXEL_PITCH_UM

    def radius_px(self, point_rc: tuple[float, float]) -> float:
        """Distance of a point from the optical centre, px."""
        return math.hypot(point_rc[0] - self.centre_rc[0], point_rc[1] - self.centre_rc[1])

    def box_in_annulus(self, box: Box) -> bool:
        """True when every pixel centre of ``box`` lies inside the annulus."""
        r0, c0, r1, c1 = box
        corners = [(r, c) for r in (r0, r1 - 1) for c in (c0, c1 - 1)]
        radii = [self.radius_px(p) for p in corners]
        # The annulus is convex outward only; the nearest point may be an edge midpoint.
        cr, cc = self.centre_rc
        near_r = min(max(cr, r0), r1 - 1)
        near_c = min(max(cc, c0), c1 - 1)
        nearest = self.radius_px((near_r, near_c))
        inner_ok = nearest >= self.annulus_inner_radius_px
        return inner_ok and max(radii) <= self.annulus_outer_radius_px

    def fov_clipped(
        self, height_px: int = SENSOR_HEIGHT_PX, width_px: int = SENSOR_WIDTH_PX
    ) -> bool:
        """True when the field-of-view circle runs off the frame."""
        r, c = self.centre_rc
        rad = self.annulus_outer_radius_px
        inside_top_left = r - rad >= -0.5 and c - rad >= -0.5
        inside_bottom_right = r + rad <= height_px - 0.5 and c + rad <= width_px - 0.5
        return not (inside_top_left and inside_bottom_right)


def radial_roi_default() -> Box:
    """The thesis's common radial ROI as a 0-based end-exclusive box."""
    return RADIAL_ROI_BOX
