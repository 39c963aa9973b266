"""The radial view's rows of ``benchlab run fov``'s tables, from the ring tube's frames.

Per position the frames are averaged; the annulus is found on each position's average and the
median taken (:mod:`benchlab.analysis.fov.annulus`); each position's azimuthal
profile against the brightest profile gives its rings (:mod:`benchlab.analysis.fov.rings`),
counted from the fiducial ring; the rings' axial positions (ring 0 at the position, the others
a pitch apart) and image radii give the mapping (:mod:`benchlab.analysis.fov.radial`; the
wide ring names the others but is not fitted); the mapping predicts every ring at every
position, and each edge of the annulus is read again on the positions where no ring is near it
(:func:`clean_positions`). Rows:

- ``field_of_view``: ``radial_field_start_mm`` / ``radial_field_end_mm`` (axial position of
  the field's ends on the wall), ``radial_field_start_deg`` / ``radial_field_end_deg`` (their
  field angles from the effective viewpoint), ``radial_fov_deg`` with Table 3.1's verdict,
  ``radial_inner_radius_mm`` / ``radial_outer_radius_mm`` (the annulus);
- ``image_height_mapping`` (``view`` "radial"): the image height at Table 4.14's radial field
  points (with the design's height, the difference and a verdict) and every
  ``analysis.radial_step_deg`` across the field, with the wall position of each angle;
- ``radial_rings``: per position the rings found and used, and the fit's residual.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import ndimage

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.fov import radial as rad
from benchlab.analysis.fov.annulus import (
    Annulus,
    AnnulusNotFoundError,
    find_annulus,
    median_annulus,
    refine_annulus,
)
from benchlab.analysis.fov.figures import Z95, Figure
from benchlab.analysis.fov.model import PIXEL_MM
from benchlab.analysis.fov.rings import (
    BIN_PX,
    RING_CENTRE_SYSTEMATIC_PX,
    Rings,
    find_rings,
    profile,
    spacing_gap,
)
from benchlab.analysis.thesis_data import read_table, thesis_fixture_path
from benchlab.drivers.errors import BenchlabError
from benchlab.protocols.fov.radial_params import RadialPlan, radial_step_id

if TYPE_CHECKING:
    from benchlab.session import Session


def design_radial_points() -> list[tuple[float, float]]:
    """Table 4.14's radial field points: ``(field angle deg, image height mm)``."""
    rows = read_table(thesis_fixture_path("table_4_14_field_points.csv"))
    return [(float(r["field_angle_deg"]), float(r["image_height_mm"])) for r in rows
            if r["view"] == "radial"]


def rings_of(level_profile: Any, baseline: FloatArray, plan: RadialPlan) -> Rings:
    """The rings of one profile; refused with too few or without the fiducial.

    Raises
    ------
    ValueError
        Fewer than ``plan.min_rings`` rings, a missed ring, or no fiducial ring.
    """
    rings = find_rings(level_profile, baseline)
    if len(rings.radius_px) < plan.min_rings:
        raise ValueError(f"only {len(rings.radius_px)} rings found; analysis.radial_min_rings "
                         f"is {plan.min_rings}")
    gap = spacing_gap(rings)
    if gap is not None and gap > 1.6:
        raise ValueError(f"a ring is missing (one spacing is {gap:.1f} x its neighbours')")
    if rings.fiducial is None:
        raise ValueError("the fiducial (wide) ring was not found")
    return rings


def count_rings(frame: FloatArray, plan: RadialPlan) -> int:
    """Rings identified in one position's frame, for the live view (its own annulus; the
    profile's upper envelope over two ring spacings as the ring-free level).

    Raises
    ------
    ValueError
        No annulus, too few rings or no fiducial.
    """
    annulus = find_annulus(frame)
    prof = profile(frame, annulus, plan.margin_px)
    envelope = ndimage.maximum_filter1d(prof.level, size=int(60.0 / BIN_PX))
    return len(rings_of(prof, envelope, plan).radius_px)


def _frames(session: Session, plan: RadialPlan) -> dict[float, list[FloatArray]]:
    out = {}
    for p in plan.positions_mm:
        frames = session.step_frames(radial_step_id(p))
        if frames:
            out[p] = [np.asarray(session.load_frame(radial_step_id(p), n)[0], dtype=np.float64)
                      for n in sorted(frames)]
    return out


def _row(name: str, f: Figure, unit: str, digits: int) -> dict[str, Any]:
    value, ci = f.rounded(digits)
    return {"quantity": name, "value": value, "value_ci95": ci, "unit": unit, "design": None,
            "verdict": ""}


