"""Procedure parameters: TOML files checked in full before any device command.

Every problem in a file is collected and reported at once, each naming the file and the dotted
field (``radial.roi: row end 2000 is outside the 1024-row frame``), so a technician fixes a
parameter file in one pass. Defaults ship as package data in ``protocols/defaults/``.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

from benchlab.checks import CAMERA_BIT_DEPTHS, BenchLimits, ParamsError, TableChecker
from benchlab.procedures import PROCEDURES, entry, entry_of
from benchlab.protocols.camera_limits import (  # the driver's limits: one source of truth
    CAMERA_SPEC,
    EXPOSURE_RANGE_MS,
    FRAME_SHAPE_PX,
    GAIN_RANGE,
    camera_exposure_ms,
    camera_gain,
)
from benchlab.protocols.target_contrast import TargetSettings, check_targets, targets_to_dict

if TYPE_CHECKING:
    from benchlab.protocols.characterise.params import CharacteriseParams
    from benchlab.protocols.depth.params import DepthParams
    from benchlab.protocols.fov.params import FovParams

__all__ = ["BenchLimits", "ParamsError"]  # defined in benchlab.checks, re-exported here

__all__ = ["CAMERA_SPEC", "EXPOSURE_RANGE_MS", "FRAME_SHAPE_PX", "GAIN_RANGE", "PROCEDURES",
           "ParamsError",
           "camera_exposure_ms", "camera_gain", "load_params", "parse_params"]
_ELEMENT_RE = re.compile(r"^G(-?\d)E([1-6])$")


@dataclass(frozen=True)
class UsafElement:
    """One USAF 1951 element, e.g. ``G2E4``."""

    group: int
    element: int

    @property
    def name(self) -> str:
        return f"G{self.group}E{self.element}"

    @classmethod
    def parse(cls, text: str) -> UsafElement:
        m = _ELEMENT_RE.match(text.strip().upper())
        if not m:
            raise ValueError(f"not a USAF element name like 'G2E4': {text!r}")
        return cls(int(m.group(1)), int(m.group(2)))


#: ROI as numpy slices: (row0, col0, row1, col1), 0-based, end-exclusive.
Roi = tuple[int, int, int, int]


@dataclass(frozen=True)
class MtfParams:
    """Parameters of the Table 4.10 procedure."""

    exposure_ms: float = 300.0
    gain: float = 1.0
    bits: int = 8
    focus_frames: int = 5
    forward_magnification: float = 16.3
    forward_elements: tuple[UsafElement, ...] = ()
    forward_roi_overrides: Mapping[str, Roi] = field(default_factory=dict)
    radial_magnification: float = 17.5
    #: Object cylinder's distance from the endoscope axis (thesis set-up: 13.88 + 6 mm); sets
    #: the sagittal (spoke) image frequency, which Eq. 4.1's axial magnification does not.
    radial_object_radius_mm: float = 19.88
    radial_frequencies_lp_per_mm: tuple[float, ...] = (0.5, 1, 2, 3, 4, 5, 6)
    radial_roi: Roi = (250, 1000, 290, 1050)
    fov_threshold_dn: float = 8.0
    estimator: str = ""
    monte_carlo_file: str = ""
    simulated_mtf_file: str = ""
    #: How the chart's and the radial patterns' own contrast is known ([targets]).
    targets: TargetSettings = field(default_factory=TargetSettings)
    raw: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class RadiometryParams:
    """Parameters of the section 4.4 relative radiometry."""

    exposure_ms: float = 375.0
    mask_gain: float = 5.0
    measurement_gain: float = 1.0
    bits: int = 8
    led_channel: int = 1
    led_current_ma: float = 20.0
    positions_mm: tuple[float, ...] = (15.0, 18.0, 20.0, 25.0, 32.0)
    stage_offset_mm: float = 0.0
    simulated_irradiance_mw_per_mm2: tuple[float, ...] = (22.48, 21.21, 19.40, 14.34, 3.014)
    mask_threshold_fraction: float = 0.5
    raw: Mapping[str, Any] = field(default_factory=dict)

    def stage_target_mm(self, position_mm: float) -> float:
        """Stage coordinate that puts the LED at a field position."""
        return position_mm + self.stage_offset_mm


#: (A string: the characterisation's parameters are imported only where they are used, so an
#: MTF re-analysis never loads them.)
Params: TypeAlias = ("MtfParams | RadiometryParams | CharacteriseParams | DepthParams | "
                     "FovParams")


class _Checker(TableChecker):
    """The generic checker plus what only parameter files have (ROIs on the frame)."""

    def roi(self, dotted: str, default: Roi, value: Any = None, found: bool | None = None) -> Roi:
        if found is None:
            found, value = self._get(dotted, default)
        if not found:
            return default
        if (
            not isinstance(value, list) or len(value) != 4
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)
        ):
            self.fail(dotted, f"must be 4 integers [row0, col0, row1, col1], got {value!r}")
            return default
        r0, c0, r1, c1 = value
        rows, cols = FRAME_SHAPE_PX
        bad = False
        if not (0 <= r0 < r1 <= rows):
            self.fail(dotted, f"rows {r0}..{r1} must satisfy 0 <= row0 < row1 <= {rows}")
            bad = True
        if not (0 <= c0 < c1 <= cols):
            self.fail(dotted, f"columns {c0}..{c1} must satisfy 0 <= col0 < col1 <= {cols}")
            bad = True
        return default if bad else (r0, c0, r1, c1)


def check_mtf(c: _Checker, limits: BenchLimits | None = None) -> MtfParams:
    d = MtfParams()
    exposure = camera_exposure_ms(c.number("camera.exposure_ms", d.exposure_ms,
                                           *EXPOSURE_RANGE_MS))
    gain = camera_gain(c.number("camera.gain", d.gain, *GAIN_RANGE))
    bits = c.choice("camera.bits", d.bits, CAMERA_BIT_DEPTHS)
    focus_frames = c.integer("focus.frames", d.focus_frames, 1, 1000)
    fwd_mag = c.number("forward.magnification", d.forward_magnification, 0.0, 1000.0, lo_open=True)
    elements: list[UsafElement] = []
    found, names = c._get("forward.elements", None)
    if not found:
        names = [f"G{g}E{e}" for g, e in ((1, 5), (1, 6), (2, 1), (2, 2), (2, 3), (2, 4),
                                          (2, 5), (2, 6), (3, 1))]
    if not isinstance(names, list) or not names:
        c.fail("forward.elements", f"must be a non-empty list of names like 'G2E4', got {names!r}")
    else:
        for i, name in enumerate(names):
            try:
                el = UsafElement.parse(str(name)) if isinstance(name, str) else None
            except ValueError as exc:
                c.fail(f"forward.elements[{i}]", str(exc))
                continue
            if el is None:
                c.fail(f"forward.elements[{i}]", f"must be a string like 'G2E4', got {name!r}")
            elif el in elements:
                c.fail(f"forward.elements[{i}]", f"{el.name} is listed twice")
            else:
                elements.append(el)
    overrides: dict[str, Roi] = {}
    found, table = c._get("forward.roi", {})
    if found:
        if not isinstance(table, Mapping):
            c.fail("forward.roi", "must be a table of element -> {sagittal, tangential} ROIs")
        else:
            for el_name, per in table.items():
                base = f"forward.roi.{el_name}"
                c.seen.add(base)
                if not _ELEMENT_RE.match(str(el_name).upper()):
                    c.fail(base, "not a USAF element name like 'G2E4'")
                    continue
                if not isinstance(per, Mapping):
                    c.fail(base, "must be a table with sagittal and/or tangential ROIs")
                    continue
                for orient, box in per.items():
                    key = f"{base}.{orient}"
                    c.seen.add(key)
                    if orient not in ("sagittal", "tangential"):
                        c.fail(key, "orientation must be 'sagittal' or 'tangential'")
                        continue
                    roi = c.roi(key, (0, 0, 1, 1), box, True)
                    overrides[f"{str(el_name).upper()}.{orient}"] = roi
    rad_mag = c.number("radial.magnification", d.radial_magnification, 0.0, 1000.0, lo_open=True)
    rad_obj_r = c.number("radial.object_radius_mm", d.radial_object_radius_mm, 0.0, 1000.0,
                         lo_open=True)
    freqs = c.numbers("radial.frequencies_lp_per_mm", d.radial_frequencies_lp_per_mm, 0.0, 100.0,
                      lo_open=True)
    radial_roi = c.roi("radial.roi", d.radial_roi)
    fov = c.number("analysis.fov_threshold_dn", d.fov_threshold_dn, 0.0, 65535.0)
    estimator = c.string("analysis.estimator", d.estimator)
    if estimator and estimator != "auto":
        from benchlab.analysis.bars.estimators import ESTIMATORS

        if estimator not in ESTIMATORS:
            c.fail("analysis.estimator", f"unknown estimator {estimator!r}; known: auto, "
                   f"{', '.join(sorted(ESTIMATORS))}")
    mc_file = c.string("analysis.monte_carlo_file", d.monte_carlo_file)
    sim_file = c.string("analysis.simulated_mtf_file", d.simulated_mtf_file)
    return MtfParams(
        exposure_ms=exposure, gain=gain, bits=bits, focus_frames=focus_frames,
        forward_magnification=fwd_mag, forward_elements=tuple(elements),
        forward_roi_overrides=overrides, radial_magnification=rad_mag,
        radial_object_radius_mm=rad_obj_r,
        radial_frequencies_lp_per_mm=freqs, radial_roi=radial_roi, fov_threshold_dn=fov,
        estimator=estimator, monte_carlo_file=mc_file, simulated_mtf_file=sim_file,
        targets=check_targets(c, len(freqs)), raw=c.data,
    )


def _check_bench(
    c: _Checker, limits: BenchLimits, channel: int, current_ma: float,
    positions: tuple[float, ...], offset_mm: float,
) -> None:
    """LED ceiling and stage travel of the bench this run will use."""
    if limits.led_ceilings_ma is not None:
        ceiling = limits.led_ceilings_ma.get(channel)
        if ceiling is None:
            c.fail("led.channel", f"channel {channel} has no current ceiling in the bench "
                   "configuration")
        elif current_ma > ceiling:
            c.fail("led.current_ma", f"{current_ma:g} mA exceeds the bench ceiling "
                   f"{ceiling:g} mA of channel {channel}")
    if limits.stage_travel_mm is not None:
        lo, hi = limits.stage_travel_mm
        for i, pos in enumerate(positions):
            if not lo <= pos + offset_mm <= hi:
                c.fail(f"positions.field_mm[{i}]", f"stage target {pos + offset_mm:g} mm is "
                       f"outside the travel {lo:g}..{hi:g} mm")


def position_step_id(position_mm: float) -> str:
    """The radiometry step of a field position (also its frames' file names)."""
    return f"position-{position_mm:g}"


def _check_step_ids(c: _Checker, positions: tuple[float, ...]) -> None:
    """Each position is one step, named ``position-<mm :g>``: positions that differ below that
    precision would be one step twice."""
    first: dict[str, int] = {}
    for i, pos in enumerate(positions):
        sid = position_step_id(pos)
        if sid in first:
            j = first[sid]
            how = "repeats" if pos == positions[j] else "is too close to"
            c.fail(f"positions.field_mm[{i}]", f"{pos!r} mm {how} positions.field_mm[{j}] "
                   f"({positions[j]!r} mm): both would be step {sid}")
        else:
            first[sid] = i


def check_radiometry(c: _Checker, limits: BenchLimits | None = None) -> RadiometryParams:
    d = RadiometryParams()
    exposure = camera_exposure_ms(c.number("camera.exposure_ms", d.exposure_ms,
                                           *EXPOSURE_RANGE_MS))
    mask_gain = camera_gain(c.number("camera.mask_gain", d.mask_gain, *GAIN_RANGE))
    meas_gain = camera_gain(c.number("camera.measurement_gain", d.measurement_gain,
                                     *GAIN_RANGE))
    bits = c.choice("camera.bits", d.bits, CAMERA_BIT_DEPTHS)
    if limits is not None and (problem := limits.bits_problem(bits)):
        c.fail("camera.bits", problem)
    channel = c.integer("led.channel", d.led_channel, 1, 16)
    current = c.number("led.current_ma", d.led_current_ma, 0.0, 5000.0, lo_open=True)
    positions = c.numbers("positions.field_mm", d.positions_mm, -1000.0, 1000.0,
                          distinct=False)  # _check_step_ids names each repeat
    offset = c.number("positions.stage_offset_mm", d.stage_offset_mm, -1000.0, 1000.0)
    # Two positions may well see the same irradiance: equal values are allowed here.
    irr = c.numbers("analysis.simulated_irradiance_mw_per_mm2",
                    d.simulated_irradiance_mw_per_mm2, 0.0, 1e9, distinct=False)
    if irr and max(irr) <= 0:
        c.fail("analysis.simulated_irradiance_mw_per_mm2", "needs a value above 0 (Table 4.16 "
               "normalises to the largest)")
    if len(irr) != len(positions):
        c.fail("analysis.simulated_irradiance_mw_per_mm2",
               f"has {len(irr)} values but positions.field_mm has {len(positions)}")
    # open at both ends: at 1.0 no pixel is above the peak, so no mask could ever be found
    thr = c.number("analysis.mask_threshold_fraction", d.mask_threshold_fraction, 0.0, 1.0,
                   lo_open=True, hi_open=True)
    _check_step_ids(c, positions)
    if limits is not None:
        _check_bench(c, limits, channel, current, positions, offset)
    return RadiometryParams(
        exposure_ms=exposure, mask_gain=mask_gain, measurement_gain=meas_gain, bits=bits,
        led_channel=channel, led_current_ma=current, positions_mm=positions,
        stage_offset_mm=offset, simulated_irradiance_mw_per_mm2=irr,
        mask_threshold_fraction=thr, raw=c.data,
    )


def default_params_path(procedure: str) -> Path:
    """The packaged default parameter file of a procedure."""
    from importlib import resources  # here, like tomllib below: a re-analysis reads neither

    return Path(str(resources.files("benchlab.protocols") / "defaults" / f"{procedure}.toml"))


def parse_params(
    procedure: str, data: Mapping[str, Any], source: str = "<params>",
    limits: BenchLimits | None = None,
) -> Params:
    """Validate a parsed parameter mapping; :class:`ParamsError` lists every problem."""
    try:
        procedure_entry = entry(procedure)
    except KeyError as exc:
        raise ParamsError(source, [f"procedure: {exc.args[0]}"]) from None
    checker = _Checker(data)
    checker.seen.add("procedure")
    declared = data.get("procedure", procedure)
    if declared != procedure:
        checker.fail("procedure", f"file is for {declared!r}, not {procedure!r}")
    params: Params = procedure_entry.load("check")(checker, limits)
    checker.unknown_keys()
    if checker.problems:
        raise ParamsError(source, checker.problems)
    return params


def load_params(
    procedure: str, path: str | Path | None = None, limits: BenchLimits | None = None
) -> Params:
    """Load and validate a procedure's parameters (``path=None``: the packaged defaults).

    With ``limits`` the values are also checked against the bench (LED ceiling, travel).
    """
    import tomllib

    p = Path(path) if path is not None else default_params_path(procedure)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ParamsError(str(p), ["file: no such parameter file"]) from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ParamsError(str(p), [f"file: not valid TOML ({exc})"]) from exc
    return parse_params(procedure, data, str(p), limits)


def params_to_dict(params: Params) -> dict[str, Any]:
    """The effective parameters (defaults filled in) in the parameter file's layout.

    This is what a session records, so a resume or re-analysis never depends on defaults that a
    later benchlab version may have changed; ``parse_params`` reads it back unchanged.
    """
    try:
        return dict(entry_of(params).load("to_dict")(params))
    except TypeError as exc:
        raise ParamsError("<params>", [f"procedure: {exc}"]) from None


def mtf_to_dict(params: MtfParams) -> dict[str, Any]:
    """:func:`params_to_dict` of the MTF test."""
    rois: dict[str, dict[str, list[int]]] = {}
    for key, box in params.forward_roi_overrides.items():
        el, orient = key.split(".")
        rois.setdefault(el, {})[orient] = list(box)
    forward: dict[str, Any] = {
        "magnification": params.forward_magnification,
        "elements": [e.name for e in params.forward_elements],
    }
    if rois:
        forward["roi"] = rois
    return {
        "procedure": "mtf",
        "camera": {"exposure_ms": params.exposure_ms, "gain": params.gain,
                   "bits": params.bits},
        "focus": {"frames": params.focus_frames},
        "forward": forward,
        "radial": {"magnification": params.radial_magnification,
                   "object_radius_mm": params.radial_object_radius_mm,
                   "frequencies_lp_per_mm": list(params.radial_frequencies_lp_per_mm),
                   "roi": list(params.radial_roi)},
        "analysis": {"estimator": params.estimator,
                     "fov_threshold_dn": params.fov_threshold_dn,
                     "monte_carlo_file": params.monte_carlo_file,
                     "simulated_mtf_file": params.simulated_mtf_file},
        "targets": targets_to_dict(params.targets),
    }


def radiometry_to_dict(params: RadiometryParams) -> dict[str, Any]:
    """:func:`params_to_dict` of the relative radiometry."""
    return {
        "procedure": "radiometry",
        "camera": {"exposure_ms": params.exposure_ms, "mask_gain": params.mask_gain,
                   "measurement_gain": params.measurement_gain, "bits": params.bits},
        "led": {"channel": params.led_channel, "current_ma": params.led_current_ma},
        "positions": {"field_mm": list(params.positions_mm),
                      "stage_offset_mm": params.stage_offset_mm},
        "analysis": {"simulated_irradiance_mw_per_mm2":
                     list(params.simulated_irradiance_mw_per_mm2),
                     "mask_threshold_fraction": params.mask_threshold_fraction},
    }
