"""The report's slanted-edge section: edge MTF against the simulated MTF (sine against sine), the
bar readings against what the edges predict they read (the set imaged through the edges'
transfer and read by the same estimator) and, for reference, the bar readings converted through
Coltman, with agreement or disagreement flagged.

Reads the ``table_sfr_edges``, ``table_sfr_curves`` and ``table_sfr_vs_bars`` tables the MTF
procedure writes (:mod:`benchlab.protocols.mtf.edges`); sessions analysed before they existed get
a note instead.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from benchlab.analysis.mtf.frequency import nyquist_lp_per_mm  # noqa: E402
from benchlab.report.html import caption, figure_img  # noqa: E402
from benchlab.report.tables import Column, html_table  # noqa: E402

Rows = Sequence[Mapping[str, Any]]

EDGE_COLUMNS: tuple[Column, ...] = (
    ("edge", "edge", ""), ("orientation", "orientation", ""),
    ("image_height_mm", "height mm", ".3f"), ("nearest_field_deg", "field deg", "g"),
    ("edge_angle_deg", "angle deg", ".2f"), ("mtf50_lp_per_mm", "MTF50 lp/mm", ".1f"),
    ("mtf50_sigma_lp_per_mm", "+-", ".1f"), ("mtf_nyquist", "MTF(Nyq)", ".3f"),
    ("contrast", "contrast", ".3f"), ("estimator", "estimator", ""), ("status", "status", ""),
    ("warnings", "warnings", ""),
)
CHECK_COLUMNS: tuple[Column, ...] = (
    ("element", "set", ""), ("orientation", "orientation", ""),
    ("image_lp_per_mm", "lp/mm", ".2f"), ("bar_modulation", "bar mod.", ".3f"),
    ("bar_modulation_predicted", "predicted", ".3f"),
    ("object_modulation", "chart mod.", ".3f"), ("ctf", "CTF", ".3f"),
    ("bar_mtf", "bars -> MTF", ".3f"), ("bar_mtf_coltman", "(Nyquist cutoff)", ".3f"),
    ("coltman_method", "Nyq. method", ""),
    ("edge", "edge", ""), ("edge_mtf", "edge MTF", ".3f"), ("edge_mtf_sigma", "+-", ".3f"),
    ("simulated_mtf", "simulated", ".3f"), ("verdict", "verdict", ""),
)
_COLOURS = {"E0": "tab:blue", "E1": "tab:green", "E2": "tab:purple"}


def _agrees(row: Mapping[str, Any]) -> bool:
    """A row whose verdict agrees (:func:`benchlab.protocols.mtf.edges.agrees`)."""
    from benchlab.protocols.mtf.edges import agrees

    return agrees(str(row.get("verdict", "")))


def _figure(tables: Mapping[str, Rows], simulated: Sequence[Any]) -> Figure:
    curves = tables.get("table_sfr_curves", [])
    checks = tables.get("table_sfr_vs_bars", [])
    nyq = nyquist_lp_per_mm()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
    for ax, orientation, d in ((axes[0], "sagittal", "S"), (axes[1], "tangential", "T")):
        for c in simulated:
            if c.view == "forward" and c.direction == d:
                ax.plot(c.freqs_lp_per_mm, c.mtf, ":", lw=0.9, color="0.45")
        ax.plot([], [], ":", color="0.45", label="simulated MTF (field points)")
        edges = sorted({r["edge"] for r in curves if r["orientation"] == orientation})
        for label in edges:
            pts = [r for r in curves if r["edge"] == label]
            f = [r["freq_lp_per_mm"] for r in pts]
            m = [r["mtf"] for r in pts]
            colour = _COLOURS.get(label[:2], None)
            ax.plot(f, m, "-", lw=1.3, color=colour, label=f"edge {label}")
            if all(r.get("mtf_sigma") is not None for r in pts):
                lo = [r["mtf"] - r["mtf_sigma"] for r in pts]
                hi = [r["mtf"] + r["mtf_sigma"] for r in pts]
                ax.fill_between(f, lo, hi, color=colour, alpha=0.15, lw=0)
        pts = [r for r in checks if r["orientation"] == orientation]
        if pts:
            ok = [r for r in pts if _agrees(r)]
            bad = [r for r in pts if not _agrees(r)]
            for group, marker, name in ((ok, "o", "bars via Coltman (row agrees)"),
                                        (bad, "X", "bars via Coltman (row DISAGREES)")):
                if group:
                    ax.plot([r["image_lp_per_mm"] for r in group],
                            [r.get("bar_mtf", r["bar_mtf_coltman"]) for r in group], marker,
                            ls="none",
                            color="k" if marker == "o" else "r", label=name)
        ax.axvline(nyq, color="r", lw=0.8, ls="--", label="Nyquist 96.15 lp/mm")
        ax.set_xlim(0, 2 * nyq)
        ax.set_ylim(0, 1.05)
        ax.set_title(f"forward view, {orientation}: sine-wave MTF")
        ax.set_xlabel("image frequency (lp/mm)")
        ax.set_ylabel("MTF (sine-wave, 0-1)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _nyquist_cutoff_note(checks: Rows) -> str:
    """How far the reference conversion (Nyquist as the cutoff) is off the edge MTF in this
    session: the largest |bar_mtf_coltman - edge_mtf| of the rows in the table."""
    gaps = [abs(float(r["bar_mtf_coltman"]) - float(r["edge_mtf"])) for r in checks
            if r.get("bar_mtf_coltman") is not None and r.get("edge_mtf") is not None]
    if not gaps:
        return "no row here to compare it on"
    return f"it is up to {max(gaps):.3f} off the edge MTF in the table below"


def render_sfr_section(tables: Mapping[str, Rows], simulated: Sequence[Any]) -> str:
    """The HTML body of the section (note, figure, the two tables)."""
    out: list[str] = []
    edges = tables.get("table_sfr_edges")
    if edges is None:
        out.append("<p class='note'>No slanted-edge tables in these results (analysed before "
                   "edge analysis existed): run <code>benchlab analyze SESSION</code> to add "
                   "them.</p>")
        return "".join(out)
    checks = tables.get("table_sfr_vs_bars", [])
    n_bad = sum(1 for r in checks if not _agrees(r))
    n_pred = sum(1 for r in checks if r.get("bar_modulation_predicted") is not None)
    clean = sum(1 for r in edges if r["status"] == "ok")
    summary = (f"{clean} of {len(edges)} edges clean; "
               + (f"{len(checks)} bar readings compared, "
                  + ("all agree" if n_bad == 0 else f"{n_bad} DISAGREE")
                  if checks else "no bar reading to compare"))
    out.append(
        "<p class='note'>Lines: MTF measured from each clean slanted edge (shaded: 1 sigma, the "
        "pixel noise propagated) and the simulated MTF at the field points (dotted) - both "
        "sine-wave responses. "
        "Points: the bar modulations below Nyquist divided by the chart's own contrast (from "
        "the edge plateaus) and converted to sine-wave MTF through Coltman's series, the "
        "harmonics' MTF (3f, 5f, ...) taken from the edges (with Nyquist as the cutoff instead, "
        f"as the table's reference column, {html.escape(_nyquist_cutoff_note(checks))}). "
        "Coltman assumes an endless square wave; a USAF set has three bars. So where the chart "
        "reading read a set, the table's 'predicted' column is what it should read if the "
        "optics were exactly what the edges say - the set imaged through the edges' transfer at "
        "its image height, at the chart's contrast, and read by the same estimator at the same "
        "ROI - and the bars are judged on their modulation against it; elsewhere on the "
        "Coltman-converted MTF against the edge MTF (each verdict names its basis; "
        f"{n_pred} of {len(checks)} rows predicted). A red cross marks a row that disagrees "
        "(bars vs edge, or the edge vs the simulation) by more than 0.05. "
        f"{html.escape(summary)}.</p>"
    )
    out.append(caption("the MTF of each slanted edge with the simulated lens MTF at the field "
                       "points and with the bars converted to sine-wave MTF, per view and "
                       "orientation.")
               + figure_img(_figure(tables, simulated), "slanted-edge MTF against simulated MTF "
                          "and Coltman-converted bars"))
    out.append("<h3>Edges</h3>" + html_table(edges, EDGE_COLUMNS))
    if checks:
        out.append("<h3>Bars vs edge (predicted reading; Coltman) vs simulated</h3>"
                   + html_table(checks, CHECK_COLUMNS))
    return "".join(out)
