"""MTF-session sections of the report: measured bar contrast against the simulated optics (CTF
against CTF), Table 4.15 with its verdict and Monte Carlo bands, and the frames with their ROIs.

The bar readings are square-wave contrast (CTF). The simulated curves are sine-wave MTF, so they
are converted to CTF with Coltman's series (:func:`benchlab.analysis.mtf_to_ctf`) before they share
an axis; the two quantities are never drawn as one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchlab.analysis.mtf.compare import SimulatedCurve
from benchlab.analysis.mtf.frequency import nyquist_lp_per_mm
from benchlab.analysis.mtf.simulated_ctf import extended_mtf, simulated_ctf
from benchlab.report.html import caption, esc, figure_img
from benchlab.report.tables import html_table
from benchlab.table_4_15 import average_of, fmt_reading, reading, verdict_rows

MC_LEVELS = (("p90", "90 %"), ("p80", "80 %"), ("p50", "50 %"), ("p20", "20 %"),
             ("p10", "10 %"))

#: Marker styles: the lens's share of a reading (measured / target contrast), a reading whose
#: target contrast is unknown, a reading that is not resolved, an aliased one.
MARKERS = {
    "share": dict(fmt="o", color="k",
                  label="lens share (measured / target), 1 sigma"),
    "resolved": dict(fmt="s", color="#555", mfc="none",
                     label="measured CTF, target unknown, 1 sigma"),
    "unresolved": dict(marker="v", color="#c0392b", ls="none", mfc="none",
                       label="not resolved (no bar contrast found)"),
    "aliased": dict(marker="x", color="#8e44ad", ls="none", label="aliased (above Nyquist)"),
}
#: The raw readings beside their shares: small and grey, so the correction shows.
RAW_STYLE = dict(marker=".", color="#999", ls="none", ms=4,
                 label="measured CTF (lens and target)")


#: Drawing order: measured points above the simulated curves.
CURVE_ZORDER = 2
POINT_ZORDER = 4


def _state(row: dict[str, Any], orient: str) -> str:
    if row.get(f"{orient}_aliased", row.get("aliased")):
        return "aliased"
    resolved = row.get(f"{orient}_resolved")
    if resolved is None:
        resolved = row.get(f"{orient}_modulation") not in (None, 0, 0.0)
    return "resolved" if resolved else "unresolved"


def ctf_figure(tables: dict[str, list[dict[str, Any]]], curves: list[SimulatedCurve],
               fields: dict[str, set[float]] | None = None) -> str:
    """2 x 2 plot (view x orientation): the lens's share of each bar reading (measured /
    target contrast) against the simulated lens's curves as CTF; a reading whose target
    contrast is unknown is drawn as measured, with its own marker. ``fields``: the field points
    drawn solid per view (default: ``table_4_13``'s nearest in image height;
    :mod:`benchlab.report.field_choice` picks them through a measured mapping)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fields_used: dict[str, set[float]] = {"forward": set(), "radial": set()}
    for r in tables.get("table_4_13", []):
        fields_used.setdefault(r["view"], set()).add(float(r["nearest_field_deg"]))
    if fields is not None:
        fields_used = fields
    # Each panel's legend sits under its axes: never on a measured point.
    fig, axes = plt.subplots(2, 2, figsize=(11, 11), sharey=True)
    nyq = nyquist_lp_per_mm()
    grid = np.linspace(1.0, 1.25 * nyq, 160)
    shares = any(r.get(f"{o}_lens_share") is not None for t in ("table_4_11", "table_4_12")
                 for r in tables.get(t, []) for o in ("sagittal", "tangential"))
    for i, (view, table) in enumerate((("forward", "table_4_11"), ("radial", "table_4_12"))):
        rows = tables.get(table, [])
        for j, (orient, d) in enumerate((("sagittal", "S"), ("tangential", "T"))):
            ax = axes[i][j]
            for c in curves:
                if c.view != view or c.direction != d:
                    continue
                used = c.field_angle_deg in fields_used.get(view, set())
                _, extrapolated = extended_mtf(c)
                ax.plot(grid, simulated_ctf(c, grid), "-" if used else ":",
                        lw=1.5 if used else 0.8, zorder=CURVE_ZORDER,
                        label=f"simulated CTF {c.field_angle_deg:g} deg"
                        + (" (nearest)" if used else "")
                        + (", MTF tail extrapolated" if extrapolated else ""))
            _draw_points(ax, rows, orient)
            ax.axvline(nyq, color="r", lw=0.8, ls="--", label=f"Nyquist {nyq:.2f} lp/mm",
                       zorder=CURVE_ZORDER)
            ax.set_title(f"{view} view, {orient}", fontsize=11)
            ax.set_xlabel("image frequency (lp/mm)", fontsize=10)
            ax.set_ylabel("lens share of the bar contrast (CTF)" if shares else
                          "square-wave contrast (CTF)", fontsize=10)
            ax.set_ylim(0, 1.05)
            ax.set_xlim(0, grid[-1])
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2,
                      frameon=False)
    # Fixed margins: a tight-layout pass costs more than drawing the plots.
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.17, top=0.97, hspace=0.62, wspace=0.06)
    return figure_img(fig, "lens share of the bar contrast and the simulated lens CTF")


