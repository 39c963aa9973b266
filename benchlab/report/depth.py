"""The depth-of-field report section: through-focus curves per field point and orientation
with the criterion line and the DOF band, and best focus against image height (field
curvature) with the S - T split, against the design values."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from benchlab.analysis.focus.through_focus import FocusFitError, fit_through_focus
from benchlab.report.html import caption, esc, figure_img

_COLOURS = {"sagittal": "tab:blue", "tangential": "tab:red"}


def _curves_figure(curves: Sequence[Mapping[str, Any]], dof: Sequence[Mapping[str, Any]],
                   criterion: str, min_mtf: float) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in dof if r["criterion"] == criterion]
    if not rows:
        return ""
    freq = rows[0]["freq_lp_per_mm"]
    squares = sorted({r["field_point"][:-1] for r in rows})
    fig, axes = plt.subplots(1, len(squares), figsize=(4.2 * len(squares), 3.6), sharey=True,
                             squeeze=False)
    for ax, sq in zip(axes[0], squares, strict=True):
        for r in (x for x in rows if x["field_point"][:-1] == sq):
            pts = [c for c in curves if c["edge"] == r["field_point"]
                   and c["freq_lp_per_mm"] == freq and c["mtf"] is not None]
            if not pts:
                continue
            z = np.array([c["distance_mm"] for c in pts], float)
            m = np.array([c["mtf"] for c in pts], float)
            s = np.array([c["mtf_sigma"] or np.nan for c in pts], float)
            colour = _COLOURS.get(r["orientation"], "k")
            ax.plot(z, m, "o", ms=3, color=colour, alpha=0.7)
            try:
                fit = fit_through_focus(z, m, s, min_mtf=min_mtf)
            except FocusFitError:
                continue
            zz = np.linspace(z.min(), z.max(), 300)
            ax.plot(zz, fit.mtf(zz), "-", lw=1, color=colour,
                    label=f"{r['field_point']} ({r['orientation'][0].upper()})")
            if r["near_mm"] is not None and r["far_mm"] is not None:
                ax.axvspan(r["near_mm"], r["far_mm"], color=colour, alpha=0.05)
        ax.axhline(rows[0]["threshold"], color="k", lw=0.8, ls="--")
        ax.set_title(f"{sq}: {criterion}")
        ax.set_xlabel("object distance (mm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel(f"MTF at {freq:g} lp/mm (0-1)")
    fig.tight_layout()
    return figure_img(fig, f"through-focus curves, {criterion}")


def _on_share(dof: Sequence[Mapping[str, Any]]) -> bool:
    """Whether the radial DOF was bounded on the lens's share (every row's target contrast
    known) rather than on the reading."""
    return all(str(r.get("threshold_on", "")).startswith("lens share") for r in dof)


def _radial_curves_figure(curves: Sequence[Mapping[str, Any]],
                          dof: Sequence[Mapping[str, Any]]) -> str:
    """The radial view: per field point (ROI), the lens's share of the print's contrast (or,
    with the target contrast unknown, the bar modulation, Eq. 2.9) against the wall distance for
    S and T - what the threshold bounds -, the threshold, the DOF band and the best focus. The
    points are joined, not refitted: the analysis fits the fundamental in the object radius, a
    curve of another quantity."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    key = "lens_share" if _on_share(dof) else "modulation"
    points = sorted({r["field_point"] for r in dof})
    fig, axes = plt.subplots(1, len(points), figsize=(4.2 * len(points), 3.6), sharey=True,
                             squeeze=False)
    for ax, fp in zip(axes[0], points, strict=True):
        for r in (x for x in dof if x["field_point"] == fp):
            pts = sorted((c["distance_mm"], c[key]) for c in curves
                         if c.get("field_point") == fp and c["orientation"] == r["orientation"]
                         and c.get("pattern") == r.get("pattern")
                         and c.get(key) is not None)
            if not pts:
                continue
            colour = _COLOURS.get(r["orientation"], "k")
            z, m = zip(*pts, strict=True)
            ax.plot(z, m, "o-", ms=3, lw=0.8, color=colour,
                    label=f"{r.get('pattern', '')} {r['orientation'][0].upper()}")
            if r["near_mm"] is not None and r["far_mm"] is not None:
                ax.axvspan(r["near_mm"], r["far_mm"], color=colour, alpha=0.05)
            if r["best_focus_mm"] is not None:
                ax.axvline(r["best_focus_mm"], color=colour, lw=0.8, ls=":")
        ax.axhline(dof[0]["threshold"], color="k", lw=0.8, ls="--")
        height = next(x["image_height_mm"] for x in dof if x["field_point"] == fp)
        ax.set_title(f"{fp} (image height {height:.2f} mm)", fontsize=9)
        ax.set_xlabel("distance from the side wall (mm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("lens share (Eq. 2.9 / target contrast)" if key == "lens_share"
                          else "bar modulation (Eq. 2.9)")
    fig.tight_layout()
    return figure_img(fig, "radial through-focus curves")


