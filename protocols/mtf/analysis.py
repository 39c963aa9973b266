"""Frames of a Table 4.10 session -> Tables 4.11-4.15 (pure apart from reading the session).

The same functions serve the live run (partial results per frame) and offline re-analysis, so a
re-analysis of unchanged frames with the same estimator reproduces the run's tables exactly.
"""

from __future__ import annotations

import math
from concurrent.futures import CancelledError, Executor, Future
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.estimators import AUTO, estimate_modulation, resolve_estimator
from benchlab.analysis.bars.result import ModulationResult
from benchlab.analysis.chart import layout as chart
from benchlab.analysis.geometry import (
    fill_holes,
    fov_centre,
    image_height_mm,
    image_height_px,
    nearest_field_point,
    roi_centroid,
)
from benchlab.analysis.mtf.compare import averaged_mtf, load_monte_carlo_table, monte_carlo_band
from benchlab.analysis.mtf.frequency import (
    azimuthal_image_frequency_lp_per_mm,
    cycles_per_px,
    image_frequency_lp_per_mm,
    nyquist_lp_per_mm,
    usaf_frequency_lp_per_mm,
)
from benchlab.analysis.sfr.measure import SfrResult, full_scale_of_frame
from benchlab.analysis.sfr.target import EdgeSpec, edge_specs
from benchlab.analysis.sfr.target_edges import measure_edge
from benchlab.analysis.thesis_data import thesis_fixture_path
from benchlab.analysis.threads import thread_pool
from benchlab.protocols.mtf.edges import (
    chart_boxes,
    chart_pose_of,
    clear_of_chart,
    edge_parts_of,
    edge_parts_tables,
)
from benchlab.protocols.mtf.params import MtfParams, UsafElement
from benchlab.protocols.mtf.targets import REFERENCE_MIN_CTF, lowest_ctf, share_columns
from benchlab.protocols.params import Roi
from benchlab.protocols.target_contrast import (
    ReferenceReading,
    TargetContrast,
    certificate,
    from_reference,
)
from benchlab.session import FRAME_LOAD_THREADS

if TYPE_CHECKING:
    from benchlab.analysis.chart.finder import ChartFit, FoundElement
    from benchlab.analysis.chart.reading import SetReading
    from benchlab.analysis.mtf.compare import SimulatedCurve
    from benchlab.session import Session

FORWARD_STEP = "forward"
FORWARD_FRAME = "forward"
RADIAL_FRAME = "radial"
ORIENTATIONS = ("sagittal", "tangential")
#: "auto" is the library's one default (:data:`benchlab.analysis.bars.estimators.DEFAULT_ESTIMATOR`)
#: in both views: it measures the bar direction itself, so the oblique spokes and rings of the
#: radial view need no other estimator.
#: A measured frequency is compared with a Monte Carlo row within this relative distance (the
#: thesis paired 73.2 with 70, 35 with 30 and 52.5 with 60 lp/mm: at most 17 % apart).
MC_MATCH_FRACTION = 0.2
#: Threads that load a session's frames (decoding releases the GIL; more buys nothing here).
LOAD_THREADS = FRAME_LOAD_THREADS


def radial_step_id(freq_lp_per_mm: float, orientation: str) -> str:
    """Step id (and frame folder key) of one radial acquisition."""
    return f"radial-{freq_lp_per_mm:g}-{orientation}"


#: A found pose this close to the configured geometry (scale within this fraction, rotation
#: within this many degrees) places the ROIs as the configured boxes shifted by the whole-pixel
#: offset, so a chart at its configured place gives exactly the configured ROIs; otherwise the
#: ROIs are the found, scaled and rotated bar sets.
NOMINAL_SCALE_TOLERANCE = 0.01
NOMINAL_ROTATION_DEG = 0.3


def _bar_group(el: UsafElement, orientation: str) -> chart.BarGroup:
    orient: chart.Orientation = "sagittal" if orientation == "sagittal" else "tangential"
    return chart.usaf_bar_group(chart.ChartLayout(), el.group, el.element, orient)


def forward_layout(params: MtfParams) -> chart.ChartLayout:
    """The configured forward-view chart geometry: the prior of the chart finder."""
    return chart.ChartLayout(magnification=params.forward_magnification)


def locate_chart(pixels: npt.NDArray[Any], params: MtfParams) -> ChartFit | None:
    """The USAF chart in the forward frame (:func:`benchlab.analysis.chart.finder.find_chart`
    with the parameter file's geometry as the prior), or None when no chart is found (the ROIs
    then stay at the configured places and each row says so)."""
    # Imported where used: in a re-analysis the import runs on the forward view's thread,
    # beside the radial frames' loads (start-up: docs/development/startup.md).
    from benchlab.analysis.chart.finder import ChartNotFoundError, find_chart

    try:
        return find_chart(pixels, forward_layout(params))
    except ChartNotFoundError:
        return None


def _near_nominal(fit: ChartFit) -> bool:
    return (abs(fit.pose.scale - 1.0) <= NOMINAL_SCALE_TOLERANCE
            and abs(fit.pose.rotation_deg) <= NOMINAL_ROTATION_DEG)


