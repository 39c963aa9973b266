"""Where the slanted-edge target falls in the forward view: pure geometry shared by the scene and
the MTF procedure (as :mod:`benchlab.analysis.chart.layout` is for the USAF chart).

The target is a set of dark squares (chrome on the same glass as the chart, so the same dark
level) turned a few degrees off square, placed in the empty upper-right part of the forward
disc at several image heights, away from the USAF elements (which sit below-left of the optical
centre, rows 598-657, cols 522-638). Each side of a square is one slanted edge; its
measurement ROI covers the middle of the side, keeping clear of the corners (where the
neighbouring side's blur reaches) and of the square's far side.

Coordinates as in :mod:`benchlab.analysis.chart.layout`: numpy (row, col), 0-based, pixel centres at
integers, boxes ``(r0, c0, r1, c1)`` end-exclusive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from benchlab.analysis.chart.layout import IMAGE_CENTRE_RC, Box, Orientation
from benchlab.analysis.chart.pose import ChartPose

#: Keep this far (px) from each corner of a side, along the side.
CORNER_MARGIN_PX = 12.0
#: Half-width (px) of an edge ROI across the edge (capped by the square's half side).
ACROSS_HALF_WIDTH_PX = 16.0


@dataclass(frozen=True)
class SlantedSquare:
    """One dark square of the target as imaged.

    Attributes
    ----------
    label : str
        Short name (``"E0"``...).
    centre_rc : (float, float)
        Centre in the image (row, col), px.
    side_px : float
        Side length, px.
    rotation_deg : float
        Turn from square-on (positive: clockwise on screen, i.e. from the column axis towards
        the row axis).
    """

    label: str
    centre_rc: tuple[float, float]
    side_px: float
    rotation_deg: float


@dataclass(frozen=True)
class EdgeSpec:
    """One side of a square as a slanted edge.

    Attributes
    ----------
    label : str
        Square label plus side: ``"E0L"``, ``"E0R"``, ``"E0T"``, ``"E0B"``.
    square : SlantedSquare
    normal_theta_rad : float
        Outward normal of the side (dark inside to bright outside) in the projection
        convention (from the column axis towards the row axis).
    midpoint_rc : (float, float)
        Middle of the side.
    roi : Box
        Measurement ROI.
    orientation : Orientation
        ``"sagittal"`` when the intensity varies along the columns (near-vertical edge; the
        forward view's sagittal direction), else ``"tangential"``.
    """

    label: str
    square: SlantedSquare
    normal_theta_rad: float
    midpoint_rc: tuple[float, float]
    roi: Box
    orientation: Orientation


def _offset(dr: float, dc: float) -> tuple[float, float]:
    return (IMAGE_CENTRE_RC[0] + dr, IMAGE_CENTRE_RC[1] + dc)


#: The target: three squares at image heights ~0.3-0.5, ~0.6-1.0 and ~0.9-1.15 mm (field points
#: 0, 12-16 and 25 deg of Table 4.14), turned 5, 7 and 10 deg.
DEFAULT_SQUARES: tuple[SlantedSquare, ...] = (
    SlantedSquare("E0", _offset(-50.0, 50.0), 72.0, 5.0),
    SlantedSquare("E1", _offset(-150.0, 20.0), 72.0, 7.0),
    SlantedSquare("E2", _offset(-60.0, 175.0), 64.0, 10.0),
)

_SIDES = (("R", 0.0), ("B", 90.0), ("L", 180.0), ("T", 270.0))


def edge_specs(squares: tuple[SlantedSquare, ...] = DEFAULT_SQUARES) -> list[EdgeSpec]:
    """Every side of every square as an :class:`EdgeSpec` (R, B, L, T per square)."""
    return [_side_spec(sq, name, base) for sq in squares for name, base in _SIDES]


def edge_spec(label: str, squares: tuple[SlantedSquare, ...] = DEFAULT_SQUARES) -> EdgeSpec:
    """The :class:`EdgeSpec` of one side (``label``, e.g. ``"E0L"``): ``edge_specs``' entry,
    computed alone (the simulator's truth asks for one edge at many distances).

    Raises
    ------
    KeyError
        No side of ``squares`` has that label.
    """
    for sq in squares:
        for name, base in _SIDES:
            if f"{sq.label}{name}" == label:
                return _side_spec(sq, name, base)
    raise KeyError(label)


def _side_spec(sq: SlantedSquare, name: str, base: float) -> EdgeSpec:
    half = sq.side_px / 2.0
    along_half = max(half - CORNER_MARGIN_PX, 1.0)
    across = min(ACROSS_HALF_WIDTH_PX, half - 4.0)
    theta = math.radians(sq.rotation_deg + base)
    n = (math.cos(theta), math.sin(theta))  # (x, y) = (col, row)
    t = (-n[1], n[0])
    mid = (sq.centre_rc[0] + half * n[1], sq.centre_rc[1] + half * n[0])
    rows, cols = [], []
    for sa in (-along_half, along_half):
        for sn in (-across, across):
            rows.append(mid[0] + sa * t[1] + sn * n[1])
            cols.append(mid[1] + sa * t[0] + sn * n[0])
    roi = (math.ceil(min(rows)), math.ceil(min(cols)),
           math.floor(max(rows)) + 1, math.floor(max(cols)) + 1)
    orientation: Orientation = "sagittal" if abs(n[0]) >= abs(n[1]) else "tangential"
    wrapped = math.atan2(n[1], n[0])
    return EdgeSpec(f"{sq.label}{name}", sq, wrapped, mid, roi, orientation)


def scaled_squares(
    scale: float, squares: tuple[SlantedSquare, ...] = DEFAULT_SQUARES
) -> tuple[SlantedSquare, ...]:
    """The squares imaged at ``scale`` about the optical centre (the target moved along the
    axis: its image scales as 1 / object distance)."""
    r0, c0 = IMAGE_CENTRE_RC
    return tuple(SlantedSquare(
        q.label, (r0 + scale * (q.centre_rc[0] - r0), c0 + scale * (q.centre_rc[1] - c0)),
        q.side_px * scale, q.rotation_deg) for q in squares)


def posed_squares(pose: ChartPose, origin_rc: tuple[float, float]) -> tuple[SlantedSquare, ...]:
    """The squares where a found chart pose puts them (they share the chart's glass, so they
    move, scale and turn with it about its origin)."""
    return tuple(SlantedSquare(
        q.label, pose.apply(q.centre_rc, origin_rc), q.side_px * pose.scale,
        q.rotation_deg + pose.rotation_deg) for q in DEFAULT_SQUARES)
