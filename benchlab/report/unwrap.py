"""The report's view-synthesis section: unwrapped radial frames and the viewpoint plot.

Shown when the results version has an ``unwrap`` table (``benchlab unwrap SESSION``). Each
unwrapped frame is drawn with its invalid pixels (outside the raw frame or the table) in a
flat colour, so nothing looks measured that was not.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

#: Widest unwrapped image drawn in the report, px (the full circle is ~2500 px at 20 px/mm).
THUMB_WIDTH_PX = 1000
_INVALID_RGB = (0.55, 0.25, 0.25)


def _png(fig: Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return (f"<img class='plot' alt='figure' src='data:image/png;base64,"
            f"{base64.b64encode(buf.getvalue()).decode()}'>")


def _view_png(path: Path, title: str) -> str:
    from benchlab.radial_views import load_view_tiff

    view, valid, meta = load_view_tiff(path)
    step = max(1, int(np.ceil(view.shape[1] / THUMB_WIDTH_PX)))
    v = np.asarray(view[::step, ::step], dtype=np.float64)
    ok = valid[::step, ::step]
    top = float(np.percentile(v[ok], 99.5)) if ok.any() else 1.0
    grey = np.clip(v / max(top, 1e-9), 0.0, 1.0)
    rgb = np.repeat(grey[..., None], 3, axis=2)
    rgb[~ok] = _INVALID_RGB
    px_per_mm = float(meta["px_per_mm"]) / step
    h, w = grey.shape
    fig = Figure(figsize=(min(12.0, w / 80 + 1), h / 80 + 0.9))
    ax = fig.add_subplot()
    arc0 = float(meta.get("arc_start_mm", 0.0))
    z_top = float(meta.get("z_top_mm", 0.0))
    ax.imshow(rgb, extent=(arc0, arc0 + w / px_per_mm, z_top - h / px_per_mm, z_top),
              interpolation="nearest")
    ax.set_xlabel("arc length around the axis, mm")
    ax.set_ylabel("axial z, mm")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return _png(fig)


def _viewpoint_png(rows: list[dict[str, Any]], operational: tuple[float, float] | None) -> str:
    rho = np.array([r["image_radius_mm"] for r in rows])
    vp = np.array([r["viewpoint_z_mm"] for r in rows])
    spread = np.array([r["spread_um"] for r in rows])
    fig = Figure(figsize=(7.5, 3.4))
    ax = fig.add_subplot()
    ax.plot(rho, vp, "o-", ms=3, color="tab:blue", label="viewpoint z (back-projected)")
    ax.set_xlabel("image radius, mm")
    ax.set_ylabel("viewpoint z on the axis, mm", color="tab:blue")
    if operational is not None:
        ax.axvspan(*operational, color="0.9", zorder=0, label="spread <= 20 um")
    ax2 = ax.twinx()
    ax2.plot(rho, spread, "-", color="tab:red", label="spread from effective, um")
    ax2.set_ylabel("spread, um", color="tab:red")
    ax.set_title("Viewpoint per image radius (thesis fig. 5.5)", fontsize=9)
    ax.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    return _png(fig)


def render_unwrap_section(results_dir: Path, tables: dict[str, list[dict[str, Any]]],
                          summary: dict[str, Any]) -> str:
    """HTML fragment for a results version (empty when it holds no unwrapped views)."""
    rows = tables.get("unwrap") or []
    if not rows:
        return ""
    esc = html.escape
    info = summary.get("unwrap") or {}
    out = ["<p class='note'>" + esc(
               f"Estimated orthographic view at {info.get('object_radius_mm')} mm from the axis"
               f"{' (EXTRAPOLATED beyond the table)' if info.get('extrapolated') else ''}, "
               f"{info.get('px_per_mm')} px/mm, centre {info.get('centre_rc')} "
               f"({info.get('centre_method')}), table {str(info.get('table_sha256'))[:16]}. "
               "Red-brown: outside the raw frame or the table (marked, not invented).") + "</p>"]
    from benchlab.drivers.errors import BenchlabError

    for row in rows:
        path = results_dir / str(row["file"])
        title = (f"{row['step_id']} {row['frame']}: {100 * float(row['valid_fraction']):.1f} % "
                 "valid")
        try:
            out.append(_view_png(path, title))
        except (BenchlabError, OSError, KeyError) as exc:
            out.append(f"<p class='note'>{esc(title)}: cannot draw ({esc(str(exc))})</p>")
    vp_rows = tables.get("viewpoint") or []
    if vp_rows:
        in_band = [r["image_radius_mm"] for r in vp_rows if r["spread_um"] <= 20.0]
        band = (min(in_band), max(in_band)) if in_band else None
        out.append("<h3>Effective viewpoint of the ray-trace table</h3>"
                   + _viewpoint_png(vp_rows, band))
    return "".join(out)
