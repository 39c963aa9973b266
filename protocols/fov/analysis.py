"""The tables of ``benchlab run fov`` from a session's frames.

Per distance the frames are averaged; the forward disc is found first on the pixelwise maximum
of the distances' averages (the dots move between distances, the field stop does not), then,
once the geometry is fitted, again on every distance's average where no predicted dot is near
the edge (:func:`benchlab.analysis.fov.fit.fit_with_clean_disc`), and the geometry fitted again; the
dots are found and identified per distance
(:mod:`benchlab.analysis.fov.dots`) and one geometry is fitted to all of them
(:mod:`benchlab.analysis.fov.fit`). Tables:

- ``field_of_view``: full field of view, direction of view (and its azimuth), entrance pupil,
  paraxial focal length and the disc's radius, each with its 95 % interval; the field of view
  against Table 3.1's lower bound with a verdict;
- ``image_height_mapping``: ``h(theta)`` at Table 4.14's forward field points (with the
  design's height, the difference and a verdict) and every ``distortion_step_deg`` to the
  edge;
- ``distortion``: local distortion (% of image height) against ``f tan theta`` and ``f theta``;
- ``fov_dots``: per distance the dots found, identified and the fit's residual;
- the radial view's rows of ``field_of_view`` and ``image_height_mapping`` (``view``
  "radial") and ``radial_rings`` (:mod:`.radial_analysis`) when the run took radial frames;
- ``simulator_truth`` (simulated bench only, :mod:`.truth`): the same figures from the
  simulator's exact mapping.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray, mean_of_frames
from benchlab.analysis.fov import figures as fig
from benchlab.analysis.fov.disc import Disc, find_disc
from benchlab.analysis.fov.dots import Dots, detect, identify
from benchlab.analysis.fov.fit import fit_with_clean_disc
from benchlab.analysis.fov.model import PIXEL_MM
from benchlab.analysis.thesis_data import read_table, thesis_fixture_path
from benchlab.drivers.errors import BenchlabError
from benchlab.protocols.fov.params import FovParams, position_step_id

if TYPE_CHECKING:
    from benchlab.session import Session



def design_field_points() -> list[tuple[float, float]]:
    """Table 4.14's forward field points: ``(field angle deg, image height mm)``."""
    rows = read_table(thesis_fixture_path("table_4_14_field_points.csv"))
    return [(float(r["field_angle_deg"]), float(r["image_height_mm"])) for r in rows
            if r["view"] == "forward"]


def dots_of(frame: npt.ArrayLike, disc: Disc, params: FovParams) -> Dots:
    """The identified dots of one averaged frame.

    Raises
    ------
    ValueError
        Fewer than ``params.min_dots`` dots identified (says how many), or no fiducial.
    """
    xy, areas = detect(frame, disc, params.edge_margin_px)
    dots = identify(xy, areas)
    if len(dots.ij) < params.min_dots:
        raise ValueError(f"only {len(dots.ij)} dots identified ({dots.found} found); "
                         f"analysis.min_dots is {params.min_dots}")
    return dots


def count_dots(frame: npt.ArrayLike, params: FovParams) -> int:
    """Dots identified in one distance's frame, for the live view (its own disc).

    Raises
    ------
    ValueError
        No disc, no fiducial or too few dots.
    """
    return len(dots_of(frame, find_disc(frame), params).ij)


def _averages(session: Session, params: FovParams) -> dict[float, FloatArray]:
    out = {}
    for z in params.distances_mm:
        frames = session.step_frames(position_step_id(z))
        if not frames:
            continue
        stack = [session.load_frame(position_step_id(z), n)[0] for n in sorted(frames)]
        out[z] = mean_of_frames(stack)
    return out


def _r(v: float | None, n: int) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), n)


def _fig(name: str, f: fig.Figure, unit: str, digits: int) -> dict[str, Any]:
    value, ci = f.rounded(digits)
    return {"quantity": name, "value": value, "value_ci95": ci, "unit": unit,
            "design": None, "verdict": ""}


def fov_verdict(f: fig.Figure, bound_deg: float) -> str:
    """Table 4.15-style verdict of the field of view against Table 3.1's lower bound."""
    if f.low >= bound_deg:
        return f"meets Table 3.1 (>= {bound_deg:g} deg)"
    if f.high < bound_deg:
        return f"below Table 3.1 (>= {bound_deg:g} deg)"
    return f"undecided: the 95 % interval straddles {bound_deg:g} deg"


def height_verdict(f: fig.Figure, design_mm: float, tol_mm: float) -> str:
    """A field point's verdict against Table 4.14's image height."""
    diff = f.value - design_mm
    if abs(diff) <= tol_mm:
        return f"agrees with Table 4.14 (within {tol_mm:g} mm)"
    return f"differs from Table 4.14 by {diff:+.3f} mm"


