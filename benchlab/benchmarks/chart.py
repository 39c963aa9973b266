"""``benchlab benchmark chart``: the chart finder scored against the simulated bench's truth.

Each trial renders the forward-view USAF scene at a random pose (scale 0.7-1.4, rotation +-15
deg, offset anywhere the chart fits inside the lit forward disc), with vignetting (10-35 % at
the disc edge), dust (dark blurred spots) and a scratch multiplied into the light, a positive
or negative target, through the camera's sensor model (Poisson + read noise, 12-bit ADC, 8 or
12-bit frames). The finder's output is compared with the scene:

- **imaged** sets lie wholly inside the frame and the lit disc; **found and correctly
  labelled** ones are reported found with their centre within half a bar width of the true
  centre of the set of that label; **wrongly labelled** ones are reported found but further;
- **centre error**: found set centre vs true centre, and bar-set ROI box centre vs the true
  set's;
- **modulation**: the chart's own reading (:meth:`FoundElement.measure`: the three-bar set
  fitted at the geometry the pose gives it, on the measurement ROI - three whole periods, bar
  ends trimmed) vs the scene's truth (:meth:`UsafScene.truth_levels_dn8` in the frame's codes,
  :func:`frame_truth_modulation`), for dust-free sets below Nyquist: the share within
  :data:`MODULATION_TOL` over every found set (a set marked not measurable, or read "not
  resolved", counts as a miss, with its reason counted), and the share of 95 % intervals that
  hold the truth; per period bucket, oblique and on the axes (the control frames give most of
  the latter). For reference the default generic estimator on the same ROIs with the set's
  priors (:meth:`FoundElement.estimator_priors`), where the finder deems it reliable
  (:attr:`FoundElement.generic_unreliable`; the others count as misses);
- **time**: :func:`find_chart` on the full 1280 x 1024 frame.
"""

from __future__ import annotations

import math
import statistics
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis import DEFAULT_ESTIMATOR, estimate_modulation
from benchlab.analysis.bars.knownbars import NAME as CHART_READING
from benchlab.analysis.bars.knownbars import read_three_bars
from benchlab.analysis.bars.result import ModulationResult, eq29_modulation
from benchlab.analysis.chart.finder import (
    GENERIC_MIN_OBLIQUE_PX_PER_PERIOD,
    ChartNotFoundError,
    FoundElement,
    find_chart,
)
from benchlab.analysis.chart.layout import box_centroid
from benchlab.analysis.chart.pose import ChartPose, PosedBarSet
from benchlab.analysis.chart.reading import read_chart
from benchlab.drivers.mightex.sim_sensor import SensorModel
from benchlab.drivers.sensor import SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX, AcquisitionState
from benchlab.scenes.usaf import UsafScene
from benchlab.synthetic.threebar import PsfSpec, render_three_bars

SCALE_RANGE = (0.7, 1.4)
ROTATION_DEG = 15.0
VIGNETTING_RANGE = (0.10, 0.35)
#: Bars at least this wide (px) are the ones the 99 % target is about.
WIDE_BAR_PX = 3.0
#: Modulation agreement asked for.
MODULATION_TOL = 0.03
#: Non-phase-sensitive sets: at least this many px per period (below 0.35 cycles/px).
WELL_SAMPLED_PX = 1.0 / 0.35
#: Period buckets (px per period) of the per-bucket modulation table: (low, high, label).
PERIOD_BUCKETS: tuple[tuple[float, float, str], ...] = (
    (2.0, 2.25, "2-2.25"), (2.25, 2.5, "2.25-2.5"), (2.5, 3.0, "2.5-3"), (3.0, 4.0, "3-4"),
    (4.0, math.inf, ">=4"),
)
#: Mean offset of an 8-bit code (the top 8 of 12 bits) below the 12-bit mean / 16.
TRUNCATION_DN8 = 15.0 / 32.0


@dataclass
class _Tally:
    imaged: int = 0
    found: int = 0
    imaged_wide: int = 0
    found_wide: int = 0
    wrong: int = 0
    centre_err: list[float] = field(default_factory=list)
    roi_err: list[float] = field(default_factory=list)
    times_s: list[float] = field(default_factory=list)
    read_times_s: list[float] = field(default_factory=list)
    cpu_s: list[float] = field(default_factory=list)
    not_found_frames: int = 0
    dusty: int = 0
    found_clean: int = 0
    found_clean_wide: int = 0
    readings: list[_Reading] = field(default_factory=list)


