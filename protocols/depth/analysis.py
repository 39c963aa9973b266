"""A depth-of-field session's frames -> through-focus curves, best focus, DOF, astigmatism and
field curvature, with 95 % intervals.

Tables (``SESSION/results/vN/<name>.csv`` + ``.json``):

- ``depth_of_field``: one row per view x orientation x field point (a slanted edge: its square
  and side) x criterion: ``best_focus_mm``, ``near_mm``, ``far_mm`` each with ``*_ci95``
  [low, high] (None: open), ``dof_mm``, ``criterion``, ``freq_lp_per_mm``, ``threshold``,
  ``image_height_mm`` (at best focus), ``peak_mtf``, and the ``verdict`` against Table 4.1's
  design DOF (best focus +- ``design_half_range_mm``; Table 4.4's 6-73 mm in ``design``);
- ``depth_astigmatism``: per field point (square) and frequency, S minus T best focus;
- ``depth_field_curvature``: per orientation and frequency, best focus = b0 + k h^2;
- ``depth_curves``: every reading (distance, segment, edge, frequency, MTF, 1-sigma, MTF50);
- ``depth_overlap``: distances taken in two segments, the same edge's MTF in each, and their
  difference in units of its 1-sigma (the segments cross-checked);
- ``depth_chart``: per distance, every found bar set's modulation at its image frequency there
  (with the magnification the found pose gives), the chart's own contrast and the lens's share
  (modulation / target contrast, :func:`chart_target_contrast`; the edges' MTF needs no such
  share: the SFR divides by the edge's own step);
- ``simulator_truth`` (simulated bench only): the ``depth_of_field`` keys from the scene's
  closed form (:mod:`benchlab.protocols.depth.truth`).
"""

from __future__ import annotations

import math
import zlib
from collections import defaultdict
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import mean_of_frames
from benchlab.analysis.chart.layout import ChartLayout
from benchlab.analysis.focus.criteria import mtf_threshold
from benchlab.analysis.focus.field import astigmatic_difference, field_curvature
from benchlab.analysis.focus.through_focus import (
    FocusEstimate,
    FocusFitError,
    ThroughFocusFit,
    fit_through_focus,
    focus_estimate,
)
from benchlab.drivers.errors import BenchlabError
from benchlab.drivers.sensor import PIXEL_PITCH_UM
from benchlab.protocols.depth.params import DESIGN_RANGE_MM, DepthParams
from benchlab.protocols.depth.readings import PositionReading, read_position
from benchlab.protocols.depth.steps import frame_name, position_step_id
from benchlab.protocols.depth.targets import target_contrast
from benchlab.protocols.target_contrast import TargetContrast, lens_share, rounded

if TYPE_CHECKING:
    from benchlab.session import Session

VIEW = "forward"


def _r(v: float | None, nd: int = 3) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), nd)


def _ci(pair: Sequence[float | None]) -> list[float | None]:
    return [_r(pair[0]), _r(pair[1])]


def position_summary(avg: npt.NDArray[Any], params: DepthParams, distance_mm: float
                     ) -> dict[str, Any]:
    """A live view's digest of one position: found scale and each orientation's median MTF50."""
    r = read_position(avg, params.frequencies_lp_per_mm, full_scale=2.0 ** params.bits - 1,
                      read_bars=False)
    out: dict[str, Any] = {"scale": _r(r.scale, 4)}
    for orient in ("sagittal", "tangential"):
        vals = [e.mtf50_lp_per_mm for e in r.edges
                if e.orientation == orient and e.mtf50_lp_per_mm is not None]
        out[f"mtf50_{orient}_lp_per_mm"] = _r(float(np.median(vals)), 2) if vals else None
    return out


def verdict(est: FocusEstimate, threshold: float, half_range_mm: float) -> str:
    """Against Table 4.1: does the DOF cover best focus +- ``half_range_mm``? ``meets`` when
    both interval ends clear it, ``fails`` when either interval (or a missing end of a curve
    that never reaches the threshold) misses it, else ``undecided``."""
    best = est.best_focus_mm
    if est.peak_mtf < threshold:
        return "fails (criterion never met)"
    want_near, want_far = best - half_range_mm, best + half_range_mm
    n_lo, n_hi = est.near_ci95
    f_lo, f_hi = est.far_ci95
    near, far = est.near_mm, est.far_mm
    if (n_lo is not None and n_lo > want_near) or (f_hi is not None and f_hi < want_far):
        return "fails"
    if n_hi is not None and n_hi <= want_near and f_lo is not None and f_lo >= want_far:
        return "meets"
    if near is None or far is None:
        return "undecided (a DOF end beyond the sweep)"
    return "undecided"


