"""MTF-session sections of the report: measured bar contrast against the simulated optics (CTF
against CTF), Table 4.15 with its verdict and Monte Carlo bands, and the frames with their ROIs.

The bar readings are square-wave contrast (CTF). The simulated curves are sine-wave MTF, so they
are converted to CTF with Coltman's series (:func:`benchlab.analysis.mtf_to_ctf`) before they share
an axis; the two quantities are never drawn as one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from benchlab.analysis.mtf.coltman import mtf_to_ctf, signed_mtf
from benchlab.analysis.mtf.compare import SimulatedCurve
from benchlab.analysis.mtf.frequency import nyquist_lp_per_mm
from benchlab.report.html import esc, figure_img
from benchlab.report.tables import html_table
from benchlab.table_4_15 import average_of, fmt_reading, reading, verdict_rows

MC_LEVELS = (("p90", "90 %"), ("p80", "80 %"), ("p50", "50 %"), ("p20", "20 %"),
             ("p10", "10 %"))

#: Marker styles: a measured value, a reading that is not resolved, an aliased one.
MARKERS = {
    "resolved": dict(fmt="o", color="k", label="measured CTF (Eq. 2.9), 1 sigma"),
    "unresolved": dict(marker="v", color="#c0392b", ls="none", mfc="none",
                       label="not resolved (no bar contrast found)"),
    "aliased": dict(marker="x", color="#8e44ad", ls="none", label="aliased (above Nyquist)"),
}


#: Drawing order: measured points above the simulated curves.
CURVE_ZORDER = 2
POINT_ZORDER = 4

#: A curve whose last value is below this has ended where the response has vanished.
TAIL_VANISHED = 0.01
#: Coltman's series is summed until its harmonics reach a frequency where the MTF is below
#: this (the terms alternate in sign: stopping while they are large overshoots 1).
SERIES_MTF_FLOOR = 1e-6
#: ... but with no more than this many odd harmonics (a tail that never vanishes).
MAX_HARMONIC = 20001


def extended_mtf(curve: SimulatedCurve) -> tuple[Callable[[Any], Any], bool]:
    """The real OTF of a simulated curve for any f >= 0, and whether its tail was
    extrapolated.

    The exported modulus is given the sign of each lobe (:func:`~benchlab.analysis.mtf.
    coltman.signed_mtf`: past a zero the contrast is reversed). Coltman's series at f needs
    the MTF at 3f, 5f, ...; a curve that ends while the response is still clearly above 0 (a
    Zemax export cut at Nyquist) is continued with a Gaussian, ``ln MTF = c - a f^2``,
    fitted to the last third of its last lobe."""
    mtf_at, extrapolated, _ = _extended(curve)
    return mtf_at, extrapolated


def _extended(curve: SimulatedCurve) -> tuple[Callable[[Any], Any], bool, float]:
    """:func:`extended_mtf` and the frequency past which its response is below
    :data:`SERIES_MTF_FLOOR` (the curve's end when not extrapolated)."""
    f = np.asarray(curve.freqs_lp_per_mm, dtype=np.float64)
    m = signed_mtf(f, np.asarray(curve.mtf, dtype=np.float64))
    plain = (lambda x: np.interp(x, f, m, right=0.0)), False, float(f[-1])
    if abs(m[-1]) <= TAIL_VANISHED or f.size < 3:
        return plain
    zeros = np.flatnonzero(m == 0.0)
    lobe = slice(int(zeros[-1]) + 1 if zeros.size else 0, None)
    fl, ml = f[lobe], np.abs(m[lobe])
    tail = slice(2 * fl.size // 3, None)
    ok = ml[tail] > 0
    if fl.size < 3 or ok.sum() < 2:
        return plain
    slope, _ = np.polyfit(fl[tail][ok] ** 2, np.log(ml[tail][ok]), 1)
    a = max(-float(slope), 1e-12)
    c = math.log(abs(float(m[-1]))) + a * float(f[-1]) ** 2  # continuous at the last point
    sign = math.copysign(1.0, float(m[-1]))

    def mtf_at(x: Any) -> Any:
        xa = np.asarray(x, dtype=np.float64)
        return np.where(xa <= f[-1], np.interp(xa, f, m), sign * np.exp(c - a * xa**2))

    support = math.sqrt(max(c - math.log(SERIES_MTF_FLOOR), 0.0) / a)
    return mtf_at, True, max(support, float(f[-1]))


def _harmonics_needed(support_lp_per_mm: float, freqs_lp_per_mm: np.ndarray) -> int:
    """The odd harmonic past which every term of the series at the lowest frequency lies
    beyond the response (at most :data:`MAX_HARMONIC`)."""
    positive = freqs_lp_per_mm[freqs_lp_per_mm > 0]
    if positive.size == 0:
        return 1
    k = min(MAX_HARMONIC, math.ceil(support_lp_per_mm / float(positive.min())) + 2)
    return k if k % 2 else k + 1


def simulated_ctf(curve: SimulatedCurve, freqs_lp_per_mm: np.ndarray) -> np.ndarray:
    """Square-wave response (CTF) of a simulated sine-wave MTF curve, by Coltman's forward
    series, summed until the harmonics reach the end of the response (see
    :func:`extended_mtf` for the sign of each lobe and for curves that end early).

    A blurred square wave stays between its levels, so no CTF exceeds 1; the shipped curves,
    sampled every 2 lp/mm, come to at most 1.002 (the export's own rounding), held at 1. A
    contrast reversal (negative CTF) is drawn as 0."""
    grid = np.asarray(freqs_lp_per_mm, dtype=np.float64)
    mtf_at, _, support = _extended(curve)
    k = _harmonics_needed(support, grid)
    return np.clip(mtf_to_ctf(mtf_at, grid, max_harmonic=k), 0.0, 1.0)


def _state(row: dict[str, Any], orient: str) -> str:
    if row.get(f"{orient}_aliased", row.get("aliased")):
        return "aliased"
    resolved = row.get(f"{orient}_resolved")
    if resolved is None:
        resolved = row.get(f"{orient}_modulation") not in (None, 0, 0.0)
    return "resolved" if resolved else "unresolved"


def ctf_figure(tables: dict[str, list[dict[str, Any]]], curves: list[SimulatedCurve],
               fields: dict[str, set[float]] | None = None) -> str:
    """2 x 2 plot (view x orientation) of measured CTF with the simulated curves as CTF;
    ``fields`` the field points drawn solid per view (default: ``table_4_13``'s nearest in
    image height; :mod:`benchlab.report.field_choice` picks them through a measured mapping)."""
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
            for state, style in MARKERS.items():
                pts = [r for r in rows if _state(r, orient) == state]
                if not pts:
                    continue
                xs = [float(r.get(f"{orient}_image_lp_per_mm", r["image_lp_per_mm"]))
                      for r in pts]
                if state == "resolved":
                    ys = [float(r[f"{orient}_modulation"]) for r in pts]
                    es = [float(r.get(f"{orient}_uncertainty") or 0.0) for r in pts]
                    ax.errorbar(xs, ys, yerr=es, ms=5, zorder=POINT_ZORDER,
                                **style)  # type: ignore[arg-type]
                else:
                    ax.plot(xs, [0.02] * len(xs), ms=8, zorder=POINT_ZORDER,
                            **style)  # type: ignore[arg-type]
            ax.axvline(nyq, color="r", lw=0.8, ls="--", label=f"Nyquist {nyq:.2f} lp/mm",
                       zorder=CURVE_ZORDER)
            ax.set_title(f"{view} view, {orient}", fontsize=11)
            ax.set_xlabel("image frequency (lp/mm)", fontsize=10)
            ax.set_ylabel("square-wave contrast (CTF)", fontsize=10)
            ax.set_ylim(0, 1.05)
            ax.set_xlim(0, grid[-1])
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2,
                      frameon=False)
    # Fixed margins: a tight-layout pass costs more than drawing the plots.
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.17, top=0.97, hspace=0.62, wspace=0.06)
    return figure_img(fig, "measured and simulated CTF")


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
            *((k, f"{p} exceed", ".2f") for k, p in MC_LEVELS if any(k in r for r in rows)),
            ("verdict", "verdict", ""))
    return ("<ul class='headline'>" + "".join(lines) + "</ul>"
            + "<p class='note'>Monte Carlo columns: the averaged MTF of a built objective exceeds "
            "the value with the stated probability. A reading that is not resolved has no "
            "number: its row has no average and no verdict (the average is at least half the "
            "other reading).</p>"
            + html_table(shown, cols) + _bands_figure(rows))


def _bands_figure(rows: list[dict[str, Any]]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 0.9 + 0.7 * len(rows)))
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
        if avg is not None:
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
            if value is not None:
                ax.plot(value, i, mark, color=color, ms=6, label=once(orient))
            else:  # not resolved: an open marker at the left edge, never a measured 0
                ax.plot(0.01, i, mark, color=color, mfc="none", ms=7,
                        label=once(f"{orient} not resolved (no value)"))
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([f"{r['view']} {float(r['mc_freq_lp_per_mm']):g} lp/mm" for r in rows])
    ax.set_ylim(-0.6, len(rows) - 0.3)
    ax.set_xlim(0, 1)
    ax.set_xlabel("averaged MTF (Eq. 4.2)")
    ax.grid(alpha=0.3, axis="x")
    ax.legend(fontsize=8, loc="lower right")
    fig.subplots_adjust(left=0.22, right=0.97, bottom=0.6 / (0.9 + 0.7 * len(rows)), top=0.95)
    return figure_img(fig, "Monte Carlo bands with the measurement")
