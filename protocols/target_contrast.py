"""A target's own contrast, shared by the procedures that read bars (MTF, depth of field): the
``[targets]`` parameters (measured on the bench, or entered from the target's certificate), the
:class:`TargetContrast` a procedure records with its source, a contrast from reference readings
(:func:`from_reference`) and the lens's share of a reading (:func:`lens_share`). Pure
arithmetic, kept outside the procedure packages so that the generic parameter loader and every
procedure can use it. How each procedure picks its reference readings:
:mod:`benchlab.protocols.mtf.targets` (where the simulated lens passes >= 0.99) and
:mod:`benchlab.protocols.depth.targets` (the plateau at best focus).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from benchlab.checks import TableChecker

MEASURED = "measured"


@dataclass(frozen=True)
class TargetSetting:
    """How one target's contrast is known: measured on the bench (``values`` None) or entered
    from its certificate (one value, or one per radial pattern) with its 1-sigma
    ``uncertainty``."""

    values: tuple[float, ...] | None = None
    uncertainty: float = 0.0

    def to_value(self) -> Any:
        """The parameter file's form: ``"measured"``, a number or a list of numbers."""
        if self.values is None:
            return MEASURED
        return self.values[0] if len(self.values) == 1 else list(self.values)


@dataclass(frozen=True)
class TargetSettings:
    """The USAF chart's and the radial patterns' contrast settings."""

    usaf: TargetSetting = field(default_factory=TargetSetting)
    radial: TargetSetting = field(default_factory=TargetSetting)


def check_targets(c: TableChecker, radial_count: int) -> TargetSettings:
    """``[targets]`` of the parameter file: ``usaf_contrast`` / ``radial_contrast``
    (``"measured"``, a number in (0, 1], for the radial patterns also a list with one per
    frequency) and ``usaf_contrast_uncertainty`` / ``radial_contrast_uncertainty`` (1 sigma,
    only with a certificate value)."""
    out = []
    for name, per_pattern in (("usaf", 0), ("radial", radial_count)):
        key = f"targets.{name}_contrast"
        found, value = c.get(key, MEASURED)
        values: tuple[float, ...] | None = None
        if isinstance(value, list) and per_pattern:
            if len(value) != per_pattern:
                c.fail(key, f"has {len(value)} values for {per_pattern} radial frequencies "
                       "(give one per frequency, or one number for all)")
            else:
                values = c.numbers(key, (1.0,), 0.0, 1.0, lo_open=True, distinct=False)
        elif isinstance(value, int | float) and not isinstance(value, bool):
            values = (c.number(key, 1.0, 0.0, 1.0, lo_open=True),)
        elif value != MEASURED:
            c.fail(key, f"must be \"measured\" or a contrast in (0, 1] from the target's "
                   f"certificate{' (or a list, one per frequency)' if per_pattern else ''}, "
                   f"got {value!r}")
        ukey = f"targets.{name}_contrast_uncertainty"
        u = c.number(ukey, 0.0, 0.0, 1.0)
        if values is None and c.get(ukey, None)[0]:
            c.fail(ukey, f"applies to a certificate value only ({key} is \"measured\": its "
                   "uncertainty is the reading's)")
        out.append(TargetSetting(values, u))
    return TargetSettings(out[0], out[1])


def targets_to_dict(settings: TargetSettings) -> dict[str, Any]:
    """``[targets]`` as the parameter file writes it."""
    out: dict[str, Any] = {}
    for name, s in (("usaf", settings.usaf), ("radial", settings.radial)):
        out[f"{name}_contrast"] = s.to_value()
        if s.values is not None:
            out[f"{name}_contrast_uncertainty"] = s.uncertainty
    return out


@dataclass(frozen=True)
class TargetContrast:
    """A target's contrast (Eq. 2.9 of the target itself) with its 1-sigma uncertainty and
    where it comes from; ``value`` None when unknown (``source`` then says why)."""

    value: float | None
    uncertainty: float | None
    source: str

    def to_dict(self) -> dict[str, Any]:
        return {"value": rounded(self.value), "uncertainty": rounded(self.uncertainty),
                "source": self.source}


def certificate(setting: TargetSetting, index: int = 0) -> TargetContrast:
    """The certificate's value for a target (``index``: the radial pattern's place)."""
    assert setting.values is not None
    v = setting.values[index] if len(setting.values) > 1 else setting.values[0]
    return TargetContrast(v, setting.uncertainty, "certificate (parameters [targets])")


@dataclass(frozen=True)
class ReferenceReading:
    """One reading of a target's reference set: ``modulation`` with its 1-sigma uncertainty,
    where the simulated lens passes ``lens_ctf`` of a square wave."""

    orientation: str
    modulation: float
    uncertainty: float
    lens_ctf: float


def from_reference(readings: Sequence[ReferenceReading], what: str,
                   where: str | None = None) -> TargetContrast:
    """A target's contrast from its reference set's readings: each divided by the lens's CTF
    there, with the correction's size added to its uncertainty (the curves are the design, not
    this lens), combined by inverse variance. ``where`` says how the readings were chosen (by
    default: where the simulated lens passes >= its lowest CTF)."""
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
    parts = " and ".join(dict.fromkeys(r.orientation for r in readings))
    where = where or f"where the simulated lens passes >= {lens:.3f} of the bar contrast"
    return TargetContrast(value, 1.0 / math.sqrt(sum(w)), f"measured: {what} ({parts}), {where}")


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


def rounded(v: float | None) -> float | None:
    """A table's figure: 6 decimals (None stays None)."""
    return None if v is None else round(float(v), 6)
