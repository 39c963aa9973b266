"""Checks on a rendered matplotlib figure, read from its artists (not pixels): each legend on
no data (points, curve vertices, error bars, scatter offsets) of any panel, each panel's axes
labelled with a unit, and no label drawn over another panel (for the report's browser tests)."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from matplotlib.collections import Collection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

#: An axis label names its unit (or its definition, for a ratio) in parentheses.
UNIT = re.compile(r"\(.+\)")


def _display_points(ax: Any) -> np.ndarray:
    """Every data point of a panel in display coordinates: line vertices (curves densified,
    so a legend across a segment is caught), error-bar segments and scatter offsets."""
    pts: list[np.ndarray] = []
    for ln in ax.get_lines():
        if not isinstance(ln, Line2D) or not ln.get_visible():
            continue
        x, y = (np.asarray(v, dtype=float) for v in ln.get_data())
        if x.size == 0 or str(ln.get_label()).startswith("_child") and x.size == 2 \
                and (x[0] == x[1] or y[0] == y[1]) and _is_reference(ax, x, y):
            continue
        xy = ax.transData.transform(np.column_stack([x, y]))
        if ln.get_linestyle() not in ("None", "none", "") and len(xy) > 1:
            t = np.linspace(0.0, 1.0, 12)[:, None]
            xy = np.concatenate([a + t * (b - a) for a, b in zip(xy[:-1], xy[1:], strict=True)])
        pts.append(xy)
    for c in ax.collections:
        if not isinstance(c, Collection) or not c.get_visible():
            continue
        for path in c.get_paths():
            v = path.vertices
            if len(v) and np.isfinite(v).all():
                pts.append(c.get_transform().transform(v))
        offs = c.get_offsets()
        if len(offs):
            pts.append(c.get_offset_transform().transform(np.asarray(offs, dtype=float)))
    finite = [p[np.isfinite(p).all(axis=1)] for p in pts]
    return np.concatenate(finite) if finite else np.empty((0, 2))


def _is_reference(ax: Any, x: np.ndarray, y: np.ndarray) -> bool:
    """A line spanning the whole panel (axhline/axvline: a threshold, Nyquist) is a
    reference, not data: a legend may cross it."""
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    return bool((x[0] == x[1] and {*y} >= {0.0, 1.0}) or (y[0] == y[1] and {*x} >= {0.0, 1.0})
                or (x[0] == x[1] and min(y) <= y0 and max(y) >= y1)
                or (y[0] == y[1] and min(x) <= x0 and max(x) >= x1))


def legend_problems(fig: Figure) -> list[str]:
    """Legends that cover a data point of any panel of the figure."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    out = []
    axes = [ax for ax in fig.axes if ax.get_visible()]
    legends = [(ax, ax.get_legend()) for ax in axes if ax.get_legend() is not None]
    if fig.legends:
        legends += [(None, leg) for leg in fig.legends]
    for owner, leg in legends:
        box = leg.get_window_extent(renderer).padded(-1.0)
        for ax in axes:
            pts = _display_points(ax)
            area = ax.get_window_extent(renderer)
            inside = pts[(pts[:, 0] >= area.x0) & (pts[:, 0] <= area.x1)
                         & (pts[:, 1] >= area.y0) & (pts[:, 1] <= area.y1)] if len(pts) else pts
            hits = [(x, y) for x, y in inside if box.contains(x, y)]
            if hits:
                title = (owner.get_title() if owner is not None else "figure") or "?"
                out.append(f"legend of {title!r} covers {len(hits)} data point(s) of panel "
                           f"{ax.get_title()!r}")
    return out


def label_problems(fig: Figure) -> list[str]:
    """Panels with data whose x or y axis has no label naming a unit."""
    out = []
    for ax in fig.axes:
        if not ax.get_visible() or not (ax.get_lines() or ax.collections):
            continue
        for name, label in (("x", _label(ax, "x")), ("y", _label(ax, "y"))):
            if name == "y" and not label and ax.get_yticklabels() and \
                    all(t.get_text() and not _number(t.get_text()) for t in ax.get_yticklabels()):
                continue  # categories (one row per test), not a quantity
            if not UNIT.search(label or ""):
                out.append(f"panel {ax.get_title()!r}: {name} axis {label!r} names no unit")
    return out


def _label(ax: Any, axis: str) -> str:
    """A panel's axis label, or that of a panel it shares the axis with (one label for a row
    or column of panels)."""
    shared = ax.get_shared_x_axes() if axis == "x" else ax.get_shared_y_axes()
    for other in [ax, *shared.get_siblings(ax)]:
        label = other.get_xlabel() if axis == "x" else other.get_ylabel()
        if label:
            return str(label)
    return ""


def _number(text: str) -> bool:
    try:
        float(text.replace("\u2212", "-"))
    except ValueError:
        return False
    return True
