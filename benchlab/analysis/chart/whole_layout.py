"""The whole USAF 1951 chart: groups -2 to 7, both orientations, in the standard arrangement.

MIL-STD-150A (Table 4.9 of the thesis; the Thorlabs R3L3S1N target holds groups -2 to 7)
arranges the groups in pairs, an even group G and the odd group G + 1, each pair a *layer*;
every layer is a copy of the one outside it at a quarter of the size, nested in its middle.
Within a layer the odd group's elements 1-6 run down a column on the right from its upper right
corner; the even group's element 1 sits at the lower right and its elements 2-6 run down a
column on the left. Each element is two sets of three bars (bar length 5 x bar width, spaces one
bar width) side by side; in the left column the horizontal-bar (tangential) set is on the left,
in the right column and the even group's element 1 the vertical-bar (sagittal) set is.

Positions, measured on a real capture of such a chart (a public bright-field frame of groups
4-7, 3x objective, 3.45 um pixels: the three-bar sets found by :mod:`.whole`'s candidate search,
their centres and bar widths), in units of ``u``, the bar width of the layer's even element 1,
about the layer's centre (the point the layers shrink towards, found from groups 4 and 6, 5 and
7 to 0.1 u), x right, y down:

- the two sets of an element are 7 bar widths apart centre to centre (a gap of 2 widths);
- the left column is aligned on its left edge, at x = -15.86 u, element 2 at y = -9.79 u; the
  right column on its right edge, at x = +8.05 u, element 1 at y = -10.69 u; an element spans
  12 of its bar widths across;
- consecutive elements of a column are 3.55 (w_e + w_e+1) apart (3.53-3.58 measured: a gap of
  about two bar widths);
- the even element 1 is centred at (+1.94 u, +9.47 u).

The numbers printed beside the groups and the solid squares are not modelled (nothing in the
finder reads them).

Self-similarity: because each layer is the next one at 4x, a view holding only some layers looks
the same at scale ``s`` as the layers two groups coarser at ``s / 4``. Which groups a frame shows
therefore needs evidence or a magnification; see
:func:`benchlab.analysis.chart.whole.find_whole_chart`.
"""

from __future__ import annotations

from collections.abc import Mapping

from benchlab.analysis.chart.layout import ChartLayout
from benchlab.analysis.mtf.frequency import usaf_bar_width_mm
from benchlab.drivers.mightex.profile import PIXEL_PITCH_UM

#: Groups on the whole chart, coarse to fine (the R3L3S1N's -2 to 7).
WHOLE_CHART_GROUPS: tuple[int, ...] = tuple(range(-2, 8))
#: Layer geometry in units of the layer's even-group element-1 bar width (x right, y down).
LEFT_COLUMN_LEFT_EDGE_U = -15.86
LEFT_COLUMN_TOP_Y_U = -9.79
RIGHT_COLUMN_RIGHT_EDGE_U = 8.05
RIGHT_COLUMN_TOP_Y_U = -10.69
EVEN_FIRST_ELEMENT_U = (1.94, 9.47)
#: An element spans this many of its bar widths across (two 5-width sets and the gap).
ELEMENT_WIDTH_WIDTHS = 12.0
#: Gap between an element's two sets, in its bar widths.
SET_GAP_WIDTHS = 2.0
#: Centre-to-centre distance of consecutive elements of a column, in their summed bar widths.
ELEMENT_PITCH_WIDTHS = 3.55
#: Each layer is the one outside it at this fraction of the size.
LAYER_SHRINK = 0.25


def _column(group: int, elements: range, edge_u: float, side: float, top_y_u: float,
            u_mm: float) -> dict[tuple[int, int], tuple[float, float]]:
    """Element centres (x, y) mm of one column aligned on one edge (``side`` +1: its left
    edge at ``edge_u``, -1: its right edge), ``elements`` top to bottom."""
    out: dict[tuple[int, int], tuple[float, float]] = {}
    y = top_y_u * u_mm
    prev: int | None = None
    for e in elements:
        w = usaf_bar_width_mm(group, e)
        if prev is not None:
            y += ELEMENT_PITCH_WIDTHS * (usaf_bar_width_mm(group, prev) + w)
        out[(group, e)] = (edge_u * u_mm + side * 0.5 * ELEMENT_WIDTH_WIDTHS * w, y)
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
            out.update(_column(even, range(2, 7), LEFT_COLUMN_LEFT_EDGE_U, 1.0,
                               LEFT_COLUMN_TOP_Y_U, u_mm))
            out[(even, 1)] = (EVEN_FIRST_ELEMENT_U[0] * u_mm, EVEN_FIRST_ELEMENT_U[1] * u_mm)
        if even + 1 in groups:
            out.update(_column(even + 1, range(1, 7), RIGHT_COLUMN_RIGHT_EDGE_U, -1.0,
                               RIGHT_COLUMN_TOP_Y_U, u_mm))
    return out


def whole_chart_sagittal_left(groups: tuple[int, ...] = WHOLE_CHART_GROUPS
                              ) -> frozenset[tuple[int, int]]:
    """Elements whose vertical-bar (sagittal) set is on the left: the right columns (odd
    groups) and the even groups' element 1; the left columns have it on the right."""
    return frozenset((g, e) for g in groups for e in range(1, 7) if g % 2 == 1 or e == 1)


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
                       sagittal_left=whole_chart_sagittal_left(groups),
                       set_gap_bar_widths=SET_GAP_WIDTHS)
