"""The radial view's field points: ROIs at several image heights of the annulus, and the reading
of a rolled bar pattern in each.

The default field points lie on the common radial ROI's azimuth (from the optical centre through
rows 250-290, cols 1000-1050), at image heights 1.80, 2.13 and 2.48 mm: inside the annulus
(300-545 px from the centre) and inside the ray-trace table's image radii, so the simulated
scene renders them validly. A field point is named by its box, ``r<row0>c<col0>``.

Each ROI is read by ``profilefit`` (:mod:`benchlab.analysis.bars.profilefit`: a blurred
square-wave model of oblique bars) - the bar benchmark's best estimator; the histogram peaks
under-read these small oblique ROIs by ~0.02 and saturate near focus. A reading gives

* the Eq. 2.9 modulation (the DOF criterion, ``radial.threshold``), and
* the fundamental (sine-wave) modulation: the MTF at the pattern's frequency x 4 / pi. Near
  focus the bars reach their full print levels and the Eq. 2.9 modulation is flat (a plateau
  1-1.5 mm long at 2 lp/mm): it has no peak to fit. The fundamental keeps falling with any blur,
  so best focus is the fundamental's peak.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy.typing as npt

from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.chart.layout import (
    IMAGE_CENTRE_RC,
    RADIAL_ROI_BOX,
    Box,
    RadialLayout,
    box_centroid,
)
from benchlab.drivers.sensor import PIXEL_PITCH_UM

#: Estimator of the radial bars (oblique through the ROI).
ESTIMATOR = "profilefit"
#: The default field points (module docstring): 40 x 50 px boxes on the radial ROI's azimuth.
DEFAULT_FIELD_ROIS: tuple[Box, ...] = ((330, 895, 370, 945), (291, 946, 331, 996),
                                       RADIAL_ROI_BOX)
#: Smallest ROI side, px: profilefit needs a few bar periods (spokes: 8-12 px, rings 5-6 px).
MIN_ROI_SIDE_PX = 16


@dataclass(frozen=True)
class RadialReading:
    """One ROI's reading: Eq. 2.9 modulation, its fundamental, and the 1-sigma of the former
    (used for both: additive noise moves them alike)."""

    modulation: float
    fundamental: float
    sigma: float


def roi_name(box: Box) -> str:
    """The field point's name: ``r<row0>c<col0>``."""
    return f"r{box[0]}c{box[1]}"


def roi_height_mm(box: Box = RADIAL_ROI_BOX) -> float:
    """Image height (mm) of the box's centroid from the optical centre."""
    r, c = box_centroid(box)
    return float(math.hypot(r - IMAGE_CENTRE_RC[0], c - IMAGE_CENTRE_RC[1])
                 * PIXEL_PITCH_UM / 1000.0)


def roi_problem(box: Box) -> str | None:
    """Why ``box`` cannot be a radial field point (None: it can). The frame bounds are checked
    by the parameter checker."""
    r0, c0, r1, c1 = box
    if min(r1 - r0, c1 - c0) < MIN_ROI_SIDE_PX:
        return (f"{r1 - r0} x {c1 - c0} px is too small: a side of {MIN_ROI_SIDE_PX} px at "
                "least (a few bar periods)")
    layout = RadialLayout()
    if not layout.box_in_annulus(box):
        return (f"lies outside the radial annulus ({layout.annulus_inner_radius_px:g}-"
                f"{layout.annulus_outer_radius_px:g} px from the optical centre "
                f"{IMAGE_CENTRE_RC}): every pixel must see the rolled pattern")
    return None


def read_roi(pixels: npt.NDArray[Any], box: Box, full_scale: float) -> RadialReading | None:
    """The reading in ``box`` (module docstring); None when not resolved."""
    r0, c0, r1, c1 = box
    res = estimate_modulation(pixels[r0:r1, c0:c1], estimator=ESTIMATOR, max_code=full_scale)
    fund = res.fundamental_modulation
    if (not res.resolved or not res.uncertainty > 0 or fund is None
            or not math.isfinite(fund) or not math.isfinite(res.modulation)):
        return None
    return RadialReading(float(res.modulation), float(fund), float(res.uncertainty))


def read_rois(pixels: npt.NDArray[Any], boxes: Sequence[Box], full_scale: float
              ) -> tuple[RadialReading | None, ...]:
    """:func:`read_roi` of every field point."""
    return tuple(read_roi(pixels, b, full_scale) for b in boxes)
