"""What the depth-of-field sweep should find on the simulated bench: the ``depth_of_field`` keys
from the scene's closed form (:mod:`benchlab.scenes.focus`).

For each slanted edge (field point) the truth MTF at the criterion's frequency is the analytic
MTF of the edge as rendered at distance ``z`` (:meth:`DefocusedEdgeScene.truth_mtf_at`: its
Gaussian blur - lens table plus defocus - times the pixel aperture), with the edge where that
distance's magnification puts it. Best focus is that curve's maximum over ``z``; the DOF ends are
where it crosses the criterion's threshold (for the ``spot`` criterion: where the edge's RMS
spot, ``sqrt(2)`` x its Gaussian width, crosses ``rms_um`` - the thesis's own criterion, which
the analysis reaches through the MTF threshold). Found by bounded scalar search and root
bracketing, to 1e-6 mm.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from benchlab.analysis.chart.layout import IMAGE_CENTRE_RC
from benchlab.analysis.focus.criteria import Criterion, mtf_threshold
from benchlab.analysis.sfr.target import edge_spec
from benchlab.drivers.sensor import PIXEL_PITCH_UM
from benchlab.protocols.depth.params import DepthParams
from benchlab.scenes.edge import EdgeScene
from benchlab.scenes.focus import DefocusedEdgeScene, ThroughFocusLens, edges_at

_EDGES = EdgeScene()


def edge_scene_at(lens: ThroughFocusLens, distance_mm: float) -> DefocusedEdgeScene:
    return edges_at(lens, distance_mm, _EDGES)


def _edge(scene: DefocusedEdgeScene, label: str) -> Any:
    return edge_spec(label, scene.squares)


def truth_mtf(lens: ThroughFocusLens, label: str, freq_lp_per_mm: float,
              distance_mm: float) -> float:
    """The edge ``label``'s analytic MTF at ``freq`` with the chart at ``distance_mm``."""
    scene = edge_scene_at(lens, distance_mm)
    return float(scene.truth_mtf_at(label, [freq_lp_per_mm * PIXEL_PITCH_UM / 1000.0])[0])


def truth_spot_um(lens: ThroughFocusLens, label: str, distance_mm: float) -> float:
    """The edge's RMS spot radius (um): sqrt(2) x its Gaussian width across it."""
    scene = edge_scene_at(lens, distance_mm)
    e = _edge(scene, label)
    return math.sqrt(2.0) * scene.side_sigma_px(e.square, e.normal_theta_rad) * PIXEL_PITCH_UM


def _crossing(g: Callable[[float], float], a: float, b: float) -> float | None:
    from scipy.optimize import brentq

    ga, gb = g(a), g(b)
    if ga == 0:
        return a
    if ga * gb > 0:
        return None
    return float(brentq(g, a, b, xtol=1e-7))


def truth_focus(lens: ThroughFocusLens, label: str, crit: Criterion, bounds_mm: tuple[float, float]
                ) -> dict[str, Any]:
    """Best focus, near and far (None: not reached within ``bounds_mm``) for one edge."""
    from scipy.optimize import minimize_scalar

    f = crit.frequency_lp_per_mm
    lo, hi = bounds_mm
    # best focus: maximum of the MTF at f, searched in vergence (the curve is smooth there)
    res = minimize_scalar(lambda u: -truth_mtf(lens, label, f, 1.0 / u),
                          bounds=(1.0 / hi, 1.0 / lo), method="bounded",
                          options={"xatol": 1e-9})
    best = 1.0 / float(res.x)
    if crit.kind == "spot":
        def g(z: float) -> float:
            return crit.rms_um - truth_spot_um(lens, label, z)
    else:
        thr = mtf_threshold(crit, PIXEL_PITCH_UM)

        def g(z: float) -> float:
            return truth_mtf(lens, label, f, z) - thr
    if g(best) < 0:
        return {"best_focus_mm": best, "near_mm": None, "far_mm": None}
    return {"best_focus_mm": best, "near_mm": _crossing(g, lo, best),
            "far_mm": _crossing(g, best, hi)}


def truth_rows(params: DepthParams, labels: Sequence[str]) -> list[dict[str, Any]]:
    """The ``depth_of_field`` keys per edge and criterion (module docstring)."""
    lens = params.lens()
    bounds = (params.near_mm * 0.5, params.far_mm * 2.0)
    rows = []
    seen: set[str] = set()
    for label in labels:
        if label in seen:
            continue
        seen.add(label)
        scene = edge_scene_at(lens, params.near_mm)
        orient = _edge(scene, label).orientation
        for crit in params.criteria:
            t = truth_focus(lens, label, crit, bounds)
            best = t["best_focus_mm"]
            e = _edge(edge_scene_at(lens, best), label)
            dr, dc = (e.midpoint_rc[0] - IMAGE_CENTRE_RC[0], e.midpoint_rc[1] - IMAGE_CENTRE_RC[1])
            h = float(np.hypot(dr, dc) * PIXEL_PITCH_UM / 1000.0)
            near, far = t["near_mm"], t["far_mm"]
            rows.append({
                "view": "forward", "field_point": label, "orientation": orient,
                "criterion": crit.name, "freq_lp_per_mm": crit.frequency_lp_per_mm,
                "threshold": round(mtf_threshold(crit, PIXEL_PITCH_UM), 4),
                "image_height_mm": round(h, 4), "best_focus_mm": round(best, 4),
                "near_mm": None if near is None else round(near, 4),
                "far_mm": None if far is None else round(far, 4),
                "dof_mm": None if near is None or far is None else round(far - near, 4),
            })
    return rows


def truth_astigmatism(truth: Sequence[dict[str, Any]]) -> dict[tuple[str, float], float]:
    """S minus T truth best focus per (square, frequency), means over the sides."""
    acc: dict[tuple[str, float, str], list[float]] = {}
    for r in truth:
        acc.setdefault((r["field_point"][:-1], r["freq_lp_per_mm"], r["orientation"]),
                       []).append(r["best_focus_mm"])
    out = {}
    for (sq, f, o), v in acc.items():
        if o == "sagittal" and (sq, f, "tangential") in acc:
            # each side appears once per criterion of that frequency: the means are unaffected
            out[(sq, f)] = float(np.mean(v) - np.mean(acc[(sq, f, "tangential")]))
    return out
