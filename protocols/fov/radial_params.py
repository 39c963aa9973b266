"""The radial view's part of ``benchlab run fov``'s parameters (``[radial]`` and the
``analysis.radial_*`` keys), checked in full before any device moves.

The plan is checked against the bench and the tube's drawing with the design's nominal radial
mapping (the shipped ray-trace table at the tube's radius, :mod:`benchlab.analysis.views`):
every position within the stage's travel, the tube's rings covering the radial field at every
position, the fiducial ring inside the field (away from its edges) at every position, the
rings far enough apart in the image, and enough of them in the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from benchlab.analysis.chart.layout import ANNULUS_INNER_RADIUS_PX, ANNULUS_OUTER_RADIUS_PX
from benchlab.analysis.fov.model import PIXEL_MM
from benchlab.analysis.views.raytrace import (
    REFERENCE_OBJECT_RADIUS_MM,
    THESIS_VIEWPOINT_Z_MM,
    RayTraceError,
)

#: Table 3.1: the field of view ("FOV range") is above 15 deg for both views.
DESIGN_RADIAL_FOV_MIN_DEG = 15.0
#: Smallest ring spacing in the image the profile separates reliably, px.
MIN_RING_SPACING_PX = 8.0


@dataclass(frozen=True)
class RadialPlan:
    """The radial view's plan (module docstring). ``positions_mm``: ring 0's axial position
    (the thesis's z: the effective viewpoint at -6.4 mm) at each step; the stage goes to
    ``position - object_offset_mm``."""

    positions_mm: tuple[float, ...] = (12.0, 12.5, 13.0, 13.5, 14.0, 14.5, 15.0, 15.5)
    object_offset_mm: float = 12.0
    tube_radius_mm: float = REFERENCE_OBJECT_RADIUS_MM
    pitch_mm: float = 4.0
    ring_mm: float = 0.3
    fiducial_scale: float = 3.0
    half_count: int = 6
    min_rings: int = 4
    margin_px: float = 6.0
    viewpoint_z_mm: float = THESIS_VIEWPOINT_Z_MM
    design_fov_min_deg: float = DESIGN_RADIAL_FOV_MIN_DEG
    step_deg: float = 2.5

    def stage_mm(self, position_mm: float) -> float:
        return position_mm - self.object_offset_mm

    @property
    def stage_travel_mm(self) -> float:
        s = [self.stage_mm(p) for p in self.positions_mm]
        return sum(abs(b - a) for a, b in zip(s, s[1:], strict=False))

    def tube(self) -> Any:
        from benchlab.scenes.rings import RingTube

        return RingTube(self.tube_radius_mm, self.pitch_mm, self.ring_mm, self.fiducial_scale,
                        self.half_count)


def radial_step_id(position_mm: float) -> str:
    return f"radial-{position_mm:g}"


def check_radial(c: Any, limits: Any = None) -> RadialPlan | None:
    """Read the radial keys with the params checker ``c`` (None: ``radial.enabled`` false)."""
    d = RadialPlan()
    enabled = c.choice("radial.enabled", True, (True, False))
    pos = c.numbers("radial.positions_mm", d.positions_mm, -1000.0, 1000.0)
    offset = c.number("radial.object_offset_mm", d.object_offset_mm, -1000.0, 1000.0)
    radius = c.number("radial.tube_radius_mm", d.tube_radius_mm, 0.0, 1000.0, lo_open=True)
    pitch = c.number("radial.pitch_mm", d.pitch_mm, 0.0, 100.0, lo_open=True)
    ring = c.number("radial.ring_mm", d.ring_mm, 0.0, 100.0, lo_open=True)
    fid = c.number("radial.fiducial_scale", d.fiducial_scale, 2.0, 6.0)
    half = c.integer("radial.half_count", d.half_count, 2, 500)
    min_rings = c.integer("analysis.radial_min_rings", d.min_rings, 4, 10000)
    margin = c.number("analysis.radial_margin_px", d.margin_px, 0.0, 100.0)
    vp = c.number("analysis.viewpoint_z_mm", d.viewpoint_z_mm, -1000.0, 1000.0)
    fov_min = c.number("analysis.design_radial_fov_min_deg", d.design_fov_min_deg, 0.0, 180.0)
    step = c.number("analysis.radial_step_deg", d.step_deg, 0.1, 45.0)
    if not enabled:
        return None
    plan = RadialPlan(pos, offset, radius, pitch, ring, fid, half, min_rings, margin, vp,
                      fov_min, step)
    if len(pos) < 2:
        c.fail("radial.positions_mm", f"{list(pos)}: the rings' direction needs two positions "
               "at least")
    travel = getattr(limits, "stage_travel_mm", None) if limits is not None else None
    if travel is not None:
        lo, hi = travel
        for i, p in enumerate(pos):
            s = plan.stage_mm(p)
            if not lo <= s <= hi:
                c.fail(f"radial.positions_mm[{i}]", f"{p:g} mm needs the stage at {s:g} mm "
                       f"(radial.object_offset_mm {offset:g}), outside its travel "
                       f"{lo:g}..{hi:g} mm")
    if ring * fid >= pitch - ring:
        c.fail("radial.fiducial_scale", f"a {ring * fid:g} mm fiducial ring touches its "
               f"neighbours on a {pitch:g} mm pitch")
    elif not c.problems:
        _check_drawing(c, plan)
    return plan


def _check_drawing(c: Any, plan: RadialPlan) -> None:
    """The tube against the radial field with the design's nominal mapping."""
    from benchlab.analysis.views.raytrace import read_raytrace_table
    from benchlab.analysis.views.synthesis import cylinder_map

    try:
        cyl = cylinder_map(read_raytrace_table(None), plan.tube_radius_mm)
    except RayTraceError as exc:
        c.fail("radial.tube_radius_mm", f"the design's ray-trace table: {exc}")
        return
    inner, outer = ANNULUS_INNER_RADIUS_PX * PIXEL_MM, ANNULUS_OUTER_RADIUS_PX * PIXEL_MM
    ends = sorted((float(cyl.axial_mm(outer)), float(cyl.axial_mm(inner))))
    margin_mm = plan.margin_px * PIXEL_MM * max(cyl.axial_magnification(inner),
                                                cyl.axial_magnification(outer))
    for i, p in enumerate(plan.positions_mm):
        lo, hi = p - plan.half_count * plan.pitch_mm, p + plan.half_count * plan.pitch_mm
        if lo > ends[0] or hi < ends[1]:
            c.fail("radial.half_count", f"at {p:g} mm the tube's rings span {lo:g}..{hi:g} mm, "
                   f"short of the radial field {ends[0]:.1f}..{ends[1]:.1f} mm")
            break
        if not ends[0] + margin_mm + plan.pitch_mm <= p <= ends[1] - margin_mm - plan.pitch_mm:
            c.fail(f"radial.positions_mm[{i}]", f"the fiducial ring at {p:g} mm is not well "
                   f"inside the radial field {ends[0]:.1f}..{ends[1]:.1f} mm")
    mag = max(cyl.axial_magnification(r) for r in (inner, (inner + outer) / 2, outer))
    spacing_px = plan.pitch_mm / mag / PIXEL_MM
    if spacing_px < MIN_RING_SPACING_PX:
        c.fail("radial.pitch_mm", f"rings {plan.pitch_mm:g} mm apart are {spacing_px:.1f} px "
               f"apart in the image; {MIN_RING_SPACING_PX:g} px at least")
    expected = math.floor((ends[1] - ends[0] - 2.0 * margin_mm) / plan.pitch_mm)
    if expected < plan.min_rings:
        c.fail("analysis.radial_min_rings", f"about {expected} rings fall in the radial field; "
               f"analysis.radial_min_rings is {plan.min_rings}")


def radial_to_dict(plan: RadialPlan | None) -> dict[str, Any]:
    """The ``[radial]`` section and the radial ``analysis`` keys (what a session records)."""
    if plan is None:
        return {"radial": {"enabled": False}, "analysis": {}}
    return {
        "radial": {"enabled": True, "positions_mm": list(plan.positions_mm),
                   "object_offset_mm": plan.object_offset_mm,
                   "tube_radius_mm": plan.tube_radius_mm, "pitch_mm": plan.pitch_mm,
                   "ring_mm": plan.ring_mm, "fiducial_scale": plan.fiducial_scale,
                   "half_count": plan.half_count},
        "analysis": {"radial_min_rings": plan.min_rings, "radial_margin_px": plan.margin_px,
                     "viewpoint_z_mm": plan.viewpoint_z_mm,
                     "design_radial_fov_min_deg": plan.design_fov_min_deg,
                     "radial_step_deg": plan.step_deg},
    }