def read_session(session: Session, params: DepthParams
                 ) -> list[tuple[float, int, PositionReading]]:
    """Every taken position's reading: (distance, segment, reading). Positions not taken yet
    (an interrupted session) are skipped. Where the chart is not found (e.g. part of it out of
    the field at the nearest distances) the edges are placed at the scale the other positions'
    found poses give for that distance (``K / distance``)."""
    out: list[tuple[float, int, PositionReading]] = []
    frames_of: dict[tuple[float, int], npt.NDArray[np.float64]] = {}
    full_scale = 2.0 ** params.bits - 1
    for seg in params.segments():
        for z in seg.distances_mm:
            sid = position_step_id(seg.index, z)
            frames = session.step_frames(sid)
            names = [frame_name(k) for k in range(params.frames)]
            if not set(names) <= set(frames):
                continue
            stack = [session.load_frame(sid, n)[0] for n in names]
            avg = mean_of_frames(stack)
            reading = read_position(avg, params.frequencies_lp_per_mm, full_scale=full_scale,
                                    read_bars=params.read_chart)
            if reading.scale is None:
                frames_of[(z, seg.index)] = avg
            out.append((z, seg.index, reading))
    if frames_of and any(r.scale is not None for _, _, r in out):
        k = _magnification_constant(out)
        out = [(z, g, r if r.scale is not None else read_position(
            frames_of[(z, g)], params.frequencies_lp_per_mm, full_scale=full_scale,
            read_bars=False, fallback_scale=k / z)) for z, g, r in out]
    return out


def _magnification_constant(readings: Sequence[tuple[float, int, PositionReading]]) -> float:
    """``K`` of scale = K / distance, from the found scales (median of scale x distance)."""
    ks = [r.scale * z for z, _, r in readings if r.scale is not None]
    if not ks:
        raise BenchlabError("the chart was found at no position: no magnification to place the "
                            "edges")
    return float(np.median(ks))


