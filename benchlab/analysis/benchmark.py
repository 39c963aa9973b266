"""Speed/accuracy benchmark of the modulation estimators on synthetic bar ROIs with known truth.

Cases span PSF sigma (0.25, 0.5 or 1 px), illumination shading (none or a 20 % ramp), bar duty (half
the cases 0.4 or 0.6 bright: printed lines come out thicker or thinner), noise level, ROI size
(12 x 12, 40 x 50, 100 x 128), pixels per period (32 down to 2.2, near Nyquist), saturation
(1.6x over-exposure), bit depth (8-bit; 12-bit MSB-aligned in 16) and frames averaged (1, 4),
with random sampling phase and orientation, plus flat fields (no bars) to count false
"resolved" calls. Every estimator gets the bar frequency and orientation, as the procedures
pass them.

Definitions (per estimator):

- truth: Eq. 2.9 contrast of the noise-free blurred image (:mod:`benchlab.analysis.synthetic`).
- *measurable* case: truth >= 0.05, effective SNR >= 5 (SNR = half peak-to-valley over
  noise sigma / sqrt(frames)) and at least one full bar period inside the ROI.
- bias, RMSE: of (estimate - truth) over measurable unsaturated cases, "not resolved" counted as
  0 (what a report would print). ``RMSE@20`` and ``<=0.02@20``: those with SNR >= 20.
  ``sat bias``: bias over the measurable saturated cases.
- wrong-res: fraction of flat cases called resolved; wrong-unres: fraction of measurable
  unsaturated cases called not resolved.
- us/ROI: median wall time of :func:`estimate_modulation` on 40 x 50 (2,000-pixel) single-frame
  8-bit ROIs, best of 3 calls each, in one process (the accuracy runs use worker processes).
"""

from __future__ import annotations

import itertools
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from benchlab.analysis.estimators import ESTIMATORS, estimate_modulation
from benchlab.analysis.synthetic import BarCase, render

MEASURABLE_TRUTH = 0.05
MEASURABLE_SNR = 5.0
TARGET_SNR = 20.0
TARGET_ERROR = 0.02


@dataclass(frozen=True)
class EstimatorScore:
    """One row of the benchmark table."""

    estimator: str
    n_cases: int
    bias: float
    rmse: float
    rmse_snr20: float
    within_target_snr20: float
    saturated_bias: float
    wrong_resolved: float
    wrong_unresolved: float
    us_per_roi_2000px: float
    rmse_by_px_per_period: dict[float, float]


def benchmark_cases(quick: bool = False, seed: int = 0) -> list[BarCase]:
    """The grid of synthetic cases (random phases and orientations from ``seed``)."""
    rng = np.random.default_rng(seed)
    periods = [32.0, 16.0, 8.0, 5.0, 3.0, 2.2]
    noises = [0.5, 2.0, 6.0] if quick else [0.5, 2.0, 6.0, 15.0]
    shapes = [(40, 50), (12, 12)] if quick else [(40, 50), (12, 12), (100, 128)]
    repeats = 1 if quick else 3
    cases = []
    for period, noise, shape, exposure, bits, frames in itertools.product(
        periods, noises, shapes, [1.0, 1.6], [8, 12], [1, 4]
    ):
        # Half the cases have a 20 % illumination ramp across the ROI (thesis: "near-uniform").
        for _ in range(repeats):
            cases.append(
                BarCase(
                    shape=shape,
                    px_per_period=period,
                    modulation=0.6,
                    mean=100.0,
                    psf_sigma_px=float(rng.choice([0.25, 0.5, 1.0])),
                    noise_sigma=noise,
                    phase=float(rng.uniform()),
                    orientation="horizontal" if rng.uniform() < 0.5 else "vertical",
                    exposure_scale=exposure,
                    bits=bits,
                    msb_aligned=bits == 12,
                    n_frames=frames,
                    shading=float(rng.choice([0.0, 0.2])),
                    duty=float(rng.choice([0.5, 0.5, 0.4, 0.6])),
                )
            )
    for noise, shape, frames in itertools.product(noises, shapes, [1, 4]):
        for _ in range(repeats * 4):
            cases.append(
                BarCase(
                    shape=shape,
                    px_per_period=float(rng.choice(periods)),
                    modulation=0.0,
                    noise_sigma=noise,
                    n_frames=frames,
                    orientation="horizontal",
                )
            )
    return cases


def _is_measurable(case: BarCase) -> bool:
    along = case.shape[1] if case.orientation == "horizontal" else case.shape[0]
    snr = case.snr * math.sqrt(case.n_frames)
    return case.truth >= MEASURABLE_TRUTH and snr >= MEASURABLE_SNR and along >= case.px_per_period


def _evaluate(chunk: list[tuple[int, BarCase]]) -> list[tuple[int, str, float, bool]]:
    """(case index, estimator, modulation, resolved) for every estimator on each case."""
    out = []
    for index, case in chunk:
        roi = render(case, np.random.default_rng(10_000 + index))
        for name in ESTIMATORS:
            r = estimate_modulation(
                roi,
                estimator=name,
                freq_cycles_per_px=case.freq_cycles_per_px,
                orientation=case.orientation,
            )
            out.append((index, name, r.modulation, r.resolved))
    return out


