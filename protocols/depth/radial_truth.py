"""What the radial sweep should find on the simulated bench: the ``depth_of_field`` keys of every
pattern and field point from the scene's closed form
(:func:`benchlab.scenes.focus.defocused_radial`).

At a field point (an ROI's centroid, at image height ``h``) the rendered pattern is a square
wave blurred by a Gaussian of width ``sigma_px`` (radial blur table plus the defocus there, plus
the pixel aperture) across the bars; in object mm that is ``sigma_px`` x the local object mm
per pixel (object radius / image radius for spokes, the ray-trace table's axial magnification
for rings), both changing with the object radius.

* **Best focus**: where the fundamental (sine-wave) modulation peaks, i.e. where the object-side
  blur ``sigma_mm`` is smallest (the fundamental is ``exp(-2 pi^2 sigma_mm^2 f^2)`` x a
  constant). Not where the Eq. 2.9 modulation peaks: near focus that is flat at the print's
  full contrast, a plateau with no maximum to find. For spokes the magnification term shifts
  it by < 0.01 mm from the lens's best-focus radius; for rings (blur table 1.6 px) by ~0.17 mm.
* **DOF ends**: where the lens's share of the print's contrast (the Eq. 2.9 modulation,
  :meth:`RadialScene.truth_modulation` there, over the scene's own ``contrast``) crosses
  ``radial.threshold``, by root bracketing. The rows give that ``target_contrast``.

Searched over the ray-trace table's object radii (2-11 mm from the wall), to 1e-6 mm.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from benchlab.analysis.chart.layout import box_centroid
from benchlab.protocols.depth.params import DepthParams
from benchlab.protocols.depth.radial_rois import roi_height_mm, roi_name
from benchlab.scenes.focus import ThroughFocusLens, defocused_radial
from benchlab.scenes.optics import PIXEL_APERTURE_VAR_PX2
from benchlab.scenes.radial import RadialScene


def _pattern_label(pattern: tuple[float, str]) -> str:
    return f"{pattern[0]:g}lp/mm"


def object_sigma_mm(template: RadialScene, lens: ThroughFocusLens, radius_mm: float) -> float:
    """Object-side Gaussian blur (mm) across the bars at ``template.reference_rc`` with the
    pattern at ``radius_mm``."""
    scene = defocused_radial(template, lens, radius_mm)
    px = math.sqrt(float(scene.across_bar_sigma_px(scene.reference_radius_px)) ** 2
                   + PIXEL_APERTURE_VAR_PX2)
    return px * scene.object_mm_per_px()


def truth_focus(template: RadialScene, lens: ThroughFocusLens, threshold: float,
                bounds_mm: tuple[float, float]) -> dict[str, float | None]:
    """Best-focus, near and far object radius (mm from the axis; None: the threshold is not
    reached inside ``bounds_mm``) at the template's reference point (module docstring)."""
    from scipy.optimize import brentq, minimize_scalar

    lo, hi = bounds_mm
    res = minimize_scalar(lambda u: object_sigma_mm(template, lens, 1.0 / u),
                          bounds=(1.0 / hi, 1.0 / lo), method="bounded",
                          options={"xatol": 1e-10})
    best = 1.0 / float(res.x)

    def g(radius: float) -> float:
        return defocused_radial(template, lens, radius).truth_modulation() - threshold

    def cross(a: float, b: float) -> float | None:
        ga, gb = g(a), g(b)
        if ga * gb > 0:
            return None
        return float(brentq(g, a, b, xtol=1e-7))

    if g(best) < 0:
        return {"best": best, "near": None, "far": None}
    return {"best": best, "near": cross(lo, best), "far": cross(best, hi)}


def truth_rows(params: DepthParams) -> list[dict[str, Any]]:
    """The radial ``depth_of_field`` keys per field point and pattern (module docstring)."""
    from benchlab.analysis.views.raytrace import read_raytrace_table

    lens = params.lens()
    wall = params.wall_radius_mm
    radii = read_raytrace_table().object_radius_mm
    bounds = (float(min(radii)), float(max(radii)))
    thr = params.radial_threshold
    rows = []
    for pattern in params.patterns:
        assert pattern is not None
        for box in params.radial_rois:
            template = RadialScene(pattern[0], "sagittal" if pattern[1] == "sagittal"
                                   else "tangential")
            template = dataclasses.replace(template, reference_rc=box_centroid(box))
            # the threshold bounds the lens's share: the reading crosses thr x the print's
            t = truth_focus(template, lens, thr * template.contrast, bounds)
            near, far = t["near"], t["far"]
            assert t["best"] is not None
            rows.append({"view": "radial", "field_point": roi_name(box),
                         "pattern": _pattern_label(pattern), "orientation": pattern[1],
                         "criterion": f"modulation>={thr:g}", "freq_lp_per_mm": pattern[0],
                         "threshold": thr, "target_contrast": round(template.contrast, 6),
                         "image_height_mm": round(roi_height_mm(box), 4),
                         "best_focus_mm": round(t["best"] - wall, 4),
                         "near_mm": None if near is None else round(near - wall, 4),
                         "far_mm": None if far is None else round(far - wall, 4),
                         "dof_mm": None if near is None or far is None
                         else round(far - near, 4)})
    return rows
