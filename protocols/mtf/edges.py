"""Forward frame -> slanted-edge MTF curves, and the three-way check: edge MTF (sine-wave) vs
simulated MTF (sine-wave) vs the bar readings (against what the edges predict they read, else
converted through Coltman).

Tables (written with the Table 4.10 results):

- ``table_sfr_edges``: one row per nominal edge of the slanted-edge target
  (:mod:`benchlab.analysis.sfr.target`): status (``ok`` or why no clean edge is there),
  angle, MTF50, MTF at Nyquist, plateau levels, the estimator the SFR chose (``model-free``,
  or ``LSF model`` where the edge is too noisy for the model-free reading: method auto of
  :func:`benchlab.analysis.sfr.measure.measure_sfr`), image height and nearest field point;
- ``table_sfr_curves``: each clean edge's MTF (with its 1-sigma, the pixel noise propagated
  analytically: :func:`benchlab.analysis.sfr.measure.measure_sfr`) every 4 lp/mm;
- ``table_sfr_vs_bars``: per USAF bar set below Nyquist, the bar modulation -> CTF (over the
  chart's own contrast, read off the edge's plateaus: chrome and glass of the same target)
  -> MTF by Coltman's series with the harmonics' MTF (3f, 5f, ...) taken from the edges
  (:func:`benchlab.analysis.mtf.coltman.ctf_to_mtf_with_harmonics`: ``bar_mtf``, what is
  compared) and, for reference, with Nyquist taken as the cutoff (``bar_mtf_coltman``, off by
  up to 0.05-0.08 on this bench: the MTF above Nyquist is not 0), beside the edge MTF of the same
  orientation at the bar set's image height (interpolated between the two edges bracketing it)
  and the simulated MTF there (interpolated between the field points' curves), with a verdict
  (agreement within :data:`AGREEMENT_TOLERANCE`). Coltman's series assumes an endless square
  wave and a USAF set has three bars: where the chart reading read a set, the set is imaged
  through the edges' transfer at its height and read by the same estimator the same way
  (:func:`predicted_bar_modulation`, :mod:`benchlab.analysis.chart.threebar`:
  ``bar_modulation_predicted``) and "bars vs edge" is judged on ``|bar_modulation -
  bar_modulation_predicted|``; elsewhere on ``|bar_mtf - edge_mtf|``. The verdict and
  ``bars_vs_edge_basis`` name the basis (:data:`BASIS_PREDICTED`, :data:`BASIS_COLTMAN`).

Clipping is judged against the camera's ceiling (``full_scale``: from the frame's metadata,
:func:`~benchlab.analysis.sfr.measure.full_scale_of_frame`
); without it, guessed from each ROI's codes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt

from benchlab.analysis.chart.layout import Box, ChartLayout
from benchlab.analysis.chart.pose import ChartPose, posed_bar_sets
from benchlab.analysis.geometry import (
    field_points,
    image_height_mm,
    nearest_field_point,
    roi_centroid,
)
from benchlab.analysis.mtf.coltman import ctf_to_mtf, ctf_to_mtf_with_harmonics
from benchlab.analysis.mtf.compare import SimulatedCurve
from benchlab.analysis.mtf.frequency import cycles_per_px, nyquist_lp_per_mm
from benchlab.analysis.sfr.measure import MAX_FREQ_CYCLES_PER_PX, SfrResult
from benchlab.analysis.sfr.target import EdgeSpec
from benchlab.analysis.sfr.target_edges import measure_edges

if TYPE_CHECKING:
    from benchlab.analysis.chart.threebar import OpticsTransfer, ReadingSetup, Transfer

#: Three-way agreement: |bar MTF - edge MTF| and |edge MTF - simulated MTF| at most this.
AGREEMENT_TOLERANCE = 0.05
#: Curve table step, image lp/mm (0 to 192, twice Nyquist).
CURVE_STEP_LP_PER_MM = 4.0
_LP_PER_CYCLE_PX = 1.0 / cycles_per_px(1.0)
#: An edge ROI within this many px of a bar set of the found chart holds other structure: no
#: clean edge there (the blur reaches ~3 sigma, under 2 px on this bench).
CHART_CLEARANCE_PX = 4.0


def chart_pose_of(chart_info: Mapping[str, Any] | None) -> ChartPose | None:
    """The found chart's pose from a forward row's ``chart`` summary (None: not found)."""
    if not chart_info or not chart_info.get("pose"):
        return None
    pose = chart_info["pose"]
    return ChartPose(offset_rc=(float(pose["offset_rc"][0]), float(pose["offset_rc"][1])),
                     scale=float(pose["scale"]), rotation_deg=float(pose["rotation_deg"]))


def chart_boxes(layout: ChartLayout, pose: ChartPose) -> list[tuple[str, Box]]:
    """Every bar set of the chart at its found pose as ``(label, bounding box)``: the
    corners' extent plus :data:`CHART_CLEARANCE_PX`, end-exclusive."""
    out: list[tuple[str, Box]] = []
    m = CHART_CLEARANCE_PX
    for posed in posed_bar_sets(layout, pose):
        rows = [p[0] for p in posed.corners()]
        cols = [p[1] for p in posed.corners()]
        out.append((posed.label, (int(np.floor(min(rows) - m)), int(np.floor(min(cols) - m)),
                                  int(np.ceil(max(rows) + m)) + 1,
                                  int(np.ceil(max(cols) + m)) + 1)))
    return out