def _point_state(row: dict[str, Any], orient: str) -> str:
    state = _state(row, orient)
    if state == "resolved" and row.get(f"{orient}_lens_share") is not None:
        return "share"
    return state


def _draw_points(ax: Any, rows: list[dict[str, Any]], orient: str) -> None:
    """One panel's readings: the lens's shares with their error bars, the raw readings they
    come from, and the readings with no number (at the foot of the axis)."""
    for state, style in MARKERS.items():
        pts = [r for r in rows if _point_state(r, orient) == state]
        if not pts:
            continue
        xs = [float(r.get(f"{orient}_image_lp_per_mm", r["image_lp_per_mm"])) for r in pts]
        if state in ("share", "resolved"):
            key = "lens_share" if state == "share" else "modulation"
            ukey = "lens_share_uncertainty" if state == "share" else "uncertainty"
            ys = [float(r[f"{orient}_{key}"]) for r in pts]
            es = [float(r.get(f"{orient}_{ukey}") or 0.0) for r in pts]
            if state == "share":
                ax.plot(xs, [float(r[f"{orient}_modulation"]) for r in pts],
                        zorder=POINT_ZORDER, **RAW_STYLE)  # type: ignore[arg-type]
            ax.errorbar(xs, ys, yerr=es, ms=5, zorder=POINT_ZORDER + 1,
                        **style)  # type: ignore[arg-type]
        else:
            ax.plot(xs, [0.02] * len(xs), ms=8, zorder=POINT_ZORDER,
                    **style)  # type: ignore[arg-type]