def _found_element(el: UsafElement, orientation: str, fit: ChartFit | None) -> FoundElement | None:
    """The found chart's placement of a set when the chart is far from the configured
    geometry (its ROIs, priors and measurability then apply), else None."""
    if fit is None or _near_nominal(fit):
        return None
    orient: chart.Orientation = "sagittal" if orientation == "sagittal" else "tangential"
    return fit.element(el.group, el.element, orient)


def forward_roi(
    params: MtfParams, el: UsafElement, orientation: str, offset: tuple[int, int] = (0, 0),
    fit: ChartFit | None = None,
) -> Roi:
    """ROI of one bar set: the technician's override, else the bar set located on the chart:
    its measurement ROI (:func:`benchlab.analysis.chart.layout.bar_set_roi`), every line across the
    three bars but none straddling the bar ends, which read bar and bright ground at once and
    biased the modulation low by up to 0.12. With a found chart ``fit`` far from the configured
    geometry the ROI is the found (scaled, rotated) set's measurement ROI (three whole periods
    across, :attr:`FoundElement.measurement_roi`); otherwise the configured ROI shifted by
    ``offset`` (the found offset in whole pixels)."""
    override = params.forward_roi_overrides.get(f"{el.name}.{orientation}")
    if override is not None:
        return override
    found = _found_element(el, orientation, fit)
    if found is not None:
        return found.measurement_roi
    r0, c0, r1, c1 = _bar_group(el, orientation).roi
    dr, dc = offset
    return (r0 + dr, c0 + dc, r1 + dr, c1 + dc)


def _measure(
    pixels: npt.NDArray[Any], roi: Roi, *, estimator: str, freq_cycles_per_px: float,
    orientation: str | None,
) -> ModulationResult:
    r0, c0, r1, c1 = roi
    if not _inside(roi, pixels.shape):
        raise ValueError(f"ROI {roi} is off the {pixels.shape} frame")
    return estimate_modulation(
        pixels[r0:r1, c0:c1], estimator=estimator, orientation=orientation,
        freq_cycles_per_px=freq_cycles_per_px,
    )


def _cells(res: ModulationResult) -> dict[str, Any]:
    if not res.measurable:  # no reading at all (ROI < 1 period): no number, never the N/A 0
        return _not_measured("; ".join(res.warnings))
    return {
        "dark": res.dark,
        "bright": res.bright,
        "modulation": round(float(res.modulation), 6),
        "resolved": res.resolved,
        "uncertainty": res.uncertainty,
        "warnings": "; ".join(res.warnings),
        # Only when set: rows of values stay as they were (a re-analysis matches them).
        **({"lower_bound": True} if res.lower_bound else {}),
    }


#: Threads of the chart reading (:func:`benchlab.analysis.chart.reading.read_chart`): its
#: transforms and products release the GIL, so the forward frame's part (on its own thread)
#: takes the second core once the rest is done.
CHART_READING_THREADS = 2

#: What Table 4.11's ``estimator`` says when the chart reading read a set.
CHART_READING = "chart reading (knownbars)"


def reads_chart(estimator: str | None) -> bool:
    """Whether the forward view is read by the chart reading: the default (``auto``) on a
    found chart. A chart of known layout is read best with its geometry fixed by the found
    pose (:func:`benchlab.analysis.chart.reading.read_chart`): every Table 4.11 set within
    0.017 of the simulator's truth at any noise seed, where a generic estimator on the small
    ROIs of group 1 and 2 read up to 0.06 off. A named estimator is used as named."""
    return estimator in (None, "", AUTO)


def analyze_forward_frame(
    pixels: npt.NDArray[Any], params: MtfParams, estimator: str | None
) -> list[dict[str, Any]]:
    """One row per element and orientation (what a UI shows while the run goes on).

    With the chart found, every set's frequency and aliasing follow from the found pose (the
    implied magnification, not the configured one), a set the finder rejected is not measured
    (its reason instead of a number), and by default (:func:`reads_chart`) every found set is
    read by the chart reading. A technician's ROI override is read by the generic estimator.
    """
    est = resolve_estimator(estimator)
    fit = locate_chart(pixels, params)
    offset = fit.offset_px if fit is not None else (0, 0)
    chart_info = _chart_info(fit)
    readings = _chart_readings(pixels, fit) if fit is not None and reads_chart(estimator) else None
    target = forward_target_contrast(pixels, params, fit, readings, est)
    nyq = nyquist_lp_per_mm()
    rows = []
    for el in params.forward_elements:
        f_conf = image_frequency_lp_per_mm(usaf_frequency_lp_per_mm(el.group, el.element),
                                           params.forward_magnification)
        for orient in ORIENTATIONS:
            override = f"{el.name}.{orient}" in params.forward_roi_overrides
            placed = _placed(el, orient, fit)
            # The found pose's frequency: a wrong configured magnification must not move the
            # frequencies (nor hide measured sets as aliased).
            f_img = placed.posed.image_lp_per_mm if placed is not None else f_conf
            roi = forward_roi(params, el, orient, offset, fit)
            used: str | None = None  # what read the set (None: not measured)
            setup: dict[str, Any] | None = None  # how the chart reading read it
            if not override and placed is not None and not placed.found:
                cells = _not_measured(f"not measured: {placed.reason}")
            elif not override and readings is not None and placed is not None:
                roi = placed.reading_roi or placed.measurement_roi
                if placed.unmeasurable:
                    cells = _not_measured(placed.unmeasurable)
                else:
                    reading = readings[placed.label]
                    used, cells = CHART_READING, _cells(reading.result)
                    dark_bars = fit is not None and fit.polarity == "positive"
                    setup = _reading_setup(placed, roi, reading, dark_bars)
            elif not _inside(roi, pixels.shape):
                cells = _not_measured("clipped by the FOV: ROI off the frame")
            else:
                found = None if override else _found_element(el, orient, fit)
                if found is not None and found.generic_unreliable:
                    cells = _not_measured(found.generic_unreliable)
                else:
                    used = est
                    # Bars off the pixel axes have their direction measured, not taken as
                    # the axis.
                    priors = (found.estimator_priors() if found is not None else
                              {"freq_cycles_per_px": cycles_per_px(f_img), "orientation": orient})
                    cells = _cells(_measure(pixels, roi, estimator=est, **priors))
            if fit is None:
                note = "chart not found: configured ROI"
                cells["warnings"] = "; ".join(w for w in (cells["warnings"], note) if w)
            rows.append({"view": "forward", "element": el.name, "orientation": orient,
                         "image_lp_per_mm": f_img, "aliased": f_img > nyq, "roi": list(roi),
                         "estimator": used, "chart_offset_px": list(offset), "chart": chart_info,
                         "reading_setup": setup, "target_contrast": target.to_dict(), **cells})
    return rows


