"""Small, fast building blocks of the HTML report: escaped text, embedded images, inline SVG.

Frames and crops are encoded with OpenCV (milliseconds) and annotated with inline SVG, whose text
stays readable at any zoom; matplotlib is kept for the few real plots, written as SVG. Nothing
is fetched from outside the page.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Iterable, Sequence
from datetime import datetime
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.storage import printable_name


def esc(text: str, quote: bool = True) -> str:
    """``text`` escaped for HTML, and as UTF-8 text: a folder name that is not UTF-8 is shown
    with backslash-x escapes (:func:`~benchlab.storage.printable_name`), never a page that
    cannot be written."""
    return html.escape(printable_name(text), quote)


#: Resolution of the matplotlib plots (pixels per inch): labels of 9-10 pt stay legible.
PLOT_DPI = 100


def display_8bit(pixels: npt.NDArray[Any], max_code: float | None = None) -> npt.NDArray[np.uint8]:
    """Scale a frame or crop to 8 bits for display (``max_code`` default: 255 for uint8 data,
    else 4095 when every value fits 12 bits, else 65535)."""
    px = np.asarray(pixels)
    if max_code is None:
        if px.dtype == np.uint8:
            max_code = 255.0
        else:
            max_code = 4095.0 if px.size and float(px.max()) <= 4095 else 65535.0
    scaled = np.clip(px.astype(np.float64) * (255.0 / max_code), 0, 255)
    return np.rint(scaled).astype(np.uint8)


def png_data_uri(image_u8: npt.NDArray[np.uint8]) -> str:
    """A grey (2-D) or BGR (3-D) 8-bit image as a ``data:image/png;base64,...`` URI."""
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(image_u8))
    if not ok:  # pragma: no cover - OpenCV always encodes a uint8 array
        raise ValueError("PNG encoding failed")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def downsample(image_u8: npt.NDArray[np.uint8], max_width_px: int) -> tuple[
        npt.NDArray[np.uint8], float]:
    """Shrink to at most ``max_width_px`` wide with an area (anti-alias) filter: no moire.

    Returns the image and the scale factor (output px per input px, <= 1)."""
    import cv2

    h, w = image_u8.shape[:2]
    if w <= max_width_px:
        return image_u8, 1.0
    scale = max_width_px / w
    out = cv2.resize(image_u8, (max_width_px, max(1, round(h * scale))),
                     interpolation=cv2.INTER_AREA)
    return np.asarray(out, dtype=np.uint8), scale


def enlarge(image_u8: npt.NDArray[np.uint8], factor: int) -> npt.NDArray[np.uint8]:
    """Nearest-neighbour enlargement by an integer factor (pixels stay pixels)."""
    if factor <= 1:
        return image_u8
    return np.repeat(np.repeat(image_u8, factor, axis=0), factor, axis=1)


def caption(compared: str) -> str:
    """A figure's caption, placed just above it: what is compared with what (plain text,
    escaped), starting "Compared: " so that a reader (and the report's browser test) finds it."""
    return f"<p class='note caption'>Compared: {esc(compared)}</p>"


def figure_img(fig: Any, alt: str) -> str:
    """A matplotlib figure as an embedded SVG ``<img>``.

    SVG rather than PNG: no rasterisation pass (about a fifth of the report's time), and the
    labels stay text, sharp at any zoom. Text is written as text, not glyph paths, and the
    figure is an ``<img>``, so the ids of several plots never collide in one page."""
    import matplotlib
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "benchlab"}):
        fig.savefig(buf, format="svg", dpi=PLOT_DPI, metadata={"Date": None})
    plt.close(fig)
    return (f"<img class='plot' alt='{esc(alt)}' src='data:image/svg+xml;base64,"
            + base64.b64encode(buf.getvalue()).decode("ascii") + "'>")


