"""The whole USAF 1951 chart: groups -2 to 7, both orientations, in the standard arrangement.

MIL-STD-150A (Table 4.9 of the thesis, the Thorlabs R3L3S1N target) arranges the groups in
pairs, an even group G and the odd group G + 1, each pair a *layer*; every layer is a copy of
the one outside it at a quarter of the size, nested in its middle (five layers for -2..7).
Within a layer the odd group's elements 1-6 run down a column on the right from its upper right
corner; the even group's element 1 sits at the lower right and its elements 2-6 run down a
column on the left. Each element is two sets of three bars (bar length 5 x bar width, spaces
one bar width) side by side, 9 bar widths apart centre to centre; the left column has its
vertical-bar (sagittal) set on the left, the right column and the even group's element 1 on
the right - the chart is mirror-like about its middle.

Positions. The spacings come from the R3L3S1N as the thesis imaged it (its ROI centroids,
Table 4.13, the same numbers as :data:`benchlab.analysis.chart.layout.THESIS_ELEMENT_CENTRES_MM`:
its forward frame shows the chart turned by 180 deg). In units of ``u``, the bar width of the
layer's even group element 1, about the layer's centre (the point the layers shrink towards):
the right column at x = +12.1 u from y = -17.8 u (element 1), the left column at x = -15.4 u
from y = -15.6 u (element 2), the even element 1 at (+9.4 u, +16.5 u); consecutive elements of
a column 6 (w_e + w_e+1) apart (the thesis's group 2 column: 5.8-6.2). The layer centre follows
from the thesis's groups 1 and 3 under the quarter-size nesting. The numbers printed beside the
groups are not modelled (nothing in the finder reads them).

Self-similarity: because each layer is the next one at 4x, a view holding only some layers looks
the same at scale ``s`` as the layers two groups coarser at ``s / 4``. Which groups a frame shows
therefore needs a magnification (a hint within a factor 2 suffices); see
:func:`benchlab.analysis.chart.whole.find_whole_chart`.
"""

from __future__ import annotations

from collections.abc import Mapping

from benchlab.analysis.chart.layout import ChartLayout
from benchlab.analysis.mtf.frequency import usaf_bar_width_mm
from benchlab.drivers.sensor import PIXEL_PITCH_UM

#: Groups on the whole chart, coarse to fine (the R3L3S1N's -2 to 7).
WHOLE_CHART_GROUPS: tuple[int, ...] = tuple(range(-2, 8))
#: Layer geometry in units of the layer's even-group element-1 bar width (x right, y down).
RIGHT_COLUMN_X_U = 12.1
RIGHT_COLUMN_TOP_Y_U = -17.8
LEFT_COLUMN_X_U = -15.4
LEFT_COLUMN_TOP_Y_U = -15.6
EVEN_FIRST_ELEMENT_U = (9.4, 16.5)
#: Centre-to-centre distance of consecutive elements of a column, in their summed bar widths.
ELEMENT_PITCH_WIDTHS = 6.0
#: Each layer is the one outside it at this fraction of the size.
LAYER_SHRINK = 0.25


def _column(group: int, elements: range, x_u: float, top_y_u: float, u_mm: float
            ) -> dict[tuple[int, int], tuple[float, float]]:
    """Element centres (x, y) mm of one column, ``elements`` top to bottom."""
    out: dict[tuple[int, int], tuple[float, float]] = {}
    y = top_y_u * u_mm
    prev: int | None = None
    for e in elements:
        if prev is not None:
            y += ELEMENT_PITCH_WIDTHS * (usaf_bar_width_mm(group, prev)
                                         + usaf_bar_width_mm(group, e))
        out[(group, e)] = (x_u * u_mm, y)
        prev = e
    return out


def whole_chart_centres_mm(groups: tuple[int, ...] = WHOLE_CHART_GROUPS
                           ) -> Mapping[tuple[int, int], tuple[float, float]]:
    """``(group, element) -> (x_mm, y_mm)`` about the chart's centre for the given groups
    (a layer is drawn for every even group G with G or G + 1 among them)."""
    out: dict[tuple[int, int], tuple[float, float]] = {}
    evens = sorted({g - (g % 2) for g in groups})
    for even in evens:
        u_mm = usaf_bar_width_mm(even, 1)
        if even in groups:
            out.update(_column(even, range(2, 7), LEFT_COLUMN_X_U, LEFT_COLUMN_TOP_Y_U, u_mm))
            out[(even, 1)] = (EVEN_FIRST_ELEMENT_U[0] * u_mm, EVEN_FIRST_ELEMENT_U[1] * u_mm)
        if even + 1 in groups:
            out.update(_column(even + 1, range(1, 7), RIGHT_COLUMN_X_U, RIGHT_COLUMN_TOP_Y_U,
                               u_mm))
    return out


def whole_chart_sagittal_left(groups: tuple[int, ...] = WHOLE_CHART_GROUPS
                              ) -> frozenset[tuple[int, int]]:
    """Elements of the left columns (even groups, elements 2-6): sagittal set on the left."""
    return frozenset((g, e) for g in groups if g % 2 == 0 for e in range(2, 7))


def whole_chart_layout(
    magnification: float,
    origin_rc: tuple[float, float] = (0.0, 0.0),
    pixel_pitch_um: float = PIXEL_PITCH_UM,
    groups: tuple[int, ...] = WHOLE_CHART_GROUPS,
) -> ChartLayout:
    """The whole chart as a :class:`~benchlab.analysis.chart.layout.ChartLayout`: its centre
    imaged at ``origin_rc`` at the Eq. 4.1 ``magnification`` (image lp/mm = object lp/mm x
    magnification: 16.3 for the forward view, 0.1 under a 10x microscope objective)."""
    if not magnification > 0:
        raise ValueError(f"magnification must be > 0, got {magnification}")
    return ChartLayout(origin_rc=origin_rc, optical_centre_rc=origin_rc,
                       magnification=magnification, pixel_pitch_um=pixel_pitch_um,
                       element_centres_mm=dict(whole_chart_centres_mm(groups)),
                       sagittal_left=whole_chart_sagittal_left(groups))
