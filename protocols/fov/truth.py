"""What ``benchlab run fov`` should find on the simulated bench, from the simulator's exact
mapping (:class:`benchlab.scenes.dots.DotGridScene`).

Rows ``{"table", "key", "value"}``: ``field_of_view`` rows keyed by quantity (the
``field_of_view`` table's ``quantity``), ``image_height_mapping`` / ``distortion_rectilinear``
/ ``distortion_equidistant`` rows keyed by field angle (deg, as text: ``"12.5"``, so the
column holds one kind). The truth distortion is against
the simulator's paraxial focal length, ``f`` (its mapping's slope at 0). The radial view's
rows (:func:`radial_truth_rows`): ``field_of_view`` keyed by its ``radial_*`` quantities and
``radial_image_height_mapping`` keyed by field angle.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchlab.analysis.fov.model import PIXEL_MM
from benchlab.protocols.fov.params import FovParams
from benchlab.protocols.fov.radial_params import RadialPlan


def truth_rows(params: FovParams, angles_deg: Sequence[float],
               radial_angles_deg: Sequence[float] = ()) -> list[dict[str, Any]]:
    """The truth rows (module docstring)."""
    from benchlab.scenes.dots import DotGridScene

    scene = DotGridScene(chart=params.chart(), lens=params.lens())
    lens = scene.lens
    h = lens.height_mm()
    rows: list[dict[str, Any]] = [
        {"table": "field_of_view", "key": "full_fov_deg",
         "value": 2.0 * math.degrees(scene.edge_angle_rad())},
        {"table": "field_of_view", "key": "direction_of_view_deg", "value": lens.tilt_deg},
        {"table": "field_of_view", "key": "entrance_pupil_mm", "value": lens.entrance_pupil_mm},
        {"table": "field_of_view", "key": "paraxial_focal_length_mm",
         "value": lens.focal_length_mm},
        {"table": "field_of_view", "key": "disc_radius_mm",
         "value": scene.circles.disc_radius_px * PIXEL_MM},
    ]
    f = lens.focal_length_mm
    for a in angles_deg:
        t = math.radians(a)
        hv = float(h(np.array([t]))[0])
        rows.append({"table": "image_height_mapping", "key": f"{a:g}", "value": hv})
        if a > 0:
            rows.append({"table": "distortion_rectilinear", "key": f"{a:g}",
                         "value": 100.0 * (hv - f * math.tan(t)) / (f * math.tan(t))})
            rows.append({"table": "distortion_equidistant", "key": f"{a:g}",
                         "value": 100.0 * (hv - f * t) / (f * t)})
    if params.radial is not None:
        rows += radial_truth_rows(params.radial, radial_angles_deg)
    return rows


def radial_truth_rows(plan: RadialPlan, angles_deg: Sequence[float]) -> list[dict[str, Any]]:
    """The radial view's truth: the ring tube's exact mapping (the ray-trace table)."""
    from benchlab.scenes.rings import RingTubeScene

    scene = RingTubeScene(tube=plan.tube())
    start, end = scene.field_ends_mm()

    def angle(z: float) -> float:
        return -math.degrees(math.atan((z - plan.viewpoint_z_mm) / plan.tube_radius_mm))

    pitch = scene.circles.pixel_pitch_um / 1000.0
    rows: list[dict[str, Any]] = [
        {"table": "field_of_view", "key": "radial_field_start_mm", "value": start},
        {"table": "field_of_view", "key": "radial_field_end_mm", "value": end},
        {"table": "field_of_view", "key": "radial_field_start_deg", "value": angle(start)},
        {"table": "field_of_view", "key": "radial_field_end_deg", "value": angle(end)},
        {"table": "field_of_view", "key": "radial_fov_deg",
         "value": abs(angle(start) - angle(end))},
        {"table": "field_of_view", "key": "radial_inner_radius_mm",
         "value": scene.circles.annulus_inner_radius_px * pitch},
        {"table": "field_of_view", "key": "radial_outer_radius_mm",
         "value": scene.circles.annulus_outer_radius_px * pitch},
    ]
    for a in angles_deg:
        z = plan.viewpoint_z_mm + plan.tube_radius_mm * math.tan(math.radians(-a))
        h = float(scene.image_radius_mm(np.array([z]))[0])
        if math.isfinite(h):
            rows.append({"table": "radial_image_height_mapping", "key": f"{a:g}", "value": h})
    return rows
