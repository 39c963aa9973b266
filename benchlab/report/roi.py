"""Evidence for one ROI reading in the report: the crop, its histogram with the dark and bright
levels used, the across-bar profile, the reading with its interval, the estimator and warnings.

An engineer checks a number by looking at these: if the levels sit on the histogram's modes and
on the profile's plateaus, the Eq. 2.9 reading follows from them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.projection import project_roi
from benchlab.report.html import display_8bit, enlarge, esc, png_data_uri, svg_plot

#: Normal quantile of a two-sided 95 % interval.
Z95 = 1.959964
#: Profiles longer than this many points are binned more coarsely (the SVG stays small).
MAX_PROFILE_POINTS = 400


@dataclass(frozen=True)
class RoiReading:
    """One reading as the results tables store it (see ``ModulationResult.to_dict``)."""

    label: str  # e.g. "G2E3 sagittal" or "radial 2 lp/mm tangential"
    roi: tuple[int, int, int, int]
    orientation: str  # "sagittal" / "tangential"
    view: str  # "forward" / "radial"
    modulation: float | None
    dark: float | None
    bright: float | None
    resolved: bool
    aliased: bool
    uncertainty: float | None
    warnings: str
    estimator: str
    angle_deg: float | None = None  # measured bar direction, when the results carry it
    lower_bound: bool = False  # the modulation is a lower bound (a clipped reading)

    @property
    def state(self) -> str:
        if self.aliased:
            return "aliased"
        if not self.resolved and self.modulation is None:
            return "not-measurable"  # no reading possible (e.g. ROI < 1 bar period)
        return "resolved" if self.resolved else "unresolved"

    @classmethod
    def from_row(cls, row: dict[str, Any], orientation: str, *, label: str, view: str,
                 roi: Any, estimator: str) -> RoiReading:
        def f(key: str) -> float | None:
            v = row.get(f"{orientation}_{key}")
            return None if v is None or v == "" else float(v)

        angle = f("angle_deg")
        return cls(
            label=label, roi=tuple(int(v) for v in roi),  # type: ignore[arg-type]
            orientation=orientation, view=view, modulation=f("modulation"),
            dark=f("dark"), bright=f("bright"),
            resolved=bool(row.get(f"{orientation}_resolved", f("modulation") not in (None, 0.0))),
            aliased=bool(row.get(f"{orientation}_aliased", row.get("aliased"))),
            uncertainty=f("uncertainty"),
            warnings=str(row.get(f"{orientation}_warnings") or ""), estimator=estimator,
            angle_deg=angle, lower_bound=row.get(f"{orientation}_lower_bound") is True)


def bar_direction_rad(crop: npt.NDArray[np.float64]) -> float:
    """Direction (radians, from the column axis towards the rows) in which the intensity varies
    most: the dominant eigenvector of the ROI's structure tensor."""
    if crop.shape[0] < 3 or crop.shape[1] < 3:
        return 0.0 if crop.shape[1] >= crop.shape[0] else math.pi / 2
    import cv2

    # Scharr kernels: far less direction bias than central differences on sharp bars.
    gx = cv2.Scharr(crop, cv2.CV_64F, 1, 0)[1:-1, 1:-1]
    gy = cv2.Scharr(crop, cv2.CV_64F, 0, 1)[1:-1, 1:-1]
    jxx, jyy, jxy = float((gx * gx).sum()), float((gy * gy).sum()), float((gx * gy).sum())
    if jxx + jyy == 0:
        return 0.0
    return 0.5 * math.atan2(2.0 * jxy, jxx - jyy)


def reading_direction_rad(reading: RoiReading, crop: npt.NDArray[np.float64]) -> float:
    """The measured angle if the results carry one; the forward view's axis for sagittal and
    tangential; otherwise the structure tensor's direction."""
    if reading.angle_deg is not None:
        return math.radians(reading.angle_deg)
    if reading.view == "forward":
        return 0.0 if reading.orientation == "sagittal" else math.pi / 2
    return bar_direction_rad(crop)


