"""The radial view's depth of field: each rolled bar pattern moved toward / away from the side
wall, its Eq. 2.9 modulation read in the common radial ROI (rows 250-290, cols 1000-1050) at
every distance, and fitted through focus like the forward view's edges
(:mod:`benchlab.analysis.focus.through_focus`, in the vergence of the object radius = wall
distance + endoscope radius). The DOF is where the bar modulation stays at or above
``radial.threshold``; distances in the tables are from the side wall, as the thesis gives them
(Table 4.4: 2-11 mm; Table 4.1: +-5 mm or larger).

The modulation is read by the histogram peaks (the radial bars run obliquely through the ROI:
the MTF procedure's choice for this view), its 1-sigma by the estimator.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.chart.layout import IMAGE_CENTRE_RC, RADIAL_ROI_BOX, box_centroid
from benchlab.analysis.focus.field import astigmatic_difference
from benchlab.analysis.focus.through_focus import (
    FocusFitError,
    fit_through_focus,
    focus_estimate,
)
from benchlab.drivers.errors import BenchlabError
from benchlab.drivers.sensor import PIXEL_PITCH_UM
from benchlab.protocols.depth.params import DepthParams
from benchlab.protocols.depth.steps import frame_name, position_step_id

if TYPE_CHECKING:
    from benchlab.session import Session

Pattern = tuple[float, str]
#: Estimator of the radial bars (oblique through the ROI).
ESTIMATOR = "histogram"


def _r(v: float | None, nd: int = 3) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), nd)


def roi_height_mm() -> float:
    r, c = box_centroid(RADIAL_ROI_BOX)
    return float(math.hypot(r - IMAGE_CENTRE_RC[0], c - IMAGE_CENTRE_RC[1])
                 * PIXEL_PITCH_UM / 1000.0)


def read_modulation(pixels: npt.NDArray[Any], full_scale: float) -> tuple[float, float] | None:
    """(modulation, 1-sigma) in the radial ROI, None when not resolved."""
    r0, c0, r1, c1 = RADIAL_ROI_BOX
    res = estimate_modulation(pixels[r0:r1, c0:c1], estimator=ESTIMATOR, max_code=full_scale)
    if not res.resolved or not res.uncertainty > 0:
        return None
    return float(res.modulation), float(res.uncertainty)


def read_radial(session: Session, params: DepthParams
                ) -> list[tuple[Pattern, float, int, tuple[float, float] | None]]:
    """(pattern, wall distance, segment, reading) of every taken position."""
    out = []
    for pattern in params.patterns:
        assert pattern is not None
        for seg in params.segments():
            for z in seg.distances_mm:
                sid = position_step_id(seg.index, z, pattern)
                frames = session.step_frames(sid)
                names = [frame_name(k) for k in range(params.frames)]
                if not set(names) <= set(frames):
                    continue
                stack = [session.load_frame(sid, n)[0] for n in names]
                avg = np.mean(np.stack(stack).astype(np.float64), axis=0)
                out.append((pattern, z, seg.index,
                            read_modulation(avg, 2.0 ** params.bits - 1)))
    return out


def _label(pattern: Pattern) -> str:
    return f"{pattern[0]:g}lp/mm"


def analyze_radial(readings: Sequence[tuple[Pattern, float, int, tuple[float, float] | None]],
                   params: DepthParams) -> tuple[dict[str, list[dict[str, Any]]],
                                                 dict[str, Any]]:
    """The radial tables (module docstring)."""
    from benchlab.protocols.depth.analysis import verdict

    if not readings:
        raise BenchlabError("no radial position taken yet; nothing to analyse")
    wall = params.wall_radius_mm
    thr = params.radial_threshold
    h = roi_height_mm()
    curves, rows = [], []
    draws: dict[Pattern, npt.NDArray[np.float64]] = {}
    for pattern in params.patterns:
        assert pattern is not None
        pts = [(z, seg, r) for p, z, seg, r in readings if p == pattern]
        for z, seg, r in pts:
            curves.append({"distance_mm": z, "segment": seg, "pattern": _label(pattern),
                           "orientation": pattern[1], "modulation": _r(r[0], 4) if r else None,
                           "modulation_sigma": _r(r[1], 4) if r else None,
                           "status": "ok" if r else "not resolved"})
        good = [(z + wall, r[0], r[1]) for z, _, r in pts if r is not None]
        base = {"view": "radial", "field_point": _label(pattern), "orientation": pattern[1],
                "criterion": f"modulation>={thr:g}", "freq_lp_per_mm": pattern[0],
                "threshold": thr, "image_height_mm": _r(h, 4)}
        try:
            fit = fit_through_focus([g[0] for g in good], [g[1] for g in good],
                                    [g[2] for g in good], min_mtf=params.min_mtf)
        except FocusFitError as exc:
            rows.append({**base, "best_focus_mm": None, "best_focus_mm_ci95": [None, None],
                         "near_mm": None, "near_mm_ci95": [None, None], "far_mm": None,
                         "far_mm_ci95": [None, None], "dof_mm": None, "peak_mtf": None,
                         "n_points": len(good), "verdict": "not measured", "note": str(exc)})
            continue
        est = focus_estimate(fit, thr, seed=zlib.crc32(_label(pattern).encode()
                                                       + pattern[1].encode()))
        draws[pattern] = est.best_focus_draws - wall

        def w(v: float | None) -> float | None:
            return None if v is None else v - wall

        near, far = w(est.near_mm), w(est.far_mm)
        rows.append({**base, "best_focus_mm": _r(est.best_focus_mm - wall),
                     "best_focus_mm_ci95": [_r(w(v)) for v in est.best_focus_ci95],
                     "near_mm": _r(near), "near_mm_ci95": [_r(w(v)) for v in est.near_ci95],
                     "far_mm": _r(far), "far_mm_ci95": [_r(w(v)) for v in est.far_ci95],
                     "dof_mm": _r(far - near) if near is not None and far is not None else None,
                     "peak_mtf": _r(est.peak_mtf, 4), "n_points": fit.n_points,
                     "verdict": verdict(est, thr, params.design_half_range_mm),
                     "note": "; ".join(n for n, on in (
                         ("near end extrapolated below the sweep", est.near_extrapolated),
                         ("far end extrapolated beyond the sweep", est.far_extrapolated))
                         if on)})
    astig = []
    for f in params.radial_frequencies_lp_per_mm:
        s, t = draws.get((f, "sagittal")), draws.get((f, "tangential"))
        if s is None or t is None:
            continue
        value, ci = astigmatic_difference([s], [t])
        astig.append({"view": "radial", "field_point": f"{f:g}lp/mm", "freq_lp_per_mm": f,
                      "s_minus_t_mm": _r(value),
                      "s_minus_t_mm_ci95": [_r(ci[0]), _r(ci[1])] if ci else [None, None],
                      "significant": bool(ci is not None and (ci[0] > 0 or ci[1] < 0))})
    summary = {"procedure": "depth", "view": "radial", "positions": len(readings),
               "frames_per_position": params.frames,
               "patterns": [_label(p) + " " + p[1] for p in params.patterns if p],
               "segments": len(params.segments()), "estimator": ESTIMATOR,
               "wall_radius_mm": wall, "design": {"half_range_mm": params.design_half_range_mm,
                                                  "table_4_4_range_mm": [2.0, 11.0]}}
    return {"depth_of_field": rows, "depth_astigmatism": astig, "depth_curves": curves}, summary


def truth_rows(params: DepthParams) -> list[dict[str, Any]]:
    """The radial ``depth_of_field`` keys from the scene's closed form: the defocused
    pattern's truth modulation at each object radius, searched over the ray-trace table's
    radii."""
    from scipy.optimize import brentq, minimize_scalar

    from benchlab.analysis.views.raytrace import read_raytrace_table
    from benchlab.scenes.focus import defocused_radial
    from benchlab.scenes.radial import RadialScene

    lens = params.lens()
    wall = params.wall_radius_mm
    radii = read_raytrace_table().object_radius_mm
    lo, hi = float(min(radii)), float(max(radii))
    thr = params.radial_threshold
    rows = []
    for pattern in params.patterns:
        assert pattern is not None
        template = RadialScene(pattern[0], "sagittal" if pattern[1] == "sagittal"
                               else "tangential")

        def m(radius: float, template: RadialScene = template) -> float:
            return defocused_radial(template, lens, radius).truth_modulation()

        res = minimize_scalar(lambda u: -m(1.0 / u), bounds=(1.0 / hi, 1.0 / lo),
                              method="bounded", options={"xatol": 1e-9})
        best = 1.0 / float(res.x)

        def cross(a: float, b: float) -> float | None:
            ga, gb = m(a) - thr, m(b) - thr
            if ga * gb > 0:
                return None
            return float(brentq(lambda r: m(r) - thr, a, b, xtol=1e-7))

        near = cross(lo, best) if m(best) >= thr else None
        far = cross(best, hi) if m(best) >= thr else None
        rows.append({"view": "radial", "field_point": _label(pattern),
                     "orientation": pattern[1], "criterion": f"modulation>={thr:g}",
                     "freq_lp_per_mm": pattern[0], "threshold": thr,
                     "image_height_mm": _r(roi_height_mm(), 4),
                     "best_focus_mm": round(best - wall, 4),
                     "near_mm": None if near is None else round(near - wall, 4),
                     "far_mm": None if far is None else round(far - wall, 4),
                     "dof_mm": None if near is None or far is None else round(far - near, 4)})
    return rows