def annotated_image(uri: str, width_px: int, height_px: int, overlay_svg: str, alt: str,
                    css_class: str = "frame") -> str:
    """An embedded image with an SVG overlay drawn in the image's own pixel coordinates."""
    return (f"<div class='{css_class}' style='width:{width_px}px'>"
            f"<img alt='{esc(alt)}' src='{uri}' width='{width_px}' height='{height_px}'>"
            f"<svg viewBox='0 0 {width_px} {height_px}' width='{width_px}' "
            f"height='{height_px}'>{overlay_svg}</svg></div>")


def svg_rect(x: float, y: float, w: float, h: float, color: str, label: str = "",
             label_px: float = 12.0, where: str = "right") -> str:
    """A rectangle outline with an optional label to its right, above or below it."""
    tx, ty = {"right": (x + w + 3, y + label_px * 0.9), "above": (x, y - 3),
              "below": (x, y + h + label_px)}[where]
    text = (f"<text x='{tx:.1f}' y='{ty:.1f}' fill='{color}' "
            f"font-size='{label_px:g}' class='roi-label'>{esc(label)}</text>" if label else "")
    return (f"<rect x='{x:.1f}' y='{y:.1f}' width='{w:.1f}' height='{h:.1f}' fill='none' "
            f"stroke='{color}' stroke-width='1.5'/>" + text)


def svg_plot(
    series: Sequence[tuple[Sequence[float], Sequence[float], str, str]],
    hlines: Iterable[tuple[float, str, str]] = (),
    vlines: Iterable[tuple[float, str, str]] = (),
    width_px: int = 260,
    height_px: int = 150,
    x_label: str = "",
    y_label: str = "",
    bars: bool = False,
) -> str:
    """A small line (or bar) plot as inline SVG.

    Parameters
    ----------
    series : sequence of (x, y, colour, name)
        Lines to draw; NaN points break a line. With ``bars`` the first series is drawn as bars.
    hlines, vlines : iterables of (value, colour, label)
        Horizontal lines at y values / vertical lines at x values, labelled.
    width_px, height_px : int
        Size of the SVG.
    x_label, y_label : str
        Axis titles.
    bars : bool
        Draw the first series as a histogram.
    """
    hl = list(hlines)
    vl = list(vlines)
    xs = [float(v) for s in series for v in s[0] if math.isfinite(float(v))]
    ys = [float(v) for s in series for v in s[1] if math.isfinite(float(v))]
    xs += [v for v, _, _ in vl if math.isfinite(v)]
    ys += [v for v, _, _ in hl if math.isfinite(v)]
    if not xs or not ys:
        return "<svg class='plot-empty'></svg>"
    x0, x1 = min(xs), max(xs)
    y0, y1 = (0.0, max(ys)) if bars else (min(ys), max(ys))
    if x1 <= x0:
        x1 = x0 + 1.0
    if y1 <= y0:
        y1 = y0 + 1.0
    pad_l, pad_r, pad_t, pad_b = 36.0, 8.0, 8.0, 26.0
    pw, ph = width_px - pad_l - pad_r, height_px - pad_t - pad_b

    def sx(v: float) -> float:
        return pad_l + (v - x0) / (x1 - x0) * pw

    def sy(v: float) -> float:
        return pad_t + (1.0 - (v - y0) / (y1 - y0)) * ph

    out = [f"<svg class='mini-plot' viewBox='0 0 {width_px} {height_px}' width='{width_px}' "
           f"height='{height_px}' font-size='10'>",
           f"<rect x='{pad_l}' y='{pad_t}' width='{pw}' height='{ph}' fill='#fafafa' "
           "stroke='#999'/>",
           f"<text x='{pad_l - 3}' y='{pad_t + 8}' text-anchor='end'>{y1:.4g}</text>",
           f"<text x='{pad_l - 3}' y='{pad_t + ph}' text-anchor='end'>{y0:.4g}</text>",
           f"<text x='{pad_l}' y='{pad_t + ph + 12}'>{x0:.4g}</text>",
           f"<text x='{pad_l + pw}' y='{pad_t + ph + 12}' text-anchor='end'>{x1:.4g}</text>",
           f"<text x='{pad_l + pw / 2}' y='{height_px - 2}' text-anchor='middle'>"
           f"{esc(x_label)}</text>",
           f"<text x='10' y='{pad_t + ph / 2}' text-anchor='middle' "
           f"transform='rotate(-90 10 {pad_t + ph / 2})'>{esc(y_label)}</text>"]
    for i, (sx_vals, sy_vals, color, name) in enumerate(series):
        if bars and i == 0:
            xv = [float(v) for v in sx_vals]
            step = (x1 - x0) / max(len(xv), 1)
            for x, y in zip(xv, sy_vals, strict=True):
                if math.isfinite(float(y)) and y > 0:
                    out.append(f"<rect x='{sx(x - step / 2):.1f}' y='{sy(float(y)):.1f}' "
                               f"width='{max(pw * step / (x1 - x0), 0.5):.1f}' "
                               f"height='{sy(y0) - sy(float(y)):.1f}' fill='{color}'/>")
            continue
        segments: list[list[str]] = [[]]
        for x, y in zip(sx_vals, sy_vals, strict=True):
            if math.isfinite(float(x)) and math.isfinite(float(y)):
                segments[-1].append(f"{sx(float(x)):.1f},{sy(float(y)):.1f}")
            elif segments[-1]:
                segments.append([])
        for seg in segments:
            if seg:
                out.append(f"<polyline fill='none' stroke='{color}' stroke-width='1.2' "
                           f"points='{' '.join(seg)}'><title>{esc(name)}</title></polyline>")
    for v, color, label in hl:
        if math.isfinite(v):
            out.append(f"<line x1='{pad_l}' x2='{pad_l + pw}' y1='{sy(v):.1f}' y2='{sy(v):.1f}' "
                       f"stroke='{color}' stroke-dasharray='4 2'/>"
                       f"<text x='{pad_l + pw - 2}' y='{sy(v) - 2:.1f}' text-anchor='end' "
                       f"fill='{color}'>{esc(label)}</text>")
    for v, color, label in vl:
        if math.isfinite(v):
            out.append(f"<line y1='{pad_t}' y2='{pad_t + ph}' x1='{sx(v):.1f}' x2='{sx(v):.1f}' "
                       f"stroke='{color}' stroke-dasharray='4 2'/>"
                       f"<text y='{pad_t + 10}' x='{sx(v) + 2:.1f}' fill='{color}'>"
                       f"{esc(label)}</text>")
    out.append("</svg>")
    return "".join(out)


