"""Printed targets (chrome on glass, back-lit paper): their two levels as sensor signal."""

from __future__ import annotations

from benchlab.drivers.sensor import rate_for_dn8


class TwoLevelPrint:
    """A target of two printed levels, given as 8-bit gray levels at a reference exposure and
    gain; the scenes need them as electron rates (e-/ms). Mixed into the scene dataclasses,
    which declare these four fields."""

    dark_dn8: float
    bright_dn8: float
    reference_exposure_ms: float
    reference_gain: float

    @property
    def contrast(self) -> float:
        """The target's own contrast: Eq. 2.9 of its two printed levels, what a perfect lens
        would read (the simulated bench's truth of ``[targets]`` in the MTF test)."""
        return (self.bright_dn8 - self.dark_dn8) / (self.bright_dn8 + self.dark_dn8)

    @property
    def dark_rate(self) -> float:
        """Electron rate (e-/ms) of the dark level (bars, chrome)."""
        return float(rate_for_dn8(self.dark_dn8, self.reference_exposure_ms, self.reference_gain))

    @property
    def bright_rate(self) -> float:
        """Electron rate (e-/ms) of the bright level (clear glass, lit paper)."""
        return float(rate_for_dn8(self.bright_dn8, self.reference_exposure_ms,
                                  self.reference_gain))