def _histogram(crop: npt.NDArray[Any]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    vals = np.asarray(crop).ravel()
    lo, hi = float(vals.min()), float(vals.max())
    integer = np.issubdtype(vals.dtype, np.integer)
    if integer and hi - lo <= 512:
        counts = np.bincount((vals - lo).astype(np.int64)).astype(np.float64)
        return lo + np.arange(counts.size, dtype=np.float64), counts
    counts_i, edges = np.histogram(vals.astype(np.float64), bins=128)
    return 0.5 * (edges[:-1] + edges[1:]), counts_i.astype(np.float64)


def reading_text(r: RoiReading) -> str:
    """The reading in words: value with its 95 % interval, or why there is no value."""
    if r.aliased:
        return "not resolved (aliased: above Nyquist)"
    if r.modulation is None:
        if r.warnings.startswith("not measur"):
            return r.warnings  # the reason says it already
        return "not measurable" + (f" ({r.warnings})" if r.warnings else "")
    if not r.resolved:
        return "not resolved"
    if r.lower_bound:  # clipped: the contrast is the reading or more, no interval around it
        return f"modulation \u2265 {r.modulation:.3f} (lower bound: a level is clipped)"
    text = f"modulation {r.modulation:.3f}"
    if r.uncertainty is not None and math.isfinite(r.uncertainty):
        lo = max(0.0, r.modulation - Z95 * r.uncertainty)
        hi = min(1.0, r.modulation + Z95 * r.uncertainty)
        text += f" (95 % interval {lo:.3f}-{hi:.3f})"
    return text


def roi_panel(frame: npt.NDArray[Any], reading: RoiReading) -> str:
    """The evidence panel of one reading (HTML)."""
    r0, c0, r1, c1 = reading.roi
    h, w = frame.shape[:2]
    r0c, c0c, r1c, c1c = max(r0, 0), max(c0, 0), min(r1, h), min(c1, w)
    state = reading.state
    head = (f"<div class='roi-panel' data-roi='{esc(reading.label)}' data-state='{state}'>"
            f"<h4>{esc(reading.label)} <span class='state state-{state}'>{state}</span></h4>")
    if r1c <= r0c or c1c <= c0c:
        return head + "<p class='warn'>ROI outside the frame</p></div>"
    crop = np.asarray(frame[r0c:r1c, c0c:c1c])
    cropf = crop.astype(np.float64)
    factor = max(1, min(8, 128 // max(crop.shape)))
    img = enlarge(display_8bit(crop), factor)
    crop_html = (f"<img class='crop' alt='crop {esc(reading.label)}' src='{png_data_uri(img)}' "
                 f"width='{img.shape[1]}' height='{img.shape[0]}'>")
    levels = [(v, c, n) for v, c, n in ((reading.dark, "#1f5fbf", "D"),
                                        (reading.bright, "#c0392b", "B")) if v is not None]
    hx, hy = _histogram(crop)
    hist = svg_plot([(hx.tolist(), hy.tolist(), "#777", "histogram")],
                    vlines=levels, x_label="gray level", y_label="pixels", bars=True)
    theta = reading_direction_rad(reading, cropf)
    oblique = abs(math.sin(2.0 * theta)) > 0.05
    span = abs(crop.shape[1] * math.cos(theta)) + abs(crop.shape[0] * math.sin(theta))
    width = max(0.5 if oblique else 1.0, span / MAX_PROFILE_POINTS)
    prof = project_roi(cropf, theta, bin_width_px=width)
    ok = prof.filled
    profile = svg_plot([(prof.u_px[ok].tolist(), prof.mean[ok].tolist(), "#222", "profile")],
                       hlines=levels, x_label=f"px across the bars ({math.degrees(theta):.0f} deg)",
                       y_label="mean gray")
    facts = [("reading", reading_text(reading)),
             ("dark / bright", " / ".join("-" if v is None else f"{v:.1f}"
                                         for v in (reading.dark, reading.bright))),
             ("estimator", reading.estimator),
             ("ROI (row0, col0, row1, col1)", ", ".join(str(v) for v in reading.roi)),
             ("pixels", f"{crop.shape[0]} x {crop.shape[1]}")]
    warn = "".join(f"<li>{esc(w.strip())}</li>" for w in reading.warnings.split(";") if w.strip())
    return (head + "<div class='roi-body'>" + crop_html + hist + profile
            + "<table class='kv'>" + "".join(f"<tr><th>{esc(k)}</th><td>{esc(v)}</td></tr>"
                                             for k, v in facts) + "</table>"
            + (f"<ul class='warnings'>{warn}</ul>" if warn else "") + "</div></div>")
