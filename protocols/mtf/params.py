"""Parameters of the Table 4.10 MTF test (``protocols/defaults/mtf.toml``): the dataclass,
its check (every problem named by file and field, :class:`benchlab.checks.ParamsError`) and the
file layout a session records. Registered in :mod:`benchlab.procedures`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from benchlab.checks import CAMERA_BIT_DEPTHS, BenchLimits
from benchlab.protocols.camera_limits import (
    EXPOSURE_RANGE_MS,
    GAIN_RANGE,
    camera_exposure_ms,
    camera_gain,
)
from benchlab.protocols.params import Roi
from benchlab.protocols.target_contrast import TargetSettings, check_targets, targets_to_dict

if TYPE_CHECKING:
    from benchlab.protocols.params import _Checker

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


def mtf_to_dict(params: MtfParams) -> dict[str, Any]:
    """:func:`benchlab.protocols.params.params_to_dict` of the MTF test."""
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
