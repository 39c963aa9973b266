"""The extremes bucket of the bar accuracy benchmark (``benchlab benchmark analysis``).

Inputs a technician produces and the seeded benchmark rarely draws: no noise, no blur, a dark
level of 0, levels clipped at full scale (8-bit 255, 12-bit 4095, 12-bit MSB-aligned 65520),
ROIs of one bar period or one pixel wide, integer-valued float TIFFs, and 16-bit frames holding
8-bit data. Each case states the answer it expects (:class:`Expect`); a reading is scored
``ok`` when it gives that answer. "Not resolved" is never the expected answer here: every case
shows its bars plainly. The answers are written out in ``docs/analysis/extremes.md``.
"""

from __future__ import annotations

import enum
import io
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.estimators import ESTIMATORS, estimate_modulation
from benchlab.analysis.bars.extremes import CENSORING
from benchlab.analysis.bars.result import ModulationResult
from benchlab.synthetic.bars import BarCase, render

#: A value within this of the truth is right (noise-free or low-noise cases).
VALUE_TOL = 0.03
#: A lower bound may exceed the truth by this much (the rounding of the codes).
BOUND_TOL = 0.01


class Expect(enum.Enum):
    """The answer a case expects."""

    VALUE_OR_BOUND = "value within 0.03, or a bound <= truth + 0.01"
    BOUND = ("a bound <= truth + 0.01; a value within 0.03 only from a model that carries the "
             "bright level above full scale (profilefit), or exactly 1 with dark 0")
    ONE = "exactly 1.000, a value (dark level 0)"
    SAME_AS_8BIT = "the reading of the same codes as uint8, to the last bit"


@dataclass(frozen=True)
class ExtremeCase:
    """One case: its bucket, the synthetic ROI, how it is stored, what it expects."""

    bucket: str
    bar: BarCase
    expect: Expect
    #: "native" (the renderer's dtype), "float-tiff" (integer-valued float32 through a TIFF),
    #: "uint16" (8-bit codes in a 16-bit frame), "clip-floor" (a black level subtracted below
    #: the dark bars: codes clipped at 0).
    storage: str = "native"
    orientation: str | None = None

    @property
    def truth(self) -> float:
        return self.bar.truth


def _bars(**kw: object) -> BarCase:
    base: dict[str, object] = dict(shape=(40, 50), px_per_period=10.0, modulation=0.6,
                                   mean=100.0, psf_sigma_px=1.0, noise_sigma=1.0)
    base.update(kw)
    return BarCase(**base)  # type: ignore[arg-type]