def verdict_section(rows: list[dict[str, Any]], partial: str = "") -> str:
    """Table 4.15 as an engineer reads it: a headline verdict, every threshold column the
    verdict may cite, the frequency mismatch stated, and the Monte Carlo bands plotted.
    ``partial`` (e.g. ``" [PARTIAL]"``) marks results of an unfinished run."""
    if not rows:
        return ("<p class='note'>No Monte Carlo comparison (no measurement near its "
                "frequencies).</p>")
    lines = []
    shown = verdict_rows(rows)
    for r, v in zip(rows, shown, strict=True):
        mc_f, t_f = float(r["mc_freq_lp_per_mm"]), float(r["measured_freq_lp_per_mm"])
        s_f = float(r.get("sagittal_freq_lp_per_mm", t_f))  # older results: one frequency
        apart = [(name, f) for name, f in (("sagittal", s_f), ("tangential", t_f))
                 if abs(f - mc_f) / mc_f > 0.02]
        note = ""
        if apart:
            worst = max(abs(f - mc_f) / mc_f for _, f in apart)
            if s_f == t_f:
                at, share = f"at {t_f:.1f} lp/mm", f"{100 * worst:.0f} % apart"
            else:
                at = " and ".join(f"{name} at {f:.1f} lp/mm" for name, f in apart)
                share = f"up to {100 * worst:.0f} % apart"
            note = (f"; measured {at} against the prediction at {mc_f:g} lp/mm ({share}: "
                    "compare with care)")
        avg, _ = average_of(r)
        avg_text = f"averaged {avg:.3f}" if avg is not None else "no average"
        lens = _share_of(r)
        if lens is not None:
            avg_text = (f"lens share averaged {lens[0]:.3f} +- {lens[1]:.3f} (S "
                        f"{float(r['sagittal_lens_share']):.3f}, T "
                        f"{float(r['tangential_lens_share']):.3f}); measured {avg_text}")
        lines.append(f"<li class='verdict'><b>{esc(str(r['view']))} view, {mc_f:g} lp/mm</b>: "
                     f"{avg_text} (S {fmt_reading(reading(r, 'sagittal'))}, T "
                     f"{fmt_reading(reading(r, 'tangential'))}) - "
                     f"{esc(str(v['verdict']))}"
                     f"{esc(note)}{esc(partial)}</li>")
    cols = (("view", "view", ""), ("mc_freq_lp_per_mm", "MC lp/mm", "g"),
            ("sagittal_freq_lp_per_mm", "S lp/mm", ".2f"),
            ("measured_freq_lp_per_mm", "T lp/mm", ".2f"),
            ("sagittal_modulation", "S", ".3f"), ("tangential_modulation", "T", ".3f"),
            ("averaged_modulation", "avg", ".3f"),
            *(((k, h, ".3f") for k, h in (("sagittal_lens_share", "S share"),
                                          ("tangential_lens_share", "T share"),
                                          ("averaged_lens_share", "avg share"),
                                          ("averaged_lens_share_uncertainty", "+-")))
              if any("averaged_lens_share" in r for r in rows) else ()),
            *((k, f"{p} exceed", ".2f") for k, p in MC_LEVELS if any(k in r for r in rows)),
            ("verdict", "verdict", ""))
    return ("<ul class='headline'>" + "".join(lines) + "</ul>"
            + f"<p class='note'>{esc(verdict_basis_note(rows))}</p>"
            + "<p class='note'>Monte Carlo columns: the averaged MTF of a built objective exceeds "
            "the value with the stated probability. A reading that is not resolved has no "
            "number: its row has no average and no verdict (the average is at least half the "
            "other reading).</p>"
            + html_table(shown, cols)
            + caption("each row's averaged lens share (black, 1 sigma; the verdict's basis), "
                      "its sagittal and tangential halves and the measured average (grey, lens "
                      "and target) with the Monte Carlo thresholds (grey band, labelled by the "
                      "probability that a built objective exceeds them).")
            + _bands_figure(rows))


def _share_of(row: dict[str, Any]) -> tuple[float, float] | None:
    """A Table 4.15 row's averaged lens share and its 1 sigma, when its verdict is on it."""
    v = row.get("averaged_lens_share")
    if not isinstance(v, int | float) or isinstance(v, bool) or average_of(row)[0] is None:
        return None  # no share, or a half not resolved (no average at all)
    return float(v), float(row.get("averaged_lens_share_uncertainty") or 0.0)


def verdict_basis_note(rows: list[dict[str, Any]]) -> str:
    """What Table 4.15's verdicts place among the Monte Carlo thresholds, in words."""
    on_share = [r for r in rows if _share_of(r) is not None]
    if on_share and len(on_share) == len(rows):
        return ("Verdicts use the lens's share: the averaged (Eq. 4.2) measured contrast "
                "divided by the target's own contrast, the lens alone, as the Monte Carlo "
                "thresholds are (the 'avg' column is as measured, lens and target together).")
    if on_share:
        return ("Verdicts use the lens's share (measured / target contrast) where the "
                "target's contrast is known, else the measured contrast (see each row's "
                "'verdict on').")
    return ("Verdicts use the measured contrast: the target's own contrast is unknown (results "
            "without it, or not measured), so the lens and the target are judged together and "
            "the lens looks worse than it is by the target's contrast.")