def _direction(found: dict[float, Rings]) -> int:
    """+1 when the fiducial's image grows with the position (ring index outwards), else -1."""
    ps = sorted(found)
    lo, hi = found[ps[0]], found[ps[-1]]
    assert lo.fiducial is not None and hi.fiducial is not None
    grow = hi.radius_px[hi.fiducial] - lo.radius_px[lo.fiducial]
    return 1 if grow > 0 else -1


def analyze_radial(session: Session, plan: RadialPlan, height_tolerance_mm: float
                   ) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any], list[str]]:
    """The radial rows (module docstring): ``({"field_of_view", "image_height_mapping",
    "radial_rings"}, summary, warnings)``; empty when no radial frame was taken.

    Raises
    ------
    BenchlabError
        No annulus, rings at fewer than two positions, or too few for the mapping.
    """
    frames = _frames(session, plan)
    avgs = {p: np.mean(np.stack(fs), axis=0) for p, fs in frames.items()}
    if not avgs:
        return {}, {}, [f"{session.path}: no radial frames; the radial view is not measured"]
    try:
        annulus = median_annulus([find_annulus(img) for img in avgs.values()])
    except AnnulusNotFoundError as exc:
        raise BenchlabError(f"{session.path}: radial annulus: {exc}") from exc
    profiles = {p: profile(img, annulus, plan.margin_px) for p, img in avgs.items()}
    baseline = np.max(np.stack([pr.level for pr in profiles.values()]), axis=0)
    found: dict[float, Rings] = {}
    warnings: list[str] = []
    ring_rows: list[dict[str, Any]] = []
    for p, pr in profiles.items():
        try:
            found[p] = rings_of(pr, baseline, plan)
        except ValueError as exc:
            warnings.append(f"{radial_step_id(p)}: left out: {exc}")
            ring_rows.append({"position_mm": p, "rings_found": None, "rings_used": 0,
                              "rms_um": None, "note": str(exc)})
    if len({round(p, 6) for p in found}) < 2:
        raise BenchlabError(f"{session.path}: rings identified at {len(found)} position(s); "
                            f"the radial mapping needs two at least ({'; '.join(warnings)})")
    sign = _direction(found)
    zs, rhos, where = [], [], []
    for p, rings in found.items():
        k = rings.indices(sign)
        plain = k != 0  # the wide ring names the others; its wider image's centre is less sure
        zs += list(p + k[plain] * plan.pitch_mm)
        rhos += list(rings.radius_px[plain] * PIXEL_MM)
        where += [p] * int(plain.sum())
    try:
        fit = fit_rings(zs, rhos, plan)
        inner, outer = clean_positions(fit, annulus, plan, list(avgs))
        if not inner or not outer:
            raise AnnulusNotFoundError(
                f"a ring is next to the {'inner' if not inner else 'outer'} edge at every "
                "position; take more positions between two rings (radial.positions_mm)")
        # the edges on each frame, not on the positions' averages: the dark side is clipped
        # at 0, and an average of two clipped frames is 0 only where both are, so its median
        # sits half a code up, and the half level with it (the outer edge moved 0.0003 px in)
        annulus = refine_annulus([f for p in inner for f in frames[p]],
                                 [f for p in outer for f in frames[p]], annulus)
    except (rad.RadialFitError, AnnulusNotFoundError) as exc:
        raise BenchlabError(f"{session.path}: {exc}") from exc
    half = plan.ring_mm / 2.0
    resid = np.array(rhos) - np.array([(fit.height_mm(z - half) + fit.height_mm(z + half)) / 2
                                       for z in zs])
    for p, rings in found.items():
        sel = np.array(where) == p
        ring_rows.append({"position_mm": p, "rings_found": len(rings.radius_px),
                          "rings_used": int(sel.sum()),
                          "rms_um": round(float(np.sqrt(np.mean(resid[sel] ** 2))) * 1e3, 4),
                          "note": ""})
    ring_rows.sort(key=lambda r: r["position_mm"])
    start = rad.field_end(fit, annulus, outer=True)
    end = rad.field_end(fit, annulus, outer=False)
    fov = rad.field_of_view_deg(fit, annulus)
    fov_row = _row("radial_fov_deg", fov, "deg", 4)
    fov_row["design"] = f">= {plan.design_fov_min_deg:g}"
    from benchlab.protocols.fov.analysis import fov_verdict, height_verdict

    fov_row["verdict"] = fov_verdict(fov, plan.design_fov_min_deg)
    fov_rows = [_row("radial_field_start_mm", start, "mm", 4),
                _row("radial_field_end_mm", end, "mm", 4),
                _row("radial_field_start_deg", rad.end_angle_deg(fit, start), "deg", 4),
                _row("radial_field_end_deg", rad.end_angle_deg(fit, end), "deg", 4),
                fov_row, _radius_row("radial_inner_radius_mm", annulus, 2),
                _radius_row("radial_outer_radius_mm", annulus, 3)]
    design = dict(design_radial_points())
    a_start, a_end = fit.angle_of_z(start.value), fit.angle_of_z(end.value)
    angles = sorted(set(design) | set(radial_angles(plan.step_deg, a_start, a_end)),
                    reverse=True)
    mapping = []
    for a in angles:
        z = fit.z_of_angle(a)
        inside = min(start.value, end.value) <= z <= max(start.value, end.value)
        h = rad.height_at_z(fit, z) if inside else None
        d_mm = design.get(a)
        value, ci = h.rounded(6) if h is not None else (None, None)
        mapping.append({
            "view": "radial", "field_angle_deg": a, "axial_position_mm": round(z, 4),
            "image_height_mm": value, "image_height_mm_ci95": ci,
            "design_image_height_mm": d_mm,
            "difference_mm": None if d_mm is None or h is None else round(h.value - d_mm, 6),
            "verdict": "" if d_mm is None else (
                height_verdict(h, d_mm, height_tolerance_mm) if h is not None
                else "beyond the measured field")})
    summary = {"radial_positions_mm": list(plan.positions_mm),
               "radial_stage_travel_mm": plan.stage_travel_mm,
               "annulus_centre_rc": [round(annulus.centre_row, 3), round(annulus.centre_col, 3)],
               "radial_noise_um": round(fit.noise_mm * 1e3, 4), "rings_fitted": fit.points,
               "radial_viewpoint_z_mm": plan.viewpoint_z_mm,
               "radial_tube_radius_mm": plan.tube_radius_mm}
    return ({"field_of_view": fov_rows, "image_height_mapping": mapping,
             "radial_rings": ring_rows}, summary, warnings)