def analyze_fov(session: Session, params: FovParams
                ) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any]]:
    """The session's tables (module docstring) and summary."""
    avgs = _averages(session, params)
    if len(avgs) < 2:
        raise BenchlabError(f"{session.path}: {len(avgs)} distance(s) taken; the fit needs two "
                            "at least")
    try:
        disc = find_disc(np.max(np.stack(list(avgs.values())), axis=0))
    except ValueError as exc:
        raise BenchlabError(f"{session.path}: forward disc: {exc}") from exc
    views: list[tuple[float, Dots]] = []
    dot_rows: list[dict[str, Any]] = []
    warnings: list[str] = []
    for z, img in avgs.items():
        try:
            views.append((z, dots_of(img, disc, params)))
        except ValueError as exc:
            warnings.append(f"{position_step_id(z)}: left out: {exc}")
            dot_rows.append({"distance_mm": z, "dots_found": None, "dots_identified": 0,
                             "rms_px": None, "note": str(exc)})
    if len(views) < 2:
        raise BenchlabError(f"{session.path}: dots identified at {len(views)} distance(s); the "
                            f"fit needs two at least ({'; '.join(warnings)})")
    try:
        disc, fit, edge_note = fit_with_clean_disc(avgs, views, disc, params.pitch_mm,
                                                   params.dot_mm, params.half_count,
                                                   params.min_dots)
    except ValueError as exc:
        raise BenchlabError(f"{session.path}: {exc}") from exc
    if edge_note:
        warnings.append(edge_note)
    for (z, v), rms in zip(views, fit.rms_px, strict=True):
        dot_rows.append({"distance_mm": z, "dots_found": v.found,
                         "dots_identified": len(v.ij), "rms_px": _r(rms, 4), "note": ""})
    dot_rows.sort(key=lambda r: r["distance_mm"])
    fov = fig.field_of_view(fit, disc)
    dov, azimuth = fig.direction_of_view(fit)
    pupil = fig.entrance_pupil(fit)
    f_par = fig.paraxial_focal_length(fit)
    radius = fig.Figure(disc.radius_px * PIXEL_MM, (disc.radius_px - fig.Z95 * disc.sigma[2])
                        * PIXEL_MM, (disc.radius_px + fig.Z95 * disc.sigma[2]) * PIXEL_MM)
    fov_row = _fig("full_fov_deg", fov, "deg", 4)
    fov_row["design"] = f">= {params.design_fov_min_deg:g}"
    fov_row["verdict"] = fov_verdict(fov, params.design_fov_min_deg)
    dov_row = _fig("direction_of_view_deg", dov, "deg", 5)
    dov_row["verdict"] = f"tilt azimuth {azimuth:.1f} deg"
    fov_rows = [fov_row, dov_row, _fig("entrance_pupil_mm", pupil, "mm", 5),
                _fig("paraxial_focal_length_mm", f_par, "mm", 6),
                _fig("disc_radius_mm", radius, "mm", 6)]
    edge_deg = fov.value / 2.0
    design = dict(design_field_points())
    angles = sorted(set(design) | set(_grid(params.distortion_step_deg, edge_deg)))
    mapping, distortion = [], []
    for a in angles:
        h = fig.image_height(fit, a)
        value, ci = h.rounded(6)  # 1 nm: well below the interval's width
        d_mm = design.get(a)
        mapping.append({
            "view": "forward", "field_angle_deg": a, "axial_position_mm": None,
            "image_height_mm": value, "image_height_mm_ci95": ci,
            "design_image_height_mm": d_mm,
            "difference_mm": None if d_mm is None else _r(h.value - d_mm, 6),
            "verdict": "" if d_mm is None else (
                height_verdict(h, d_mm, params.height_tolerance_mm) if a <= edge_deg
                else "beyond the measured field")})
        if a > 0:
            rect = fig.local_distortion(fit, a, "rectilinear")
            equi = fig.local_distortion(fit, a, "equidistant")
            distortion.append({"field_angle_deg": a, "image_height_mm": value,
                               "rectilinear_pct": rect.rounded(5)[0],
                               "rectilinear_pct_ci95": rect.rounded(5)[1],
                               "equidistant_pct": equi.rounded(5)[0],
                               "equidistant_pct_ci95": equi.rounded(5)[1]})
    tables: dict[str, list[dict[str, Any]]] = {
        "field_of_view": fov_rows, "image_height_mapping": mapping, "distortion": distortion,
        "fov_dots": dot_rows}
    radial_summary: dict[str, Any] = {}
    radial_angles: list[float] = []
    if params.radial is not None:
        from benchlab.protocols.fov.radial_analysis import analyze_radial

        extra, radial_summary, radial_warnings = analyze_radial(session, params.radial,
                                                                params.height_tolerance_mm)
        warnings += radial_warnings
        for name, rows in extra.items():
            tables[name] = tables.get(name, []) + rows
        radial_angles = [r["field_angle_deg"] for r in extra.get("image_height_mapping", [])]
    if session.meta.get("devices", {}).get("simulated"):
        from benchlab.protocols.fov.truth import truth_rows

        tables["simulator_truth"] = truth_rows(params, angles, radial_angles)
    summary = {"procedure": "fov", "distances_mm": list(params.distances_mm),
               "frames_per_distance": params.frames,
               "stage_travel_mm": params.stage_travel_mm,
               "disc_centre_rc": [round(disc.centre_row, 3), round(disc.centre_col, 3)],
               "centroid_noise_px": round(fit.noise_px, 4), "dots_fitted": fit.dots,
               "interval_method": "delta method on the fit's covariance (direction of view: "
                                  "profile of the tilt's 2-D region)",
               **radial_summary, "warnings": warnings}
    return tables, summary


def _grid(step_deg: float, edge_deg: float) -> list[float]:
    n = int(math.floor(edge_deg / step_deg + 1e-9))
    return [round(k * step_deg, 6) for k in range(0, n + 1)]