@dataclass(frozen=True)
class _Reading:
    """One found dust-free set: its period and axis, the chart reading's error (None when it
    gave no number) and whether its interval held the truth, the reason when no number, and
    the generic estimator's error (None when not reliable or not resolved)."""

    px_per_period: float
    axis_aligned: bool
    wide: bool
    err: float | None
    covered: bool
    reason: str | None
    err_generic: float | None
    err_histogram: float | None
    half_width: float | None = None
    generic_covered: bool = False


def _dust(rng: np.random.Generator, scene: UsafScene, shape: tuple[int, int]) -> npt.NDArray[
    np.float64
]:
    """Transmission map: dark blurred spots and one scratch over the lit disc."""
    h, w = shape
    out = np.ones(shape)
    cr, cc = scene.circles.centre_rc
    rad = scene.circles.disc_radius_px
    rows = np.arange(h, dtype=np.float64)[:, None]
    cols = np.arange(w, dtype=np.float64)[None, :]
    for _ in range(int(rng.integers(4, 10))):
        a, rr = rng.uniform(0, 2 * math.pi), rad * math.sqrt(rng.uniform(0, 1))
        y, x = cr + rr * math.sin(a), cc + rr * math.cos(a)
        s, depth = rng.uniform(0.8, 3.5), rng.uniform(0.3, 0.8)
        r0, r1 = max(int(y - 5 * s), 0), min(int(y + 5 * s) + 2, h)
        c0, c1 = max(int(x - 5 * s), 0), min(int(x + 5 * s) + 2, w)
        blob = np.exp(-((rows[r0:r1] - y) ** 2 + (cols[:, c0:c1] - x) ** 2) / (2 * s * s))
        out[r0:r1, c0:c1] *= 1.0 - depth * blob
    # one thin scratch: a line of half-transmission, 0.7 px wide, across part of the disc
    a = rng.uniform(0, math.pi)
    y0, x0 = cr + rng.uniform(-rad, rad) * 0.6, cc + rng.uniform(-rad, rad) * 0.6
    dist = np.abs((cols - x0) * math.sin(a) - (rows - y0) * math.cos(a))
    along = (cols - x0) * math.cos(a) + (rows - y0) * math.sin(a)
    out *= 1.0 - 0.5 * np.exp(-(dist**2) / (2 * 0.35**2)) * (np.abs(along) < rad * 0.4)
    return out


def _fits(scene: UsafScene, sets: list[PosedBarSet], margin_px: float = 3.0) -> int:
    """How many sets lie wholly inside the lit disc."""
    cr, cc = scene.circles.centre_rc
    lim = scene.circles.disc_radius_px - margin_px
    return sum(all(math.hypot(r - cr, c - cc) <= lim for r, c in s.corners()) for s in sets)


def _random_scene(rng: np.random.Generator, upright: bool = False) -> UsafScene:
    scale = rng.uniform(*SCALE_RANGE)
    rot = 0.0 if upright else rng.uniform(-ROTATION_DEG, ROTATION_DEG)
    base = UsafScene(vignetting=float(rng.uniform(*VIGNETTING_RANGE)),
                     negative=bool(rng.uniform() < 0.25))
    best: tuple[int, UsafScene] | None = None
    n_sets = 2 * len(base.layout.elements)
    for _ in range(60):  # offset anywhere the chart fits in the disc (or fits best)
        off = (float(rng.uniform(-220, 220)), float(rng.uniform(-220, 220)))
        scene = UsafScene(pose=ChartPose(off, scale, rot), vignetting=base.vignetting,
                          negative=base.negative)
        n = _fits(scene, _sets(scene))
        if best is None or n > best[0]:
            best = (n, scene)
        if n == n_sets:
            break
    assert best is not None
    return best[1]


def _sets(scene: UsafScene) -> list[PosedBarSet]:
    return [scene.bar_set(g, e, o)  # type: ignore[arg-type]
            for g, e in scene.layout.elements for o in ("sagittal", "tangential")]


