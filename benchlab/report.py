"""``benchlab report SESSION``: one self-contained HTML file (PNG plots embedded as base64).

Contents: the session's identity (operator, devices, software, parameters), the results tables
of its latest results version, measured vs simulated MTF per view and orientation (like the
thesis's figs. 4.15-4.18), the radiometry fall-off (fig. 4.21), and the frames with their ROIs
or LED masks drawn. The report only reads the session: frames and results are untouched.
"""

from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from benchlab.analysis.frequency import nyquist_lp_per_mm  # noqa: E402
from benchlab.drivers.errors import BenchlabError  # noqa: E402
from benchlab.report_curves import load_curves  # noqa: E402
from benchlab.report_tables import TABLE_VIEWS, html_table  # noqa: E402
from benchlab.session import Session, read_results  # noqa: E402

_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:0.9em}
th,td{border:1px solid #bbb;padding:2px 8px;text-align:right}
th{background:#eee} h2{border-bottom:1px solid #ccc;margin-top:2em}
img{max-width:100%} pre{background:#f6f6f6;padding:0.8em;overflow:auto;font-size:0.8em}
.note{color:#555;font-size:0.9em}
"""


class ReportError(BenchlabError):
    """The session has nothing to report yet (no results)."""


def _png(fig: Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80, bbox_inches="tight")
    plt.close(fig)
    return ("<img alt='figure' src='data:image/png;base64,"
            + base64.b64encode(buf.getvalue()).decode("ascii") + "'>")


# -- MTF ----------------------------------------------------------------------------------------
def _mtf_figure(tables: dict[str, list[dict[str, Any]]], curves_path: str) -> str:
    try:
        curves = load_curves(curves_path or None)
    except (OSError, ValueError) as exc:
        curves = []
        note = f"<p class='note'>No simulated curves: {html.escape(str(exc))}</p>"
    else:
        note = ""
    fields_used: dict[str, set[float]] = {"forward": set(), "radial": set()}
    for r in tables.get("table_4_13", []):
        fields_used.setdefault(r["view"], set()).add(float(r["nearest_field_deg"]))
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), sharey=True)
    nyq = nyquist_lp_per_mm()
    for i, (view, table) in enumerate((("forward", "table_4_11"), ("radial", "table_4_12"))):
        rows = tables.get(table, [])
        for j, (orient, d) in enumerate((("sagittal", "S"), ("tangential", "T"))):
            ax = axes[i][j]
            for c in curves:
                if c.view != view or c.direction != d:
                    continue
                used = c.field_angle_deg in fields_used.get(view, set())
                ax.plot(c.freqs_lp_per_mm, c.mtf, "-" if used else ":", lw=1.5 if used else 0.8,
                        label=f"simulated {c.field_angle_deg:g} deg" + (" (nearest)" if used
                                                                        else ""))
            xs = [r["image_lp_per_mm"] for r in rows if r.get(f"{orient}_modulation") is not None]
            ys = [r[f"{orient}_modulation"] for r in rows
                  if r.get(f"{orient}_modulation") is not None]
            es = [r.get(f"{orient}_uncertainty") or 0.0 for r in rows
                  if r.get(f"{orient}_modulation") is not None]
            if xs:
                ax.errorbar(xs, ys, yerr=es, fmt="o", color="k", label="measured (bar modulation)")
            ax.axvline(nyq, color="r", lw=0.8, ls="--", label="Nyquist 96.15 lp/mm")
            ax.set_title(f"{view} view, {orient}")
            ax.set_xlabel("image frequency (lp/mm)")
            ax.set_ylabel("modulation / MTF")
            ax.set_ylim(0, 1.05)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
    fig.tight_layout()
    return note + _png(fig)


# -- radiometry ---------------------------------------------------------------------------------
def _radiometry_figure(rows: list[dict[str, Any]]) -> str:
    fig, ax = plt.subplots(figsize=(7, 4.5))
    pos = [r["position_mm"] for r in rows]
    ax.plot(pos, [r["simulated_normalised"] for r in rows], "s--", label="simulated irradiance")
    ax.plot(pos, [r["measured_normalised"] for r in rows], "o-", label="measured mean gray")
    ax.set_xlabel("LED field position (mm)")
    ax.set_ylabel("normalised to maximum")
    ax.set_ylim(0, 1.1)
    ax.set_title("Relative radiometry (fig. 4.21)")
    ax.grid(alpha=0.3)
    ax.legend()
    return _png(fig)


# -- frames -------------------------------------------------------------------------------------
def _frame_axes(pixels: np.ndarray, title: str, ax: Any) -> None:
    ax.imshow(pixels, cmap="gray", vmin=0, vmax=255 if pixels.dtype == np.uint8 else 4095,
              interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])


def _box(ax: Any, roi: list[int], color: str, label: str | None = None) -> None:
    r0, c0, r1, c1 = roi
    ax.add_patch(Rectangle((c0 - 0.5, r0 - 0.5), c1 - c0, r1 - r0, fill=False, ec=color, lw=1))
    if label:
        ax.text(c1 + 2, r0, label, color=color, fontsize=6, va="top")


def _mtf_frames(session: Session, tables: dict[str, list[dict[str, Any]]]) -> str:
    parts = []
    rows = tables.get("table_4_11", [])
    if "forward" in session.step_frames("forward"):
        px, _ = session.load_frame("forward", "forward")
        fig, axes = plt.subplots(1, 2, figsize=(12, 5))
        _frame_axes(px, "forward view with the element ROIs (S yellow, T cyan)", axes[0])
        boxes = [(r["sagittal_roi"], "y", r["element"] + "S") for r in rows] + [
            (r["tangential_roi"], "c", r["element"] + "T") for r in rows]
        for roi, color, _label in boxes:
            _box(axes[0], roi, color)
        _frame_axes(px, "zoom on the ROIs", axes[1])
        all_r = [b[0] for b in boxes]
        if all_r:
            r0 = min(b[0] for b in all_r) - 15
            r1 = max(b[2] for b in all_r) + 15
            c0 = min(b[1] for b in all_r) - 15
            c1 = max(b[3] for b in all_r) + 40
            for roi, color, label in boxes:
                _box(axes[1], roi, color, label)
            axes[1].set_xlim(c0, c1)
            axes[1].set_ylim(r1, r0)
        parts.append(_png(fig))
    radial_rows = tables.get("table_4_12", [])
    shown = 0
    frames = [(r, orient, f"radial-{r['object_lp_per_mm']:g}-{orient}")
              for r in radial_rows for orient in ("sagittal", "tangential")]
    frames = [f for f in frames if "radial" in session.step_frames(f[2])]
    if frames:
        ncols = 4
        nrows = max(1, -(-len(frames) // ncols))
        fig, axes = plt.subplots(nrows, ncols, figsize=(12, 3 * nrows))
        flat = np.atleast_1d(axes).ravel()
        for r, orient, sid in frames:
            px, meta = session.load_frame(sid, "radial")
            ax = flat[shown]
            roi = meta.get("roi") or _radial_roi(session)
            _frame_axes(px, f"{r['object_lp_per_mm']:g} lp/mm {orient}", ax)
            if roi:
                r0, c0, r1, c1 = roi
                _box(ax, roi, "y")
                ax.set_xlim(c0 - 60, c1 + 60)
                ax.set_ylim(r1 + 60, r0 - 60)
            shown += 1
        for ax in flat[shown:]:
            ax.axis("off")
        fig.suptitle("radial frames around the common ROI (yellow)")
        parts.append(_png(fig))
    return "".join(parts)


def _radial_roi(session: Session) -> list[int] | None:
    roi = session.params.get("radial", {}).get("roi")
    return list(roi) if roi else [249, 999, 290, 1050]


def _radiometry_frames(session: Session, rows: list[dict[str, Any]]) -> str:
    from benchlab.protocols.radiometry import mask_of, position_step_id

    if not rows:
        return ""
    fig, axes = plt.subplots(1, len(rows), figsize=(3 * len(rows), 3.2))
    thr = float(session.params.get("analysis", {}).get("mask_threshold_fraction", 0.5))
    for ax, r in zip(np.atleast_1d(axes), rows, strict=True):
        sid = position_step_id(r["position_mm"])
        mask_px, _ = session.load_frame(sid, "mask")
        meas, _ = session.load_frame(sid, "measurement")
        mask = mask_of(mask_px, thr)
        _frame_axes(meas, f"{r['position_mm']:g} mm (mask outlined)", ax)
        ax.contour(mask.astype(float), levels=[0.5], colors="y", linewidths=0.8)
        rows_idx, cols_idx = np.nonzero(mask)
        if rows_idx.size:
            ax.set_xlim(cols_idx.min() - 30, cols_idx.max() + 30)
            ax.set_ylim(rows_idx.max() + 30, rows_idx.min() - 30)
    fig.tight_layout()
    return _png(fig)


# -- the page -----------------------------------------------------------------------------------
def render_report(session_path: str | Path) -> str:
    """The report of a session as one HTML string."""
    session = Session.open(Path(session_path))
    results = session.latest_results()
    if results is None:
        raise ReportError(f"{session.path}: no results yet (finish the run or resume it, or "
                          "run benchlab analyze on it)")
    tables, doc = read_results(results)
    meta = session.meta
    esc = html.escape
    out = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>benchlab report "
           f"{esc(session.path.name)}</title><style>{_CSS}</style></head><body>",
           f"<h1>benchlab - {esc(meta['procedure'])} session {esc(session.path.name)}</h1>"]
    ident = [("operator", meta.get("operator") or "-"), ("status", meta.get("status")),
             ("started", meta.get("started_at")), ("finished", meta.get("finished_at") or "-"),
             ("software", meta.get("software_version")),
             ("results", f"{results.name} (estimator {doc.get('estimator')}, "
                         f"{doc.get('created_at')})")]
    for kind, dev in (meta.get("devices") or {}).items():
        if isinstance(dev, dict):
            ident.append((kind, ", ".join(f"{k} {v}" for k, v in dev.items())))
        else:
            ident.append((kind, str(dev)))
    out.append("<table>" + "".join(f"<tr><th>{esc(str(k))}</th><td style='text-align:left'>"
                                   f"{esc(str(v))}</td></tr>" for k, v in ident) + "</table>")
    out.append("<h2>Results</h2>")
    summ = doc.get("summary") or {}
    notes = [f"{k.replace('_', ' ')}: {v}" for k, v in summ.items()
             if k in ("forward_estimator", "radial_estimator", "image_centre_rc",
                      "image_centre_method", "chart_offset_px") and v is not None]
    if notes:
        out.append("<p class='note'>" + esc("; ".join(notes)) + ". Coordinates are 0-based "
                   "(row, col); the thesis quotes 1-based ones.</p>")
    for name, rows in tables.items():
        view = TABLE_VIEWS.get(name)
        if view is not None and rows:
            out.append(f"<h3>{esc(view.title)}</h3>{html_table(rows, view.columns)}")
    if meta["procedure"] == "mtf":
        out.append("<h2>Measured vs simulated MTF (figs. 4.15-4.18)</h2>"
                   "<p class='note'>Points: measured bar modulation (Eq. 2.9, square-wave "
                   "response) with 1-sigma uncertainty; lines: simulated sine-wave MTF of the "
                   "Table 4.14 field points, solid where a test's nearest field point. Points "
                   "beyond Nyquist are aliased.</p>")
        curves_file = str(session.params.get("analysis", {}).get("simulated_mtf_file", ""))
        out.append(_mtf_figure(tables, curves_file))
        out.append("<h2>Frames with ROIs</h2>" + _mtf_frames(session, tables))
    else:
        rows = tables.get("table_4_16", [])
        out.append("<h2>Radiometric fall-off (fig. 4.21)</h2>" + _radiometry_figure(rows))
        out.append("<h2>Measurement frames with LED masks</h2>"
                   + _radiometry_frames(session, rows))
    out.append("<h2>Parameters</h2><pre>" + esc(json.dumps(meta.get("params"), indent=2))
               + "</pre></body></html>")
    return "".join(out)


def write_report(session_path: str | Path, out: str | Path | None = None) -> Path:
    """Write the HTML report (default ``SESSION/report.html``); returns its path."""
    from benchlab.catalog import record_session
    from benchlab.storage import atomic_write_text

    target = Path(out) if out is not None else Path(session_path) / "report.html"
    written = atomic_write_text(target, render_report(session_path))
    record_session(Path(session_path))
    return written