def local_time(iso: Any) -> str:
    """An ISO-8601 timestamp in the machine's local time zone, to the second; '-' if missing."""
    if not iso:
        return "-"
    try:
        t = datetime.fromisoformat(str(iso))
    except ValueError:
        return str(iso)
    if t.tzinfo is not None:
        t = t.astimezone()
    return t.strftime("%Y-%m-%d %H:%M:%S %Z").strip()


def flatten(obj: Any, prefix: str = "") -> list[tuple[str, Any]]:
    """Nested parameters as (dotted key, value) rows; lists of scalars stay one value."""
    if isinstance(obj, dict):
        rows: list[tuple[str, Any]] = []
        for k, v in obj.items():
            rows += flatten(v, f"{prefix}.{k}" if prefix else str(k))
        return rows
    if isinstance(obj, list) and obj and all(isinstance(v, dict) for v in obj):
        rows = []
        for i, v in enumerate(obj):
            rows += flatten(v, f"{prefix}[{i}]")
        return rows
    return [(prefix, obj)]


def key_value_table(rows: Iterable[tuple[str, Any]], css_class: str = "kv") -> str:
    """A two-column table (left-aligned values)."""
    body = "".join(f"<tr><th>{esc(str(k))}</th><td>{esc(_plain(v))}</td></tr>" for k, v in rows)
    return f"<table class='{css_class}'>{body}</table>"


def _plain(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list | tuple):
        return ", ".join(_plain(x) for x in v)
    if v is None:
        return "-"
    return str(v)