def run_chart_benchmark(frames: int = 40, seed: int = 0, control_frames: int = 8) -> dict[str, Any]:
    """Score the finder over ``frames`` random poses; returns the summary figures.

    ``control_frames`` more poses at rotation 0 (bars on the pixel axes) score the modulation
    alone: they separate the ROIs' placement from the estimator's handling of oblique bars.
    """
    rng = np.random.default_rng(seed)
    tally, control = _Tally(), _Tally()
    for i in range(frames + control_frames):
        upright = i >= frames
        _trial(rng, seed + i, i, control if upright else tally, upright)
    summary = _summary(tally, frames)
    summary["control_modulation_n"] = sum(r.err is not None for r in control.readings)
    summary["control_modulation_within"] = _read_share([r.err for r in control.readings])
    summary["control_found_clean"] = control.found_clean
    summary["control_modulation_within_all"] = _within([r.err for r in control.readings])
    summary["control_generic_within_all"] = _within([r.err_generic for r in control.readings])
    summary["buckets"] = _bucket_rows(tally.readings + control.readings)
    summary["control_frames"] = control_frames
    return summary


def _trial(rng: np.random.Generator, seed: int, i: int, tally: _Tally, upright: bool) -> None:
    """One random pose: render, add dust and sensor noise, find, score."""
    shape = (SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX)
    scene = _random_scene(rng, upright)
    bits = 12 if i % 2 else 8
    dust = _dust(rng, scene, shape)
    rate = scene.render(*shape) * dust
    state = AcquisitionState(exposure_ms=300.0, gain=1.0, bits=bits, width=shape[1],
                             height=shape[0], time_s=0.0, frame_index=i)
    dn12 = SensorModel(seed).render_dn12(lambda _s: rate, state).reshape(shape)
    pixels = (dn12 >> 4).astype(np.uint8) if bits == 8 else dn12.copy()
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        fit = find_chart(pixels)
    except ChartNotFoundError:
        tally.not_found_frames += 1
        fit = None
    tally.times_s.append(time.perf_counter() - t0)
    tally.cpu_s.append(time.process_time() - c0)
    _score(tally, scene, dust, pixels, fit, bits)


def frame_truth_modulation(scene: UsafScene, truth: PosedBarSet, bits: int) -> float:
    """The scene's Eq. 2.9 truth in the frame's own codes.

    :meth:`UsafScene.truth_levels_dn8` are mean codes on the 8-bit scale; a 12-bit frame rounds
    its codes (no offset), but an 8-bit frame keeps the top 8 of the 12 bits (``dn12 >> 4``), so
    its codes are on average ``15/32`` of a code below them: 0.5 % of a 20-code dark level,
    which lifts every 8-bit reading by ~0.004 against the rate-based truth.
    """
    dark, bright = scene.truth_levels_dn8(truth.group, truth.element, truth.orientation)
    if bits == 8:
        dark, bright = dark - TRUNCATION_DN8, bright - TRUNCATION_DN8
    return eq29_modulation(dark, bright)


def _reason_key(note: str) -> str:
    """A short key for a 'not measured' note or a 'not resolved' warning (no figures)."""
    if "px per period" in note:
        return "period too fine on oblique bars"
    if "periods across" in note:
        return "ROI spans too few periods"
    if "standard errors" in note:
        return "bars not above the noise"
    if "too few pixels" in note:
        return "too few pixels"
    return note


def _read(el: FoundElement, res: ModulationResult, pixels: npt.NDArray[Any],
          truth: float) -> _Reading:
    """Score one found set: the chart reading ``res``, and the generic estimators for
    reference."""
    p = el.posed
    reason = el.unmeasurable
    if reason is None and not res.resolved:
        reason = next((w for w in res.warnings if "not resolved" in w), "not resolved")
    err = res.modulation - truth if reason is None else None
    covered = reason is None and res.interval[0] <= truth <= res.interval[1]
    err_generic = err_hist = None
    generic_covered = False
    if el.generic_unreliable is None:
        r0, c0, r1, c1 = el.measurement_roi
        priors = el.estimator_priors()
        gen = estimate_modulation(pixels[r0:r1, c0:c1], estimator=DEFAULT_ESTIMATOR, **priors)
        err_generic = gen.modulation - truth if gen.resolved else None
        generic_covered = gen.resolved and gen.interval[0] <= truth <= gen.interval[1]
        hist = estimate_modulation(pixels[r0:r1, c0:c1], estimator="histogram",
                                   freq_cycles_per_px=priors["freq_cycles_per_px"])
        err_hist = hist.modulation - truth if hist.resolved else None
    half = 0.5 * (res.interval[1] - res.interval[0]) if reason is None else None
    return _Reading(p.px_per_period, p.axis_aligned, p.bar_width_px >= WIDE_BAR_PX, err,
                    covered, reason, err_generic, err_hist, half, generic_covered)