def analyze_readings(readings: Sequence[tuple[float, int, PositionReading]],
                     params: DepthParams) -> tuple[dict[str, list[dict[str, Any]]],
                                                   dict[str, Any]]:
    """The tables from the positions' readings (module docstring)."""
    if not readings:
        raise BenchlabError("no position taken yet; nothing to analyse")
    k_scale = _magnification_constant(readings)
    curves: list[dict[str, Any]] = []
    series: dict[tuple[str, float], list[tuple[float, float, float, int]]] = defaultdict(list)
    orient_of: dict[str, str] = {}
    height_ref: dict[str, list[float]] = defaultdict(list)
    for z, seg, r in readings:
        for e in r.edges:
            orient_of[e.label] = e.orientation
            scale = r.scale if r.scale is not None else k_scale / z
            height_ref[e.label].append(e.image_height_mm / scale)
            for f in params.frequencies_lp_per_mm:
                m, s = e.mtf.get(f, (math.nan, math.nan))
                curves.append({"distance_mm": z, "segment": seg, "edge": e.label,
                               "orientation": e.orientation, "freq_lp_per_mm": f,
                               "mtf": _r(m, 4), "mtf_sigma": _r(s, 4),
                               "mtf50_lp_per_mm": _r(e.mtf50_lp_per_mm, 2),
                               "status": e.status[:200]})
                if e.status == "ok":
                    series[(e.label, f)].append((z, m, s, seg))
    fits: dict[tuple[str, float], ThroughFocusFit | str] = {}
    for key, pts in series.items():
        try:
            fits[key] = fit_through_focus([p[0] for p in pts], [p[1] for p in pts],
                                          [p[2] for p in pts], min_mtf=params.min_mtf)
        except FocusFitError as exc:
            fits[key] = str(exc)
    labels = sorted(orient_of)
    rows: list[dict[str, Any]] = []
    draws: dict[tuple[str, float], npt.NDArray[np.float64]] = {}
    heights: dict[tuple[str, float], float] = {}
    for label in labels:
        h_ref = float(np.median(height_ref[label]))
        for crit in params.criteria:
            f = crit.frequency_lp_per_mm
            thr = mtf_threshold(crit, PIXEL_PITCH_UM)
            fit = fits.get((label, f), "no clean reading of this edge")
            base = {"view": VIEW, "field_point": label, "orientation": orient_of[label],
                    "criterion": crit.name, "freq_lp_per_mm": f, "threshold": round(thr, 4)}
            if isinstance(fit, str):
                rows.append({**base, "image_height_mm": None,
                             "best_focus_mm": None, "best_focus_mm_ci95": [None, None],
                             "near_mm": None, "near_mm_ci95": [None, None], "far_mm": None,
                             "far_mm_ci95": [None, None], "dof_mm": None, "peak_mtf": None,
                             "n_points": len(series.get((label, f), [])),
                             "verdict": "not measured", "note": fit})
                continue
            # one seed per curve: its criteria share the best-focus draws
            est = focus_estimate(fit, thr, seed=zlib.crc32(f"{label}@{f:g}".encode()))
            if (label, f) not in draws:
                draws[(label, f)] = est.best_focus_draws
                heights[(label, f)] = h_ref * k_scale / est.best_focus_mm
            notes = []
            if est.peak_mtf >= thr and (est.near_mm is None or est.far_mm is None):
                notes.append("a DOF end lies beyond the sweep's reach: widen it")
            if est.near_extrapolated:
                notes.append("near end extrapolated below the sweep")
            if est.far_extrapolated:
                notes.append("far end extrapolated beyond the sweep")
            if fit.reduced_chi2 > 4:
                notes.append(f"scatter {fit.reduced_chi2:.1f} x the readings' sigma")
            dof = (est.far_mm - est.near_mm if est.near_mm is not None and est.far_mm is not None
                   else None)
            rows.append({**base, "image_height_mm": _r(heights[(label, f)], 4),
                         "best_focus_mm": _r(est.best_focus_mm),
                         "best_focus_mm_ci95": _ci(est.best_focus_ci95),
                         "near_mm": _r(est.near_mm), "near_mm_ci95": _ci(est.near_ci95),
                         "far_mm": _r(est.far_mm), "far_mm_ci95": _ci(est.far_ci95),
                         "dof_mm": _r(dof), "peak_mtf": _r(est.peak_mtf, 4),
                         "n_points": fit.n_points,
                         "verdict": verdict(est, thr, params.design_half_range_mm),
                         "note": "; ".join(notes)})
    astig = _astigmatism(draws, orient_of, params)
    curvature = _curvature(draws, heights, orient_of, params)
    overlap = _overlap(series)
    chart = [{"distance_mm": z, "segment": seg, "scale": _r(r.scale, 4),
              "magnification": _r(ChartLayout().magnification / r.scale, 3) if r.scale
              else None, **row}
             for z, seg, r in readings for row in r.chart]
    target = chart_target_contrast(chart, params)
    for row in chart:
        row.update(_share_cells(row, target))
    within = [abs(o["z_score"]) <= 2 for o in overlap if o["z_score"] is not None]
    summary = {
        "procedure": "depth", "view": VIEW, "positions": len(readings),
        "frames_per_position": params.frames,
        "distances_mm": sorted({z for z, _, _ in readings}),
        "segments": len(params.segments()),
        "criteria": [c.name for c in params.criteria],
        "magnification_constant_mm": round(k_scale, 3),
        "design": {"half_range_mm": params.design_half_range_mm,
                   "table_4_4_range_mm": list(DESIGN_RANGE_MM)},
        "overlap_within_2_sigma": (round(sum(within) / len(within), 3) if within else None),
        "chart_not_found_at_mm": [z for z, _, r in readings if r.scale is None],
        "target_contrast": {"forward": target.to_dict()},
    }
    tables = {"depth_of_field": rows, "depth_astigmatism": astig,
              "depth_field_curvature": curvature, "depth_curves": curves,
              "depth_overlap": overlap, "depth_chart": chart}
    return tables, summary


def _sigma(row: dict[str, Any]) -> float:
    """A bar reading's 1-sigma from its 95 % interval."""
    ci = row.get("modulation_ci95") or [None, None]
    return (ci[1] - ci[0]) / 3.92 if None not in ci else math.nan


def chart_target_contrast(chart: Sequence[dict[str, Any]], params: DepthParams
                          ) -> TargetContrast:
    """The USAF chart's own contrast (:mod:`benchlab.protocols.depth.targets`): the
    certificate's, or measured on the plateau through focus of the coarsest element read (its
    object frequency ~ image lp/mm x distance, as the magnification goes as 1 / distance)."""
    setting = params.targets.usaf
    if setting.values is not None or not chart:
        return (target_contrast(setting, [], "") if setting.values is not None else
                TargetContrast(None, None, "not measured: no bar set read (analysis.read_chart)"))
    by_element: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for row in chart:
        if row["modulation"] is not None:
            by_element[row["element"]].append(row)
    if not by_element:
        return TargetContrast(None, None, "not measured: no bar set read")
    coarsest = min(by_element, key=lambda el: float(np.median(
        [r["image_lp_per_mm"] * r["distance_mm"] for r in by_element[el]])))
    series = [(o, [(r["distance_mm"], r["modulation"], _sigma(r)) for r in by_element[coarsest]
                   if r["orientation"] == o]) for o in ("sagittal", "tangential")]
    return target_contrast(setting, [s for s in series if s[1]], f"USAF {coarsest}")