def extreme_cases() -> list[ExtremeCase]:
    """Every case of the extremes bucket, in bucket order (deterministic)."""
    out: list[ExtremeCase] = []
    for p, a in ((6.0, 0.0), (10.0, 90.0), (16.0, 0.0), (10.0, 30.0)):
        out.append(ExtremeCase("zero noise", _bars(px_per_period=p, angle_deg=a,
                                                   noise_sigma=0.0), Expect.VALUE_OR_BOUND))
        out.append(ExtremeCase("zero blur", _bars(px_per_period=p, angle_deg=a,
                                                  psf_sigma_px=0.0, noise_sigma=2.0),
                               Expect.VALUE_OR_BOUND))
        out.append(ExtremeCase("perfect (no noise, no blur)",
                               _bars(px_per_period=p, angle_deg=a, psf_sigma_px=0.0,
                                     noise_sigma=0.0, phase=0.1), Expect.VALUE_OR_BOUND))
    for p, a in ((10.0, 0.0), (20.0, 90.0), (8.0, 30.0)):
        out.append(ExtremeCase("dark level 0", _bars(px_per_period=p, angle_deg=a,
                                                     modulation=1.0, psf_sigma_px=0.0,
                                                     noise_sigma=0.0), Expect.ONE))
        # Dark 0, the bright level far above full scale (the 0/255 pattern).
        out.append(ExtremeCase("dark 0, bright clipped",
                               _bars(px_per_period=p, angle_deg=a, modulation=1.0, mean=200.0,
                                     psf_sigma_px=0.0, noise_sigma=0.0), Expect.ONE))
    for bits, msb in ((8, False), (12, False), (12, True)):
        for p, a, blur in ((20.0, 0.0, 0.0), (10.0, 90.0, 1.0), (12.0, 30.0, 0.5)):
            out.append(ExtremeCase(
                f"bright clipped {'12-bit MSB' if msb else f'{bits}-bit'}",
                _bars(px_per_period=p, angle_deg=a, psf_sigma_px=blur, bits=bits,
                      msb_aligned=msb, mean=150.0, exposure_scale=1.6, noise_sigma=1.0),
                Expect.BOUND))
    for p, a in ((20.0, 0.0), (10.0, 90.0)):
        out.append(ExtremeCase("both levels clipped",
                               _bars(px_per_period=p, angle_deg=a, psf_sigma_px=0.0,
                                     mean=150.0, modulation=0.9, exposure_scale=1.6,
                                     noise_sigma=1.0), Expect.BOUND, storage="clip-floor"))
    for p, phase in ((20.0, 0.25), (12.0, 0.25), (16.0, 0.0)):
        out.append(ExtremeCase("one-period ROI",
                               _bars(shape=(40, int(p)), px_per_period=p, angle_deg=0.0,
                                     phase=phase, psf_sigma_px=0.5),
                               Expect.VALUE_OR_BOUND, orientation="horizontal"))
    for shape, a, orient in (((1, 60), 0.0, "horizontal"), ((60, 1), 90.0, "vertical"),
                             ((1, 60), 0.0, None)):
        out.append(ExtremeCase("1-px-wide ROI",
                               _bars(shape=shape, px_per_period=10.0, angle_deg=a,
                                     psf_sigma_px=0.5), Expect.VALUE_OR_BOUND,
                               orientation=orient))
    for p, a, scale in ((10.0, 0.0, 1.0), (8.0, 30.0, 1.0), (12.0, 0.0, 1.6)):
        kw = dict(px_per_period=p, angle_deg=a, exposure_scale=scale, noise_sigma=2.0)
        out.append(ExtremeCase("integer float TIFF", _bars(**kw), Expect.SAME_AS_8BIT,
                               storage="float-tiff"))
        out.append(ExtremeCase("16-bit holding 8-bit", _bars(**kw), Expect.SAME_AS_8BIT,
                               storage="uint16"))
    return out


def _tiff_round_trip(pixels: npt.NDArray[np.generic]) -> npt.NDArray[np.generic]:
    """``pixels`` written to a TIFF and read back (as a user's file would be)."""
    import tifffile

    buf = io.BytesIO()
    tifffile.imwrite(buf, pixels, photometric="minisblack")
    return np.asarray(tifffile.imread(io.BytesIO(buf.getvalue())))


def roi_of(case: ExtremeCase, seed: int) -> npt.NDArray[np.generic]:
    """The case's ROI as stored (see :attr:`ExtremeCase.storage`)."""
    rng = np.random.default_rng(seed)
    if case.storage == "clip-floor":
        # A black level subtracted below the dark bars: the camera's codes minus 40, clipped
        # at 0 (and the bright bars at full scale).
        codes = render(case.bar, rng).astype(np.int64) - 40
        return np.clip(codes, 0, 255).astype(np.uint8)
    roi = render(case.bar, rng)
    if case.storage == "float-tiff":
        return _tiff_round_trip(roi.astype(np.float32))
    if case.storage == "uint16":
        return _tiff_round_trip(roi.astype(np.uint16))
    return roi


def _read(case: ExtremeCase, roi: npt.NDArray[np.generic], name: str) -> ModulationResult:
    return estimate_modulation(roi, estimator=name, freq_cycles_per_px=case.bar.freq_cycles_per_px,
                               orientation=case.orientation)


@dataclass(frozen=True)
class Outcome:
    """One reading of one case and whether it gives the expected answer."""

    case: ExtremeCase
    estimator: str
    result: ModulationResult
    ok: bool


