"""The found USAF chart drawn on its frame (``find-chart --plot`` and the MTF report).

Each bar set of the fitted layout is drawn as its (rotated) square: green when found (orange
when found but not measurable), with its measurement ROI in yellow and its label; red dashed
when rejected. The left panel is the whole
frame, the right one zooms on the chart.
"""

from __future__ import annotations

import html
import io
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Polygon, Rectangle  # noqa: E402

from benchlab.analysis.chart.finder import ChartFit, ChartNotFoundError, find_chart  # noqa: E402
from benchlab.analysis.chart.layout import ChartLayout  # noqa: E402

#: Labels are drawn for found sets at least this many px wide (smaller ones crowd the zoom).
LABEL_MIN_SET_PX = 7.0


def chart_figure(pixels: npt.NDArray[Any], fit: ChartFit, title: str = "") -> Figure:
    """A two-panel figure: the frame with every placed set, and a zoom on the chart."""
    img = np.asarray(pixels, dtype=np.float64)
    if img.ndim == 3:
        img = img.mean(axis=0)
    vmax = float(np.percentile(img, 99.9)) or 1.0
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2))
    for ax in axes:
        ax.imshow(img, cmap="gray", vmin=0, vmax=vmax, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        for el in fit.elements:
            pts = [(c, r) for r, c in el.posed.corners()]
            if el.found:
                ax.add_patch(Polygon(pts, closed=True, fill=False, lw=0.8,
                                     ec="orange" if el.unmeasurable else "lime"))
                r0, c0, r1, c1 = el.measurement_roi
                ax.add_patch(Rectangle((c0 - 0.5, r0 - 0.5), c1 - c0, r1 - r0, fill=False,
                                       ec="yellow", lw=0.6))
            else:
                ax.add_patch(Polygon(pts, closed=True, fill=False, ec="red", lw=0.6, ls="--"))
    zoom = axes[1]
    rows = [r for el in fit.elements for r, _ in el.posed.corners()]
    cols = [c for el in fit.elements for _, c in el.posed.corners()]
    zoom.set_xlim(max(min(cols) - 20, -0.5), min(max(cols) + 20, img.shape[1] - 0.5))
    zoom.set_ylim(min(max(rows) + 20, img.shape[0] - 0.5), max(min(rows) - 20, -0.5))
    for el in fit.found:
        if 5 * el.posed.bar_width_px >= LABEL_MIN_SET_PX:
            r, c = el.posed.centre_rc
            zoom.text(c, r - 2.9 * el.posed.bar_width_px, el.label, color="lime", fontsize=5,
                      ha="center", va="bottom")
    p = fit.pose
    axes[0].set_title(title or "found elements (green), ROIs (yellow), rejected (red)",
                      fontsize=9)
    zoom.set_title(
        f"offset ({p.offset_rc[0]:+.1f}, {p.offset_rc[1]:+.1f}) px, scale {p.scale:.3f}, "
        f"rotation {p.rotation_deg:+.2f} deg, {fit.polarity}; {len(fit.found)} found, "
        f"{len(fit.rejected)} rejected", fontsize=9)
    fig.tight_layout()
    return fig


def chart_png(pixels: npt.NDArray[Any], fit: ChartFit, title: str = "") -> bytes:
    """:func:`chart_figure` as PNG bytes."""
    fig = chart_figure(pixels, fit, title)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def forward_chart_section(pixels: npt.NDArray[Any], magnification: float) -> str:
    """HTML for the MTF report: the forward frame with the found chart drawn, or why not."""
    try:
        fit = find_chart(pixels, ChartLayout(magnification=magnification))
    except ChartNotFoundError as exc:
        return f"<p class='note'>{html.escape(str(exc))}</p>"
    p = fit.pose
    note = (f"<p class='note'>Chart finder: offset ({p.offset_rc[0]:+.2f}, "
            f"{p.offset_rc[1]:+.2f}) px, scale {p.scale:.4f}, rotation {p.rotation_deg:+.2f} "
            f"deg; implied magnification {fit.implied_magnification:.3g} (configured "
            f"{fit.configured_magnification:.3g}); {len(fit.found)} elements found, "
            f"{len(fit.rejected)} rejected.")
    if fit.warnings:
        note += " Warning: " + html.escape("; ".join(fit.warnings)) + "."
    return note + "</p>" + chart_html(pixels, fit)


def chart_html(pixels: npt.NDArray[Any], fit: ChartFit) -> str:
    """The frame (area-reduced) and a full-resolution zoom on the chart, with every placed set
    drawn as SVG: found green with its ROI yellow, rejected red dashed. Fast: no plotting."""
    from benchlab.report.html import (
        annotated_image,
        display_8bit,
        downsample,
        enlarge,
        esc,
        png_data_uri,
    )

    img = np.asarray(pixels)
    if img.ndim == 3:
        img = img.mean(axis=0)
    vmax = float(np.percentile(img, 99.9)) or 1.0
    grey = display_8bit(img, vmax)

    def shapes(scale: float, r0: float, c0: float, labels: bool) -> str:
        out = []
        for el in fit.elements:
            pts = " ".join(f"{(c - c0) * scale:.1f},{(r - r0) * scale:.1f}"
                           for r, c in el.posed.corners())
            if el.found:
                colour = "orange" if el.unmeasurable else "lime"
                out.append(f"<polygon points='{pts}' fill='none' stroke='{colour}' "
                           "stroke-width='1'/>")
                rr0, cc0, rr1, cc1 = el.measurement_roi
                out.append(f"<rect x='{(cc0 - c0) * scale:.1f}' y='{(rr0 - r0) * scale:.1f}' "
                           f"width='{(cc1 - cc0) * scale:.1f}' "
                           f"height='{(rr1 - rr0) * scale:.1f}' fill='none' stroke='yellow' "
                           "stroke-width='0.8'/>")
                if labels and 5 * el.posed.bar_width_px * scale >= 2 * LABEL_MIN_SET_PX:
                    r, c = el.posed.centre_rc
                    y = (r - r0 - 2.9 * el.posed.bar_width_px) * scale
                    out.append(f"<text x='{(c - c0) * scale:.1f}' y='{y:.1f}' fill='lime' "
                               f"font-size='11' text-anchor='middle' class='roi-label'>"
                               f"{esc(el.label)}</text>")
            else:
                out.append(f"<polygon points='{pts}' fill='none' stroke='red' "
                           "stroke-width='1' stroke-dasharray='3 2'/>")
        return "".join(out)

    small, k = downsample(grey, 560)
    parts = [annotated_image(png_data_uri(small), small.shape[1], small.shape[0],
                             shapes(k, 0.0, 0.0, False), "frame with the found chart")]
    rows = [r for el in fit.elements for r, _ in el.posed.corners()]
    cols = [c for el in fit.elements for _, c in el.posed.corners()]
    r0, r1 = max(int(min(rows)) - 20, 0), min(int(max(rows)) + 21, img.shape[0])
    c0, c1 = max(int(min(cols)) - 20, 0), min(int(max(cols)) + 21, img.shape[1])
    if r1 > r0 and c1 > c0:
        z = max(1, min(4, 640 // max(c1 - c0, 1)))
        zoom = enlarge(grey[r0:r1, c0:c1], z)
        parts.append(annotated_image(png_data_uri(zoom), zoom.shape[1], zoom.shape[0],
                                     shapes(z, r0, c0, True), "zoom on the chart"))
    return ("".join(parts) + "<p class='note'>Found sets green with their measurement ROIs "
            "yellow (orange: found but not measurable), rejected sets red (dashed); the zoom "
            "shows every pixel.</p>")
