"""One position of the sweep: the averaged frame read at that position's own magnification.

The chart is found in the frame (:func:`benchlab.analysis.chart.finder.find_chart`): its pose's
scale is the image scale at that distance (the magnification changes as ``1 / distance``). The
slanted-edge squares are placed at that scale about the optical centre, each side measured by the
SFR (:func:`benchlab.analysis.sfr.target_edges.measure_edges`), and, when asked, every found bar set
below Nyquist is read at its image frequency there (:func:`benchlab.analysis.chart.reading.
read_chart`). Pure functions of the pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.chart.finder import ChartFit, ChartNotFoundError, find_chart
from benchlab.analysis.chart.layout import IMAGE_CENTRE_RC
from benchlab.analysis.chart.pose import ChartPose
from benchlab.analysis.sfr.measure import SfrResult
from benchlab.analysis.sfr.target import (
    DEFAULT_SQUARES,
    EdgeSpec,
    edge_specs,
    posed_squares,
    scaled_squares,
)
from benchlab.analysis.sfr.target_edges import measure_edges
from benchlab.drivers.sensor import PIXEL_PITCH_UM


@dataclass(frozen=True)
class EdgeReading:
    """One edge at one position: MTF at each frequency (with 1-sigma) and MTF50, or why not."""

    label: str
    orientation: str
    image_height_mm: float
    mtf: dict[float, tuple[float, float]] = field(default_factory=dict)
    mtf50_lp_per_mm: float | None = None
    status: str = "ok"


@dataclass(frozen=True)
class PositionReading:
    """What one position gave: the found scale (None: chart not found), the edges, the chart."""

    scale: float | None
    edges: tuple[EdgeReading, ...]
    chart: tuple[dict[str, Any], ...]
    chart_status: str


def find_scale(pixels: npt.NDArray[Any], prior_scale: float | None = None) -> tuple[
        float | None, ChartFit | None, str]:
    """The chart's image scale in ``pixels`` (relative to the layout's), its fit, and a status."""
    prior = ChartPose(scale=prior_scale) if prior_scale is not None else ChartPose()
    try:
        fit = find_chart(pixels, prior=prior)
    except (ChartNotFoundError, ValueError) as exc:
        return None, None, f"chart not found: {exc}"
    return float(fit.pose.scale), fit, "ok"


def _height_mm(point_rc: tuple[float, float]) -> float:
    return float(np.hypot(point_rc[0] - IMAGE_CENTRE_RC[0], point_rc[1] - IMAGE_CENTRE_RC[1])
                 * PIXEL_PITCH_UM / 1000.0)


def edge_reading(spec: EdgeSpec, res: SfrResult | str,
                 freqs_lp_per_mm: tuple[float, ...]) -> EdgeReading:
    """The MTF of one measured edge at the chosen frequencies (linear interpolation of the SFR's
    grid, cycles/px = lp/mm x pitch)."""
    h = _height_mm(spec.midpoint_rc)
    if isinstance(res, str):
        return EdgeReading(spec.label, spec.orientation, h, status=res)
    f_px = np.asarray(res.freqs_cycles_per_px)
    mtf = np.asarray(res.mtf)
    sig = np.asarray(res.mtf_sigma) if res.mtf_sigma is not None else np.full_like(mtf, np.nan)
    values: dict[float, tuple[float, float]] = {}
    for f in freqs_lp_per_mm:
        x = f * PIXEL_PITCH_UM / 1000.0
        values[f] = (float(np.interp(x, f_px, mtf)), float(np.interp(x, f_px, sig)))
    m50 = (res.mtf50_cycles_per_px * 1000.0 / PIXEL_PITCH_UM
           if res.mtf50_cycles_per_px is not None else None)
    return EdgeReading(spec.label, spec.orientation, h, values, m50)


def read_position(pixels: npt.NDArray[Any], freqs_lp_per_mm: tuple[float, ...], *,
                  full_scale: float | None, read_bars: bool,
                  prior_scale: float | None = None,
                  fallback_scale: float | None = None) -> PositionReading:
    """Read one averaged frame (module docstring). ``fallback_scale`` places the edges when the
    chart is not found (None: the edges are not measured then)."""
    scale, fit, status = find_scale(pixels, prior_scale)
    edges: list[EdgeReading] = []
    squares = (posed_squares(fit.pose, fit.layout.origin_rc) if fit is not None else
               scaled_squares(fallback_scale, DEFAULT_SQUARES) if fallback_scale is not None
               else None)
    if squares is not None:
        specs = edge_specs(squares)
        for spec, res in measure_edges(pixels, specs, full_scale=full_scale):
            edges.append(edge_reading(spec, res, freqs_lp_per_mm))
    chart: list[dict[str, Any]] = []
    if read_bars and fit is not None:
        from benchlab.analysis.chart.reading import read_chart

        for el, r in zip(fit.found, read_chart(pixels, fit, full_scale), strict=True):
            posed = el.posed
            chart.append({
                "element": f"G{posed.group}E{posed.element}", "orientation": posed.orientation,
                "image_lp_per_mm": round(posed.image_lp_per_mm, 3),
                "image_height_mm": round(posed.image_height_mm, 4),
                "modulation": (round(float(r.modulation), 4)
                               if el.unmeasurable is None else None),
                "modulation_ci95": [round(float(v), 4) for v in r.interval]
                if el.unmeasurable is None else None,
                "note": el.unmeasurable or "",
            })
    return PositionReading(scale, tuple(edges), tuple(chart), status)
