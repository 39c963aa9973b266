"""Parameters of ``benchlab run fov``, checked in full before any device moves.

Read by :func:`benchlab.protocols.params.parse_params` like the other procedures' files: every
problem is listed at once, naming the file and the dotted field. Besides ranges, the plan is
checked against the bench and the chart's drawing with the design's nominal mapping
(``analysis.design_focal_length_mm``, equidistant, Table 4.14): every distance within the
stage's travel, the chart covering the forward field at the farthest distance, the dots
resolved there and apart at the nearest, and enough dots in the disc at the nearest distance.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from benchlab.analysis.chart.layout import FORWARD_DISC_RADIUS_PX
from benchlab.analysis.fov.model import PIXEL_MM
from benchlab.protocols.camera_limits import (
    EXPOSURE_RANGE_MS,
    GAIN_RANGE,
    camera_exposure_ms,
    camera_gain,
)
from benchlab.protocols.fov.radial_params import RadialPlan, check_radial, radial_to_dict

#: Table 3.1 / section 3.2: the forward view's full field of view is at least 40 deg.
DESIGN_FOV_MIN_DEG = 40.0
#: Smallest dot spacing (px) the identification follows reliably, and smallest dot (px).
MIN_SPACING_PX = 8.0
MIN_DOT_PX = 2.0


@dataclass(frozen=True)
class FovParams:
    """Parameters of ``benchlab run fov`` (module docstring)."""

    exposure_ms: float = 300.0
    gain: float = 1.0
    bits: int = 12
    frames: int = 2
    distances_mm: tuple[float, ...] = (15.0, 25.0, 35.0)
    #: Object distance (lens front to chart) with the stage at 0: stage = distance - offset.
    object_offset_mm: float = 10.0
    pitch_mm: float = 1.0
    dot_mm: float = 0.3
    fiducial_scale: float = 2.0
    half_count: int = 25
    min_dots: int = 30
    edge_margin_px: float = 12.0
    design_focal_length_mm: float = 2.83
    design_fov_min_deg: float = DESIGN_FOV_MIN_DEG
    height_tolerance_mm: float = 0.01
    distortion_step_deg: float = 2.5
    simulator: Mapping[str, Any] = field(default_factory=dict)
    #: The radial view's plan (None: ``radial.enabled = false``, the forward view only).
    radial: RadialPlan | None = field(default_factory=RadialPlan)
    raw: Mapping[str, Any] = field(default_factory=dict)

    def stage_mm(self, distance_mm: float) -> float:
        return distance_mm - self.object_offset_mm

    def chart(self) -> Any:
        from benchlab.scenes.dots import DotChart

        return DotChart(self.pitch_mm, self.dot_mm, self.fiducial_scale, self.half_count)

    def lens(self) -> Any:
        from benchlab.scenes.dots import FovLens

        return FovLens(**{k: float(v) for k, v in self.simulator.items()})

    @property
    def stage_travel_mm(self) -> float:
        """Total stage travel of a run (from the first distance's position; the radial
        positions follow after a homing)."""
        s = [self.stage_mm(d) for d in self.distances_mm]
        forward = sum(abs(b - a) for a, b in zip(s, s[1:], strict=False))
        return forward + (self.radial.stage_travel_mm if self.radial is not None else 0.0)


def position_step_id(distance_mm: float) -> str:
    return f"distance-{distance_mm:g}"


def check_fov(c: Any, limits: Any = None) -> FovParams:
    """Read a ``fov`` parameter mapping with the params checker ``c``."""
    d = FovParams()
    exposure = camera_exposure_ms(c.number("camera.exposure_ms", d.exposure_ms,
                                           *EXPOSURE_RANGE_MS))
    gain = camera_gain(c.number("camera.gain", d.gain, *GAIN_RANGE))
    bits = c.choice("camera.bits", d.bits, (8, 12))
    frames = c.integer("camera.frames", d.frames, 1, 64)
    dist = c.numbers("positions.distances_mm", d.distances_mm, 0.0, 1000.0, lo_open=True)
    offset = c.number("positions.object_offset_mm", d.object_offset_mm, -1000.0, 1000.0)
    pitch = c.number("chart.pitch_mm", d.pitch_mm, 0.0, 100.0, lo_open=True)
    dot = c.number("chart.dot_mm", d.dot_mm, 0.0, 100.0, lo_open=True)
    fid = c.number("chart.fiducial_scale", d.fiducial_scale, 1.5, 4.0)
    half = c.integer("chart.half_count", d.half_count, 2, 500)
    min_dots = c.integer("analysis.min_dots", d.min_dots, 12, 100000)
    margin = c.number("analysis.edge_margin_px", d.edge_margin_px, 0.0, 200.0)
    f_design = c.number("analysis.design_focal_length_mm", d.design_focal_length_mm, 0.0, 100.0,
                        lo_open=True)
    fov_min = c.number("analysis.design_fov_min_deg", d.design_fov_min_deg, 0.0, 180.0)
    tol = c.number("analysis.height_tolerance_mm", d.height_tolerance_mm, 0.0, 10.0,
                   lo_open=True)
    step = c.number("analysis.distortion_step_deg", d.distortion_step_deg, 0.1, 45.0)
    simulator = _simulator(c)
    radial = check_radial(c, limits)
    if len(dist) < 2:
        c.fail("positions.distances_mm", f"{list(dist)}: the pupil and the tilt need the chart "
               "at two distances at least")
    elif max(dist) - min(dist) < 5.0:
        c.fail("positions.distances_mm", f"{list(dist)} span {max(dist) - min(dist):g} mm; "
               "at least 5 mm is needed to locate the entrance pupil")
    travel = getattr(limits, "stage_travel_mm", None) if limits is not None else None
    if travel is not None:
        lo, hi = travel
        for i, z in enumerate(dist):
            s = z - offset
            if not lo <= s <= hi:
                c.fail(f"positions.distances_mm[{i}]", f"{z:g} mm needs the stage at {s:g} mm "
                       f"(positions.object_offset_mm {offset:g}), outside its travel "
                       f"{lo:g}..{hi:g} mm")
    if dot >= pitch:
        c.fail("chart.dot_mm", f"{dot:g} mm dots on a {pitch:g} mm pitch touch each other")
    elif dot * fid >= pitch - dot:
        c.fail("chart.fiducial_scale", f"a {dot * fid:g} mm fiducial touches its neighbours on "
               f"a {pitch:g} mm pitch")
    if dist and not c.problems:
        _check_drawing(c, dist, pitch, dot, half, min_dots, f_design)
    return FovParams(
        exposure_ms=exposure, gain=gain, bits=bits, frames=frames, distances_mm=dist,
        object_offset_mm=offset, pitch_mm=pitch, dot_mm=dot, fiducial_scale=fid,
        half_count=half, min_dots=min_dots, edge_margin_px=margin,
        design_focal_length_mm=f_design, design_fov_min_deg=fov_min, height_tolerance_mm=tol,
        distortion_step_deg=step, simulator=simulator, radial=radial, raw=c.data,
    )


def _check_drawing(c: Any, dist: tuple[float, ...], pitch: float, dot: float, half: int,
                   min_dots: int, f_mm: float) -> None:
    """The chart against the frame, with the design's nominal equidistant mapping."""
    theta = FORWARD_DISC_RADIUS_PX * PIXEL_MM / f_mm  # half field at the disc's edge
    near, far = min(dist), max(dist)
    need = far * math.tan(theta) + pitch
    if half * pitch < need:
        c.fail("chart.half_count", f"the chart's {half * pitch:g} mm half width does not cover "
               f"the forward field ({math.degrees(theta):.1f} deg half angle) at {far:g} mm: "
               f"{need:.1f} mm needed")
    spacing_px = f_mm * pitch / far / PIXEL_MM
    if spacing_px < MIN_SPACING_PX:
        c.fail("positions.distances_mm", f"at {far:g} mm the dots are {spacing_px:.1f} px "
               f"apart; {MIN_SPACING_PX:g} px at least (move the chart nearer or take a "
               "coarser chart)")
    elif f_mm * dot / far / PIXEL_MM < MIN_DOT_PX:
        c.fail("chart.dot_mm", f"at {far:g} mm a {dot:g} mm dot is "
               f"{f_mm * dot / far / PIXEL_MM:.1f} px; {MIN_DOT_PX:g} px at least")
    radius_mm = near * math.tan(theta)
    expected = math.pi * radius_mm ** 2 / pitch ** 2
    if expected < min_dots:
        c.fail("positions.distances_mm", f"at {near:g} mm about {expected:.0f} dots fall in the "
               f"disc; analysis.min_dots is {min_dots}")