def _score(tally: _Tally, scene: UsafScene, dust: npt.NDArray[np.float64],
           pixels: npt.NDArray[Any], fit: Any, bits: int) -> None:
    cr, cc = scene.circles.centre_rc
    lim = scene.circles.disc_radius_px - 3.0
    h, w = pixels.shape
    readings: dict[str, ModulationResult] = {}
    if fit is not None:
        t0 = time.perf_counter()
        readings = dict(zip([e.label for e in fit.found], read_chart(pixels, fit), strict=True))
        tally.read_times_s.append(time.perf_counter() - t0)
    for truth in _sets(scene):
        corners = truth.corners()
        imaged = all(math.hypot(r - cr, c - cc) <= lim and 0 <= r <= h - 1 and 0 <= c <= w - 1
                     for r, c in corners)
        below_nyquist = truth.px_per_period >= 2.0
        wide = truth.bar_width_px >= WIDE_BAR_PX
        if not (imaged and below_nyquist):
            continue
        tally.imaged += 1
        tally.imaged_wide += wide
        if fit is None:
            continue
        el = fit.element(truth.group, truth.element, truth.orientation)
        if not el.found:
            continue
        err = math.dist(el.posed.centre_rc, truth.centre_rc)
        if err > 0.5 * truth.bar_width_px:
            continue  # counted as wrongly labelled below
        tally.found += 1
        tally.found_wide += wide
        tally.centre_err.append(err)
        tally.roi_err.append(math.dist(box_centroid(el.roi), box_centroid(truth.roi)))
        rs = [round(r) for r, _ in corners]
        cs = [round(c) for _, c in corners]
        if float(dust[min(rs):max(rs) + 1, min(cs):max(cs) + 1].min()) < 0.98:
            tally.dusty += 1
            continue
        tally.found_clean += 1
        tally.found_clean_wide += wide
        tally.readings.append(_read(el, readings[el.label], pixels,
                                    frame_truth_modulation(scene, truth, bits)))
    # every element reported found but away from the true set of its label is wrongly labelled
    if fit is not None:
        for el in fit.found:
            t = scene.bar_set(el.posed.group, el.posed.element, el.posed.orientation)
            if math.dist(el.posed.centre_rc, t.centre_rc) > 0.5 * t.bar_width_px:
                tally.wrong += 1


def _within(errs: list[float | None]) -> float:
    """Share of the sets read within :data:`MODULATION_TOL` (None: no reading, a miss)."""
    return sum(e is not None and abs(e) <= MODULATION_TOL for e in errs) / len(errs) if errs \
        else math.nan


def _read_share(errs: list[float | None]) -> float:
    """Share within the tolerance of the sets that gave a number."""
    return _within([e for e in errs if e is not None])


def _bucket_rows(readings: list[_Reading]) -> list[dict[str, Any]]:
    """Per period bucket, oblique then on the axes: count, share within the tolerance, interval
    coverage, sets without a number, and the generic estimator's share."""
    out = []
    for axis in (False, True):
        for lo, hi, label in PERIOD_BUCKETS:
            sel = [r for r in readings if r.axis_aligned == axis and lo <= r.px_per_period < hi]
            out.append({
                "bars": "axis" if axis else "oblique", "px_per_period": label, "n": len(sel),
                "within": _within([r.err for r in sel]),
                "coverage": sum(r.covered for r in sel) / len(sel) if sel else math.nan,
                "no_number": sum(r.err is None for r in sel),
                "half_width_median": statistics.median(halves) if (halves := [
                    r.half_width for r in sel if r.half_width is not None]) else math.nan,
                "abs_err_p95": float(np.percentile([abs(r.err) for r in sel if r.err is not None],
                                                   95)) if any(r.err is not None for r in sel)
                else math.nan,
                "generic_within": _within([r.err_generic for r in sel]),
                "generic_read": sum(r.err_generic is not None for r in sel),
                "generic_coverage": (sum(r.generic_covered for r in sel) / len(sel) if sel
                                     else math.nan),
            })
    return out