def _curves(params: MtfParams) -> list[SimulatedCurve] | str:
    """The simulated lens curves, or why there are none."""
    from benchlab.protocols.mtf.curves import load_curves

    try:
        return load_curves(params.simulated_mtf_file or None)
    except (OSError, ValueError) as exc:
        return f"no simulated curves ({exc})"


def _reference_readings(view: str, candidates: list[tuple[str, float | None, float, float]],
                        curves: list[SimulatedCurve]) -> list[ReferenceReading] | str:
    """The readings ``(orientation, modulation or None, uncertainty, image lp/mm)`` of one
    candidate reference set where the lens passes >= :data:`REFERENCE_MIN_CTF` in each
    orientation, or why the set cannot serve."""
    out = []
    for orient, m, u, f in candidates:
        ctf = lowest_ctf(curves, view, orient[0].upper(), f)
        if ctf is None:
            return f"no simulated {view} {orient} curve"
        if ctf < REFERENCE_MIN_CTF:
            return (f"the simulated lens passes only {ctf:.3f} of the bar contrast at "
                    f"{f:.1f} lp/mm ({orient}), below {REFERENCE_MIN_CTF}")
        if m is not None:
            out.append(ReferenceReading(orient, m, u, ctf))
    return out


def forward_target_contrast(
    pixels: npt.NDArray[Any], params: MtfParams, fit: ChartFit | None,
    readings: dict[str, SetReading] | None, est: str,
) -> TargetContrast:
    """The USAF chart's own contrast: the certificate's, or measured on its coarsest found
    element (both orientations, read the way the sets are read: the chart reading, else the
    named estimator) where the simulated lens passes >= 0.99 of the bar contrast."""
    setting = params.targets.usaf
    if setting.values is not None:
        return certificate(setting)
    if fit is None:
        return TargetContrast(None, None, "not measured: chart not found")
    curves = _curves(params)
    if isinstance(curves, str):
        return TargetContrast(None, None, f"not measured: {curves}")
    by_element: dict[tuple[int, int], list[FoundElement]] = {}
    for e in fit.found:
        by_element.setdefault((e.posed.group, e.posed.element), []).append(e)
    why = "no element of the chart found"
    for (g, el), sets in sorted(by_element.items(),
                                key=lambda kv: kv[1][0].posed.image_lp_per_mm):
        cands: list[tuple[str, float | None, float, float]] = []
        for e in sorted(sets, key=lambda e: e.posed.orientation):
            res = _reference_result(pixels, e, readings, est)
            ok = res is not None and res.measurable and res.resolved
            cands.append((e.posed.orientation, float(res.modulation) if ok and res else None,
                          float(res.uncertainty or 0.0) if ok and res else 0.0,
                          e.posed.image_lp_per_mm))
        got = _reference_readings("forward", cands, curves)
        if isinstance(got, str):
            why = got
            break  # finer elements pass even less
        if got:
            return from_reference(got, f"USAF G{g}E{el} at {sets[0].posed.image_lp_per_mm:.1f} "
                                  "lp/mm")
        why = f"G{g}E{el} not read"
    return TargetContrast(None, None, f"not measured: {why}")


def _reference_result(pixels: npt.NDArray[Any], e: FoundElement,
                      readings: dict[str, SetReading] | None, est: str) -> ModulationResult | None:
    if readings is not None and e.label in readings and e.unmeasurable is None:
        return readings[e.label].result
    if e.generic_unreliable is not None or not _inside(e.measurement_roi, pixels.shape):
        return None
    return _measure(pixels, e.measurement_roi, estimator=resolve_estimator(est),
                    **e.estimator_priors())