def _share_cells(row: dict[str, Any], target: TargetContrast) -> dict[str, Any]:
    share, u = lens_share(row["modulation"], _sigma(row) if row["modulation"] is not None
                          else None, target)
    return {"target_contrast": rounded(target.value),
            "target_contrast_uncertainty": rounded(target.uncertainty),
            "lens_share": _r(share, 4), "lens_share_uncertainty": _r(u, 4)}


def _square(label: str) -> str:
    return label[:-1]


def _astigmatism(draws: dict[tuple[str, float], npt.NDArray[np.float64]],
                 orient_of: dict[str, str], params: DepthParams) -> list[dict[str, Any]]:
    rows = []
    for f in params.frequencies_lp_per_mm:
        squares = sorted({_square(lab) for lab, ff in draws if ff == f})
        for sq in squares:
            s = [d for (lab, ff), d in draws.items() if ff == f and _square(lab) == sq
                 and orient_of[lab] == "sagittal"]
            t = [d for (lab, ff), d in draws.items() if ff == f and _square(lab) == sq
                 and orient_of[lab] == "tangential"]
            if not s or not t:
                continue
            value, ci = astigmatic_difference(s, t)
            rows.append({"view": VIEW, "field_point": sq, "freq_lp_per_mm": f,
                         "s_minus_t_mm": _r(value), "s_minus_t_mm_ci95":
                         _ci(ci) if ci is not None else [None, None],
                         "significant": bool(ci is not None and (ci[0] > 0 or ci[1] < 0))})
    return rows


def _curvature(draws: dict[tuple[str, float], npt.NDArray[np.float64]],
               heights: dict[tuple[str, float], float], orient_of: dict[str, str],
               params: DepthParams) -> list[dict[str, Any]]:
    rows = []
    for f in params.frequencies_lp_per_mm:
        for orient in ("sagittal", "tangential"):
            keys = [k for k in draws if k[1] == f and orient_of[k[0]] == orient]
            if len(keys) < 2:
                continue
            try:
                k, b0, k_ci, b0_ci = field_curvature([heights[x] for x in keys],
                                                     [draws[x] for x in keys])
            except ValueError:
                continue
            rows.append({"view": VIEW, "orientation": orient, "freq_lp_per_mm": f,
                         "curvature_mm_per_mm2": _r(k),
                         "curvature_mm_per_mm2_ci95": _ci(k_ci) if k_ci else [None, None],
                         "best_focus_on_axis_mm": _r(b0),
                         "best_focus_on_axis_mm_ci95": _ci(b0_ci) if b0_ci else [None, None],
                         "field_points": len(keys)})
    return rows


def _overlap(series: dict[tuple[str, float], list[tuple[float, float, float, int]]]
             ) -> list[dict[str, Any]]:
    rows = []
    for (label, f), pts in sorted(series.items()):
        by_z: dict[float, list[tuple[float, float, int]]] = defaultdict(list)
        for z, m, s, seg in pts:
            by_z[z].append((m, s, seg))
        for z, got in sorted(by_z.items()):
            if len(got) < 2:
                continue
            (m1, s1, g1), (m2, s2, g2) = got[0], got[1]
            sd = math.hypot(s1, s2)
            rows.append({"distance_mm": z, "edge": label, "freq_lp_per_mm": f,
                         "segment_a": g1, "mtf_a": _r(m1, 4), "segment_b": g2,
                         "mtf_b": _r(m2, 4), "difference": _r(m2 - m1, 4),
                         "z_score": _r((m2 - m1) / sd, 2) if sd > 0 else None})
    return rows


def analyze_depth(session: Session, params: DepthParams
                  ) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any]]:
    """The session's tables; a simulated session also gets ``simulator_truth``."""
    simulated = bool(session.meta.get("devices", {}).get("simulated"))
    if params.view == "radial":
        from benchlab.protocols.depth import radial

        rad = radial.read_radial(session, params)
        if not rad:
            raise BenchlabError(f"{session.path}: no position taken yet; nothing to analyse")
        tables, summary = radial.analyze_radial(rad, params)
        if simulated:
            tables["simulator_truth"] = radial.truth_rows(params)
        return tables, summary
    readings = read_session(session, params)
    if not readings:
        raise BenchlabError(f"{session.path}: no position taken yet; nothing to analyse")
    tables, summary = analyze_readings(readings, params)
    if simulated:
        from benchlab.protocols.depth.truth import truth_rows

        tables["simulator_truth"] = truth_rows(params, [r["field_point"] for r in
                                                        tables["depth_of_field"]])
    return tables, summary