def fit_rings(z_mm: list[float], rho_mm: list[float], plan: RadialPlan) -> rad.RadialFit:
    """The mapping through the rings (``z``, ``rho`` mm): each ring fitted as its edges'
    midpoint, the ring-centre estimator's modelling error in the interval
    (:data:`benchlab.analysis.fov.rings.RING_CENTRE_SYSTEMATIC_PX`).

    Raises
    ------
    benchlab.analysis.fov.radial.RadialFitError
        Too few rings.
    """
    return rad.fit_mapping(z_mm, rho_mm, plan.tube_radius_mm, plan.viewpoint_z_mm,
                           plan.ring_mm, RING_CENTRE_SYSTEMATIC_PX * PIXEL_MM)


def clean_positions(fit: rad.RadialFit, annulus: Annulus, plan: RadialPlan,
                    positions: list[float]) -> tuple[list[float], list[float]]:
    """The positions with no ring near the inner edge, and those with none near the outer
    (the fitted mapping predicts every ring, those beyond the edges too): a ring's image,
    widened by 6 px of blur, must stay off the edge's profile (12 px on the lit side, 4.5 px of
    soft edge on the dark side; :mod:`benchlab.analysis.fov.edges`)."""
    inner, outer = [], []
    k = np.arange(-plan.half_count, plan.half_count + 1, dtype=np.float64)
    for p in positions:
        z = p + k * plan.pitch_mm
        rho = np.array([fit.height_mm(v) for v in z]) / PIXEL_MM
        slope = np.abs([fit.height_mm(v + 0.01) - fit.height_mm(v - 0.01) for v in z]) / 0.02
        half = 0.5 * plan.ring_mm * np.where(k == 0, plan.fiducial_scale, 1.0) * slope / PIXEL_MM
        lo, hi = rho - half - 6.0, rho + half + 6.0
        # inner edge: lit outside it (larger radius)
        if not np.any((lo < annulus.inner_px + 12.0) & (hi > annulus.inner_px - 4.5)):
            inner.append(p)
        if not np.any((hi > annulus.outer_px - 12.0) & (lo < annulus.outer_px + 4.5)):
            outer.append(p)
    return inner, outer


def _radius_row(name: str, annulus: Annulus, which: int) -> dict[str, Any]:
    px = annulus.inner_px if which == 2 else annulus.outer_px
    s = float(annulus.sigma[which])
    f = Figure(px * PIXEL_MM, (px - Z95 * s) * PIXEL_MM, (px + Z95 * s) * PIXEL_MM)
    return _row(name, f, "mm", 6)


def radial_angles(step_deg: float, a_start: float, a_end: float) -> list[float]:
    """Every ``step_deg`` (multiples of it) strictly inside the field's angles."""
    lo, hi = sorted((a_start, a_end))
    k0, k1 = math.ceil(lo / step_deg + 1e-9), math.floor(hi / step_deg - 1e-9)
    return [round(k * step_deg, 6) for k in range(k0, k1 + 1)]
