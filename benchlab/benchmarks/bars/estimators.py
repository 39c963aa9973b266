"""Speed/accuracy benchmark of the modulation estimators on synthetic bar ROIs with known truth.

The generator (:mod:`benchlab.synthetic.bars`) draws, from a seed, cases covering: bar
angle 0-90 deg (axis-aligned and oblique), period 2.2-40 px (log-uniform; plus 1.5-1.99 px,
above Nyquist), Gaussian PSF sigma 0-4 px, SNR 5-200 with Poisson shot noise and read noise,
8-bit and 12-bit (MSB-aligned) data, linear shading 0-30 %, duty 0.4-0.6, ROIs from 5 x 5 to
200 x 200, over-exposed cases that really clip, flat ROIs and below-noise ROIs. Every estimator
gets the bar frequency; the orientation only where the bars are axis-aligned (as the
procedures call them).

Definitions:

- truth: Eq. 2.9 contrast of the noiseless, blurred, pixel-integrated continuous profile.
- *measurable*: truth >= 0.05, SNR >= 5, period >= 2.2 px, unclipped, at least one period across
  the ROI. Errors are over measurable cases, "not resolved" counted as 0 (what a report prints).
  The *clipped* bucket holds cases measurable but for real clipping, scored against the
  unclipped truth (kept out of "all": no estimator can see above the top code).
- wrong res: flat, below-noise (bars whose fundamental over the noise of the whole ROI,
  ``amplitude / (noise sqrt(2 / n))``, is 0.3-1.5) or aliased (period < 2 px) cases called
  resolved.
- wrong unres: measurable cases called "not resolved".
- cover: share of measurable resolved readings whose 95 % interval holds the truth.
- us: median wall time per call in the accuracy run (worker processes on a shared machine).
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from benchlab.analysis.bars.estimators import ESTIMATORS, estimate_modulation
from benchlab.synthetic.bars import BarCase, render

MEASURABLE_TRUTH = 0.05
MEASURABLE_SNR = 5.0
MIN_PERIOD_PX = 2.2
#: Error bounds reported (modulation units).
TOLERANCES = (0.02, 0.03)
ROI_SHAPES = ((5, 5), (10, 40), (40, 50), (20, 100), (64, 64), (200, 200))


@dataclass(frozen=True)
class Case:
    """One benchmark case: the synthetic ROI parameters and its kind."""

    bar: BarCase
    kind: str  # "bars", "flat", "below-noise", "aliased"
    snr: float
    axis_aligned: bool


def _with_snr(bar: BarCase, snr: float, shot_share: float) -> BarCase:
    """``bar`` with noise set for ``snr`` (half peak-to-valley over noise at the mean), a share
    ``shot_share`` of the noise variance from Poisson shot noise."""
    amp = (bar.mean * bar.exposure_scale + bar.pedestal) * max(bar.truth, 1e-3)
    sigma = amp / snr
    shot2 = shot_share * sigma**2
    epd = bar.mean * bar.exposure_scale / shot2 if shot2 > 0 else 0.0
    return replace(bar, noise_sigma=math.sqrt(sigma**2 - shot2), electrons_per_dn=epd)


def benchmark_cases(n_cases: int = 1500, seed: int = 0) -> list[Case]:
    """``n_cases`` seeded cases: 80 % bar ROIs (a tenth of them over-exposed), then flat,
    below-noise and aliased ROIs."""
    rng = np.random.default_rng(seed)
    out: list[Case] = []
    n_bars = int(0.8 * n_cases)
    for i in range(n_cases):
        if i < n_bars:
            kind = "bars"
        else:
            kind = ("flat", "below-noise", "aliased")[i % 3]
        axis = rng.uniform() < 0.35
        angle = float(rng.choice([0.0, 90.0])) if axis else float(rng.uniform(3.0, 87.0))
        shape = ROI_SHAPES[int(rng.integers(len(ROI_SHAPES)))]
        if rng.uniform() < 0.5:
            shape = shape[::-1]
        period = float(np.exp(rng.uniform(math.log(2.2), math.log(40.0))))
        if kind == "aliased":
            period = float(rng.uniform(1.5, 1.99))
        bits = 12 if rng.uniform() < 0.4 else 8
        mean = float(rng.uniform(50.0, 120.0))
        over = kind == "bars" and rng.uniform() < 0.1
        bar = BarCase(
            shape=shape,
            px_per_period=period,
            modulation=0.0 if kind == "flat" else float(rng.uniform(0.2, 0.9)),
            mean=mean,
            psf_sigma_px=float(rng.uniform(0.0, 4.0)) if rng.uniform() < 0.8 else 0.0,
            phase=float(rng.uniform()),
            exposure_scale=float(rng.uniform(1.6, 2.5)) if over else 1.0,
            bits=bits,
            msb_aligned=bits == 12 and rng.uniform() < 0.7,
            duty=float(rng.uniform(0.4, 0.6)),
            shading=float(rng.uniform(0.0, 0.3)) if rng.uniform() < 0.6 else 0.0,
            angle_deg=angle,
            pedestal=float(rng.choice([0.0, 0.0, 8.0])),
        )
        if kind == "flat":
            snr = 50.0
            noise = bar.mean / float(rng.uniform(5.0, 200.0))
            bar = replace(bar, noise_sigma=noise)
        elif kind == "below-noise":
            # Realistic noise (mean / 10-50) and bars whose fundamental is below the noise of
            # the whole ROI (amplitude over noise * sqrt(2 / n) of 0.3-1.5): no estimator can
            # know they are there.
            n_px = bar.shape[0] * bar.shape[1]
            noise = bar.mean / float(rng.uniform(10.0, 50.0))
            amp = float(rng.uniform(0.3, 1.5)) * noise * math.sqrt(2.0 / n_px)
            bar = replace(bar, modulation=min(amp / bar.mean * 1.3, 0.5), noise_sigma=noise)
            snr = bar.snr
        else:
            snr = float(np.exp(rng.uniform(math.log(5.0), math.log(200.0))))
            bar = _with_snr(bar, snr, float(rng.uniform()))
        out.append(Case(bar=bar, kind=kind, snr=snr, axis_aligned=axis))
    return out


def is_measurable(case: Case) -> bool:
    """See the module docstring."""
    return not case.bar.clipped and _measurable_but_for_clipping(case)


def is_clipped_measurable(case: Case) -> bool:
    """Measurable but for real clipping: scored in their own bucket against the unclipped
    truth (what the bars would read on a camera that did not saturate)."""
    return case.bar.clipped and _measurable_but_for_clipping(case)


def _measurable_but_for_clipping(case: Case) -> bool:
    bar = case.bar
    if case.kind != "bars" or bar.px_per_period < MIN_PERIOD_PX:
        return False
    h, w = bar.shape
    extent = abs((w - 1) * math.cos(bar.theta_rad)) + abs((h - 1) * math.sin(bar.theta_rad))
    return bar.truth >= MEASURABLE_TRUTH and case.snr >= MEASURABLE_SNR and extent + 1 >= (
        bar.px_per_period
    )


#: One reading: case index, estimator, modulation, resolved, interval low and high, seconds.
Row = tuple[int, str, float, bool, float, float, float]


def _evaluate(
    chunk: list[tuple[int, Case]], names: tuple[str, ...]
) -> list[Row]:
    """(case, estimator, modulation, resolved, interval low, high, seconds) per call."""
    out: list[Row] = []
    for index, case in chunk:
        roi = render(case.bar, np.random.default_rng(10_000 + index))
        for name in names:
            t0 = time.perf_counter()
            r = estimate_modulation(
                roi,
                estimator=name,
                freq_cycles_per_px=case.bar.freq_cycles_per_px,
                orientation=(
                    ("horizontal" if case.bar.theta_rad < 0.1 else "vertical")
                    if case.axis_aligned
                    else None
                ),
            )
            dt = time.perf_counter() - t0
            out.append((index, name, r.modulation, r.resolved, r.interval[0], r.interval[1], dt))
    return out


@dataclass(frozen=True)
class Score:
    """One row of the table: an estimator on one bucket of cases."""

    estimator: str
    bucket: str
    n: int
    bias: float
    rmse: float
    within_002: float
    within_003: float
    wrong_resolved: int
    n_negative: int
    wrong_unresolved: int
    coverage: float
    us_median: float


def _buckets(case: Case) -> list[str]:
    bar = case.bar
    p = bar.px_per_period
    n_px = bar.shape[0] * bar.shape[1]
    out = ["all", "axis 0/90" if case.axis_aligned else "oblique"]
    out.append(
        "period 2.2-3.5" if p < 3.5 else "period 3.5-8" if p < 8 else "period 8-20"
        if p < 20 else "period 20-40"
    )
    out.append("SNR 5-10" if case.snr < 10 else "SNR 10-30" if case.snr < 30 else "SNR 30-200")
    out.append(
        "ROI 5x5" if n_px <= 25 else "ROI <=640 px" if n_px <= 640 else "ROI 2000-4096 px"
        if n_px <= 4096 else "ROI 200x200"
    )
    if case.snr >= 10:
        out.append("SNR >= 10")
    return out


def score(cases: list[Case], rows: list[tuple[int, str, float, bool, float, float, float]],
          names: tuple[str, ...]) -> list[Score]:
    """Per estimator and bucket: see the module docstring."""
    order = ["all", "axis 0/90", "oblique", "period 2.2-3.5", "period 3.5-8", "period 8-20",
             "period 20-40", "SNR 5-10", "SNR 10-30", "SNR 30-200", "SNR >= 10", "ROI 5x5",
             "ROI <=640 px", "ROI 2000-4096 px", "ROI 200x200", "clipped"]
    acc: dict[tuple[str, str], dict[str, list[float]]] = {}
    for index, name, mod, res, lo, hi, dt in rows:
        case = cases[index]
        clipped = is_clipped_measurable(case)
        keys = _buckets(case) if is_measurable(case) else ["clipped"] if clipped else ["all"]
        for b in keys:
            d = acc.setdefault((name, b), {"err": [], "miss": [], "cov": [], "t": [], "neg": []})
            d["t"].append(dt)
            if is_measurable(case) or clipped:
                d["err"].append(mod - case.bar.truth)
                d["miss"].append(float(not res))
                if res:
                    d["cov"].append(float(lo <= case.bar.truth <= hi))
            elif case.kind in ("flat", "below-noise", "aliased") and b == "all":
                d["neg"].append(float(res))
    out = []
    for name in names:
        for b in order:
            got = acc.get((name, b))
            if got is None or not got["err"]:
                continue
            d = got
            e = np.asarray(d["err"])
            out.append(Score(
                estimator=name, bucket=b, n=e.size, bias=float(e.mean()),
                rmse=float(np.sqrt(np.mean(e * e))),
                within_002=float(np.mean(np.abs(e) <= TOLERANCES[0])),
                within_003=float(np.mean(np.abs(e) <= TOLERANCES[1])),
                wrong_resolved=int(sum(d["neg"])), n_negative=len(d["neg"]),
                wrong_unresolved=int(sum(d["miss"])),
                coverage=float(np.mean(d["cov"])) if d["cov"] else math.nan,
                us_median=1e6 * float(np.median(d["t"])),
            ))
    return out


def run_benchmark(
    n_cases: int = 1500, seed: int = 0, workers: int | None = None,
    estimators: tuple[str, ...] | None = None, rows_out: list[Row] | None = None,
) -> tuple[list[Case], list[Score]]:
    """Score ``estimators`` (default all of :data:`ESTIMATORS`) on :func:`benchmark_cases`,
    using ``workers`` processes (default 2; 1 runs in this process). The raw readings
    (case index, estimator, modulation, resolved, interval, seconds) are appended to
    ``rows_out`` when given (for :func:`format_worst`)."""
    names = estimators or tuple(ESTIMATORS)
    cases = benchmark_cases(n_cases, seed)
    indexed = list(enumerate(cases))
    n_workers = workers if workers is not None else min(os.cpu_count() or 1, 2)
    if n_workers > 1 and len(indexed) > 50:
        chunks = [indexed[i :: n_workers * 4] for i in range(n_workers * 4)]
        with ProcessPoolExecutor(max_workers=n_workers) as pool:
            parts = pool.map(_evaluate, chunks, [names] * len(chunks))
            rows = [row for part in parts for row in part]
    else:
        rows = _evaluate(indexed, names)
    if rows_out is not None:
        rows_out.extend(rows)
    return cases, score(cases, rows, names)


def format_worst(cases: list[Case], rows: list[Row], n_worst: int) -> str:
    """The ``n_worst`` largest errors per estimator among measurable and clipped cases, each
    with its reading, interval and the case's parameters (what to look at first when a bucket
    misses its target); intervals missing the truth are marked ``OUT``."""
    lines = []
    by_name: dict[str, list[tuple[float, str]]] = {}
    for index, name, mod, res, lo, hi, _ in rows:
        case = cases[index]
        measurable = is_measurable(case)
        if not (measurable or is_clipped_measurable(case)):
            continue
        bar = case.bar
        err = mod - bar.truth
        covered = "" if not res else ("ok " if lo <= bar.truth <= hi else "OUT")
        shape = f"{bar.shape[0]}x{bar.shape[1]}"
        text = (
            f"{index:>5} {'clip' if not measurable else '':<4} {err:>+7.3f} {bar.truth:>6.3f} "
            f"{mod if res else math.nan:>6.3f} [{lo:.3f}, {hi:.3f}] {covered:<3}  {shape:>7} "
            f"period {bar.px_per_period:5.2f} angle {bar.angle_deg or 0.0:4.1f} "
            f"psf {bar.psf_sigma_px:4.2f} duty {bar.duty:.2f} shading {bar.shading:.2f} "
            f"SNR {case.snr:5.1f} {bar.bits}-bit{' MSB' if bar.msb_aligned else ''}"
        )
        by_name.setdefault(name, []).append((abs(err), text))
    for name, entries in by_name.items():
        entries.sort(key=lambda e: -e[0])
        lines.append(f"{name}: {min(n_worst, len(entries))} worst of {len(entries)} "
                     "(case, error, truth, reading, 95 % interval, parameters)")
        lines.extend(text for _, text in entries[:n_worst])
    return "\n".join(lines)


def time_per_roi(name: str, shape: tuple[int, int], repeats: int = 15, seed: int = 0) -> float:
    """Median microseconds of :func:`estimate_modulation` on oblique 8 px bars of ``shape``
    (frequency given, orientation not), best of 3 per ROI."""
    rng = np.random.default_rng(seed)
    per = []
    for i in range(repeats):
        bar = BarCase(shape=shape, px_per_period=8.0, angle_deg=20.0 + i, noise_sigma=2.0,
                      electrons_per_dn=20.0, phase=float(rng.uniform()))
        roi = render(bar, rng)
        best = math.inf
        for _ in range(3):
            t0 = time.perf_counter()
            estimate_modulation(roi, estimator=name, freq_cycles_per_px=0.125)
            best = min(best, time.perf_counter() - t0)
        per.append(best)
    return 1e6 * float(np.median(per))


def format_table(scores: list[Score]) -> str:
    """Plain-text table, one line per estimator and bucket."""
    head = (f"{'estimator':<14} {'bucket':<17} {'n':>5} {'bias':>7} {'RMSE':>6} {'<=.02':>6} "
            f"{'<=.03':>6} {'wrong res':>10} {'wrong unres':>11} {'cover95':>7} {'us':>7}")
    lines = [head, "-" * len(head)]
    last = ""
    for s in scores:
        if s.estimator != last and last:
            lines.append("")
        last = s.estimator
        wres = f"{s.wrong_resolved}/{s.n_negative}" if s.bucket == "all" else ""
        lines.append(
            f"{s.estimator:<14} {s.bucket:<17} {s.n:>5} {s.bias:>+7.3f} {s.rmse:>6.3f} "
            f"{100 * s.within_002:>5.0f}% {100 * s.within_003:>5.0f}% {wres:>10} "
            f"{s.wrong_unresolved:>11} {100 * s.coverage:>6.0f}% {s.us_median:>7.0f}"
        )
    return "\n".join(lines)


def format_speed(names: tuple[str, ...], shapes: tuple[tuple[int, int], ...]) -> str:
    """Median microseconds per ROI for each estimator and ROI shape (in this process)."""
    head = f"{'us per ROI':<14} " + " ".join(f"{f'{h}x{w}':>10}" for h, w in shapes)
    lines = [head]
    for name in names:
        reps = [15 if h * w <= 40_000 else 3 for h, w in shapes]
        vals = [time_per_roi(name, s, r) for s, r in zip(shapes, reps, strict=True)]
        lines.append(f"{name:<14} " + " ".join(f"{v:>10.0f}" for v in vals))
    return "\n".join(lines)
