"""The ``[targets]`` parameters of the MTF test: how each target's own contrast is known
(measured on the bench, or entered from its certificate). The analysis that uses them:
:mod:`benchlab.protocols.mtf.targets`. Kept outside the procedure package so that the generic
parameter loader can read them.
"""

from __future__ import annotations

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