def _reading_setup(placed: FoundElement, roi: Roi, reading: SetReading,
                   dark_bars: bool) -> dict[str, Any] | None:
    """How the chart reading read a set (:class:`benchlab.analysis.chart.threebar.ReadingSetup`
    as a dict: ROI, centre, bar width and angle, polarity, blur prior, noise and ground level),
    so that the set imaged through a slanted edge's transfer is read the same way
    (``table_sfr_vs_bars``); None when the reading has no levels."""
    res = reading.result
    if not res.measurable or res.dark is None or res.bright is None:
        return None
    p = placed.posed
    prior = reading.blur_prior_px
    return {"roi": list(roi), "centre_rc": [float(p.centre_rc[0]), float(p.centre_rc[1])],
            "bar_width_px": float(p.bar_width_px), "theta_deg": float(p.theta_deg),
            "dark_bars": dark_bars,
            "blur_prior_px": None if prior is None else [float(prior[0]), float(prior[1])],
            "noise_sigma": float(res.diagnostics.noise_sigma or 0.0),
            "ground_level": float(res.bright if dark_bars else res.dark)}


def _placed(el: UsafElement, orientation: str, fit: ChartFit | None) -> FoundElement | None:
    """The found chart's placement of a set (found or rejected), or None without a chart."""
    if fit is None:
        return None
    orient: chart.Orientation = "sagittal" if orientation == "sagittal" else "tangential"
    try:
        return fit.element(el.group, el.element, orient)
    except KeyError:
        return None


def _chart_readings(pixels: npt.NDArray[Any], fit: ChartFit) -> dict[str, SetReading]:
    """Every found set read by the chart reading, by label (``G2E4S``)."""
    from benchlab.analysis.chart.reading import read_chart_details  # loaded only where used

    readings = read_chart_details(pixels, fit, workers=CHART_READING_THREADS)
    return dict(zip([e.label for e in fit.found], readings, strict=True))


def _not_measured(reason: str) -> dict[str, Any]:
    """A set with no reading: modulation None (the tables say "not measurable") and why."""
    return {"dark": None, "bright": None, "modulation": None, "resolved": False,
            "uncertainty": None, "warnings": reason}


def _inside(roi: Roi, shape: tuple[int, ...]) -> bool:
    r0, c0, r1, c1 = roi
    return 0 <= r0 < r1 <= shape[-2] and 0 <= c0 < c1 <= shape[-1]


def _chart_info(fit: ChartFit | None) -> dict[str, Any] | None:
    """The found chart in brief (pose, magnification, counts, warnings) for the summary."""
    if fit is None:
        return None
    d = fit.to_dict()
    return {k: d[k] for k in ("pose", "polarity", "configured_magnification",
                              "implied_magnification", "matched_sets", "residual_px", "found",
                              "rejected", "warnings")}


def radial_image_lp_per_mm(freq_lp_per_mm: float, orientation: str, params: MtfParams,
                           centre: tuple[float, float]) -> float:
    """Image frequency of a radial pattern at the radial ROI: Eq. 4.1's axial magnification for
    tangential bars (rings); object radius / image radius for sagittal bars (spokes), the
    rotational symmetry's azimuthal magnification."""
    if orientation != "sagittal":
        return image_frequency_lp_per_mm(freq_lp_per_mm, params.radial_magnification)
    r_mm = image_height_mm(centre, roi_centroid(params.radial_roi))
    return azimuthal_image_frequency_lp_per_mm(freq_lp_per_mm, params.radial_object_radius_mm,
                                               r_mm)


def analyze_radial_frame(
    pixels: npt.NDArray[Any], freq_lp_per_mm: float, orientation: str, params: MtfParams,
    estimator: str | None, centre: tuple[float, float] | None = None,
) -> dict[str, Any]:
    """Modulation of one radial frame in the common radial ROI. ``centre`` (row, col) is the
    image centre; by default it is found from this frame's field of view."""
    est = resolve_estimator(estimator)
    if centre is None:
        centre = _centre([pixels], params.fov_threshold_dn)[0]
    f_img = radial_image_lp_per_mm(freq_lp_per_mm, orientation, params, centre)
    res = _measure(pixels, params.radial_roi, estimator=est,
                   freq_cycles_per_px=cycles_per_px(f_img), orientation=None)
    # a live reading's target: the certificate's; a measured one comes with the analysis
    setting, freqs = params.targets.radial, params.radial_frequencies_lp_per_mm
    target = (certificate(setting, freqs.index(freq_lp_per_mm))
              if setting.values is not None and freq_lp_per_mm in freqs else
              TargetContrast(None, None, "measured by the analysis (lowest-frequency pattern)"))
    return {"view": "radial", "freq_lp_per_mm": freq_lp_per_mm, "orientation": orientation,
            "image_lp_per_mm": f_img, "aliased": f_img > nyquist_lp_per_mm(),
            "roi": list(params.radial_roi), "target_contrast": target.to_dict(), **_cells(res)}


def _centre(radial_frames: list[npt.NDArray[Any]], threshold_dn: float) -> tuple[
    tuple[float, float], str
]:
    """Optical centre from the radial frames' field-of-view mask (section 4.3.3).

    The lit annulus of every radial frame together traces the field-of-view circle; with its
    hole (the forward disc) filled, the circle's centre is the optical axis (a circle fit when
    the frame edge clips it). Falls back to the chart's nominal centre when no mask exists.
    """
    if radial_frames:
        # Lit in any frame = the frames' maximum above the threshold: one comparison instead
        # of one per frame (each converts the whole frame to float), the same mask.
        brightest = np.array(radial_frames[0], dtype=np.result_type(*radial_frames), copy=True)
        for px in radial_frames[1:]:
            np.maximum(brightest, px, out=brightest)
        mask = fill_holes(brightest > threshold_dn)
        try:
            circle = fov_centre(mask)
            return circle.centre_rc, circle.method
        except ValueError:
            pass
    return chart.IMAGE_CENTRE_RC, "nominal"