def _summary(t: _Tally, frames: int) -> dict[str, Any]:
    def med(v: list[float]) -> float:
        return statistics.median(v) if v else math.nan

    return {
        "frames": frames, "frames_without_chart": t.not_found_frames,
        "imaged_sets": t.imaged, "found_share": t.found / t.imaged if t.imaged else math.nan,
        "imaged_wide": t.imaged_wide,
        "found_share_wide": t.found_wide / t.imaged_wide if t.imaged_wide else math.nan,
        "wrongly_labelled": t.wrong,
        "centre_err_median_px": med(t.centre_err),
        "centre_err_max_px": max(t.centre_err) if t.centre_err else math.nan,
        "roi_centre_err_median_px": med(t.roi_err),
        "roi_centre_err_max_px": max(t.roi_err) if t.roi_err else math.nan,
        "dusty_sets": t.dusty,
        "found_clean": t.found_clean, "found_clean_wide": t.found_clean_wide,
        "reading": CHART_READING,
        "no_number": dict(Counter(_reason_key(r.reason) for r in t.readings if r.reason)),
        "modulation_n": sum(r.err is not None for r in t.readings),
        "modulation_within_all": _within([r.err for r in t.readings]),
        "modulation_within": _read_share([r.err for r in t.readings]),
        "modulation_wide_within_all": _within([r.err for r in t.readings if r.wide]),
        "modulation_coverage": (sum(r.covered for r in t.readings) / len(t.readings)
                                if t.readings else math.nan),
        "modulation_median_abs": med([abs(r.err) for r in t.readings if r.err is not None]),
        "generic_n": sum(r.err_generic is not None for r in t.readings),
        "generic_within_all": _within([r.err_generic for r in t.readings]),
        "generic_within": _read_share([r.err_generic for r in t.readings]),
        "histogram_within": _read_share([r.err_histogram for r in t.readings]),
        "read_time_median_s": med(t.read_times_s),
        "time_median_s": med(t.times_s), "time_max_s": max(t.times_s) if t.times_s else math.nan,
        "cpu_median_s": med(t.cpu_s), "cpu_max_s": max(t.cpu_s) if t.cpu_s else math.nan,
        "estimator": DEFAULT_ESTIMATOR,
    }


