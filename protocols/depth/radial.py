"""The radial view's depth of field: each rolled bar pattern moved toward / away from the side
wall, read at every distance in each field point's ROI
(:mod:`benchlab.protocols.depth.radial_rois`) and fitted through focus like the forward view's
edges (:mod:`benchlab.analysis.focus.through_focus`, in the object radius = wall distance +
endoscope radius). Distances in the tables are from the side wall, as the thesis
gives them (Table 4.4: 2-11 mm; Table 4.1: +-5 mm or larger).

Per pattern and field point two curves are fitted: the fundamental (sine-wave) modulation, whose
peak is **best focus** (the Eq. 2.9 modulation is flat near focus), and the Eq. 2.9 modulation,
whose crossings of ``radial.threshold`` are the **DOF ends**: the threshold bounds the lens's
share of the print's contrast (reading / target contrast, :mod:`benchlab.protocols.depth.targets`)
when that is known (``threshold_on``), else the reading itself; the contrast's 1 sigma is drawn
with the fit's coefficients, so the ends' intervals carry it. Both are fitted as polynomials in
the object radius ``R``, not in its vergence ``1/R`` as the forward view's edges are: a
pattern of fixed *object* frequency is blurred, in object mm, by the image blur (linear in
``|1/R - u_b|``) times the object mm per pixel (``R / rho`` around the circle), so its blur is
``|1 - R u_b|``-linear and ``ln`` of its fundamental an exact quadratic in ``R`` for spokes;
the quartic in vergence left the peak 0.004-0.009 mm off on noise-free frames, in ``R`` < 1e-4.

Per pattern, best focus against image height gives the radial **field curvature**
(:func:`benchlab.analysis.focus.field.field_curvature`).
The simulated truth: :mod:`benchlab.protocols.depth.radial_truth`.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import mean_of_frames
from benchlab.analysis.chart.layout import Box
from benchlab.analysis.focus.field import astigmatic_difference, field_curvature
from benchlab.analysis.focus.through_focus import (
    FocusEstimate,
    FocusFitError,
)
from benchlab.drivers.errors import BenchlabError
from benchlab.protocols.depth.params import DepthParams
from benchlab.protocols.depth.radial_fit import estimate, with_model_term
from benchlab.protocols.depth.radial_rois import (
    ESTIMATOR,
    RadialReading,
    read_rois,
    roi_height_mm,
    roi_name,
)
from benchlab.protocols.depth.radial_truth import truth_rows
from benchlab.protocols.depth.steps import frame_name, position_step_id
from benchlab.protocols.depth.targets import target_contrast
from benchlab.protocols.target_contrast import TargetContrast, lens_share, rounded

if TYPE_CHECKING:
    from benchlab.session import Session

__all__ = ["analyze_radial", "read_radial", "truth_rows"]

Pattern = tuple[float, str]
#: One taken position: pattern, wall distance, segment, a reading per field point (None: not
#: resolved).
Position = tuple[Pattern, float, int, tuple[RadialReading | None, ...]]


def _r(v: float | None, nd: int = 3) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), nd)


def read_radial(session: Session, params: DepthParams) -> list[Position]:
    """(pattern, wall distance, segment, readings) of every taken position."""
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
                avg = mean_of_frames(stack)
                out.append((pattern, z, seg.index,
                            read_rois(avg, params.radial_rois, 2.0 ** params.bits - 1)))
    return out


def _label(pattern: Pattern) -> str:
    return f"{pattern[0]:g}lp/mm"


def _seed(*parts: str) -> int:
    return zlib.crc32("|".join(parts).encode())


def _row(base: dict[str, Any], est: FocusEstimate, n_points: int, note: str,
         params: DepthParams, target: TargetContrast, threshold: float) -> dict[str, Any]:
    from benchlab.protocols.depth.analysis import verdict

    wall = params.wall_radius_mm

    def w(v: float | None) -> float | None:
        return None if v is None else v - wall

    near, far = w(est.near_mm), w(est.far_mm)
    notes = [n for n, on in (("near end extrapolated below the sweep", est.near_extrapolated),
                             ("far end extrapolated beyond the sweep", est.far_extrapolated))
             if on] + ([note] if note else [])
    return {**base, "best_focus_mm": _r(est.best_focus_mm - wall),
            "best_focus_mm_ci95": [_r(w(v)) for v in est.best_focus_ci95],
            "near_mm": _r(near), "near_mm_ci95": [_r(w(v)) for v in est.near_ci95],
            "far_mm": _r(far), "far_mm_ci95": [_r(w(v)) for v in est.far_ci95],
            "dof_mm": _r(far - near) if near is not None and far is not None else None,
            "peak_mtf": _r(est.peak_mtf, 4),
            "peak_lens_share": _r(lens_share(est.peak_mtf, None, target)[0], 4),
            "n_points": n_points,
            "verdict": verdict(est, threshold, params.design_half_range_mm),
            "note": "; ".join(notes)}


def analyze_radial(readings: Sequence[Position], params: DepthParams
                   ) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any]]:
    """The radial tables (module docstring)."""
    if not readings:
        raise BenchlabError("no radial position taken yet; nothing to analyse")
    wall = params.wall_radius_mm
    thr = params.radial_threshold
    boxes: tuple[Box, ...] = params.radial_rois
    curves, rows = [], []
    draws: dict[tuple[Pattern, Box], npt.NDArray[np.float64]] = {}
    targets = _targets(readings, params)
    for pattern in params.patterns:
        assert pattern is not None
        pts = [(z, seg, r) for p, z, seg, r in readings if p == pattern]
        target = targets[pattern]
        # the DOF is the lens's (thesis section 2.2.4): its share of the print's contrast
        # crosses radial.threshold where the reading crosses threshold x target contrast
        on_share = target.value is not None
        reading_thr = thr * target.value if target.value is not None else thr
        # the contrast's own 1 sigma moves that crossing: drawn into the ends' intervals
        reading_sd = thr * (target.uncertainty or 0.0) if on_share else 0.0
        for i, box in enumerate(boxes):
            name = roi_name(box)
            for z, seg, rr in pts:
                r = rr[i] if i < len(rr) else None
                curves.append({"distance_mm": z, "segment": seg, "pattern": _label(pattern),
                               "field_point": name, "orientation": pattern[1],
                               "modulation": _r(r.modulation, 4) if r else None,
                               "lens_share": _r(lens_share(r.modulation if r else None, None,
                                                           target)[0], 4),
                               "fundamental": _r(r.fundamental, 4) if r else None,
                               "modulation_sigma": _r(r.sigma, 4) if r else None,
                               "status": "ok" if r else "not resolved"})
            good = [(z + wall, rr[i]) for z, _, rr in pts if i < len(rr) and rr[i] is not None]
            base = {"view": "radial", "field_point": name, "pattern": _label(pattern),
                    "orientation": pattern[1], "criterion": f"modulation>={thr:g}",
                    "freq_lp_per_mm": pattern[0], "threshold": thr,
                    "threshold_on": SHARE_BASIS if on_share else READING_BASIS,
                    "reading_threshold": _r(reading_thr, 4),
                    "target_contrast": rounded(target.value),
                    "target_contrast_uncertainty": rounded(target.uncertainty),
                    "target_contrast_source": target.source,
                    "image_height_mm": _r(roi_height_mm(box), 4)}
            seed = _seed(_label(pattern), pattern[1], name)
            try:
                est, n, note = estimate([(z, r) for z, r in good if r is not None], params,
                                        seed, reading_thr, reading_sd)
            except FocusFitError as exc:
                rows.append({**base, "best_focus_mm": None, "best_focus_mm_ci95": [None, None],
                             "near_mm": None, "near_mm_ci95": [None, None], "far_mm": None,
                             "far_mm_ci95": [None, None], "dof_mm": None, "peak_mtf": None,
                             "peak_lens_share": None, "n_points": len(good),
                             "verdict": "not measured", "note": str(exc)})
                continue
            est = with_model_term(est, seed + 2)
            draws[(pattern, box)] = est.best_focus_draws - wall
            rows.append(_row(base, est, n, note, params, target, reading_thr))
    return ({"depth_of_field": rows, "depth_astigmatism": _astigmatism(draws, params),
             "depth_field_curvature": _curvature(draws, params), "depth_curves": curves},
            {"procedure": "depth", "view": "radial", "positions": len(readings),
             "frames_per_position": params.frames,
             "patterns": [_label(p) + " " + p[1] for p in params.patterns if p],
             "field_points": {roi_name(b): {"box": list(b),
                                            "image_height_mm": _r(roi_height_mm(b), 4)}
                              for b in boxes},
             "segments": len(params.segments()), "estimator": ESTIMATOR,
             "best_focus_from": "fundamental modulation", "ends_from": "Eq. 2.9 modulation",
             "wall_radius_mm": wall,
             "target_contrast": {_label(p) + " " + p[1]: targets[p].to_dict()
                                 for p in params.patterns if p},
             "design": {"half_range_mm": params.design_half_range_mm,
                        "table_4_4_range_mm": [2.0, 11.0]}})


#: ``threshold_on`` of a radial row: what ``radial.threshold`` bounds.
SHARE_BASIS = "lens share (reading / target contrast)"
READING_BASIS = "reading (target contrast unknown: lens and print together)"


def _targets(readings: Sequence[Position], params: DepthParams
             ) -> dict[Pattern, TargetContrast]:
    """Each pattern's own contrast (:mod:`benchlab.protocols.depth.targets`): the certificate's,
    or measured on the lowest-frequency pattern's plateaus (every field point, both rolls) and
    taken for every pattern (printed alike, as in the MTF test)."""
    setting = params.targets.radial
    freqs = params.radial_frequencies_lp_per_mm
    measured = None
    if setting.values is None:
        f0 = min(freqs)
        series = []
        for orient in params.radial_orientations:
            for i in range(len(params.radial_rois)):
                pts = [(z, r.modulation, r.sigma) for p, z, _, rr in readings
                       if p == (f0, orient) and i < len(rr) and (r := rr[i]) is not None]
                series.append((orient, pts))
        measured = target_contrast(setting, series, f"the {f0:g} lp/mm pattern")
    return {p: measured if measured is not None else
            target_contrast(setting, [], "", freqs.index(p[0]))
            for p in params.patterns if p is not None}


def _astigmatism(draws: dict[tuple[Pattern, Box], npt.NDArray[np.float64]],
                 params: DepthParams) -> list[dict[str, Any]]:
    """S minus T best focus per field point and frequency, draw by draw."""
    out = []
    for f in params.radial_frequencies_lp_per_mm:
        for box in params.radial_rois:
            s, t = draws.get(((f, "sagittal"), box)), draws.get(((f, "tangential"), box))
            if s is None or t is None:
                continue
            value, ci = astigmatic_difference([s], [t])
            out.append({"view": "radial", "field_point": roi_name(box),
                        "image_height_mm": _r(roi_height_mm(box), 4), "freq_lp_per_mm": f,
                        "s_minus_t_mm": _r(value),
                        "s_minus_t_mm_ci95": [_r(ci[0]), _r(ci[1])] if ci else [None, None],
                        "significant": bool(ci is not None and (ci[0] > 0 or ci[1] < 0))})
    return out


def _curvature(draws: dict[tuple[Pattern, Box], npt.NDArray[np.float64]],
               params: DepthParams) -> list[dict[str, Any]]:
    """Per pattern: best focus = b0 + k h^2 over its field points, draw by draw."""
    out = []
    for pattern in params.patterns:
        assert pattern is not None
        boxes = [b for b in params.radial_rois if (pattern, b) in draws]
        try:
            k, b0, k_ci, b0_ci = field_curvature([roi_height_mm(b) for b in boxes],
                                                 [draws[(pattern, b)] for b in boxes])
        except ValueError:  # fewer than two field points fitted
            continue
        out.append({"view": "radial", "pattern": _label(pattern), "orientation": pattern[1],
                    "freq_lp_per_mm": pattern[0], "curvature_mm_per_mm2": _r(k, 4),
                    "curvature_mm_per_mm2_ci95": ([_r(k_ci[0], 4), _r(k_ci[1], 4)] if k_ci
                                                  else [None, None]),
                    "best_focus_on_axis_mm": _r(b0),
                    "best_focus_on_axis_mm_ci95": ([_r(b0_ci[0]), _r(b0_ci[1])] if b0_ci
                                                   else [None, None]),
                    "field_points": len(boxes)})
    return out