#: Height (inches) of the band under the Monte Carlo plot that holds its legend.
LEGEND_IN = 0.8


def _bands_figure(rows: list[dict[str, Any]]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # The legend sits under the axes (its own band of LEGEND_IN inches): never on a marker.
    height_in = 0.9 + 0.7 * len(rows) + LEGEND_IN
    fig, ax = plt.subplots(figsize=(7, height_in))
    right = 1.0
    seen: set[str] = set()

    def once(label: str) -> str | None:  # one legend entry per kind of marker
        if label in seen:
            return None
        seen.add(label)
        return label

    for i, r in enumerate(rows):
        levels = [(p, float(r[k])) for k, p in MC_LEVELS if r.get(k) is not None]
        vals = [v for _, v in levels]
        if vals:
            ax.plot([min(vals), max(vals)], [i, i], color="#bbb", lw=8, solid_capstyle="butt")
            for n, (p, v) in enumerate(levels):  # labels alternate above / below: no overlap
                ax.plot([v, v], [i - 0.25, i + 0.25], color="#555", lw=1)
                ax.text(v, i + (0.3 if n % 2 == 0 else -0.45), p, ha="center", fontsize=8)
        avg, missing = average_of(r)
        share = _share_of(r)
        if share is not None:  # the verdict's basis, with its 1 sigma; the raw average in grey
            right = max(right, share[0] + share[1])
            ax.errorbar(share[0], i, xerr=share[1], fmt="D", color="k", ms=7,
                        label=once("lens share, averaged (verdict), 1 sigma"))
            if avg is not None:
                ax.plot(avg, i, "D", color="#999", mfc="none", ms=6,
                        label=once("measured average (lens and target)"))
        elif avg is not None:
            ax.plot(avg, i, "D", color="k", ms=7, label=once("measured average"))
        else:  # no measured average: its lower bound, open, with an arrow to the right
            halves = [reading(r, o) or 0.0 for o in ("sagittal", "tangential")]
            bound = sum(halves) / 2.0
            ax.plot(bound, i, "D", color="k", mfc="none", ms=7,
                    label=once("average at least (a reading not resolved)"))
            ax.annotate("", xy=(bound + 0.06, i), xytext=(bound, i),
                        arrowprops=dict(arrowstyle="->", color="k"))
            ax.text(0.01, i + 0.3, missing, fontsize=8, color="#c0392b")
        for orient, mark, color in (("sagittal", ">", "#1f5fbf"), ("tangential", "^", "#c0392b")):
            value = reading(r, orient)
            if value is not None and share is not None:
                value = float(r[f"{orient}_lens_share"])
                right = max(right, value)
            if value is not None:
                ax.plot(value, i, mark, color=color, ms=6, label=once(orient))
            else:  # not resolved: an open marker at the left edge, never a measured 0
                ax.plot(0.01, i, mark, color=color, mfc="none", ms=7,
                        label=once(f"{orient} not resolved (no value)"))
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([f"{r['view']} {float(r['mc_freq_lp_per_mm']):g} lp/mm" for r in rows])
    ax.set_ylim(-0.6, len(rows) - 0.3)
    ax.set_xlim(0, max(1.0, right + 0.03))
    ax.set_xlabel("averaged MTF (Eq. 4.2): lens share where the target contrast is known")
    ax.grid(alpha=0.3, axis="x")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.5 / (0.7 * len(rows) + 0.1)),
              ncol=2, frameon=False)
    fig.subplots_adjust(left=0.22, right=0.97, bottom=(0.6 + LEGEND_IN) / height_in,
                        top=1.0 - 0.2 / height_in)
    return figure_img(fig, "Monte Carlo bands with the measurement")