def format_benchmark(s: dict[str, Any]) -> str:
    """The summary as a table with the issue's targets beside the figures, then the modulation
    per period bucket."""
    rows = [
        ("frames (no chart found)", f"{s['frames']} ({s['frames_without_chart']})", ""),
        ("imaged sets below Nyquist", f"{s['imaged_sets']}", ""),
        ("found + correctly labelled", f"{100 * s['found_share']:.1f} %", ""),
        (f"  of sets with bars >= {WIDE_BAR_PX:g} px ({s['imaged_wide']})",
         f"{100 * s['found_share_wide']:.1f} %", ">= 99 %"),
        ("wrongly labelled", f"{s['wrongly_labelled']}", "0"),
        ("set centre error median / max", f"{s['centre_err_median_px']:.3f} / "
         f"{s['centre_err_max_px']:.3f} px", "median <= 1 px"),
        ("ROI box centre error median / max", f"{s['roi_centre_err_median_px']:.3f} / "
         f"{s['roi_centre_err_max_px']:.3f} px", "median <= 1 px"),
        (f"found dust-free sets (bars >= {WIDE_BAR_PX:g} px)",
         f"{s['found_clean']} ({s['found_clean_wide']})", ""),
        *[(f"  no number: {why}", f"{n}", "(reason given per set)")
          for why, n in sorted(s["no_number"].items())],
        (f"modulation within {MODULATION_TOL} of truth, all found dust-free sets "
         f"({s['found_clean']}; no number = miss)",
         f"{100 * s['modulation_within_all']:.1f} %", "each"),
        (f"  ... of the sets read ({s['modulation_n']})",
         f"{100 * s['modulation_within']:.1f} %", ""),
        (f"  ... bars >= {WIDE_BAR_PX:g} px ({s['found_clean_wide']})",
         f"{100 * s['modulation_wide_within_all']:.1f} %", ""),
        ("  95 % intervals holding the truth (no number = miss)",
         f"{100 * s['modulation_coverage']:.1f} %", "~95 %"),
        ("modulation error median |d|", f"{s['modulation_median_abs']:.4f}", ""),
        (f"  reference: {s['estimator']} with priors, all found (read: {s['generic_n']}; "
         f"oblique < {GENERIC_MIN_OBLIQUE_PX_PER_PERIOD:g} px/period not read)",
         f"{100 * s['generic_within_all']:.1f} / {100 * s['generic_within']:.1f} %",
         "(all / read)"),
        ("  reference: histogram estimator, of the sets read",
         f"{100 * s['histogram_within']:.1f} %", ""),
        (f"  control: {s.get('control_frames', 0)} more poses at rotation 0, all found "
         f"({s.get('control_found_clean', 0)}) / read ({s.get('control_modulation_n', 0)})",
         f"{100 * s.get('control_modulation_within_all', math.nan):.1f} / "
         f"{100 * s.get('control_modulation_within', math.nan):.1f} %",
         "(bars on the pixel axes)"),
        ("finder time per frame median / max", f"{s['time_median_s']:.3f} / "
         f"{s['time_max_s']:.3f} s", "<= 0.5 s"),
        ("chart reading (every found set) per frame, median",
         f"{s['read_time_median_s']:.3f} s", "(shared machine)"),
        ("finder CPU time per frame median / max", f"{s['cpu_median_s']:.3f} / "
         f"{s['cpu_max_s']:.3f} s", "(shared machine: CPU)"),
    ]
    width = max(len(r[0]) for r in rows)
    out = [f"chart finder on the simulated bench: scale {SCALE_RANGE[0]}-{SCALE_RANGE[1]}, "
           f"rotation +-{ROTATION_DEG:g} deg, vignetting, dust, 8/12-bit, 25 % negative; "
           f"modulation by the chart reading ({s['reading']}: the set fitted at the pose's "
           "geometry)",
           f"{'figure':<{width}}  {'measured':>22}  target"]
    out += [f"{a:<{width}}  {b:>22}  {c}" for a, b, c in rows]
    out += ["", f"modulation per period bucket (every frame, control included): within "
            f"{MODULATION_TOL} / 95 % interval coverage / no number / 95th percentile of |error| "
            f"/ median half-width of the 95 % interval; then {s['estimator']} (generic, with "
            "priors: the reading before the chart reading) within and coverage, unread = miss",
            f"{'bars':<8} {'px/period':<9} {'sets':>5} {'within':>7} {'coverage':>8} "
            f"{'no number':>9} {'|d| p95':>8} {'median +-':>9} {'generic':>8} {'gen.cov':>8}"]
    for b in s.get("buckets", []):
        if not b["n"]:
            continue
        out.append(f"{b['bars']:<8} {b['px_per_period']:<9} {b['n']:>5} "
                   f"{100 * b['within']:>6.1f}% {100 * b['coverage']:>7.1f}% "
                   f"{b['no_number']:>9} {b['abs_err_p95']:>8.4f} "
                   f"{b['half_width_median']:>9.4f} {100 * b['generic_within']:>7.1f}% "
                   f"{100 * b['generic_coverage']:>7.1f}%")
    return "\n".join(out)


#: ``--psf-check``: the PSFs a real lens may have (px), each read through the chart reading's
#: model; bar-width buckets (px) and the sets per PSF, bucket and bar direction.
PSF_CHECK_PSFS: tuple[PsfSpec, ...] = (
    PsfSpec("gauss", sigma_px=0.5), PsfSpec("gauss", sigma_px=0.8),
    PsfSpec("disc", radius_px=1.0), PsfSpec("disc", radius_px=1.6),
    PsfSpec("gauss+halo", sigma_px=0.6), PsfSpec("disc+gauss", radius_px=1.2, sigma_px=0.4),
)
PSF_CHECK_BUCKETS_PX: tuple[tuple[float, float], ...] = (
    (1.0, 1.25), (1.25, 1.5), (1.5, 2.0), (2.0, 3.0))
PSF_CHECK_REPEATS = 6


def _psf_label(p: PsfSpec) -> str:
    parts = ([f"s{p.sigma_px:g}"] if p.kind != "disc" else []) + (
        [f"R{p.radius_px:g}"] if p.kind.startswith("disc") else [])
    return f"{p.kind} {' '.join(parts)}"


