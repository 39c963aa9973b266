"""A terminal plot of bar contrast against frequency: the measured points of a running MTF test
over the simulated optics' CTF band (best and worst field point), in braille dots.

Square-wave contrast against square-wave contrast: the simulated sine-wave MTF curves are
converted with Coltman's series (:func:`benchlab.report.mtf.simulated_ctf`) before they share the
axes with the bar readings. Lens against lens: the curves are the lens alone, so when every
reading of the view comes with its target's own contrast the plot draws the lens's share
(reading / target contrast) and its legend says so (``share M/0.81``); otherwise the raw
readings (legend ``CTF``: the lens and the print together).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from rich.text import Text
from textual.widgets import Static

#: Braille dot bits by (column 0/1, row 0..3) inside one character cell.
_DOTS = ((0x01, 0x02, 0x04, 0x40), (0x08, 0x10, 0x20, 0x80))
#: Marker, style and legend word of each point state and orientation.
MARKS = {"sagittal": ("s", "bold yellow"), "tangential": ("t", "bold cyan")}
UNRESOLVED = ("x", "bold red")
ALIASED = ("a", "bold magenta")


@dataclass(frozen=True)
class PlotPoint:
    freq_lp_per_mm: float
    modulation: float | None  # None when not resolved
    orientation: str
    aliased: bool
    #: The target's own contrast (None: unknown while the run goes on).
    target_contrast: float | None = None


def lens_shares(points: Sequence[PlotPoint]) -> tuple[list[PlotPoint], float | None]:
    """The points as the plot draws them: each reading divided by its target's contrast when
    every point has one (and that contrast, the first when they differ), else unchanged
    (None)."""
    targets = [p.target_contrast for p in points]
    if not points or any(t is None or t <= 0 for t in targets):
        return list(points), None
    shown = [replace(p, modulation=None if p.modulation is None
                     else p.modulation / p.target_contrast)  # type: ignore[operator]
             for p in points]
    return shown, targets[0]


def render_plot(
    points: Sequence[PlotPoint],
    curves: Sequence[tuple[Sequence[float], Sequence[float]]],
    width: int,
    height: int,
    x_max: float,
    nyquist: float,
) -> Text:
    """The plot as Rich text of ``height`` lines (the last is the frequency axis).

    Parameters
    ----------
    points : measured readings (unresolved ones sit on the bottom row as ``x``).
    curves : (frequencies lp/mm, CTF) pairs drawn as braille dots.
    width, height : characters, axis labels included (at least 12 x 4).
    x_max : right end of the frequency axis (lp/mm).
    nyquist : frequency marked with a ``|`` on the axis.
    """
    width, height = max(width, 12), max(height, 4)
    plot_w, plot_h = width - 4, height - 1
    cells = [[0] * plot_w for _ in range(plot_h)]
    marks: dict[tuple[int, int], tuple[str, str]] = {}

    def col_of(f: float) -> float:
        return f / x_max * (plot_w * 2 - 1)

    def row_of(m: float) -> float:
        return (1.0 - min(max(m, 0.0), 1.0)) * (plot_h * 4 - 1)

    for freqs, ctf in curves:
        for i in range(plot_w * 2):
            f = i / (plot_w * 2 - 1) * x_max
            y = _interp(f, freqs, ctf)
            if y is None:
                continue
            r = int(round(row_of(y)))
            cells[r // 4][i // 2] |= _DOTS[i % 2][r % 4]
    for p in points:
        c = min(int(col_of(p.freq_lp_per_mm) // 2), plot_w - 1)
        if p.aliased:
            marks[(plot_h - 1, c)] = ALIASED
        elif p.modulation is None:
            marks[(plot_h - 1, c)] = UNRESOLVED
        else:
            marks[(int(row_of(p.modulation) // 4), c)] = MARKS.get(p.orientation, ("o", "bold"))
    text = Text(no_wrap=True, overflow="crop")
    for r in range(plot_h):
        label = "1.0" if r == 0 else ("0.0" if r == plot_h - 1 else "   ")
        text.append(label + "\u2502", style="dim")
        for c in range(plot_w):
            if (r, c) in marks:
                ch, style = marks[(r, c)]
                text.append(ch, style=style)
            elif cells[r][c]:
                text.append(chr(0x2800 + cells[r][c]), style="green")
            else:
                text.append(" ")
        text.append("\n")
    axis = ["\u2500"] * plot_w
    nyq_c = min(int(col_of(nyquist) // 2), plot_w - 1)
    axis[nyq_c] = "\u253c"
    text.append("   \u2514" + "".join(axis), style="dim")
    return text


def _interp(f: float, xs: Sequence[float], ys: Sequence[float]) -> float | None:
    if not xs or f < xs[0] or f > xs[-1]:
        return None
    lo, hi = 0, len(xs) - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xs[mid] <= f:
            lo = mid
        else:
            hi = mid
    if xs[hi] == xs[lo]:
        return float(ys[lo])
    t = (f - xs[lo]) / (xs[hi] - xs[lo])
    v = float(ys[lo]) + t * (float(ys[hi]) - float(ys[lo]))
    return v if math.isfinite(v) else None


class CtfPlot(Static):
    """Measured bar contrast of the running test (the lens's share when the targets' contrast
    is known: :func:`lens_shares`) over the simulated CTF band of its view."""

    DEFAULT_CSS = """
    CtfPlot { height: 8; padding: 0 0; }
    """

    def __init__(self, *, id: str | None = None) -> None:  # noqa: A002 - Textual's name
        super().__init__("", id=id)
        self.view = "forward"
        self.points: list[PlotPoint] = []
        self.curves: dict[str, list[tuple[list[float], list[float]]]] = {}
        self.nyquist = 96.15
        self.x_max = 110.0

    def set_curves(self, curves: dict[str, list[tuple[list[float], list[float]]]],
                   nyquist: float) -> None:
        """Simulated CTF band per view: ``{"forward": [(f, best), (f, worst)], ...}``."""
        self.curves = curves
        self.nyquist = nyquist
        self.x_max = 1.15 * nyquist
        self.refresh_plot()

    def clear_points(self) -> None:
        self.points = []
        self.refresh_plot()

    def add_point(self, view: str, point: PlotPoint) -> None:
        """Add a reading; the plot follows the view being measured."""
        if view != self.view:
            self.view = view
            self.points = []
        self.points.append(point)
        self.refresh_plot()

    def refresh_plot(self) -> None:
        if not self.is_mounted:
            return
        width = max(self.size.width, 12)
        height = max(self.size.height - 1, 4)  # one line of legend
        shown, target = lens_shares(self.points)
        legend = Text(f"{self.view} ", style="bold", no_wrap=True, overflow="crop")
        if target is not None:  # first: the basis must survive a narrow panel's crop
            legend.append(f"share M/{target:.2f} ", style="bold")
        legend.append("s", style=MARKS["sagittal"][1])
        legend.append(" ")
        legend.append("t", style=MARKS["tangential"][1])
        legend.append(" CTF " if target is None else " ")
        legend.append("x", style=UNRESOLVED[1])
        legend.append(" unres. ")
        legend.append("\u28ff", style="green")
        legend.append(" sim. \u253c Nyq.")
        legend.truncate(width)
        legend.append("\n")
        legend.append(render_plot(shown, self.curves.get(self.view, []), width, height,
                                  self.x_max, self.nyquist))
        self.update(legend)

    def on_resize(self) -> None:
        self.refresh_plot()
