"""What ``benchlab run fov`` should find on the simulated bench, from the simulator's exact
mapping (:class:`benchlab.scenes.dots.DotGridScene`).

Rows ``{"table", "key", "value"}``: ``field_of_view`` rows keyed by quantity (the
``field_of_view`` table's ``quantity``), ``image_height_mapping`` / ``distortion_rectilinear``
/ ``distortion_equidistant`` rows keyed by field angle (deg). The truth distortion is against
the simulator's paraxial focal length, ``f`` (its mapping's slope at 0).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchlab.analysis.fov.model import PIXEL_MM
from benchlab.protocols.fov.params import FovParams


def truth_rows(params: FovParams, angles_deg: Sequence[float]) -> list[dict[str, Any]]:
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
        rows.append({"table": "image_height_mapping", "key": a, "value": hv})
        if a > 0:
            rows.append({"table": "distortion_rectilinear", "key": a,
                         "value": 100.0 * (hv - f * math.tan(t)) / (f * math.tan(t))})
            rows.append({"table": "distortion_equidistant", "key": a,
                         "value": 100.0 * (hv - f * t) / (f * t)})
    return rows
