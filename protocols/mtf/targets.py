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

from collections.abc import Sequence
from typing import Any

import numpy as np

from benchlab.analysis.mtf.compare import SimulatedCurve
from benchlab.analysis.mtf.simulated_ctf import simulated_ctf
from benchlab.protocols.target_contrast import TargetContrast, lens_share, rounded

#: The journal event that keeps a simulated target's printed levels (its truth's contrast).
SIMULATED_TARGET_EVENT = "simulated_target"
#: A target's contrast is read only where the simulated lens passes at least this share of a
#: square wave (CTF) at every field point: the reading is then the target's within 1 %.
REFERENCE_MIN_CTF = 0.99


def lowest_ctf(curves: Sequence[SimulatedCurve], view: str, direction: str,
               freq_lp_per_mm: float) -> float | None:
    """The simulated lens's lowest square-wave response (CTF) at a frequency over the view's
    field points in one direction (``"S"`` / ``"T"``); None without curves."""
    ctfs = [float(simulated_ctf(c, np.array([freq_lp_per_mm]))[0]) for c in curves
            if c.view == view and c.direction == direction]
    return min(ctfs) if ctfs else None


def share_columns(orient: str, row: dict[str, Any], target: TargetContrast) -> dict[str, Any]:
    """A table row's target contrast and lens share columns for one orientation (the share
    only for a resolved reading)."""
    m = row.get(f"{orient}_modulation")
    ok = m is not None and row.get(f"{orient}_resolved") is not False
    reading = float(m) if ok and m is not None else None
    share, u = lens_share(reading, row.get(f"{orient}_uncertainty"), target)
    return {f"{orient}_target_contrast": rounded(target.value),
            f"{orient}_target_contrast_uncertainty": rounded(target.uncertainty),
            f"{orient}_lens_share": rounded(share), f"{orient}_lens_share_uncertainty": rounded(u)}
