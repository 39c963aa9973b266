"""The live focus aid drawn as text: one line per chart element with its S and T modulation
as bars (a peak-hold mark on each), the slanted edges' MTF50 and a sparkline of the history.

Pure functions of the readings (no widgets): the panel in :mod:`benchlab.tui.focus_aid` calls
:func:`render_focus_aid` with what it holds.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from rich.text import Text

#: Eighth blocks: a bar's fractional last cell, and the sparkline's levels.
_EIGHTHS = " \u258f\u258e\u258d\u258c\u258b\u258a\u2589\u2588"
_SPARK = "\u2581\u2582\u2583\u2584\u2585\u2586\u2587\u2588"
#: The peak-hold mark drawn over a bar.
PEAK_MARK = "\u2502"
_SET = re.compile(r"^G(-?\d+)E(\d+)([ST])$")
_EDGE = re.compile(r"^E(\d+)([LRTB])$")


@dataclass(frozen=True)
class FocusAidView:
    """What one drawing of the panel shows.

    ``modulation`` / ``mtf50_lp_per_mm``: the latest reading (``None``: not resolved / refused),
    ``peaks``: the best value of each key so far, ``history``: the summary value's recent
    readings (oldest first), ``status``: the first line (rate, or why there are no bars).
    """

    modulation: Mapping[str, float | None]
    mtf50_lp_per_mm: Mapping[str, float | None]
    peaks: Mapping[str, float]
    history: Sequence[float]
    status: str
    summary_label: str = "mean MTF50"
    summary_now: float | None = None
    summary_peak: float | None = None


def element_rows(keys: Sequence[str]) -> list[str]:
    """The elements (``"G2E4"``) of set keys (``"G2E4S"``), coarsest group first."""
    found = {}
    for key in keys:
        m = _SET.match(key)
        if m:
            found[(int(m.group(1)), int(m.group(2)))] = f"G{m.group(1)}E{m.group(2)}"
    return [found[k] for k in sorted(found)]


def bar(value: float | None, peak: float | None, full: float, width: int) -> Text:
    """``value`` of ``full`` as a bar ``width`` cells wide; the peak as a mark at its cell."""
    width = max(1, width)
    cells = [" "] * width
    if value is not None and math.isfinite(value) and full > 0:
        eighths = round(max(0.0, min(1.0, value / full)) * width * 8)
        whole, part = divmod(eighths, 8)
        for i in range(whole):
            cells[i] = _EIGHTHS[8]
        if part and whole < width:
            cells[whole] = _EIGHTHS[part]
    text = Text("".join(cells), style="green")
    if peak is not None and math.isfinite(peak) and full > 0:
        at = min(width - 1, max(0, math.ceil(min(1.0, peak / full) * width) - 1))
        text = Text.assemble(text[:at], Text(PEAK_MARK, style="bold yellow"), text[at + 1:])
    return text


def sparkline(values: Sequence[float], width: int, min_span: float = 0.1) -> str:
    """The last ``width`` values as eighth blocks from their min up to their min plus the larger
    of their range and ``min_span`` x their largest magnitude (so that the noise of a steady
    reading stays a ripple instead of filling the height)."""
    shown = [v for v in values if math.isfinite(v)][-max(1, width):]
    if not shown:
        return ""
    lo, hi = min(shown), max(shown)
    span = max(hi - lo, min_span * max(abs(lo), abs(hi)))
    if span <= 0:
        return _SPARK[0] * len(shown)
    top = len(_SPARK) - 1
    return "".join(_SPARK[round((v - lo) / span * top)] for v in shown)


def _num(value: float | None) -> str:
    return "  -" if value is None or not math.isfinite(value) else f"{value:3.0f}"


def render_focus_aid(view: FocusAidView, width: int) -> Text:
    """The panel's text for ``width`` columns.

    Lines: the status; per element ``G2E4 S|bar| T|bar|`` (modulation 0-1, peak marked);
    the edges' MTF50 in lp/mm per square (``E0 L 91 R 95 T 88 B 90``); the summary value now
    and its peak (lp/mm); its history as a sparkline. With no current reading (chart not found) only
    the status and the history are drawn: bars of an older frame are never shown as current.
    """
    width = max(20, width)
    out = Text(view.status, style="bold")
    elements = element_rows(list(view.modulation))
    bar_w = max(1, (width - len("G2E4 S") - len(" T")) // 2)
    for el in elements:
        line = Text(f"\n{el:<5}")
        for o in ("S", "T"):
            key = el + o
            line.append(f" {o}" if o == "T" else o, style="bold")
            line.append_text(bar(view.modulation.get(key), view.peaks.get(key), 1.0, bar_w))
        out.append_text(line)
    squares: dict[str, dict[str, float | None]] = {}
    for key, v in view.mtf50_lp_per_mm.items():
        m = _EDGE.match(key)
        if m:
            squares.setdefault(f"E{m.group(1)}", {})[m.group(2)] = v
    if squares:
        out.append("\nedges MTF50 lp/mm", style="dim")
    for sq in sorted(squares):
        sides = squares[sq]
        out.append(f"\n{sq} " + " ".join(f"{s}{_num(sides.get(s))}" for s in "LRTB"))
    if view.summary_now is not None or view.summary_peak is not None:
        peak = "-" if view.summary_peak is None else f"{view.summary_peak:.1f}"
        now = "-" if view.summary_now is None else f"{view.summary_now:.1f}"
        out.append(f"\n{view.summary_label} {now} peak {peak}")
    spark = sparkline(view.history, width)
    if spark:
        out.append("\n" + spark, style="cyan")
    return out