def judge(case: ExtremeCase, r: ModulationResult, reference: ModulationResult | None) -> bool:
    """Whether ``r`` gives ``case``'s expected answer (``reference``: the uint8 reading, for
    :attr:`Expect.SAME_AS_8BIT`)."""
    if case.expect is Expect.SAME_AS_8BIT:
        return reference is not None and (r.modulation, r.resolved, r.lower_bound) == (
            reference.modulation, reference.resolved, reference.lower_bound)
    if not r.resolved:
        return False
    if case.expect is Expect.ONE:
        return r.modulation == 1.0 and not r.lower_bound
    truth = case.truth if case.storage != "clip-floor" else 1.0  # its dark is below 0
    if r.lower_bound:
        return r.modulation <= truth + BOUND_TOL
    if case.expect is Expect.BOUND and r.modulation == 1.0:
        # exactly 1 only where the dark level is 0 (clipped there: below the black level)
        return case.storage == "clip-floor"
    if case.expect is Expect.BOUND and r.estimator not in CENSORING:
        return False  # a plain value from clipped data
    return abs(r.modulation - truth) <= VALUE_TOL


def run_extremes(estimators: tuple[str, ...] | None = None, seed: int = 0) -> list[Outcome]:
    """Every estimator (default all of :data:`ESTIMATORS`) on every :func:`extreme_cases`."""
    names = estimators or tuple(ESTIMATORS)
    out = []
    for i, case in enumerate(extreme_cases()):
        roi = roi_of(case, seed + i)
        native = render(case.bar, np.random.default_rng(seed + i))
        for name in names:
            r = _read(case, roi, name)
            ref = _read(case, native, name) if case.expect is Expect.SAME_AS_8BIT else None
            out.append(Outcome(case, name, r, judge(case, r, ref)))
    return out


def format_extremes(outcomes: list[Outcome]) -> str:
    """Per estimator and bucket: cases, ok, values, bounds, "not resolved", the largest error
    of a value and the largest excess of a bound over the truth."""
    head = (f"{'estimator':<16} {'extremes bucket':<27} {'n':>3} {'ok':>3} {'value':>5} "
            f"{'bound':>5} {'unres':>5} {'max|err|':>8} {'bound-truth':>11}")
    lines = [head, "-" * len(head)]
    groups: dict[tuple[str, str], list[Outcome]] = {}
    names = list(dict.fromkeys(o.estimator for o in outcomes))
    buckets = list(dict.fromkeys(o.case.bucket for o in outcomes))
    for o in outcomes:
        groups.setdefault((o.estimator, o.case.bucket), []).append(o)
    last = ""
    for name, bucket in ((n, b) for n in names for b in buckets if (n, b) in groups):
        got = groups[(name, bucket)]
        if name != last and last:
            lines.append("")
        last = name
        values = [o for o in got if o.result.resolved and not o.result.lower_bound]
        bounds = [o for o in got if o.result.lower_bound]
        truth = {id(o): (1.0 if o.case.storage == "clip-floor" else o.case.truth) for o in got}
        err = max((abs(o.result.modulation - truth[id(o)]) for o in values), default=math.nan)
        over = max((o.result.modulation - truth[id(o)] for o in bounds), default=math.nan)
        lines.append(
            f"{name:<16} {bucket:<27} {len(got):>3} {sum(o.ok for o in got):>3} "
            f"{len(values):>5} {len(bounds):>5} "
            f"{sum(not o.result.resolved for o in got):>5} "
            f"{'-' if math.isnan(err) else f'{err:.3f}':>8} "
            f"{'-' if math.isnan(over) else f'{over:+.3f}':>11}")
    return "\n".join(lines)


def expected_answers() -> str:
    """Each bucket and the answer its cases expect (the legend printed under the table)."""
    seen: dict[str, Expect] = {}
    for c in extreme_cases():
        seen.setdefault(c.bucket, c.expect)
    return "\n".join(f"  {b}: {e.value}" for b, e in seen.items())
