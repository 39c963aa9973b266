"""The characterisation part of the HTML report: photon transfer, linearity deviation and dark
signal plots per gain and bit depth, the figures beside the simulator's truth, the warnings and
the response calibration written."""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from benchlab.report.html import caption, figure_img  # noqa: E402

Rows = Sequence[Mapping[str, Any]]


def _by_config(rows: Rows) -> dict[tuple[float, int], list[Mapping[str, Any]]]:
    out: dict[tuple[float, int], list[Mapping[str, Any]]] = {}
    for r in rows:
        out.setdefault((float(r["gain"]), int(r["bits"])), []).append(r)
    return out


def _label(key: tuple[float, int]) -> str:
    return f"gain {key[0]:g}, {key[1]}-bit"


def photon_transfer_figure(curve: Rows, results: Rows) -> str:
    """Signal variance against signal (log-log), points in the K fit filled, the fitted line."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    k_of = {(float(r["gain"]), int(r["bits"])): r.get("system_gain_dn_per_e") for r in results}
    for key, pts in _by_config(curve).items():
        sig = [max(float(p["signal_dn"]), 1e-3) for p in pts]
        var = [max(float(p["signal_variance_dn2"]), 1e-4) for p in pts]
        line = ax.loglog(sig, var, "o", mfc="none", ms=4, label=_label(key))[0]
        fit = [(s, v) for s, v, p in zip(sig, var, pts, strict=True) if p["in_k_fit"]]
        if fit:
            ax.loglog(*zip(*fit, strict=True), "o", color=line.get_color(), ms=4)
        k = k_of.get(key)
        if k:
            xs = [min(sig), max(sig)]
            ax.loglog(xs, [k * x for x in xs], "-", color=line.get_color(), lw=0.8)
        sat = [p for p in pts if p.get("saturation_step")]
        if sat:
            ax.axvline(float(sat[0]["signal_dn"]), color=line.get_color(), ls=":", lw=0.8)
    ax.set_xlabel("signal mu_y - mu_y.dark (DN)")
    ax.set_ylabel("temporal variance s2_y - s2_y.dark (DN^2)")
    ax.set_title("Photon transfer (filled: K fit; line: slope K; dotted: saturation)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return figure_img(fig, "photon transfer curve")


def linearity_figure(curve: Rows) -> str:
    """Relative deviation from the EMVA line (%) against signal; the 5-95 % range filled."""
    fig, ax = plt.subplots(figsize=(7, 4))
    for key, pts in _by_config(curve).items():
        top = max((float(p["signal_dn"]) for p in pts if p.get("saturation_step")),
                  default=max(float(p["signal_dn"]) for p in pts))
        xs = [100.0 * float(p["signal_dn"]) / top for p in pts]
        ys = [p["linearity_deviation_pct"] for p in pts]
        keep = [(x, y) for x, y, p in zip(xs, ys, pts, strict=True)
                if y is not None and p["in_linearity_range"]]
        if keep:
            ax.plot(*zip(*keep, strict=True), "o-", ms=3, label=_label(key))
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("signal (% of saturation)")
    ax.set_ylabel("deviation from linear fit (%)")
    ax.set_title("Linearity deviation over the EMVA range (5-95 % of saturation)")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return figure_img(fig, "linearity deviation")


def dark_signal_figure(curve: Rows) -> str:
    """Dark mean and dark temporal variance against exposure."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6))
    for key, pts in _by_config(curve).items():
        t = [float(p["exposure_ms"]) for p in pts]
        ax1.plot(t, [p["dark_mean_dn"] for p in pts], "o-", ms=3, label=_label(key))
        ax2.plot(t, [p["dark_variance_dn2"] for p in pts], "o-", ms=3, label=_label(key))
    ax1.set_xlabel("exposure (ms)")
    ax1.set_ylabel("dark mean (DN)")
    ax1.set_title("Dark signal (slope: dark current)")
    ax2.set_xlabel("exposure (ms)")
    ax2.set_ylabel("dark temporal variance (DN^2)")
    ax2.set_title("Dark noise (intercept: read noise)")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return figure_img(fig, "dark signal and dark noise")


def characterise_html(tables: Mapping[str, Rows], summary: Mapping[str, Any]) -> str:
    """The characterisation section of the report (warnings, three plots, a note)."""
    esc = html.escape
    curve = tables.get("photon_transfer", [])
    results = tables.get("characterisation", [])
    out = []
    warnings = [f"{_label((float(c['gain']), int(c['bits'])))}: {w}"
                for c in summary.get("configs", []) for w in c.get("warnings", [])]
    if warnings:
        items = "".join(f"<li>{esc(w)}</li>" for w in warnings)
        out.append(f"<h3>Warnings</h3><ul class='warnings'>{items}</ul>")
    if curve:
        out.append("<h3>Photon transfer</h3>" + caption(
            "each exposure step's temporal variance (DN^2, dark subtracted) with its signal "
            "above dark (DN), per gain and bit depth: filled points are in the fit whose slope "
            "is the system gain K (line); the dotted line marks saturation. Open points at the "
            "foot: steps with no variance above dark.") + photon_transfer_figure(curve, results))
        out.append("<h3>Linearity deviation</h3>" + caption(
            "each step's signal with the straight line fitted over 5-95 % of saturation, as the "
            "deviation in % of that line, per gain and bit depth.") + linearity_figure(curve))
        out.append("<h3>Dark signal</h3>" + caption(
            "the dark mean (left, DN) and the dark temporal variance (right, DN^2) with the "
            "exposure time: the first's slope is the dark current, the second's intercept the "
            "read noise squared.") + dark_signal_figure(curve))
    out.append("<p class='note'>EMVA 1288 linear model: K is the slope of temporal variance "
               "against signal up to 70 % of saturation; saturation is the step of peak "
               "variance; linearity error over 5-95 % of saturation; DSNU / PRNU from averaged "
               "stacks with defect pixels left out (dsnu_all_pixels_dn keeps them).</p>")
    return "".join(out)