def clear_of_chart(
    measured: Sequence[tuple[EdgeSpec, SfrResult | str]], boxes: Sequence[tuple[str, Box]]
) -> list[tuple[EdgeSpec, SfrResult | str]]:
    """The edges with every one whose ROI overlaps a chart bar set (:func:`chart_boxes`)
    marked as no clean edge: the edge ROIs are fixed boxes, the chart may sit anywhere."""
    out: list[tuple[EdgeSpec, SfrResult | str]] = []
    for spec, res in measured:
        r0, c0, r1, c1 = spec.roi
        hits = [label for label, (b0, d0, b1, d1) in boxes
                if r0 < b1 and b0 < r1 and c0 < d1 and d0 < c1]
        if hits:
            res = (f"the found chart's {', '.join(hits[:3])}{' ...' if len(hits) > 3 else ''} "
                   f"overlap{'s' if len(hits) == 1 else ''} the edge ROI")
        out.append((spec, res))
    return out


def edge_tables(
    measured: Sequence[tuple[EdgeSpec, SfrResult | str]], centre_rc: tuple[float, float]
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """``(table_sfr_edges, table_sfr_curves)`` rows."""
    rows: list[dict[str, Any]] = []
    curves: list[dict[str, Any]] = []
    grid_lp = np.arange(0.0, 2 * nyquist_lp_per_mm() + 1e-9, CURVE_STEP_LP_PER_MM)
    grid_c = grid_lp / _LP_PER_CYCLE_PX
    for spec, res in measured:
        h = image_height_mm(centre_rc, roi_centroid(spec.roi))
        base = {"edge": spec.label, "orientation": spec.orientation, "roi": list(spec.roi),
                "image_height_mm": round(h, 4),
                "nearest_field_deg": nearest_field_point("forward", h).field_angle_deg}
        if isinstance(res, str):
            rows.append({**base, "status": f"no clean edge: {res}", "edge_angle_deg": None,
                         "mtf50_cycles_per_px": None, "mtf50_lp_per_mm": None,
                         "mtf_nyquist": None, "dark": None, "bright": None, "contrast": None,
                         "estimator": None, "warnings": ""})
            continue
        m50 = res.mtf50_cycles_per_px
        rows.append({
            **base, "status": "ok", "edge_angle_deg": round(res.edge_angle_deg, 3),
            "mtf50_cycles_per_px": None if m50 is None else round(m50, 5),
            "mtf50_lp_per_mm": None if m50 is None else round(m50 * _LP_PER_CYCLE_PX, 3),
            "mtf50_sigma_lp_per_mm": None if res.mtf50_sigma is None
            else round(res.mtf50_sigma * _LP_PER_CYCLE_PX, 3),
            "mtf_nyquist": round(res.mtf_nyquist, 5), "dark": round(res.dark, 3),
            "bright": round(res.bright, 3), "contrast": round(res.contrast, 5),
            "estimator": res.estimator,  # model-free, or the LSF model at low SNR (auto)
            "warnings": "; ".join(res.warnings),
        })
        sig = res.sigma_at(grid_c)
        for i, (f_lp, f_c, m) in enumerate(zip(grid_lp, grid_c, res.mtf_at(grid_c), strict=True)):
            curves.append({"edge": spec.label, "orientation": spec.orientation,
                           "freq_lp_per_mm": float(f_lp), "freq_cycles_per_px": round(f_c, 6),
                           "mtf": round(float(m), 5),
                           "mtf_sigma": None if sig is None else round(float(sig[i]), 5)})
    return rows, curves


def _simulated(curves: Sequence[SimulatedCurve], orientation: str, height_mm: float,
               f_lp: float) -> float | None:
    """Simulated MTF at ``f_lp`` and image height, interpolated linearly in height between the
    field points' curves (constant beyond the outermost)."""
    d = "S" if orientation == "sagittal" else "T"
    heights = {p.field_angle_deg: p.image_height_mm for p in field_points("forward")}
    pts = sorted(
        (heights[c.field_angle_deg], float(np.interp(f_lp, c.freqs_lp_per_mm, c.mtf)))
        for c in curves
        if c.view == "forward" and c.direction == d and c.field_angle_deg in heights
    )
    if not pts:
        return None
    return float(np.interp(height_mm, [h for h, _ in pts], [m for _, m in pts]))


def _height_weights(
    edges: Sequence[tuple[EdgeSpec, SfrResult]], height_mm: float,
    centre_rc: tuple[float, float],
) -> list[tuple[str, SfrResult, float]]:
    """The edges that stand for an image height, with their weights: the two bracketing it
    (linear in height: the blur changes with height), else the nearest. ``(label, SFR,
    weight)``."""
    pts = sorted(((image_height_mm(centre_rc, roi_centroid(s.roi)), s.label, r)
                  for s, r in edges), key=lambda p: p[0])
    below = [p for p in pts if p[0] <= height_mm]
    above = [p for p in pts if p[0] > height_mm]
    if below and above:
        (h0, l0, r0), (h1, l1, r1) = below[-1], above[0]
        w = (height_mm - h0) / (h1 - h0)
        return [(l0, r0, 1 - w), (l1, r1, w)]
    _, label, r = min(pts, key=lambda p: abs(p[0] - height_mm))
    return [(label, r, 1.0)]


def _edge_at_height(
    edges: Sequence[tuple[EdgeSpec, SfrResult]], height_mm: float, f_cycles_per_px: float,
    centre_rc: tuple[float, float],
) -> tuple[str, float, float | None]:
    """Edge MTF (and 1-sigma) at a frequency for an image height: interpolated linearly in
    height between the two edges bracketing it (the blur changes with height), else the
    nearest edge (:func:`_height_weights`). Returns ``(edge label(s), mtf, sigma)``."""
    parts = _height_weights(edges, height_mm, centre_rc)
    label = "+".join(lab for lab, _, _ in parts)
    m = sum(w * float(r.mtf_at(f_cycles_per_px)) for _, r, w in parts)
    sigmas = [r.sigma_at(f_cycles_per_px) for _, r, _ in parts]
    known = [float(x) for x in sigmas if x is not None]
    if len(known) < len(sigmas):
        return label, m, None
    return label, m, float(sum(w * x for (_, _, w), x in zip(parts, known, strict=True)))


def _edge_harmonics(edges: Sequence[tuple[EdgeSpec, SfrResult]], height_mm: float,
                    f_lp: npt.NDArray[np.float64], centre_rc: tuple[float, float]
                    ) -> npt.NDArray[np.float64]:
    """The edges' MTF at the height (:func:`_edge_at_height`) at each frequency (lp/mm);
    0 beyond the SFR's range."""
    f_c = np.asarray(f_lp, dtype=np.float64) / _LP_PER_CYCLE_PX
    return np.array([_edge_at_height(edges, height_mm, float(fc), centre_rc)[1]
                     if fc <= MAX_FREQ_CYCLES_PER_PX else 0.0 for fc in f_c])


#: What "bars vs edge" was judged on (``bars_vs_edge_basis``, and named in the verdict).
BASIS_PREDICTED = "predicted reading"
BASIS_COLTMAN = "Coltman"


def agrees(verdict: str) -> bool:
    """Whether a ``table_sfr_vs_bars`` verdict is an agreement (``agree``, with or without the
    basis it names)."""
    return verdict == "agree" or verdict.startswith("agree ")


def predicted_bar_modulation(
    setup: ReadingSetup, height_mm: float,
    across_edges: Sequence[tuple[EdgeSpec, SfrResult]],
    along_edges: Sequence[tuple[EdgeSpec, SfrResult]],
    contrast: float, centre_rc: tuple[float, float],
    optics: dict[str, OpticsTransfer] | None = None,
) -> float | None:
    """What the bar set read with ``setup`` should read if the optics were what the edges say
    (:func:`benchlab.analysis.chart.threebar.predict_reading`): the set imaged through the
    optics of ``across_edges`` (its orientation) at its image height - the edges bracketing
    it, weighted as :func:`_edge_at_height` weighs their MTFs - and of ``along_edges`` (the
    other orientation: the bar ends), at the chart's ``contrast``, and read with the chart
    reading's estimator the way the real set was. None when there is no such reading (no
    edge, a contrast out of (0, 1), the estimator not resolving the image). ``optics``: each
    edge's transfer by label, where already computed."""
    if not across_edges or not 0.0 < contrast < 1.0:
        return None
    # loaded only where a set was read by the chart reading (start-up, issue 11)
    from benchlab.analysis.chart.threebar import mixed, optics_from_edge, predict_reading

    known = optics if optics is not None else {}

    def transfer(edges: Sequence[tuple[EdgeSpec, SfrResult]]) -> Transfer:
        return mixed([(known[label] if label in known else optics_from_edge(res), w)
                      for label, res, w in _height_weights(edges, height_mm, centre_rc)])

    try:
        pred = predict_reading(setup, transfer(across_edges),
                               transfer(along_edges or across_edges), contrast=contrast)
    except ValueError:
        return None
    return pred.modulation


def _setup(setups: Mapping[tuple[str, str], Any] | None, element: str,
           orientation: str) -> ReadingSetup | None:
    """The set's reading setup from ``setups`` (a dict is parsed; None: none usable)."""
    raw = None if setups is None else setups.get((element, orientation))
    if raw is None:
        return None
    from benchlab.analysis.chart.threebar import ReadingSetup

    if isinstance(raw, ReadingSetup):
        return raw
    try:
        return ReadingSetup.from_dict(dict(raw))
    except (KeyError, TypeError, ValueError, IndexError):
        return None


def edge_vs_bars(
    t411: Sequence[dict[str, Any]],
    measured: Sequence[tuple[EdgeSpec, SfrResult | str]],
    curves: Sequence[SimulatedCurve],
    centre_rc: tuple[float, float],
    setups: Mapping[tuple[str, str], Any] | None = None,
) -> list[dict[str, Any]]:
    """The three-way comparison rows (bar sets below Nyquist with a clean edge to compare).

    ``setups``: by ``(element, orientation)``, how the chart reading read each set
    (:class:`benchlab.analysis.chart.threebar.ReadingSetup` or its dict, the forward rows'
    ``reading_setup``). Where one is given, the set imaged through the edges' transfer and
    read the same way gives ``bar_modulation_predicted`` and "bars vs edge" is judged on
    ``|bar_modulation - bar_modulation_predicted|``; elsewhere (another estimator, no chart
    found) on the Coltman-converted bars against the edge MTF. ``bars_vs_edge_basis`` and the
    verdict say which."""
    nyq = nyquist_lp_per_mm()
    clean = [(s, r) for s, r in measured if not isinstance(r, str)]
    rows: list[dict[str, Any]] = []
    jobs: list[Callable[[], float | None] | None] = []
    optics: dict[str, OpticsTransfer] = {}
    if setups and clean:
        from benchlab.analysis.chart.threebar import optics_from_edge

        optics = {s.label: optics_from_edge(r) for s, r in clean}
    for orientation in ("sagittal", "tangential"):
        edges = [(s, r) for s, r in clean if s.orientation == orientation]
        others = [(s, r) for s, r in clean if s.orientation != orientation]
        sets = [r for r in t411 if r["image_lp_per_mm"] < nyq
                and r.get(f"{orientation}_modulation") is not None]
        if not edges or not sets:
            continue
        # One edge for the chart's contrast: the one nearest the bar sets on average.
        heights = [image_height_mm(centre_rc, roi_centroid(tuple(r[f"{orientation}_roi"])))
                   for r in sets]
        mean_h = float(np.mean(heights))
        ref_spec, ref = min(edges, key=lambda e: abs(
            image_height_mm(centre_rc, roi_centroid(e[0].roi)) - mean_h))
        object_mod = ref.contrast
        freqs = [float(r["image_lp_per_mm"]) for r in sets]
        ctf = [float(r[f"{orientation}_modulation"]) / object_mod for r in sets]
        # Shown for reference: Coltman with Nyquist as the cutoff (MTF taken as 0 above it),
        # up to 0.05-0.08 off on this bench (the optics x pixel MTF at 3f is ~0.2).
        conv = ctf_to_mtf(freqs, ctf, cutoff_lp_per_mm=nyq)
        for r, h, f_lp, c, m_nyq, how in zip(sets, heights, freqs, ctf, conv.mtf, conv.method,
                                             strict=True):
            label, m_edge, sig = _edge_at_height(edges, h, cycles_per_px(f_lp), centre_rc)
            # The series with the harmonics' MTF from the edges at that height (the 4x
            # oversampled curve runs to 1 cycle/px; 0 beyond).
            def harmonics(fk: npt.NDArray[np.float64], h: float = h,
                          e: list[tuple[EdgeSpec, SfrResult]] = edges
                          ) -> npt.NDArray[np.float64]:
                return _edge_harmonics(e, h, fk, centre_rc)

            m_bar = float(ctf_to_mtf_with_harmonics([f_lp], [c], harmonics)[0])
            m_sim = _simulated(curves, orientation, h, f_lp)
            setup = _setup(setups, r["element"], orientation)
            jobs.append(None if setup is None else partial(
                predicted_bar_modulation, setup, h, edges, others, object_mod, centre_rc,
                optics))
            rows.append({
                "element": r["element"], "orientation": orientation,
                "image_lp_per_mm": round(f_lp, 3), "image_height_mm": round(h, 4),
                "bar_modulation": r[f"{orientation}_modulation"],
                "bar_modulation_predicted": None, "bars_vs_edge_basis": None,
                "object_modulation": round(object_mod, 5), "contrast_from_edge": ref_spec.label,
                "ctf": round(c, 5),
                "bar_mtf": round(m_bar, 5),
                "bar_mtf_coltman": round(float(m_nyq), 5), "coltman_method": how,
                "edge": label, "edge_mtf": round(m_edge, 5),
                "edge_mtf_sigma": None if sig is None else round(float(sig), 5),
                "simulated_mtf": None if m_sim is None else round(m_sim, 5),
                "verdict": None,
                # for the verdict, unrounded (dropped below)
                "_gaps": (m_bar - m_edge, None if m_sim is None else m_edge - m_sim),
            })
    # ~5 ms a set, one thread (two threads took longer: the fits are small)
    for row, job in zip(rows, jobs, strict=True):
        predicted = None if job is None else job()
        coltman_gap, sim_gap = row.pop("_gaps")
        if predicted is not None:
            # Compared: the bars against what the set reads imaged through the edges
            basis, gap = BASIS_PREDICTED, float(row["bar_modulation"]) - predicted
            row["bar_modulation_predicted"] = round(predicted, 5)
        else:
            # Compared: Coltman's series with the edges' harmonics against the edge MTF
            basis, gap = BASIS_COLTMAN, coltman_gap
        problems = []
        if abs(gap) > AGREEMENT_TOLERANCE:
            problems.append(f"bars vs edge ({basis}) {gap:+.3f}")
        if sim_gap is not None and abs(sim_gap) > AGREEMENT_TOLERANCE:
            problems.append(f"edge vs simulated {sim_gap:+.3f}")
        row["bars_vs_edge_basis"] = basis
        row["verdict"] = (f"agree ({basis})" if not problems
                          else "DISAGREE: " + ", ".join(problems))
    return rows


class EdgeParts(NamedTuple):
    """What the edge tables need besides the bar readings (Table 4.11)."""

    measured: list[tuple[EdgeSpec, SfrResult | str]]
    rows: list[dict[str, Any]]
    curve_rows: list[dict[str, Any]]
    curves: list[SimulatedCurve]


def edge_parts_of(measured: list[tuple[EdgeSpec, SfrResult | str]],
                  centre_rc: tuple[float, float], simulated_mtf_file: str = "") -> EdgeParts:
    """The forward frame's edge tables and the simulated curves - all but the comparison
    with the bars - from the edges already measured (:func:`measure_edges`, which
    needs no centre: a re-analysis measures them while the forward view's bar sets are
    read on another thread)."""
    from benchlab.protocols.mtf.curves import load_curves  # the simulated curves' loader

    rows, curve_rows = edge_tables(measured, centre_rc)
    try:
        curves = load_curves(simulated_mtf_file or None)
    except (OSError, ValueError):
        curves = []  # the comparison still runs; the simulated column stays empty
    return EdgeParts(measured, rows, curve_rows, list(curves))


def forward_edge_tables(
    pixels: npt.NDArray[Any], t411: Sequence[dict[str, Any]], centre_rc: tuple[float, float],
    simulated_mtf_file: str = "", chart_boxes_px: Sequence[tuple[str, Box]] = (), *,
    full_scale: float | None = None, setups: Mapping[tuple[str, str], Any] | None = None,
) -> dict[str, list[dict[str, Any]]]:
    """The three edge tables of a forward frame (see the module docstring); edges whose ROI
    overlaps one of ``chart_boxes_px`` (:func:`chart_boxes` of the found chart) are not
    clean. ``full_scale``: as for :func:`measure_edges`; ``setups``: as for
    :func:`edge_vs_bars`."""
    measured = clear_of_chart(measure_edges(pixels, full_scale=full_scale), chart_boxes_px)
    return edge_parts_tables(edge_parts_of(measured, centre_rc, simulated_mtf_file), t411,
                             centre_rc, setups)


def edge_parts_tables(
    parts: EdgeParts, t411: Sequence[dict[str, Any]], centre_rc: tuple[float, float],
    setups: Mapping[tuple[str, str], Any] | None = None,
) -> dict[str, list[dict[str, Any]]]:
    """:func:`forward_edge_tables` from :func:`edge_parts_of` already computed (a re-analysis
    measures the edges beside the bar ROIs, then compares them with the bars' Table 4.11);
    ``setups``: as for :func:`edge_vs_bars`."""
    return {"table_sfr_edges": parts.rows, "table_sfr_curves": parts.curve_rows,
            "table_sfr_vs_bars": edge_vs_bars(t411, parts.measured, parts.curves, centre_rc,
                                              setups)}