def _curvature_figure(dof: Sequence[Mapping[str, Any]], criterion: str,
                      half_range_mm: float | None) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in dof if r["criterion"] == criterion and r["best_focus_mm"] is not None]
    if not rows:
        return ""
    fig, ax = plt.subplots(figsize=(6, 4))
    for orient, colour in _COLOURS.items():
        sel = [r for r in rows if r["orientation"] == orient]
        if not sel:
            continue
        h = [r["image_height_mm"] for r in sel]
        b = [r["best_focus_mm"] for r in sel]
        lo = [r["best_focus_mm"] - (r["best_focus_mm_ci95"][0] or r["best_focus_mm"])
              for r in sel]
        hi = [(r["best_focus_mm_ci95"][1] or r["best_focus_mm"]) - r["best_focus_mm"]
              for r in sel]
        ax.errorbar(h, b, yerr=[lo, hi], fmt="o", color=colour, capsize=3, label=orient)
    ax.set_xlabel("image height at best focus (mm)")
    ax.set_ylabel("best-focus object distance (mm)")
    note = f" (design DOF: +-{half_range_mm:g} mm about it)" if half_range_mm else ""
    ax.set_title(f"Best focus vs image height, {criterion}{note}", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    return figure_img(fig, "best focus against image height")


_CURVATURE_CAPTION = caption(
    "each field point's best-focus distance (95 % interval) with its image height, sagittal "
    "against tangential: a slope is field curvature, a gap between the two astigmatism.")


def depth_section(tables: Mapping[str, Any], params: Mapping[str, Any]) -> str:
    """The section's HTML (empty without a ``depth_of_field`` table)."""
    dof = tables.get("depth_of_field") or []
    if not dof:
        return ""
    curves = tables.get("depth_curves") or []
    analysis = params.get("analysis", {}) if isinstance(params, Mapping) else {}
    min_mtf = float(analysis.get("min_mtf", 0.05))
    half = analysis.get("design_half_range_mm")
    if all(r.get("view") == "radial" for r in dof):
        shown = ("the lens's share of the print's contrast (its modulation, Eq. 2.9, over the "
                 "pattern's own contrast, "
                 + " / ".join(f"{v:.3f}" for v in sorted({float(r["target_contrast"])
                                                          for r in dof}))
                 + f", {dof[0].get('target_contrast_source')})" if _on_share(dof) else
                 "modulation (Eq. 2.9) - the print's own contrast unknown: lens and print "
                 "together -")
        return (caption("each field point's bar modulation through focus with the threshold "
                        "(where it crosses: the DOF ends).")
                + f"<p class='note'>Points: the rolled bar pattern's {shown} in each "
                "field point's ROI at each distance from the side wall; dashed: the threshold; "
                "bands: the DOF; dotted: best focus (the peak of the fundamental's fit in the "
                "object radius). Blue sagittal, red tangential.</p>"
                + _radial_curves_figure(curves, dof)
                + "<h3>Field curvature and astigmatism</h3>" + _CURVATURE_CAPTION
                + _curvature_figure(dof, dof[0]["criterion"], float(half) if half else None))
    out = ["<p class='note'>Points: the slanted edges' MTF at the criterion's frequency at each "
           "object distance (both segments); lines: the through-focus fit (degree-4 polynomial "
           "of ln MTF in 1/distance); dashed: the criterion's threshold; bands: the DOF. Blue "
           "sagittal (near-vertical edges), red tangential.</p>"]
    criteria = list(dict.fromkeys(r["criterion"] for r in dof))
    for crit in criteria:
        out.append(f"<h3>{esc(crit)}</h3>"
                   + caption(f"each field point's MTF at the criterion's frequency through "
                             f"focus with the threshold of {crit} (where it crosses: the DOF "
                             "ends).")
                   + _curves_figure(curves, dof, crit, min_mtf))
    out.append("<h3>Field curvature and astigmatism</h3>" + _CURVATURE_CAPTION
               + _curvature_figure(dof, criteria[0], float(half) if half else None))
    return "".join(out)
