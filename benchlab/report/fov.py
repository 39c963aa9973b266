"""The report's field-of-view section: the measured image-height mapping with its intervals,
Table 4.14's forward field points, the f tan(theta) and f theta models, and the local
distortion against both; then the radial view: its mapping over field angle and over the
axial position on the wall, Table 4.14's radial field points, the field's ends."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from benchlab.report.html import caption, esc, figure_img


def _figure(mapping: Sequence[Mapping[str, Any]], distortion: Sequence[Mapping[str, Any]],
            f_mm: float, fov_deg: float) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
    a = np.array([float(r["field_angle_deg"]) for r in mapping])
    h = np.array([float(r["image_height_mm"]) for r in mapping])
    lo = np.array([float(r["image_height_mm_ci95"][0]) for r in mapping])
    hi = np.array([float(r["image_height_mm_ci95"][1]) for r in mapping])
    ax.errorbar(a, h, yerr=[h - lo, hi - h], fmt="o", ms=4, capsize=3,
                label="measured (95 % interval)")
    t = np.linspace(0.0, max(float(a.max()), fov_deg / 2.0), 200)
    ax.plot(t, f_mm * np.tan(np.radians(t)), "--", label=f"f tan(theta), f = {f_mm:.3f} mm")
    ax.plot(t, f_mm * np.radians(t), ":", label="f theta")
    design = [(float(r["field_angle_deg"]), float(r["design_image_height_mm"])) for r in mapping
              if r.get("design_image_height_mm") is not None]
    if design:
        ax.plot(*zip(*design, strict=True), "s", mfc="none", ms=9, label="Table 4.14 (design)")
    ax.axvline(fov_deg / 2.0, color="grey", lw=0.8)
    ax.set_xlabel("field angle (deg)")
    ax.set_ylabel("image height (mm)")
    ax.set_title("Image-height mapping (forward view)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if distortion:
        da = [float(r["field_angle_deg"]) for r in distortion]
        for key, fmt, label in (("rectilinear_pct", "o-", "vs f tan(theta)"),
                                ("equidistant_pct", "s-", "vs f theta")):
            v = np.array([float(r[key]) for r in distortion])
            ci = np.array([r[f"{key}_ci95"] for r in distortion], dtype=np.float64)
            ax2.errorbar(da, v, yerr=[v - ci[:, 0], ci[:, 1] - v], fmt=fmt, ms=3, capsize=2,
                         label=label)
        ax2.axhline(0.0, color="grey", lw=0.8)
        ax2.set_xlabel("field angle (deg)")
        ax2.set_ylabel("local distortion (% of image height)")
        ax2.set_title("Distortion")
        ax2.grid(alpha=0.3)
        ax2.legend(fontsize=8)
    fig.tight_layout()
    return figure_img(fig, "image-height mapping and distortion")


def _radial_figure(mapping: Sequence[Mapping[str, Any]], ends: Mapping[str, float]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in mapping if r.get("image_height_mm") is not None]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
    a = np.array([float(r["field_angle_deg"]) for r in rows])
    z = np.array([float(r["axial_position_mm"]) for r in rows])
    h = np.array([float(r["image_height_mm"]) for r in rows])
    lo = np.array([float(r["image_height_mm_ci95"][0]) for r in rows])
    hi = np.array([float(r["image_height_mm_ci95"][1]) for r in rows])
    ax.errorbar(a, h, yerr=[h - lo, hi - h], fmt="o", ms=4, capsize=3,
                label="measured (95 % interval)")
    design = [(float(r["field_angle_deg"]), float(r["design_image_height_mm"])) for r in mapping
              if r.get("design_image_height_mm") is not None]
    if design:
        ax.plot(*zip(*design, strict=True), "s", mfc="none", ms=9, label="Table 4.14 (design)")
    for key in ("radial_field_start_deg", "radial_field_end_deg"):
        if key in ends:
            ax.axvline(ends[key], color="grey", lw=0.8)
    ax.set_xlabel("radial field angle from the effective viewpoint (deg)")
    ax.set_ylabel("image height (mm)")
    ax.set_title("Image-height mapping (radial view)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax2.errorbar(z, h, yerr=[h - lo, hi - h], fmt="o-", ms=3, capsize=2)
    for key in ("radial_field_start_mm", "radial_field_end_mm"):
        if key in ends:
            ax2.axvline(ends[key], color="grey", lw=0.8)
    ax2.set_xlabel("axial position on the wall (mm, thesis z)")
    ax2.set_ylabel("image height (mm)")
    ax2.set_title("Radial field on the wall (grey: start and end)")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    return figure_img(fig, "radial image-height mapping")


def _items(fov: Mapping[str, Mapping[str, Any]], names: Sequence[tuple[str, str]]) -> list[str]:
    lines = []
    for name, label in names:
        r = fov.get(name)
        if r is not None and r.get("value") is not None:
            lo, hi = r["value_ci95"]
            unit = r.get("unit", "")
            verdict = f" - {esc(r['verdict'])}" if r.get("verdict") else ""
            lines.append(f"<li>{label}: {r['value']:g} {unit} (95 %: {lo:g} - {hi:g})"
                         f"{verdict}</li>")
    return lines


def radial_section(tables: Mapping[str, Any]) -> str:
    """The radial view's part (empty without radial rows)."""
    mapping = [r for r in tables.get("image_height_mapping") or [] if r.get("view") == "radial"]
    if not mapping:
        return ""
    fov = {r["quantity"]: r for r in tables.get("field_of_view") or []}
    lines = _items(fov, (("radial_field_start_mm", "radial field's start on the wall (z)"),
                         ("radial_field_end_mm", "radial field's end on the wall (z)"),
                         ("radial_fov_deg", "radial field of view from the viewpoint")))
    verdicts = [f"<li>{r['field_angle_deg']:g} deg: {esc(r['verdict'])}</li>" for r in mapping
                if r.get("verdict")]
    ends = {k: float(fov[k]["value"]) for k in ("radial_field_start_deg", "radial_field_end_deg",
                                                "radial_field_start_mm", "radial_field_end_mm")
            if k in fov and fov[k].get("value") is not None}
    note = ("<p class='note'>Radial view: the ring tube's rings at every stage position give "
            "the image height over the axial position on the wall; field angles are taken from "
            "the effective viewpoint on the axis (chapter 5). Squares: Table 4.14's radial field "
            "points.</p>")
    return ("<h3>Radial view</h3>" + note + "<ul>" + "".join(lines) + "</ul>"
            + ("<p>Table 4.14's radial field points:</p><ul>" + "".join(verdicts) + "</ul>"
               if verdicts else "") + _radial_figure(mapping, ends))