def _simulator(c: Any) -> dict[str, float]:
    from benchlab.scenes.dots import FovLens

    out = c.number_table("simulator", set(FovLens().to_dict()), "lens values")
    try:
        FovLens(**out)
    except ValueError as exc:
        c.fail("simulator", str(exc))
    return out


def fov_to_dict(p: FovParams) -> dict[str, Any]:
    """The effective parameters in the file's layout (what a session records)."""
    radial = radial_to_dict(p.radial)
    out: dict[str, Any] = {
        "procedure": "fov",
        "camera": {"exposure_ms": p.exposure_ms, "gain": p.gain, "bits": p.bits,
                   "frames": p.frames},
        "positions": {"distances_mm": list(p.distances_mm),
                      "object_offset_mm": p.object_offset_mm},
        "chart": {"pitch_mm": p.pitch_mm, "dot_mm": p.dot_mm,
                  "fiducial_scale": p.fiducial_scale, "half_count": p.half_count},
        "analysis": {"min_dots": p.min_dots, "edge_margin_px": p.edge_margin_px,
                     "design_focal_length_mm": p.design_focal_length_mm,
                     "design_fov_min_deg": p.design_fov_min_deg,
                     "height_tolerance_mm": p.height_tolerance_mm,
                     "distortion_step_deg": p.distortion_step_deg,
                     **radial["analysis"]},
        "simulator": dict(p.simulator),
        "radial": radial["radial"],
    }
    return out