#: A frame and its metadata (:meth:`benchlab.session.Session.load_frame`).
_Frame = tuple[npt.NDArray[Any], dict[str, Any]]


def _load_frame(session: Session, step_id: str, name: str) -> _Frame | None:
    if name not in session.step_frames(step_id):
        return None
    pixels, meta = session.load_frame(step_id, name)  # checks its hash against the journal
    return np.asarray(pixels), meta


def _load(session: Session, step_id: str, name: str) -> npt.NDArray[Any] | None:
    frame = _load_frame(session, step_id, name)
    return None if frame is None else frame[0]


_ForwardView = tuple[dict[tuple[str, str], dict[str, Any]], list[dict[str, Any]]]


#: A forward frame's slanted edges measured, by index in :func:`edge_specs`.
_Edges = dict[int, tuple[EdgeSpec, SfrResult | str]]


class ForwardPart(NamedTuple):
    """What the forward frame alone gives (no radial frame, no centre): its bar sets' rows
    by (element, orientation) with Table 4.11, and its slanted edges measured; None for both
    without a forward frame. ``estimator`` is the one used."""

    estimator: str
    view: _ForwardView | None
    edges: _Edges | None


def mtf_estimator(params: MtfParams, estimator: str | None) -> str:
    """The estimator of an MTF analysis: the caller's, else the parameter file's, else auto."""
    return estimator or params.estimator or AUTO


def _measure_edges(frame: _Frame) -> _Edges:
    """Every slanted edge measured; clipping is judged against the camera's ceiling,
    ``2**bits - 1`` from the frame's own metadata
    (:func:`benchlab.analysis.sfr.measure.full_scale_of_frame`; inferred from each ROI's codes
    when the metadata has no usable ``bits``)."""
    pixels, meta = frame
    full_scale = full_scale_of_frame(pixels, meta)
    return {i: (spec, measure_edge(pixels, spec, full_scale))
            for i, spec in enumerate(edge_specs())}


def analyze_mtf(
    session: Session, params: MtfParams, estimator: str | None,
) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any], str]:
    """All MTF tables from a session's frames: ``(tables, summary, estimator_used)``."""
    est = mtf_estimator(params, estimator)
    centre, centre_method, radial, t412, part = _with_forward_thread(session, params, est)
    forward = part.view
    edges_done = None
    if part.edges is not None:
        measured = [part.edges[i] for i in sorted(part.edges)]
        pose = (chart_pose_of(next(iter(forward[0].values()))["chart"])
                if forward is not None and forward[0] else None)
        if pose is not None:  # the edge ROIs are fixed: a moved chart may lie across them
            measured = clear_of_chart(measured, chart_boxes(forward_layout(params), pose))
        edges_done = edge_parts_of(measured, centre, params.simulated_mtf_file)
    nyq = nyquist_lp_per_mm()

    t411: list[dict[str, Any]] = []
    t413: list[dict[str, Any]] = []
    per: dict[tuple[str, str], dict[str, Any]] = {}
    edges: dict[str, list[dict[str, Any]]] = {}
    if forward is not None and edges_done is not None:
        per, t411 = forward
        setups = {key: r.get("reading_setup") for key, r in per.items()}
        edges = edge_parts_tables(edges_done, t411, centre, setups)
        for el in params.forward_elements:
            for orient in ORIENTATIONS:
                t413.append(_height_row("forward", f"{el.name}{orient[0].upper()}",
                                        tuple(per[(el.name, orient)]["roi"]), centre))
    if radial:
        t413.append(_height_row("radial", "radial ROI", params.radial_roi, centre))

    t415 = _monte_carlo_rows(t411, t412, params)
    tables = {"table_4_11": t411, "table_4_12": t412, "table_4_13": t413, "table_4_15": t415}
    tables.update(edges)  # slanted-edge MTF where a clean edge exists (issue 16)
    if session.meta.get("devices", {}).get("simulated"):
        from benchlab.protocols.mtf.truth import journalled_levels, truth_rows  # the scenes

        tables["simulator_truth"] = truth_rows(params, t411, t412,
                                               journalled_levels(session.events()))
    summary = {
        "procedure": "mtf",
        "estimator": est,
        "forward_estimator": _forward_estimator(per, est),
        "radial_estimator": resolve_estimator(est),
        "image_centre_rc": list(centre),
        "image_centre_method": centre_method,
        "chart_offset_px": next(iter(per.values()))["chart_offset_px"] if per else None,
        "chart": next(iter(per.values()))["chart"] if per else None,
        "nyquist_lp_per_mm": nyq,
        "frames_analysed": (forward is not None) + len(radial),
        "target_contrast": {"forward": _target_summary(t411), "radial": _target_summary(t412)},
        "table_4_15_basis": sorted({str(r["verdict_basis"]) for r in t415}),
    }
    return tables, summary, est


