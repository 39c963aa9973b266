"""``benchlab benchmark focus-aid``: whole-chart readings per second for the live focus aid
(:mod:`benchlab.analysis.focus.live`) at 1280 x 1024, 8 and 12 bit, and their accuracy cost
against the full chart reading of the same frames.

Frames come from the simulated bench (noise on), grabbed before the clock starts: the figure is
the reading rate, not the camera's frame rate. The tracker finds the chart on its first frame
and every ``refind_every`` frames after, as in use.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

ESTIMATORS = ("histogram", "sinefit")


def _frames(bits: int, n: int, seed: int) -> list[Any]:
    from benchlab.bench import Bench, BenchConfig

    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True, seed=seed) as bench:
        bench.configure_camera(bits=bits)
        bench.mount("usaf")
        return [bench.grab(exposure_ms=300.0, gain=1.0)[0] for _ in range(n)]


def run_benchmark(seconds: float = 3.0, frames: int = 8) -> list[dict[str, Any]]:
    """One row per bit depth and estimator: readings/s, and the median / 95th percentile
    absolute difference of its modulations from :func:`read_chart` on the same frames."""
    from benchlab.analysis.chart.finder import find_chart
    from benchlab.analysis.chart.reading import read_chart
    from benchlab.analysis.focus.live import ChartTracker

    rows = []
    for bits in (8, 12):
        stack = _frames(bits, frames, seed=bits)
        full: dict[str, list[float]] = {}
        for px in stack[:2]:
            fit = find_chart(px)
            top = float(2**bits - 1)
            for el, r in zip(fit.found, read_chart(px, fit, top), strict=True):
                if r.resolved:
                    full.setdefault(el.posed.label, []).append(float(r.modulation))
        for est in ESTIMATORS:
            tracker = ChartTracker(estimator=est)
            diffs: list[float] = []
            for px in stack[:2]:
                tracker.reset()
                got = tracker.read(px).modulation
                for key, ref in full.items():
                    if got.get(key) is not None:
                        diffs.append(abs(float(got[key]) - statistics.mean(ref)))  # type: ignore[arg-type]
            tracker.reset()
            n = 0
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < seconds:
                tracker.read(stack[n % len(stack)])
                n += 1
            rate = n / (time.perf_counter() - t0)
            d = np.asarray(diffs)
            rows.append({"bits": bits, "estimator": est, "readings_per_s": rate,
                         "sets": len(full), "median_abs_diff": float(np.median(d)),
                         "p95_abs_diff": float(np.percentile(d, 95))})
    return rows


def format_benchmark(rows: list[dict[str, Any]]) -> str:
    lines = ["live focus aid: whole-chart readings (every found set + the 12 edges' MTF50) per "
             "second at 1280 x 1024, pose tracked (found every 10 frames); accuracy against the "
             "full chart reading of the same frames", "",
             f"{'bits':>4} {'estimator':<10} {'readings/s':>10} {'sets':>5} "
             f"{'median |diff|':>13} {'95% |diff|':>10}"]
    for r in rows:
        lines.append(f"{r['bits']:>4} {r['estimator']:<10} {r['readings_per_s']:>10.1f} "
                     f"{r['sets']:>5} {r['median_abs_diff']:>13.3f} {r['p95_abs_diff']:>10.3f}")
    return "\n".join(lines)
