"""The limits buckets of the bar accuracy benchmark (``benchlab benchmark analysis --limits-only``).

Cases at the sampling limit and at the codes' limits that the seeded benchmark draws too rarely
to show (issue 37), each bucket seeded and scored against the exact truth of
:mod:`benchlab.synthetic.bars`:

- *near-Nyquist narrow ROI*: 2.1-2.45 px per period across an ROI 10-14 px wide (the live
  view's default ROI on the forward view's finest elements), frequency given, the orientation
  given for half of them.
- *period 2.0-2.1 px*, with and without the frequency: a value whose interval holds the truth,
  or a lower bound.
- *integer period 3 / 4 / 5 px, sharp*: axis-aligned bars at exactly 3, 4 or 5 px per period,
  duty 0.4-0.6, PSF sigma 0-0.2 px, orientation and frequency given (half as many cases each).
- *two-code*: noise-free bars with their edges on pixel boundaries (two codes in the ROI).
- *over-exposed*: the bright level 1.2-2.5 x full scale, scored against the unclipped truth:
  a value within 0.03 or a lower bound.
- *bar structure vs noise*: small ROIs of slightly rotated sharp bars: the noise the estimator
  reports over the true per-pixel noise (it must not take the bars for noise).
- *element with its ground*: an uncropped ROI over a whole three-bar element (bars 3-5 px
  wide, contrast 0.5-0.9, 0-45 deg, 8-bit) with 3 px of ground around it, half of them with
  the frequency given (:func:`benchlab.synthetic.threebar.element_with_ground`).

Columns: ``n``; values, bounds and "not resolved"; RMSE, the share within 0.02 and the 95 %
interval coverage of the values; ``ok`` = the answer the bucket expects (a value within 0.03
whose interval holds the truth, or a bound at most 0.01 above it); ``false 1`` = "resolved
1.000" where the truth is below 0.9; the largest excess of a bound over the truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.bars.result import ModulationResult, eq29_modulation
from benchlab.synthetic.bars import BarCase, render
from benchlab.synthetic.threebar import element_with_ground

#: A value within this of the truth (and an interval holding it) is right.
VALUE_TOL = 0.03
#: A lower bound may exceed the truth by this much.
BOUND_TOL = 0.01
#: A "resolved 1.000" below this truth is a false one.
FALSE_ONE_TRUTH = 0.9
BUCKETS = ("near-Nyquist narrow ROI", "period 2.0-2.1 px, freq", "period 2.0-2.1 px, blind",
           "integer period 3 px, sharp", "integer period 4 px, sharp",
           "integer period 5 px, sharp", "two-code", "over-exposed", "bar structure vs noise",
           "element with its ground")


@dataclass(frozen=True)
class LimitCase:
    """One case: its bucket, how to make the ROI, the truth, what the call is given."""

    bucket: str
    bar: BarCase | None  # None: ``codes`` holds the ROI (two-code cases) or ``element`` does
    codes: tuple[tuple[int, ...], ...] | None
    truth: float
    freq: float | None
    orientation: str | None
    noise: float  # true per-pixel noise (gray units of the stored codes)
    #: A three-bar element on its ground: bar width (px), angle (deg), ground and bar levels.
    element: tuple[float, float, float, float] | None = None


def _noise_for(bar: BarCase, snr: float) -> BarCase:
    amp = bar.mean * max(bar.truth, 1e-3)
    return replace(bar, noise_sigma=amp / snr)


def _axis_case(rng: np.random.Generator, bucket: str, period: float, across: int,
               along: int, psf: float, give_orientation: bool, give_freq: bool = True,
               snr: tuple[float, float] = (10.0, 200.0)) -> LimitCase:
    horizontal = bool(rng.uniform() < 0.5)
    orient = "horizontal" if horizontal else "vertical"
    bits = 12 if rng.uniform() < 0.4 else 8
    bar = BarCase(shape=(along, across) if horizontal else (across, along),
                  px_per_period=period, modulation=float(rng.uniform(0.3, 0.9)),
                  mean=float(rng.uniform(60.0, 110.0)), psf_sigma_px=psf,
                  phase=float(rng.uniform()), orientation=orient, bits=bits,
                  duty=float(rng.uniform(0.45, 0.55)))
    bar = _noise_for(bar, float(np.exp(rng.uniform(math.log(snr[0]), math.log(snr[1])))))
    scale = 16.0 if bits == 12 else 1.0
    return LimitCase(bucket, bar, None, bar.truth, bar.freq_cycles_per_px if give_freq else None,
                     orient if give_orientation else None, bar.noise_sigma * scale)


def limit_cases(seed: int = 0, per_bucket: int = 60) -> list[LimitCase]:
    """``per_bucket`` seeded cases in every bucket of :data:`BUCKETS` (in that order; half as
    many in each whole-period bucket and the element bucket, drawn last so the others keep
    their cases)."""
    rng = np.random.default_rng(seed)
    out: list[LimitCase] = []
    for i in range(per_bucket):
        out.append(_axis_case(rng, BUCKETS[0], float(rng.uniform(2.1, 2.45)),
                              int(rng.integers(10, 15)), int(rng.integers(10, 41)),
                              float(rng.uniform(0.0, 1.0)), give_orientation=i % 2 == 0))
    for bucket, give_freq in ((BUCKETS[1], True), (BUCKETS[2], False)):
        for i in range(per_bucket):
            across, along = ((40, 50), (50, 40), (100, 20), (64, 64), (12, 40))[i % 5]
            # PSF up to 0.6 px: more blur leaves no contrast at 2 px per period.
            out.append(_axis_case(rng, bucket, float(rng.uniform(2.0, 2.1)), across, along,
                                  float(rng.uniform(0.0, 0.6)), give_orientation=i % 2 == 0,
                                  give_freq=give_freq))
    for period in (3, 4, 5):
        for i in range(per_bucket // 2):
            across, along = ((50, 40), (40, 50), (100, 20), (64, 64))[i % 4]
            c = _axis_case(rng, BUCKETS[period], float(period), across, along,
                           float(rng.uniform(0.0, 0.2)), give_orientation=True,
                           snr=(20.0, 200.0))
            assert c.bar is not None
            bar = replace(c.bar, duty=float(rng.uniform(0.4, 0.6)))
            out.append(replace(c, bar=bar, truth=bar.truth))
    for i in range(per_bucket):
        bits = 12 if i % 3 == 0 else 8
        top = 4095 if bits == 12 else 255
        lo = int(rng.integers(0, top // 2))
        hi = int(rng.integers(lo + max(top // 50, 2), top))  # below full scale
        bright_px, dark_px = int(rng.integers(1, 7)), int(rng.integers(1, 7))
        row = ([hi] * bright_px + [lo] * dark_px) * 40
        start = int(rng.integers(0, bright_px + dark_px))
        width = int(rng.integers(max(14, 2 * (bright_px + dark_px)), 60))
        line = tuple(row[start:start + width])
        codes = tuple(line for _ in range(int(rng.integers(5, 41))))
        out.append(LimitCase(BUCKETS[6], None, codes, eq29_modulation(lo, hi),
                             1.0 / (bright_px + dark_px), "horizontal" if i % 2 else None, 0.0))
    for i in range(per_bucket):
        axis = i % 3 == 0
        bits = 12 if rng.uniform() < 0.4 else 8
        # The bright bars 1.2-2.5 x full scale (255 in the 8-bit units of the generator), the
        # dark ones 0.1-0.8 x.
        dark, bright = 255.0 * float(rng.uniform(0.1, 0.8)), 255.0 * float(rng.uniform(1.2, 2.5))
        mean, modulation = (dark + bright) / 2.0, (bright - dark) / (bright + dark)
        bar = BarCase(shape=((40, 50), (64, 64), (20, 100))[i % 3],
                      px_per_period=float(np.exp(rng.uniform(math.log(3.0), math.log(30.0)))),
                      modulation=modulation, mean=mean,
                      psf_sigma_px=float(rng.uniform(0.0, 3.0)), phase=float(rng.uniform()),
                      bits=bits,
                      msb_aligned=bits == 12 and rng.uniform() < 0.7,
                      duty=float(rng.uniform(0.4, 0.6)),
                      angle_deg=float(rng.choice([0.0, 90.0])) if axis
                      else float(rng.uniform(3.0, 87.0)))
        bar = _noise_for(bar, float(np.exp(rng.uniform(math.log(10.0), math.log(200.0)))))
        # Less blur until the imaged dark bars lie below full scale (else every pixel clips).
        while bar.truth < 0.05 or bar.mean * (1.0 - bar.truth) >= 0.9 * 255.0:
            bar = replace(bar, psf_sigma_px=bar.psf_sigma_px / 2.0)
        orient = ("horizontal" if bar.theta_rad < 0.1 else "vertical") if axis else None
        scale = 16.0 if bits == 12 else 1.0
        out.append(LimitCase(BUCKETS[7], bar, None, bar.truth, bar.freq_cycles_per_px, orient,
                             bar.noise_sigma * scale))
    for _ in range(per_bucket):
        bar = BarCase(shape=(26, 26), px_per_period=float(rng.uniform(4.0, 12.0)),
                      modulation=float(rng.uniform(0.5, 0.9)), mean=float(rng.uniform(60, 110)),
                      psf_sigma_px=float(rng.uniform(0.0, 0.7)), phase=float(rng.uniform()),
                      noise_sigma=float(rng.uniform(1.0, 4.0)),
                      angle_deg=float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.5, 4.0)))
        out.append(LimitCase(BUCKETS[8], bar, None, bar.truth, bar.freq_cycles_per_px, None,
                             bar.noise_sigma))
    for i in range(per_bucket // 2):
        w = float(rng.uniform(3.0, 5.0))
        ground = float(rng.uniform(120.0, 230.0))
        m = float(rng.uniform(0.5, 0.9))
        bar_level = ground * (1.0 - m) / (1.0 + m)
        noise = float(rng.uniform(1.0, 4.0))
        out.append(LimitCase(BUCKETS[9], None, None, eq29_modulation(bar_level, ground),
                             1.0 / (2.0 * w) if i % 2 else None, None, noise,
                             (w, float(rng.uniform(0.0, 45.0)), ground, bar_level)))
    return out


def roi_of(case: LimitCase, seed: int) -> npt.NDArray[np.generic]:
    """The case's ROI (codes as a camera stores them)."""
    if case.element is not None:
        w, theta, ground, bar = case.element
        return element_with_ground(w, theta, ground, bar, math.ceil(5.0 * w) + 6, case.noise,
                                   np.random.default_rng(seed))
    if case.codes is not None:
        top = max(max(r) for r in case.codes)
        return np.asarray(case.codes, dtype=np.uint8 if top <= 255 else np.uint16)
    assert case.bar is not None
    return render(case.bar, np.random.default_rng(seed))