def _time_estimators(n_rois: int, seed: int) -> dict[str, float]:
    """Median microseconds per call on 2,000-pixel ROIs (best of 3 calls each)."""
    rng = np.random.default_rng(seed)
    rois = []
    for i in range(n_rois):
        case = BarCase(
            shape=(40, 50),
            px_per_period=[16.0, 8.0, 5.0, 3.0][i % 4],
            noise_sigma=2.0,
            phase=float(rng.uniform()),
        )
        rois.append((render(case, rng), case.freq_cycles_per_px))
    times: dict[str, float] = {}
    for name in ESTIMATORS:
        per_roi = []
        for roi, freq in rois:
            best = math.inf
            for _ in range(3):
                t0 = time.perf_counter()
                estimate_modulation(
                    roi, estimator=name, freq_cycles_per_px=freq, orientation="horizontal"
                )
                best = min(best, time.perf_counter() - t0)
            per_roi.append(best)
        times[name] = 1e6 * float(np.median(per_roi))
    return times


def run_benchmark(
    quick: bool = False, seed: int = 0, max_cases: int | None = None, workers: int | None = None
) -> list[EstimatorScore]:
    """Score every estimator of :data:`ESTIMATORS` over :func:`benchmark_cases` (an evenly
    spaced subset of ``max_cases`` when given), using ``workers`` processes (default: the CPU
    count, at most 4; 1 runs in this process)."""
    cases = benchmark_cases(quick, seed)
    if max_cases is not None and max_cases < len(cases):
        cases = [cases[i] for i in np.linspace(0, len(cases) - 1, max_cases).astype(int)]
    indexed = list(enumerate(cases))
    n_workers = workers if workers is not None else min(os.cpu_count() or 1, 4)
    if n_workers > 1 and len(indexed) > 50:
        chunks = [indexed[i :: n_workers * 4] for i in range(n_workers * 4)]
        with ProcessPoolExecutor(max_workers=n_workers) as pool:
            rows = [row for part in pool.map(_evaluate, chunks) for row in part]
    else:
        rows = _evaluate(indexed)
    times = _time_estimators(20 if quick or max_cases else 60, seed)

    scores = []
    for name in ESTIMATORS:
        errors, errors20, sat_errors, flat_calls, missed = [], [], [], [], []
        by_period: dict[float, list[float]] = {}
        for index, est, modulation, resolved in rows:
            if est != name:
                continue
            case = cases[index]
            if case.modulation == 0.0:
                flat_calls.append(resolved)
                continue
            if not _is_measurable(case):
                continue
            err = modulation - case.truth
            if case.exposure_scale > 1.0:
                sat_errors.append(err)
                continue
            errors.append(err)
            missed.append(not resolved)
            by_period.setdefault(case.px_per_period, []).append(err)
            if case.snr * math.sqrt(case.n_frames) >= TARGET_SNR:
                errors20.append(err)
        e, e20 = np.asarray(errors), np.asarray(errors20)

        def rms(a: np.ndarray) -> float:
            return float(np.sqrt(np.mean(np.square(a)))) if len(a) else math.nan

        scores.append(
            EstimatorScore(
                estimator=name,
                n_cases=len(cases),
                bias=float(e.mean()) if e.size else math.nan,
                rmse=rms(e),
                rmse_snr20=rms(e20),
                within_target_snr20=float(np.mean(np.abs(e20) <= TARGET_ERROR))
                if e20.size
                else math.nan,
                saturated_bias=float(np.mean(sat_errors)) if sat_errors else math.nan,
                wrong_resolved=float(np.mean(flat_calls)) if flat_calls else math.nan,
                wrong_unresolved=float(np.mean(missed)) if missed else math.nan,
                us_per_roi_2000px=times[name],
                rmse_by_px_per_period={
                    p: rms(np.asarray(v)) for p, v in sorted(by_period.items(), reverse=True)
                },
            )
        )
    return scores


def recommend(scores: list[EstimatorScore]) -> str:
    """The estimator with the smallest RMSE at SNR >= 20 among those with a false "resolved"
    rate of at most 2 %."""
    ok = [s for s in scores if not s.wrong_resolved > 0.02] or scores
    return min(
        ok, key=lambda s: s.rmse_snr20 if math.isfinite(s.rmse_snr20) else math.inf
    ).estimator


def format_table(scores: list[EstimatorScore]) -> str:
    """Plain-text tables: the summary per estimator, then RMSE by pixels per period."""
    head = (
        f"{'estimator':<10} {'bias':>7} {'RMSE':>6} {'RMSE@20':>7} {'<=0.02@20':>9} "
        f"{'sat bias':>8} {'wrong-res':>9} {'wrong-unres':>11} {'us/ROI':>7}"
    )
    lines = [head, "-" * len(head)]
    for s in scores:
        lines.append(
            f"{s.estimator:<10} {s.bias:>+7.3f} {s.rmse:>6.3f} {s.rmse_snr20:>7.3f} "
            f"{100 * s.within_target_snr20:>8.0f}% {s.saturated_bias:>+8.3f} "
            f"{100 * s.wrong_resolved:>8.1f}% {100 * s.wrong_unresolved:>10.1f}% "
            f"{s.us_per_roi_2000px:>7.0f}"
        )
    periods = sorted({p for s in scores for p in s.rmse_by_px_per_period}, reverse=True)
    lines.append("")
    lines.append("RMSE by px per period " + " ".join(f"{p:>6g}" for p in periods))
    for s in scores:
        vals = " ".join(f"{s.rmse_by_px_per_period.get(p, math.nan):>6.3f}" for p in periods)
        lines.append(f"  {s.estimator:<19} {vals}")
    return "\n".join(lines)