def run_psf_check(seed: int = 0) -> list[dict[str, Any]]:
    """Read three-bar sets rendered through non-Gaussian PSFs (:mod:`~benchlab.synthetic.threebar`:
    Poisson + read noise, 12-bit, the chart reading's ROI) with :func:`.knownbars.read_three_bars`
    and score them against their truth, per PSF, bar-width bucket and bar direction (on a pixel
    axis or oblique, 5-40 deg).

    Returns
    -------
    list of dict
        One row per (PSF, bucket, direction): ``psf, width_px, bars, n, within, coverage,
        reversed_truth, reversed_called, abs_err_p95, half_width_median``.
    """
    rng = np.random.default_rng(seed)
    rows: list[dict[str, Any]] = []
    for psf in PSF_CHECK_PSFS:
        for lo, hi in PSF_CHECK_BUCKETS_PX:
            for bars in ("axis", "oblique"):
                errs, covered, half, rev_truth, rev_called = [], 0, [], 0, 0
                for _ in range(PSF_CHECK_REPEATS):
                    w = float(rng.uniform(lo, hi))
                    theta = (float(rng.choice([0.0, 90.0])) if bars == "axis"
                             else float(rng.uniform(5.0, 40.0)) * float(rng.choice([-1, 1])))
                    s = render_three_bars(
                        w, theta, psf, rng=rng, full_well_e=20000.0, read_noise_e=10.0,
                        bits=12, centre_offset_px=(float(rng.uniform()), float(rng.uniform())))
                    r = read_three_bars(s.roi, centre_rc=s.centre_rc, bar_width_px=w,
                                        theta_deg=theta, max_code=s.max_code, dark_bars=True)
                    truth = s.truth_modulation
                    m = r.modulation if r.resolved else None
                    errs.append(None if m is None else m - truth)
                    covered += int(r.resolved and r.interval[0] <= truth <= r.interval[1])
                    if r.resolved:
                        half.append(0.5 * (r.interval[1] - r.interval[0]))
                    if truth < 0:
                        rev_truth += 1
                        rev_called += int(r.resolved and r.modulation < 0 and any(
                            "contrast reversed" in x for x in r.warnings))
                n = len(errs)
                abs_err = [abs(e) for e in errs if e is not None]
                rows.append({
                    "psf": _psf_label(psf), "width_px": f"{lo:g}-{hi:g}", "bars": bars, "n": n,
                    "within": sum(1 for e in errs if e is not None and abs(e) <= MODULATION_TOL)
                    / n,
                    "coverage": covered / n, "reversed_truth": rev_truth,
                    "reversed_called": rev_called,
                    "abs_err_p95": float(np.percentile(abs_err, 95)) if abs_err else math.nan,
                    "half_width_median": float(np.median(half)) if half else math.nan,
                })
    return rows


def format_psf_check(rows: list[dict[str, Any]]) -> str:
    """:func:`run_psf_check`'s rows as a table, with totals."""
    out = ["chart reading through non-Gaussian PSFs (threebar_synthetic: supersampled 2-D PSF, "
           "pixel integration, Poisson + read noise, 12-bit): within "
           f"{MODULATION_TOL} / 95 % interval coverage / contrast reversals (truth < 0) called "
           "reversed / 95th percentile of |error| / median half-width",
           f"{'psf':<20} {'bar px':<9} {'bars':<8} {'sets':>4} {'within':>7} {'coverage':>8} "
           f"{'reversed':>9} {'|d| p95':>8} {'median +-':>9}"]
    for r in rows:
        rev = f"{r['reversed_called']}/{r['reversed_truth']}" if r["reversed_truth"] else "-"
        out.append(f"{r['psf']:<20} {r['width_px']:<9} {r['bars']:<8} {r['n']:>4} "
                   f"{100 * r['within']:>6.1f}% {100 * r['coverage']:>7.1f}% {rev:>9} "
                   f"{r['abs_err_p95']:>8.4f} {r['half_width_median']:>9.4f}")
    n = sum(r["n"] for r in rows)
    within = sum(r["within"] * r["n"] for r in rows) / n
    cov = sum(r["coverage"] * r["n"] for r in rows) / n
    rt = sum(r["reversed_truth"] for r in rows)
    rc = sum(r["reversed_called"] for r in rows)
    out.append(f"{'all':<20} {'':<9} {'':<8} {n:>4} {100 * within:>6.1f}% {100 * cov:>7.1f}% "
               f"{f'{rc}/{rt}':>9}")
    return "\n".join(out)