@dataclass(frozen=True)
class LimitOutcome:
    """One reading of one case."""

    case: LimitCase
    result: ModulationResult

    @property
    def ok(self) -> bool:
        """The answer the bucket expects (module docstring)."""
        r, truth = self.result, self.case.truth
        if not r.resolved:
            return False
        if r.lower_bound:
            return r.modulation <= truth + BOUND_TOL
        return abs(r.modulation - truth) <= VALUE_TOL and r.interval[0] <= truth <= r.interval[1]

    @property
    def false_one(self) -> bool:
        r = self.result
        return r.resolved and not r.lower_bound and r.modulation >= 0.9995 and (
            self.case.truth < FALSE_ONE_TRUTH)


def run_limits(estimator: str = "auto", seed: int = 0, per_bucket: int = 60
               ) -> list[LimitOutcome]:
    """``estimator`` on every :func:`limit_cases` case."""
    out = []
    for i, case in enumerate(limit_cases(seed, per_bucket)):
        roi = roi_of(case, 20_000 + seed + i)
        r = estimate_modulation(roi, estimator=estimator, freq_cycles_per_px=case.freq,
                                orientation=case.orientation)
        out.append(LimitOutcome(case, r))
    return out


def format_limits(outcomes: list[LimitOutcome]) -> str:
    """The table: per bucket, the counts and scores of the module docstring; the noise bucket
    adds the median and largest ratio of the reported noise to the true one."""
    head = (f"{'limits bucket':<30} {'n':>3} {'value':>5} {'bound':>5} {'unres':>5} "
            f"{'RMSE':>6} {'<=0.02':>6} {'cover':>5} {'ok':>4} {'false 1':>7} "
            f"{'bound-truth':>11}")
    lines = [head, "-" * len(head)]
    for bucket in BUCKETS:
        got = [o for o in outcomes if o.case.bucket == bucket]
        if not got:
            continue
        values = [o for o in got if o.result.resolved and not o.result.lower_bound]
        bounds = [o for o in got if o.result.lower_bound]
        err = np.array([o.result.modulation - o.case.truth for o in values])
        cover = [o.result.interval[0] <= o.case.truth <= o.result.interval[1] for o in values]
        over = max((o.result.modulation - o.case.truth for o in bounds), default=math.nan)
        rmse = f"{math.sqrt(float(np.mean(err * err))):.4f}" if err.size else "-"
        within = f"{100 * float(np.mean(np.abs(err) <= 0.02)):.0f}%" if err.size else "-"
        cov = f"{100 * float(np.mean(cover)):.0f}%" if cover else "-"
        lines.append(
            f"{bucket:<30} {len(got):>3} {len(values):>5} {len(bounds):>5} "
            f"{sum(not o.result.resolved for o in got):>5} {rmse:>6} {within:>6} {cov:>5} "
            f"{sum(o.ok for o in got):>4} {sum(o.false_one for o in got):>7} "
            f"{'-' if math.isnan(over) else f'{over:+.3f}':>11}")
        if bucket in (BUCKETS[8], BUCKETS[9]):
            ratio = np.array([o.result.diagnostics.noise_sigma / o.case.noise for o in got
                              if o.case.noise > 0])
            lines.append(f"{'':<30} reported / true noise: median {np.median(ratio):.2f}, "
                         f"largest {ratio.max():.2f}")
    return "\n".join(lines)
