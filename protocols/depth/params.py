"""Parameters of the depth-of-field sweep (``benchlab run depth``), checked in full.

Read by :func:`benchlab.protocols.params.parse_params` like the other procedures' files: every
problem is listed at once, naming the file and the dotted field, before any device moves.

The sweep: object distances ``near_mm, near_mm + step_mm, ... <= far_mm`` (distances from the
prototype to the chart). The stage carries the chart over at most ``segment_mm`` at a time
(default: the stage's travel); a longer range is taken in segments that overlap by at least
``overlap_mm``, the chart re-mounted on the carriage between them (a prompt). Segment ``i``
puts its first distance at stage coordinate ``stage_start_mm``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from benchlab.analysis.focus.criteria import KINDS, Criterion, CriterionKind
from benchlab.analysis.mtf.frequency import nyquist_lp_per_mm
from benchlab.checks import CAMERA_BIT_DEPTHS
from benchlab.protocols.camera_limits import (
    EXPOSURE_RANGE_MS,
    GAIN_RANGE,
    camera_exposure_ms,
    camera_gain,
)
from benchlab.protocols.depth.radial_rois import DEFAULT_FIELD_ROIS, roi_problem
from benchlab.protocols.target_contrast import TargetSettings, check_targets, targets_to_dict

#: Nyquist of the camera (its profile's pitch), lp/mm: a criterion above it is refused.
NYQUIST_LP_PER_MM = nyquist_lp_per_mm()
#: Segment length when neither the file nor a bench gives one (an MTS50 from 1 mm).
DEFAULT_SEGMENT_MM = 48.0
#: Table 4.1: forward depth of field "+-40 mm or larger" (RMS spot < 12 um).
DESIGN_HALF_RANGE_MM = 40.0
#: Table 4.1: radial depth of field "+-5 mm or larger" (RMS spot < 12 um).
RADIAL_HALF_RANGE_MM = 5.0
#: Table 4.4: forward depth of field 6-73 mm (RMS spot < 10 um).
DESIGN_RANGE_MM = (6.0, 73.0)


def _default_criteria() -> tuple[Criterion, ...]:
    return (Criterion("mtf50", 35.0),  # Table 4.1: toleranced forward MTF50 > 35 lp/mm
            Criterion("mtf", 70.0, threshold=0.46),  # Table 4.15: forward 70 lp/mm, 90 % > 0.46
            Criterion("spot", 20.0, rms_um=12.0))  # Table 4.1: RMS spot < 12 um


@dataclass(frozen=True)
class Segment:
    """One stage segment: the distances it takes and where the chart is mounted."""

    index: int
    distances_mm: tuple[float, ...]
    #: Object distance at stage coordinate 0: distance = offset + stage position.
    object_offset_mm: float

    def stage_mm(self, distance_mm: float) -> float:
        return distance_mm - self.object_offset_mm


@dataclass(frozen=True)
class DepthParams:
    """Parameters of ``benchlab run depth`` (module docstring)."""

    exposure_ms: float = 300.0
    gain: float = 1.0
    bits: int = 8
    frames: int = 2
    view: str = "forward"
    near_mm: float = 40.0
    far_mm: float = 94.0
    step_mm: float = 2.0
    overlap_mm: float = 6.0
    #: 0: the stage's travel from stage_start_mm (resolved when checked against the bench;
    #: :data:`DEFAULT_SEGMENT_MM` without one).
    segment_mm: float = 0.0
    stage_start_mm: float = 1.0
    criteria: tuple[Criterion, ...] = field(default_factory=_default_criteria)
    min_mtf: float = 0.05
    read_chart: bool = True
    design_half_range_mm: float = DESIGN_HALF_RANGE_MM
    #: Radial view: the rolled patterns (object lp/mm x orientation), each swept in turn, and
    #: the Eq. 2.9 bar modulation that bounds the DOF; distances are from the side wall.
    radial_frequencies_lp_per_mm: tuple[float, ...] = (2.0,)
    radial_orientations: tuple[str, ...] = ("sagittal", "tangential")
    radial_threshold: float = 0.3
    wall_radius_mm: float = 13.88
    #: Radial view: the field points (ROIs ``(row0, col0, row1, col1)`` at several image
    #: heights; :mod:`benchlab.protocols.depth.radial_rois`).
    radial_rois: tuple[tuple[int, int, int, int], ...] = DEFAULT_FIELD_ROIS
    #: How the chart's and the radial patterns' own contrast is known ([targets], as in the
    #: MTF test; :mod:`benchlab.protocols.depth.targets`).
    targets: TargetSettings = field(default_factory=TargetSettings)
    simulator: Mapping[str, Any] = field(default_factory=dict)
    raw: Mapping[str, Any] = field(default_factory=dict)

    @property
    def patterns(self) -> tuple[tuple[float, str] | None, ...]:
        """What is swept: the forward chart once (None), or each radial pattern."""
        if self.view == "forward":
            return (None,)
        return tuple((f, o) for f in self.radial_frequencies_lp_per_mm
                     for o in self.radial_orientations)

    def lens(self) -> Any:
        """The simulated lens of the view (``[simulator]`` over the view's defaults)."""
        from benchlab.scenes.focus import RADIAL_LENS, ThroughFocusLens

        base = RADIAL_LENS if self.view == "radial" else {}
        return ThroughFocusLens.from_mapping({**base, **self.simulator})

    def object_distance_mm(self, sweep_mm: float) -> float:
        """The object distance the lens sees at a sweep coordinate (radial: the object
        radius, the wall distance plus the endoscope radius)."""
        return sweep_mm + (self.wall_radius_mm if self.view == "radial" else 0.0)

    @property
    def distances_mm(self) -> tuple[float, ...]:
        n = int(math.floor((self.far_mm - self.near_mm) / self.step_mm + 1e-9))
        return tuple(round(self.near_mm + k * self.step_mm, 6) for k in range(n + 1))

    def segments(self) -> list[Segment]:
        """The stage segments (module docstring)."""
        span = self.segment_mm or DEFAULT_SEGMENT_MM
        dist = self.distances_mm
        out: list[Segment] = []
        i = 0
        while True:
            first = dist[i]
            taken = [d for d in dist[i:] if d <= first + span + 1e-9]
            out.append(Segment(len(out), tuple(taken), first - self.stage_start_mm))
            if taken[-1] >= dist[-1]:
                return out
            # the next segment starts overlap_mm (at least) below this one's end
            j = max(k for k in range(len(dist)) if dist[k] <= taken[-1] - self.overlap_mm + 1e-9)
            i = max(j, i + 1)

    @property
    def frequencies_lp_per_mm(self) -> tuple[float, ...]:
        return tuple(sorted({c.frequency_lp_per_mm for c in self.criteria}))


def check_depth(c: Any, limits: Any = None) -> DepthParams:
    """Read a ``depth`` parameter mapping with the params checker ``c``."""
    d = DepthParams()
    exposure = camera_exposure_ms(c.number("camera.exposure_ms", d.exposure_ms,
                                           *EXPOSURE_RANGE_MS))
    gain = camera_gain(c.number("camera.gain", d.gain, *GAIN_RANGE))
    bits = c.choice("camera.bits", d.bits, CAMERA_BIT_DEPTHS)
    if limits is not None and (problem := limits.bits_problem(bits)):
        c.fail("camera.bits", problem)
    frames = c.integer("camera.frames", d.frames, 1, 64)
    view = c.choice("sweep.view", d.view, ("forward", "radial"))
    # the radial view sweeps the wall distance: Table 4.4's 2-11 mm with margin
    dn, df, ds = (d.near_mm, d.far_mm, d.step_mm) if view == "forward" else (2.5, 10.5, 0.5)
    near = c.number("sweep.near_mm", dn, 0.0, 10000.0, lo_open=view == "forward")
    far = c.number("sweep.far_mm", df, 0.0, 10000.0, lo_open=True)
    step = c.number("sweep.step_mm", ds, 0.0, 1000.0, lo_open=True)
    overlap = c.number("sweep.overlap_mm", d.overlap_mm, 0.0, 1000.0)
    segment = c.number("sweep.segment_mm", d.segment_mm, 0.0, 10000.0)
    start = c.number("sweep.stage_start_mm", d.stage_start_mm, -10000.0, 10000.0)
    if not near < far:
        c.fail("sweep.far_mm", f"{far:g} mm must be beyond sweep.near_mm {near:g} mm")
    elif (far - near) / step + 1 < 7:
        c.fail("sweep.step_mm", f"{step:g} mm gives {int((far - near) / step) + 1} distances "
               f"over {near:g}-{far:g} mm; a through-focus fit needs 7 at least")
    elif (far - near) / step > 400:
        c.fail("sweep.step_mm", f"{step:g} mm gives more than 400 distances; take a coarser step")
    travel = getattr(limits, "stage_travel_mm", None) if limits is not None else None
    span = segment
    if travel is not None:
        lo, hi = travel
        if not lo <= start <= hi:
            c.fail("sweep.stage_start_mm", f"{start:g} mm is outside the stage travel "
                   f"{lo:g}..{hi:g} mm")
        elif segment and start + segment > hi:
            c.fail("sweep.segment_mm", f"{segment:g} mm from sweep.stage_start_mm {start:g} "
                   f"runs past the stage travel {lo:g}..{hi:g} mm")
        span = segment = segment or hi - start  # recorded resolved: a resume plans the same
    span = span or DEFAULT_SEGMENT_MM
    if span < 2 * step:
        c.fail("sweep.segment_mm", f"a segment of {span:g} mm holds fewer than 3 distances "
               f"{step:g} mm apart")
    elif overlap >= span - step:
        c.fail("sweep.overlap_mm", f"{overlap:g} mm leaves no new distance in a {span:g} mm "
               "segment")
    criteria = _criteria(c, d)
    min_mtf = c.number("analysis.min_mtf", d.min_mtf, 0.0, 0.5, lo_open=True, hi_open=True)
    found, read_chart = c.get("analysis.read_chart", d.read_chart)
    if found and not isinstance(read_chart, bool):
        c.fail("analysis.read_chart", f"must be true or false, got {read_chart!r}")
        read_chart = d.read_chart
    # Table 4.1: forward +-40 mm, radial +-5 mm
    half = c.number("analysis.design_half_range_mm",
                    d.design_half_range_mm if view == "forward" else RADIAL_HALF_RANGE_MM,
                    0.0, 10000.0, lo_open=True)
    rad_f = c.numbers("radial.frequencies_lp_per_mm", d.radial_frequencies_lp_per_mm, 0.0,
                      100.0, lo_open=True)
    rad_o = d.radial_orientations
    found, orients = c.get("radial.orientations", list(rad_o))
    if found:
        if (not isinstance(orients, list) or not orients
                or any(o not in ("sagittal", "tangential") for o in orients)
                or len(set(orients)) != len(orients)):
            c.fail("radial.orientations", f"must be a list of distinct 'sagittal' / "
                   f"'tangential', got {orients!r}")
        else:
            rad_o = tuple(orients)
    rad_t = c.number("radial.threshold", d.radial_threshold, 0.0, 1.0, lo_open=True,
                     hi_open=True)
    wall = c.number("radial.wall_radius_mm", d.wall_radius_mm, 0.0, 1000.0)
    rois = _radial_rois(c, d)
    if view == "radial" and "criteria" in c.data:
        c.fail("criteria", "apply to the forward view's edges; the radial view's DOF is bounded "
               "by radial.threshold (bar modulation)")
    simulator = _simulator(c)
    return DepthParams(
        exposure_ms=exposure, gain=gain, bits=bits, frames=frames, view=view, near_mm=near,
        far_mm=far, step_mm=step, overlap_mm=overlap, segment_mm=segment, stage_start_mm=start,
        criteria=criteria, min_mtf=min_mtf, read_chart=bool(read_chart),
        design_half_range_mm=half, radial_frequencies_lp_per_mm=rad_f,
        radial_orientations=rad_o, radial_threshold=rad_t, wall_radius_mm=wall,
        radial_rois=rois, targets=check_targets(c, len(rad_f)), simulator=simulator,
        raw=c.data,
    )


def _criteria(c: Any, d: DepthParams) -> tuple[Criterion, ...]:
    found, items = c.get("criteria", None)
    if not found:
        return d.criteria
    if not isinstance(items, list) or not items:
        c.fail("criteria", "must be a non-empty array of tables ([[criteria]] kind = ...)")
        return d.criteria
    out: list[Criterion] = []
    for i, item in enumerate(items):
        key = f"criteria[{i}]"
        if not isinstance(item, Mapping):
            c.fail(key, f"must be a table, got {item!r}")
            continue
        extra = sorted(set(item) - {"kind", "frequency_lp_per_mm", "threshold", "rms_um"})
        for name in extra:
            c.fail(f"{key}.{name}", "unknown parameter")
        kind = item.get("kind")
        if kind not in KINDS:
            c.fail(f"{key}.kind", f"must be one of {', '.join(KINDS)}; got {kind!r}")
            continue
        freq = _positive(c, f"{key}.frequency_lp_per_mm", item.get("frequency_lp_per_mm"))
        if freq is not None and freq >= NYQUIST_LP_PER_MM:
            c.fail(f"{key}.frequency_lp_per_mm", f"{freq:g} lp/mm is at or above Nyquist "
                   f"({NYQUIST_LP_PER_MM:.2f} lp/mm): aliased, not measurable")
            freq = None
        threshold = 0.5
        if kind == "mtf":
            t = _positive(c, f"{key}.threshold", item.get("threshold"))
            if t is not None and t >= 1.0:
                c.fail(f"{key}.threshold", f"must be below 1, got {t:g}")
                t = None
            threshold = t if t is not None else math.nan
        elif "threshold" in item:
            c.fail(f"{key}.threshold", f"only a kind = \"mtf\" criterion takes a threshold "
                   f"({kind} sets its own)")
        rms = 12.0
        if kind == "spot":
            r = _positive(c, f"{key}.rms_um", item.get("rms_um", 12.0))
            rms = r if r is not None else math.nan
        elif "rms_um" in item:
            c.fail(f"{key}.rms_um", "only a kind = \"spot\" criterion takes rms_um")
        if freq is None or math.isnan(threshold) or math.isnan(rms):
            continue
        kind_t: CriterionKind = kind
        crit = Criterion(kind_t, freq, threshold=threshold, rms_um=rms)
        if any(o.name == crit.name for o in out):
            c.fail(key, f"repeats {crit.name}")
            continue
        out.append(crit)
    return tuple(out) if out else d.criteria


def _radial_rois(c: Any, d: DepthParams) -> tuple[tuple[int, int, int, int], ...]:
    found, items = c.get("radial.rois", None)
    if not found:
        return d.radial_rois
    if not isinstance(items, list) or not items:
        c.fail("radial.rois", "must be a non-empty list of [row0, col0, row1, col1] boxes")
        return d.radial_rois
    out: list[tuple[int, int, int, int]] = []
    for i, item in enumerate(items):
        key = f"radial.rois[{i}]"
        before = len(c.problems)
        box = c.roi(key, d.radial_rois[0], value=item, found=True)
        if len(c.problems) > before:
            continue
        why = roi_problem(box)
        if why is not None:
            c.fail(key, f"{list(box)} {why}")
        elif box in out:
            c.fail(key, f"repeats {list(box)}")
        else:
            out.append(box)
    return tuple(out) if out else d.radial_rois


def _positive(c: Any, key: str, value: Any) -> float | None:
    if value is None:
        c.fail(key, "is required")
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or value <= 0:
        c.fail(key, f"must be a number > 0, got {value!r}")
        return None
    return float(value)


def _simulator(c: Any) -> dict[str, float]:
    from benchlab.scenes.focus import ThroughFocusLens

    out = c.number_table("simulator", set(ThroughFocusLens().to_dict()), "lens values")
    try:
        ThroughFocusLens.from_mapping(out)
    except ValueError as exc:
        c.fail("simulator", str(exc))
    return out


def depth_to_dict(p: DepthParams) -> dict[str, Any]:
    """The effective parameters in the file's layout (what a session records)."""
    crit: list[dict[str, Any]] = []
    for cr in p.criteria:
        row: dict[str, Any] = {"kind": cr.kind, "frequency_lp_per_mm": cr.frequency_lp_per_mm}
        if cr.kind == "mtf":
            row["threshold"] = cr.threshold
        if cr.kind == "spot":
            row["rms_um"] = cr.rms_um
        crit.append(row)
    out: dict[str, Any] = {
        "procedure": "depth",
        "camera": {"exposure_ms": p.exposure_ms, "gain": p.gain, "bits": p.bits,
                   "frames": p.frames},
        "sweep": {"view": p.view, "near_mm": p.near_mm, "far_mm": p.far_mm,
                  "step_mm": p.step_mm, "overlap_mm": p.overlap_mm,
                  "segment_mm": p.segment_mm, "stage_start_mm": p.stage_start_mm},
        "analysis": {"min_mtf": p.min_mtf, "read_chart": p.read_chart,
                     "design_half_range_mm": p.design_half_range_mm},
        "radial": {"frequencies_lp_per_mm": list(p.radial_frequencies_lp_per_mm),
                   "orientations": list(p.radial_orientations),
                   "threshold": p.radial_threshold, "wall_radius_mm": p.wall_radius_mm,
                   "rois": [list(b) for b in p.radial_rois]},
        "targets": targets_to_dict(p.targets),
        "simulator": dict(p.simulator),
    }
    if p.view == "forward":  # the radial view's DOF is bounded by radial.threshold
        out["criteria"] = crit
    return out
