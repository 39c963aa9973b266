"""The simulated bench's truth for an MTF session (``simulator_truth``): for every bar set of
Tables 4.11 and 4.12, the target's own contrast (:attr:`~benchlab.scenes.printed.TwoLevelPrint.
contrast`), the noise-free imaged contrast and the lens's share of it (imaged / target).

The simulated bench mounts its default scenes (:class:`~benchlab.scenes.world.SimWorld`): the
USAF chart at its layout's place and the rolled patterns read at the radial ROI's centroid.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from benchlab.analysis.chart.layout import Orientation
from benchlab.analysis.geometry import roi_centroid
from benchlab.protocols.mtf.params import MtfParams
from benchlab.protocols.mtf.targets import SIMULATED_TARGET_EVENT
from benchlab.scenes.radial import RadialScene
from benchlab.scenes.usaf import UsafScene

ORIENTATIONS: tuple[Orientation, ...] = ("sagittal", "tangential")


def truth_rows(params: MtfParams, t411: list[dict[str, Any]], t412: list[dict[str, Any]],
               levels: dict[str, tuple[float, float]] | None = None) -> list[dict[str, Any]]:
    """One row per measured bar set and orientation: ``view``, ``pattern``, ``orientation``,
    ``image_lp_per_mm``, ``target_contrast``, ``modulation`` (Eq. 2.9, noise-free) and
    ``lens_share``. ``levels``: the printed ``(dark_dn8, bright_dn8)`` per view the session
    journalled (:func:`journalled_levels`; else the scenes' defaults)."""
    levels = levels or {}
    usaf = UsafScene()
    if "forward" in levels:
        usaf = dataclasses.replace(usaf, dark_dn8=levels["forward"][0],
                                   bright_dn8=levels["forward"][1])
    rows: list[dict[str, Any]] = []
    elements = {el.name: el for el in params.forward_elements}
    for r in t411:
        el = elements[str(r["element"])]
        for orient in ORIENTATIONS:
            m = usaf.truth_modulation(el.group, el.element, orient)
            rows.append(_row("forward", el.name, orient, r[f"{orient}_image_lp_per_mm"],
                             usaf.contrast, m))
    template = RadialScene(1.0, "sagittal", object_radius_mm=params.radial_object_radius_mm)
    if "radial" in levels:
        template = dataclasses.replace(template, dark_dn8=levels["radial"][0],
                                       bright_dn8=levels["radial"][1])
    at = roi_centroid(params.radial_roi)
    for r in t412:
        f = float(r["object_lp_per_mm"])
        for orient in ORIENTATIONS:
            scene = dataclasses.replace(template, object_lp_per_mm=f, orientation=orient)
            rows.append(_row("radial", f"{f:g} lp/mm", orient, scene.image_lp_per_mm,
                             scene.contrast, scene.truth_modulation(at)))
    return rows


def journalled_levels(events: list[dict[str, Any]]) -> dict[str, tuple[float, float]]:
    """The last printed levels journalled per view (``simulated_target`` events)."""
    out: dict[str, tuple[float, float]] = {}
    for e in events:
        if e.get("kind") == SIMULATED_TARGET_EVENT:
            out[str(e["view"])] = (float(e["dark_dn8"]), float(e["bright_dn8"]))
    return out


def _row(view: str, pattern: str, orient: str, f: float, target: float,
         modulation: float) -> dict[str, Any]:
    return {"view": view, "pattern": pattern, "orientation": orient,
            "image_lp_per_mm": round(float(f), 6), "target_contrast": round(target, 6),
            "modulation": round(modulation, 6), "lens_share": round(modulation / target, 6)}
