"""Depth-of-field criteria as MTF thresholds at one image frequency.

Three kinds, each reduced to "MTF at ``frequency`` >= ``threshold``" so one through-focus fit
per frequency serves them all:

* ``mtf``: MTF at a frequency >= a threshold, as given;
* ``mtf50``: MTF50 >= a frequency. Where the MTF falls monotonically with frequency (any
  defocused lens below its first zero) that is MTF(frequency) >= 0.5;
* ``spot``: the thesis's RMS spot size < ``rms_um`` (Table 4.1: 12 um, "so the empirical
  verification can be performed over a greater range"). The stated model: a round Gaussian
  spot of radial RMS ``r`` has the MTF ``exp(-pi^2 r^2 f^2)`` (its per-axis sigma is
  ``r / sqrt 2``); the camera adds its pixel aperture, ``sinc(f p)`` (pitch ``p``, the edge's
  small slant neglected: < 0.1 % at 10 deg). So the spot criterion is MTF(f) >=
  ``exp(-pi^2 r^2 f^2) sinc(f p)`` at the chosen ``f``, exact for Gaussian spots (the simulated
  bench) and an approximation for others (a defocus disc has a different MTF for the same
  RMS). Per orientation the spot is taken round with that orientation's width.

Pure functions; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

CriterionKind = Literal["mtf", "mtf50", "spot"]
KINDS: tuple[CriterionKind, ...] = ("mtf", "mtf50", "spot")


@dataclass(frozen=True)
class Criterion:
    """One DOF criterion (module docstring). ``threshold`` is used by ``mtf``, ``rms_um`` by
    ``spot``."""

    kind: CriterionKind
    frequency_lp_per_mm: float
    threshold: float = 0.5
    rms_um: float = 12.0

    @property
    def name(self) -> str:
        """Short label, e.g. ``MTF(70)>=0.3``, ``MTF50>=35``, ``spot<=12um@20``."""
        f = f"{self.frequency_lp_per_mm:g}"
        if self.kind == "mtf":
            return f"MTF({f})>={self.threshold:g}"
        if self.kind == "mtf50":
            return f"MTF50>={f}"
        return f"spot<={self.rms_um:g}um@{f}"


def spot_threshold(rms_um: float, frequency_lp_per_mm: float, pixel_pitch_um: float) -> float:
    """MTF at ``frequency`` of a round Gaussian spot of radial RMS ``rms_um`` seen through a
    pixel aperture of ``pixel_pitch_um`` (module docstring)."""
    f = frequency_lp_per_mm / 1000.0  # cycles per um
    x = f * pixel_pitch_um
    aperture = math.sin(math.pi * x) / (math.pi * x) if x > 0 else 1.0
    return math.exp(-(math.pi * rms_um * f) ** 2) * aperture


def mtf_threshold(criterion: Criterion, pixel_pitch_um: float) -> float:
    """The MTF threshold at ``criterion.frequency_lp_per_mm`` the criterion amounts to."""
    if criterion.kind == "mtf":
        return criterion.threshold
    if criterion.kind == "mtf50":
        return 0.5
    return spot_threshold(criterion.rms_um, criterion.frequency_lp_per_mm, pixel_pitch_um)
