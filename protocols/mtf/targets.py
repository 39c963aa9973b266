"""The contrast of the MTF test's targets themselves, and the lens's share of each reading.

A bar reading (Eq. 2.9) is the target's own contrast times what the lens passes of it: a
printed paper pattern of dark bars at 20 and paper at 190 DN reads 0.81 through a perfect
lens. The simulated MTF curves (and the Monte Carlo thresholds of Table 4.15) are the lens
alone, so a reading is compared with them as the lens's share, ``measured / target``.

Each target's contrast comes from one of two sources (``[targets]`` in the parameters):

- ``"measured"`` (the default): read on the bench from the lowest-frequency bar set where the
  simulated lens passes at least :data:`REFERENCE_MIN_CTF` of a square wave at every field
  point of the view (the forward view: the chart's coarsest set found in the frame; the
  radial view: the lowest-frequency pattern, both rolls), divided by that CTF. Every radial
  pattern is taken to be printed like the reference one (same paper, ink and printer).
- a number (or, for the radial patterns, one per frequency) from the target's certificate,
  with its 1-sigma uncertainty.

Uncertainties are 1 sigma and independent: a lens share ``m / t`` has the relative
uncertainty ``hypot(u_m / m, u_t / t)``. At the reference set itself ``m`` and ``t`` come from
one reading, so its share's uncertainty is overstated there (conservative).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchlab.analysis.mtf.compare import SimulatedCurve
from benchlab.analysis.mtf.simulated_ctf import simulated_ctf
from benchlab.protocols.target_contrast import TargetSetting

#: The journal event that keeps a simulated target's printed levels (its truth's contrast).
SIMULATED_TARGET_EVENT = "simulated_target"
#: A target's contrast is read only where the simulated lens passes at least this share of a
#: square wave (CTF) at every field point: the reading is then the target's within 1 %.
REFERENCE_MIN_CTF = 0.99


@dataclass(frozen=True)
class TargetContrast:
    """A target's contrast (Eq. 2.9 of the target itself) with its 1-sigma uncertainty and
    where it comes from; ``value`` None when unknown (``source`` then says why)."""

    value: float | None
    uncertainty: float | None
    source: str

    def to_dict(self) -> dict[str, Any]:
        return {"value": _r(self.value), "uncertainty": _r(self.uncertainty),
                "source": self.source}


def certificate(setting: TargetSetting, index: int = 0) -> TargetContrast:
    """The certificate's value for a target (``index``: the radial pattern's place)."""
    assert setting.values is not None
    v = setting.values[index] if len(setting.values) > 1 else setting.values[0]
    return TargetContrast(v, setting.uncertainty, "certificate (parameters [targets])")


def lowest_ctf(curves: Sequence[SimulatedCurve], view: str, direction: str,
               freq_lp_per_mm: float) -> float | None:
    """The simulated lens's lowest square-wave response (CTF) at a frequency over the view's
    field points in one direction (``"S"`` / ``"T"``); None without curves."""
    ctfs = [float(simulated_ctf(c, np.array([freq_lp_per_mm]))[0]) for c in curves
            if c.view == view and c.direction == direction]
    return min(ctfs) if ctfs else None


@dataclass(frozen=True)
class ReferenceReading:
    """One reading of a target's reference set: ``modulation`` with its 1-sigma uncertainty,
    where the simulated lens passes ``lens_ctf`` of a square wave."""

    orientation: str
    modulation: float
    uncertainty: float
    lens_ctf: float


def from_reference(readings: Sequence[ReferenceReading], what: str) -> TargetContrast:
    """A target's contrast from its reference set's readings: each divided by the lens's CTF
    there, with the correction's size added to its uncertainty (the curves are the design, not
    this lens), combined by inverse variance."""
    if not readings:
        return TargetContrast(None, None, f"not measured: {what} gave no reading")
    est = []
    for r in readings:
        t = r.modulation / r.lens_ctf
        u = math.hypot(r.uncertainty, t - r.modulation) / r.lens_ctf
        est.append((t, max(u, 1e-6)))
    w = [1.0 / u**2 for _, u in est]
    value = sum(wi * t for wi, (t, _) in zip(w, est, strict=True)) / sum(w)
    lens = min(r.lens_ctf for r in readings)
    parts = " and ".join(r.orientation for r in readings)
    return TargetContrast(value, 1.0 / math.sqrt(sum(w)),
                          f"measured: {what} ({parts}), where the simulated lens passes "
                          f">= {lens:.3f} of the bar contrast")


def lens_share(modulation: float | None, uncertainty: float | None,
               target: TargetContrast) -> tuple[float | None, float | None]:
    """``measured / target`` with its propagated 1-sigma uncertainty; None without a reading
    or a target contrast."""
    if modulation is None or target.value is None:
        return None, None
    share = modulation / target.value
    rel = math.hypot((uncertainty or 0.0) / target.value,
                     share * (target.uncertainty or 0.0) / target.value)
    return share, rel


def share_columns(orient: str, row: dict[str, Any], target: TargetContrast) -> dict[str, Any]:
    """A table row's target contrast and lens share columns for one orientation (the share
    only for a resolved reading)."""
    m = row.get(f"{orient}_modulation")
    ok = m is not None and row.get(f"{orient}_resolved") is not False
    reading = float(m) if ok and m is not None else None
    share, u = lens_share(reading, row.get(f"{orient}_uncertainty"), target)
    return {f"{orient}_target_contrast": _r(target.value),
            f"{orient}_target_contrast_uncertainty": _r(target.uncertainty),
            f"{orient}_lens_share": _r(share), f"{orient}_lens_share_uncertainty": _r(u)}


def _r(v: float | None) -> float | None:
    return None if v is None else round(float(v), 6)
