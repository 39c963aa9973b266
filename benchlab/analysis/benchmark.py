"""Speed/accuracy benchmark of the modulation estimators on synthetic bar ROIs with known truth.

Cases span noise level, ROI size, pixels per period (down to 2.2, near Nyquist), saturation,
bit depth (8-bit; 12-bit MSB-aligned in 16) and frames averaged, with random sampling phase,
plus flat fields (no bars) to count false "resolved" calls. Every estimator gets the bar
frequency and orientation, as the procedures pass them.

Definitions (per estimator):

- truth: Eq. 2.9 contrast of the noise-free blurred image (:mod:`benchlab.analysis.synthetic`).
- *resolvable* case: truth >= 0.05 and effective SNR >= 5, where SNR = half peak-to-valley /
  (noise sigma / sqrt(frames)); *flat* case: no bars at all.
- bias, RMSE: of (estimate - truth) over resolvable cases, "not resolved" counted as 0 (what a
  report would print). ``RMSE@20`` and ``<=0.02@20``: resolvable, unsaturated cases with SNR >= 20.
- wrong-resolved: fraction of flat cases called resolved; wrong-unresolved: fraction of
  resolvable cases called not resolved.
- us/ROI: wall time of :func:`estimate_modulation` on 40 x 50 (2,000-pixel) single-frame ROIs.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from benchlab.analysis.estimators import ESTIMATORS, estimate_modulation
from benchlab.analysis.synthetic import BarCase, render

RESOLVABLE_TRUTH = 0.05
RESOLVABLE_SNR = 5.0
TARGET_SNR = 20.0
TARGET_ERROR = 0.02


@dataclass
class _Tally:
    errors: list[float] = field(default_factory=list)
    errors_snr20: list[float] = field(default_factory=list)
    flat_calls: list[bool] = field(default_factory=list)
    missed: list[bool] = field(default_factory=list)
    times_2000_s: list[float] = field(default_factory=list)
    by_period: dict[float, list[float]] = field(default_factory=dict)


@dataclass(frozen=True)
class EstimatorScore:
    """One row of the benchmark table."""

    estimator: str
    n_cases: int
    bias: float
    rmse: float
    rmse_snr20: float
    within_target_snr20: float
    wrong_resolved: float
    wrong_unresolved: float
    us_per_roi_2000px: float
    rmse_by_px_per_period: dict[float, float]


def benchmark_cases(quick: bool = False, seed: int = 0) -> list[BarCase]:
    """The grid of synthetic cases (random phases from ``seed``)."""
    rng = np.random.default_rng(seed)
    periods = [32.0, 16.0, 8.0, 5.0, 3.0, 2.2]
    noises = [0.5, 2.0, 6.0] if quick else [0.5, 2.0, 6.0, 15.0]
    shapes = [(40, 50), (12, 12)] if quick else [(40, 50), (12, 12), (100, 128)]
    exposures = [1.0, 1.6]
    bits = [8, 12]
    frames = [1, 4]
    repeats = 1 if quick else 4
    cases = []
    for period, noise, shape, exposure, nbits, nf in itertools.product(
        periods, noises, shapes, exposures, bits, frames
    ):
        for _ in range(repeats):
            cases.append(
                BarCase(
                    shape=shape,
                    px_per_period=period,
                    modulation=0.6,
                    mean=100.0,
                    psf_sigma_px=1.0,
                    noise_sigma=noise,
                    phase=float(rng.uniform()),
                    orientation="horizontal" if rng.uniform() < 0.5 else "vertical",
                    exposure_scale=exposure,
                    bits=nbits,
                    msb_aligned=nbits == 12,
                    n_frames=nf,
                )
            )
    for noise, shape, nf in itertools.product(noises, shapes, frames):
        for _ in range(repeats * 4):
            period = float(rng.choice(periods))
            cases.append(
                BarCase(
                    shape=shape,
                    px_per_period=period,
                    modulation=0.0,
                    noise_sigma=noise,
                    n_frames=nf,
                    orientation="horizontal",
                )
            )
    return cases


def run_benchmark(
    quick: bool = False, seed: int = 0, max_cases: int | None = None
) -> list[EstimatorScore]:
    """Score every estimator of :data:`ESTIMATORS` over :func:`benchmark_cases` (an evenly
    spaced subset of ``max_cases`` when given)."""
    cases = benchmark_cases(quick, seed)
    if max_cases is not None and max_cases < len(cases):
        cases = [cases[i] for i in np.linspace(0, len(cases) - 1, max_cases).astype(int)]
    rng = np.random.default_rng(seed + 1)
    tallies = {name: _Tally() for name in ESTIMATORS}
    for case in cases:
        roi = render(case, rng)
        truth = case.truth
        snr = case.snr * math.sqrt(case.n_frames)
        saturated = case.exposure_scale > 1.0
        flat = case.modulation == 0.0
        resolvable = truth >= RESOLVABLE_TRUTH and snr >= RESOLVABLE_SNR
        timed = case.shape == (40, 50) and case.n_frames == 1
        for name, tally in tallies.items():
            t0 = time.perf_counter()
            result = estimate_modulation(
                roi,
                estimator=name,
                freq_cycles_per_px=case.freq_cycles_per_px,
                orientation=case.orientation,
            )
            dt = time.perf_counter() - t0
            if timed:
                tally.times_2000_s.append(dt)
            if flat:
                tally.flat_calls.append(result.resolved)
                continue
            if not resolvable:
                continue
            err = result.modulation - truth
            tally.errors.append(err)
            tally.missed.append(not result.resolved)
            tally.by_period.setdefault(case.px_per_period, []).append(err)
            if snr >= TARGET_SNR and not saturated:
                tally.errors_snr20.append(err)
    scores = []
    for name, t in tallies.items():
        e = np.asarray(t.errors)
        e20 = np.asarray(t.errors_snr20)
        scores.append(
            EstimatorScore(
                estimator=name,
                n_cases=len(cases),
                bias=float(e.mean()) if e.size else math.nan,
                rmse=float(np.sqrt(np.mean(e**2))) if e.size else math.nan,
                rmse_snr20=float(np.sqrt(np.mean(e20**2))) if e20.size else math.nan,
                within_target_snr20=float(np.mean(np.abs(e20) <= TARGET_ERROR))
                if e20.size
                else math.nan,
                wrong_resolved=float(np.mean(t.flat_calls)) if t.flat_calls else math.nan,
                wrong_unresolved=float(np.mean(t.missed)) if t.missed else math.nan,
                us_per_roi_2000px=1e6 * float(np.median(t.times_2000_s))
                if t.times_2000_s
                else math.nan,
                rmse_by_px_per_period={
                    p: float(np.sqrt(np.mean(np.square(v)))) for p, v in sorted(t.by_period.items())
                },
            )
        )
    return scores


def recommend(scores: list[EstimatorScore]) -> str:
    """The estimator with the smallest RMSE at SNR >= 20, among those with a <= 2 % false
    "resolved" rate."""
    ok = [s for s in scores if not s.wrong_resolved > 0.02] or scores
    return min(ok, key=lambda s: s.rmse_snr20).estimator


def format_table(scores: list[EstimatorScore]) -> str:
    """Plain-text tables: the summary per estimator, then RMSE by pixels per period."""
    head = (
        f"{'estimator':<10} {'bias':>7} {'RMSE':>7} {'RMSE@20':>8} {'<=0.02@20':>9} "
        f"{'wrong-res':>9} {'wrong-unres':>11} {'us/ROI':>7}"
    )
    lines = [head, "-" * len(head)]
    for s in scores:
        lines.append(
            f"{s.estimator:<10} {s.bias:>+7.3f} {s.rmse:>7.3f} {s.rmse_snr20:>8.3f} "
            f"{100 * s.within_target_snr20:>8.0f}% {100 * s.wrong_resolved:>8.1f}% "
            f"{100 * s.wrong_unresolved:>10.1f}% {s.us_per_roi_2000px:>7.0f}"
        )
    periods = sorted({p for s in scores for p in s.rmse_by_px_per_period}, reverse=True)
    lines.append("")
    lines.append("RMSE by px per period: " + " ".join(f"{p:>6g}" for p in periods))
    for s in scores:
        vals = " ".join(f"{s.rmse_by_px_per_period.get(p, math.nan):>6.3f}" for p in periods)
        lines.append(f"  {s.estimator:<21} {vals}")
    return "\n".join(lines)