def fov_section(tables: Mapping[str, Any]) -> str:
    """The section's HTML (empty without an ``image_height_mapping`` table)."""
    everything = tables.get("image_height_mapping") or []
    mapping = [r for r in everything if r.get("view", "forward") == "forward"]
    if not everything:
        return ""
    radial = radial_section(tables)
    fov = {r["quantity"]: r for r in tables.get("field_of_view") or []}
    f_mm = float(fov.get("paraxial_focal_length_mm", {}).get("value") or 0.0)
    full = fov.get("full_fov_deg", {})
    fov_deg = float(full.get("value") or 0.0)
    lines = _items(fov, (("full_fov_deg", "full field of view"),
                         ("direction_of_view_deg", "direction of view"),
                         ("entrance_pupil_mm", "entrance pupil behind the front")))
    note = ("<p class='note'>Points: the fitted mapping h(theta) at each field angle with its "
            "95 % interval (often smaller than the marker); squares: Table 4.14's forward field "
            "points; lines: f tan(theta) and f theta with the measured paraxial focal length; "
            "the grey line: the field's edge (half the field of view).</p>")
    if not mapping or not math.isfinite(fov_deg) or f_mm <= 0:
        return note + "<ul>" + "".join(lines) + "</ul>" + radial
    return (note + "<ul>" + "".join(lines) + "</ul>"
            + caption("the measured image height at each field angle (95 % interval) with "
                      "f tan(theta), f theta and Table 4.14's design points (left), and its "
                      "distortion against each (right).")
            + _figure(mapping, tables.get("distortion") or [], f_mm, fov_deg) + radial)