def _target_summary(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """A view's target contrast in brief: its value (a list when the patterns differ), 1-sigma
    uncertainty and source; None without rows."""
    if not rows:
        return None
    values = [r.get("sagittal_target_contrast") for r in rows]
    return {"value": values[0] if len(set(values)) == 1 else values,
            "uncertainty": rows[0].get("sagittal_target_contrast_uncertainty"),
            "source": rows[0].get("target_contrast_source")}


def _forward_estimator(per: dict[tuple[str, str], dict[str, Any]], est: str) -> str:
    """What read the forward view: the chart reading where it read the found sets."""
    used = sorted({str(r["estimator"]) for r in per.values() if r["estimator"]})
    return " and ".join(used) if used else resolve_estimator(est)


_Radial = dict[tuple[float, str], npt.NDArray[Any]]
_RadialPart = tuple[tuple[float, float], str, _Radial, list[dict[str, Any]], ForwardPart]


def _radial_keys(params: MtfParams) -> list[tuple[float, str]]:
    return [(f, orient) for f in params.radial_frequencies_lp_per_mm for orient in ORIENTATIONS]


def _collect(keys: list[tuple[float, str]],
             jobs: list[Future[npt.NDArray[Any] | None]]) -> _Radial:
    radial: _Radial = {}
    for key, job in zip(keys, jobs, strict=True):
        px = job.result()
        if px is not None:
            radial[key] = px
    return radial


def _submit_radial_loads(session: Session, keys: list[tuple[float, str]],
                         pool: Executor) -> list[Future[npt.NDArray[Any] | None]]:
    """Start loading every radial frame on ``pool`` (one job per key, in order)."""
    return [pool.submit(_load, session, radial_step_id(f, o), RADIAL_FRAME) for f, o in keys]


def _radial_part(
    keys: list[tuple[float, str]], jobs: list[Future[npt.NDArray[Any] | None]], params: MtfParams,
    est: str,
) -> tuple[_Radial, tuple[float, float], str, list[dict[str, Any]]]:
    """The radial frames once loaded, the optical centre fitted to them and the radial
    rows (Table 4.12)."""
    radial = _collect(keys, jobs)
    centre, centre_method = _centre(list(radial.values()), params.fov_threshold_dn)
    return radial, centre, centre_method, _radial_rows(radial, params, est, centre)


def _with_forward_thread(session: Session, params: MtfParams, est: str) -> _RadialPart:
    """The centre, Table 4.12 and the forward part (the forward view on its own thread)."""
    radial_keys = _radial_keys(params)
    # Frames are read, hashed and inflated on threads: zlib and sha256 release the GIL, so on
    # several cores the 15 frames of a session load in a fraction of the time. The forward
    # view's chart finder and bar ROIs run on their own thread beside the radial frames, the
    # centre and the radial rows; this thread then measures the forward frame's slanted edges
    # (which need neither the centre nor the chart) while the bar ROIs finish, so neither
    # thread waits long for the other; the larger numpy calls release the GIL. Every
    # estimate is a pure function of its frame, so the numbers are those of one thread. A
    # failure is raised as before (the forward frame's first).
    frame_ready: Future[_Frame | None] = Future()
    # (in a batch worker both run on this thread, in this order: benchlab.analysis.threads)
    with thread_pool(1) as forward_pool, thread_pool(LOAD_THREADS) as pool:
        forward_job = forward_pool.submit(_forward_view, session, params, est, frame_ready)
        radial_jobs = _submit_radial_loads(session, radial_keys, pool)
        try:
            radial, centre, centre_method, t412 = _radial_part(radial_keys, radial_jobs,
                                                               params, est)
            forward_frame = frame_ready.result()
            measured = _measure_edges(forward_frame) if forward_frame is not None else None
        except BaseException:
            failed = forward_job.exception()
            if failed is not None and not isinstance(failed, CancelledError):
                raise failed from None
            raise
        forward = forward_job.result()
    return centre, centre_method, radial, t412, ForwardPart(est, forward, measured)


def _forward_view(session: Session, params: MtfParams, est: str,
                  frame_ready: Future[_Frame | None]) -> _ForwardView | None:
    """The forward frame's rows by (element, orientation) and Table 4.11, or None without a
    forward frame; the frame and its metadata (or its load's failure) are handed to
    ``frame_ready`` first."""
    try:
        forward = _load_frame(session, FORWARD_STEP, FORWARD_FRAME)
    except BaseException as exc:
        frame_ready.set_exception(exc)
        raise
    frame_ready.set_result(forward)
    if forward is None:
        return None
    return _forward_rows(forward[0], params, est)


def _forward_rows(forward: npt.NDArray[Any], params: MtfParams, est: str) -> _ForwardView:
    """The forward frame's rows by (element, orientation) and Table 4.11."""
    per = {(r["element"], r["orientation"]): r
           for r in analyze_forward_frame(forward, params, est)}
    nyq = nyquist_lp_per_mm()
    t411: list[dict[str, Any]] = []
    for el in params.forward_elements:
        s, t = per[(el.name, "sagittal")], per[(el.name, "tangential")]
        f_img = t["image_lp_per_mm"]
        # image_lp_per_mm / aliased: the tangential set's (the found pose gives both sets of
        # an element the same frequency); each orientation also has its own.
        row: dict[str, Any] = {
            "element": el.name,
            "object_lp_per_mm": usaf_frequency_lp_per_mm(el.group, el.element),
            "image_lp_per_mm": f_img, "aliased": f_img > nyq,
        }
        for orient, r in (("sagittal", s), ("tangential", t)):
            row.update({f"{orient}_{k}": r[k] for k in
                        ("dark", "bright", "modulation", "resolved", "uncertainty",
                         "warnings", "estimator")})
            if r.get("lower_bound"):
                row[f"{orient}_lower_bound"] = True
            row[f"{orient}_image_lp_per_mm"] = r["image_lp_per_mm"]
            row[f"{orient}_aliased"] = r["aliased"]
            row[f"{orient}_roi"] = r["roi"]
        target = _target_of(t)
        for orient in ORIENTATIONS:
            row.update(share_columns(orient, row, target))
        row["target_contrast_source"] = target.source
        t411.append(row)
    return per, t411


def _radial_rows(radial: dict[tuple[float, str], npt.NDArray[Any]], params: MtfParams,
                 est: str, centre: tuple[float, float]) -> list[dict[str, Any]]:
    """Table 4.12: one row per radial frequency, both orientations (missing frames say so)."""
    nyq = nyquist_lp_per_mm()
    t412: list[dict[str, Any]] = []
    for f in params.radial_frequencies_lp_per_mm:
        f_img = image_frequency_lp_per_mm(f, params.radial_magnification)
        # image_lp_per_mm / aliased: Eq. 4.1 (the thesis's column, the tangential rings); the
        # sagittal spokes image at the azimuthal magnification, in their own columns.
        f_sag = radial_image_lp_per_mm(f, "sagittal", params, centre)
        row: dict[str, Any] = {
            "object_lp_per_mm": f, "image_lp_per_mm": f_img, "aliased": f_img > nyq,
            "sagittal_image_lp_per_mm": f_sag, "sagittal_aliased": f_sag > nyq,
            "tangential_image_lp_per_mm": f_img, "tangential_aliased": f_img > nyq}
        for orient in ORIENTATIONS:
            px = radial.get((f, orient))
            if px is None:
                row.update({f"{orient}_{k}": None for k in
                            ("dark", "bright", "modulation", "resolved", "uncertainty")})
                row[f"{orient}_warnings"] = "frame missing"
                continue
            r = analyze_radial_frame(px, f, orient, params, est, centre)
            row.update({f"{orient}_{k}": r[k] for k in
                        ("dark", "bright", "modulation", "resolved", "uncertainty", "warnings")})
            if r.get("lower_bound"):
                row[f"{orient}_lower_bound"] = True
        t412.append(row)
    measured = None if params.targets.radial.values is not None else \
        radial_target_contrast(t412, params)
    for i, row in enumerate(t412):
        target = measured if measured is not None else certificate(params.targets.radial, i)
        for orient in ORIENTATIONS:
            row.update(share_columns(orient, row, target))
        row["target_contrast_source"] = target.source
    return t412


def _target_of(row: dict[str, Any]) -> TargetContrast:
    t = row.get("target_contrast") or {}
    return TargetContrast(t.get("value"), t.get("uncertainty"),
                          str(t.get("source", "not measured")))


def radial_target_contrast(t412: list[dict[str, Any]], params: MtfParams) -> TargetContrast:
    """The printed radial patterns' own contrast, measured on the lowest-frequency pattern
    (both rolls) where the simulated lens passes >= 0.99 of the bar contrast."""
    curves = _curves(params)
    if isinstance(curves, str):
        return TargetContrast(None, None, f"not measured: {curves}")
    why = "no radial frame"
    for row in sorted(t412, key=lambda r: float(r["object_lp_per_mm"])):
        cands: list[tuple[str, float | None, float, float]] = []
        for orient in ORIENTATIONS:
            m = row.get(f"{orient}_modulation")
            ok = m is not None and row.get(f"{orient}_resolved") is not False
            cands.append((orient, float(m) if ok and m is not None else None,
                          float(row.get(f"{orient}_uncertainty") or 0.0) if ok else 0.0,
                          float(row[f"{orient}_image_lp_per_mm"])))
        got = _reference_readings("radial", cands, curves)
        if isinstance(got, str):
            why = got
            break
        if got:
            return from_reference(got, f"the {float(row['object_lp_per_mm']):g} lp/mm pattern")
        why = f"the {float(row['object_lp_per_mm']):g} lp/mm pattern not read"
    return TargetContrast(None, None, f"not measured: {why}")


def _height_row(view: str, test: str, roi: Roi, centre: tuple[float, float]) -> dict[str, Any]:
    rc = roi_centroid(roi)
    h_mm = image_height_mm(centre, rc)
    fp = nearest_field_point(view, h_mm)
    return {
        "view": view, "test": test, "roi_centroid_row": rc[0], "roi_centroid_col": rc[1],
        "image_height_px": round(image_height_px(centre, rc), 3),
        "image_height_mm": round(h_mm, 4),
        "nearest_field_deg": fp.field_angle_deg,
        "nearest_field_height_mm": fp.image_height_mm,
    }


def _monte_carlo_rows(
    t411: list[dict[str, Any]], t412: list[dict[str, Any]], params: MtfParams
) -> list[dict[str, Any]]:
    """Eq. 4.2 averages near each Monte Carlo frequency, placed among its thresholds by
    :mod:`benchlab.analysis.mtf.compare` (the one comparison).

    Each orientation is taken at its own measured frequency nearest the prediction's: in the
    forward view sagittal and tangential bars share one frequency, but the radial view's spokes
    image at object radius / image radius, not at Eq. 4.1's frequency of the rings (their rows'
    ``sagittal_image_lp_per_mm``), so pairing a row's S and T would average two frequencies
    about 2x apart. ``measured_freq_lp_per_mm`` is the tangential reading's frequency (Eq. 4.1,
    the thesis's column); both frequencies are in the row.

    Sagittal and tangential stay beside the average: the thesis's lesson is that the average
    alone hid a poor tangential response.
    """
    # (frequency, modulation, resolved) per view and orientation; aliased readings are no
    # readings. A not-resolved one stays (it is the finding at its frequency) but is never a 0.
    measured: dict[tuple[str, str], list[_Pick]] = {}
    for view, table in (("forward", t411), ("radial", t412)):
        for r in table:
            for orient in ORIENTATIONS:
                m = r.get(f"{orient}_modulation")
                f = float(r.get(f"{orient}_image_lp_per_mm", r["image_lp_per_mm"]))
                if m is None or r.get(f"{orient}_aliased", r["aliased"]):
                    continue
                resolved = bool(r.get(f"{orient}_resolved", float(m) != 0.0))
                bound = bool(r.get(f"{orient}_lower_bound"))
                measured.setdefault((view, orient), []).append(
                    _Pick(f, float(m), resolved, bound, r.get(f"{orient}_lens_share"),
                          r.get(f"{orient}_lens_share_uncertainty")))
    source = params.monte_carlo_file or thesis_fixture_path("table_4_15_monte_carlo")
    out = []
    for mc in load_monte_carlo_table(source):
        picks = []
        for orient in ORIENTATIONS:
            cands = measured.get((mc.view, orient), [])
            if cands:
                pick = min(cands, key=lambda c: abs(c[0] - mc.freq_lp_per_mm))
                if abs(pick[0] - mc.freq_lp_per_mm) <= MC_MATCH_FRACTION * mc.freq_lp_per_mm:
                    picks.append(pick)
        if len(picks) < 2:
            continue  # nothing measured near this prediction's frequency in one orientation
        (f_s, s, s_ok, s_bound, s_share, s_u), (f_t, t, t_ok, t_bound, t_share, t_u) = picks
        shares = s_ok and t_ok and s_share is not None and t_share is not None
        row: dict[str, Any] = {
            "view": mc.view, "mc_freq_lp_per_mm": mc.freq_lp_per_mm,
            "measured_freq_lp_per_mm": f_t, "sagittal_modulation": s if s_ok else None,
            "tangential_modulation": t if t_ok else None,
        }
        lens: dict[str, Any] = {
            "sagittal_lens_share": s_share if s_ok else None,
            "tangential_lens_share": t_share if t_ok else None,
            "averaged_lens_share": None, "averaged_lens_share_uncertainty": None,
            "verdict_basis": VERDICT_ON_SHARE if shares else VERDICT_ON_READING}
        if s_ok and t_ok:
            avg = averaged_mtf(s, t)
            row["averaged_modulation"] = round(avg.average, 6)
            placed = avg.average
            if shares:  # the lens alone against the lens's prediction
                placed = averaged_mtf(s_share, t_share).average
                lens["averaged_lens_share"] = round(placed, 6)
                lens["averaged_lens_share_uncertainty"] = round(
                    0.5 * math.hypot(s_u or 0.0, t_u or 0.0), 6)
            verdict = monte_carlo_band(placed, mc)[1]
            if s_bound or t_bound:
                # A half read as a lower bound (clipped): so is the average, and the verdict
                # places the bound - the true average is there or higher.
                row.update({"sagittal_lower_bound": s_bound, "tangential_lower_bound": t_bound,
                            "averaged_modulation_lower_bound": True})
                verdict = f"at least: {verdict}"
        else:
            # No number for an unresolved reading: the average is unknown, only bounded below
            # by the resolved half (a contrast is never negative).
            row["averaged_modulation"] = None
            row["averaged_lower_bound"] = round(averaged_mtf(s if s_ok else 0.0,
                                                             t if t_ok else 0.0).average, 6)
            verdict = "not available: " + unresolved_note(s_ok, t_ok)
        out.append({
            **row, **mc.columns(), "verdict": verdict,
            "sagittal_freq_lp_per_mm": f_s, "tangential_freq_lp_per_mm": f_t,
            "sagittal_resolved": s_ok, "tangential_resolved": t_ok, **lens,
        })
    return out


#: Table 4.15's ``verdict_basis``: what its verdict places among the Monte Carlo thresholds.
VERDICT_ON_SHARE = "lens share (measured / target contrast)"
VERDICT_ON_READING = "measured contrast (target contrast unknown: lens and target together)"


class _Pick(NamedTuple):
    """A reading a Table 4.15 row may pair: frequency, modulation, resolved, lower bound, and
    the lens's share with its uncertainty (None without a target contrast)."""

    freq_lp_per_mm: float
    modulation: float
    resolved: bool
    lower_bound: bool
    lens_share: float | None
    lens_share_uncertainty: float | None


def unresolved_note(sagittal_resolved: bool, tangential_resolved: bool) -> str:
    """Which half of a Table 4.15 average is missing, in words (``"T not resolved"``)."""
    missing = [o for o, ok in (("S", sagittal_resolved), ("T", tangential_resolved)) if not ok]
    return " and ".join(missing) + " not resolved" if missing else ""
