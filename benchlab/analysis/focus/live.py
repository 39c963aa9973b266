"""A live focus aid: the whole chart read on every frame, fast enough to turn the lens by.

The full chart reading (:func:`benchlab.analysis.chart.reading.read_chart`: every set fitted
with its geometry fixed, the blur shared across sets) takes ~0.25 s per frame, and finding the
chart another ~0.04 s. While a technician turns the back focus the chart does not move, so:

* the pose is **tracked**: the chart is found once and its placement reused for the next
  ``refind_every`` frames (then found again, in case the set-up was bumped);
* each found set is read by a **fast estimator** on its measurement ROI (default
  ``histogram``: the thesis's two peaks, ~0.5 ms a set; ``sinefit`` is ~3x slower and closer to
  the full reading), and each slanted edge gives its MTF50 by the SFR.

The price is accuracy against the full reading, measured by ``benchlab benchmark focus-aid``
(the estimator's own bias on small ROIs; the trend through focus, which is what a technician
follows, is unaffected). :class:`PeakHold` keeps each reading's best value and a short
history for the bars-with-peak-hold display. Pure numpy; no I/O.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.chart.finder import ChartFit, ChartNotFoundError, find_chart
from benchlab.analysis.sfr.measure import SfrRefused, measure_sfr
from benchlab.analysis.sfr.target import edge_specs, posed_squares
from benchlab.drivers.mightex.profile import PIXEL_PITCH_UM

PIXEL_PITCH_MM = PIXEL_PITCH_UM / 1000.0


@dataclass(frozen=True)
class LiveReading:
    """One frame's whole-chart reading: modulation per set (``"G2E4S"``), MTF50 (lp/mm) per
    edge (``"E0L"``), and whether the chart was found again on this frame."""

    modulation: dict[str, float | None]
    edge_mtf50_lp_per_mm: dict[str, float | None]
    refound: bool
    seconds: float


class ChartTracker:
    """Reads the whole chart on each frame, finding it only every ``refind_every`` frames."""

    def __init__(self, estimator: str = "histogram", refind_every: int = 10,
                 edges: bool = True) -> None:
        if refind_every < 1:
            raise ValueError(f"refind_every must be >= 1, got {refind_every}")
        self.estimator = estimator
        self.refind_every = refind_every
        self.edges = edges
        self.fit: ChartFit | None = None
        self._since = 0

    def reset(self) -> None:
        """Find the chart again on the next frame (the set-up was changed)."""
        self.fit = None

    def read(self, pixels: npt.NDArray[Any]) -> LiveReading:
        """The reading of one frame (module docstring). Raises ``ChartNotFoundError`` when
        the chart must be found and is not there."""
        t0 = time.perf_counter()
        refound = self.fit is None or self._since >= self.refind_every
        if refound:
            prior = self.fit.pose if self.fit is not None else None
            try:
                self.fit = (find_chart(pixels, prior=prior) if prior is not None
                            else find_chart(pixels))
            except ChartNotFoundError:
                self.fit = None
                raise
            self._since = 0
        self._since += 1
        fit = self.fit
        assert fit is not None
        top = float(np.iinfo(pixels.dtype).max) if pixels.dtype.kind in "ui" else None
        mods: dict[str, float | None] = {}
        for el in fit.found:
            r0, c0, r1, c1 = el.measurement_roi
            p = el.posed
            res = estimate_modulation(
                pixels[r0:r1, c0:c1], estimator=self.estimator,
                freq_cycles_per_px=1.0 / p.px_per_period,
                orientation="horizontal" if p.orientation == "sagittal" else "vertical",
                max_code=top)
            mods[p.label] = float(res.modulation) if res.resolved else None
        mtf50: dict[str, float | None] = {}
        if self.edges:
            for spec in edge_specs(posed_squares(fit.pose, fit.layout.origin_rc)):
                r0, c0, r1, c1 = spec.roi
                try:
                    sfr = measure_sfr(pixels[r0:r1, c0:c1], full_scale=top)
                except SfrRefused:
                    mtf50[spec.label] = None
                    continue
                m = sfr.mtf50_cycles_per_px
                mtf50[spec.label] = m / PIXEL_PITCH_MM if m is not None else None
        return LiveReading(mods, mtf50, refound, time.perf_counter() - t0)


@dataclass
class PeakHold:
    """Each key's best value so far and the last ``history`` readings of it."""

    history: int = 200
    peaks: dict[str, float] = field(default_factory=dict)
    series: dict[str, deque[float]] = field(default_factory=dict)

    def update(self, values: dict[str, float | None]) -> None:
        for key, v in values.items():
            if v is None:
                continue
            self.peaks[key] = max(v, self.peaks.get(key, -np.inf))
            self.series.setdefault(key, deque(maxlen=self.history)).append(v)

    def fraction_of_peak(self, key: str) -> float | None:
        """The latest value over the best (1.0 at best focus so far)."""
        s = self.series.get(key)
        peak = self.peaks.get(key)
        if not s or peak is None or peak <= 0:
            return None
        return s[-1] / peak


def mean_edge_mtf50(reading: LiveReading) -> float | None:
    """The mean MTF50 (lp/mm) over the edges that gave one: a single number that peaks at best
    focus (the focus aid's history); ``None`` when no edge did."""
    values = [v for v in reading.edge_mtf50_lp_per_mm.values() if v is not None]
    return float(np.mean(values)) if values else None


def nothing_read(reading: LiveReading) -> bool:
    """Whether a reading got no set resolved and no edge's MTF50: at a tracked pose, the chart
    has left the view (a defocused chart still resolves its coarse sets)."""
    return (all(v is None for v in reading.modulation.values())
            and all(v is None for v in reading.edge_mtf50_lp_per_mm.values()))
