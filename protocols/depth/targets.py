"""The depth sweep's targets' own contrast (the USAF chart's, the printed radial patterns'),
with its source, and the lens's share of the bar readings (``measured / target``).

The ``[targets]`` parameters are the MTF test's (:mod:`benchlab.protocols.target_contrast`):
a certificate value with its 1-sigma, or ``"measured"`` (the default). Measured here means
read on the sweep itself, from the lowest-frequency bar set (forward: the chart's coarsest
found element; radial: the lowest-frequency pattern, every field point), at its **plateau**
through focus: near best focus the blur is narrower than a bar, the bars' centres reach the
printed levels and the Eq. 2.9 reading stops rising - it *is* the print's contrast there (the
lens passes all of it, more than the MTF test's 0.99). A plateau is :data:`MIN_PLATEAU_POINTS`
or more neighbouring distances whose readings lie within :data:`PLATEAU_TOLERANCE` of the
highest; their mean is the target's contrast, the series combined by inverse variance
(:func:`benchlab.protocols.target_contrast.from_reference`). A broad peak below the print's
contrast that happens to be flat to 1 % would pass too: a certificate value is the firmer
source when the target has one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from benchlab.protocols.target_contrast import (
    ReferenceReading,
    TargetContrast,
    TargetSetting,
    certificate,
    from_reference,
)

#: Readings within this fraction of the highest one belong to its plateau.
PLATEAU_TOLERANCE = 0.01
#: Fewer neighbouring distances on the plateau than this: no plateau (a peak).
MIN_PLATEAU_POINTS = 3
#: How a measured contrast is read, for its ``source``.
PLATEAU_WHERE = (f"its plateau through focus (>= {MIN_PLATEAU_POINTS} distances within "
                 f"{PLATEAU_TOLERANCE:.0%} of the highest reading)")

#: One reading through focus: (distance mm, Eq. 2.9 modulation, its 1-sigma).
Point = tuple[float, float, float]


def plateau(points: Sequence[Point], orientation: str) -> ReferenceReading | None:
    """One series' plateau (module docstring) as a reference reading, or None without one."""
    pts = sorted((z, m, s) for z, m, s in points if math.isfinite(m))
    if not pts:
        return None
    top = max(range(len(pts)), key=lambda i: pts[i][1])
    floor = (1.0 - PLATEAU_TOLERANCE) * pts[top][1]
    lo = hi = top
    while lo > 0 and pts[lo - 1][1] >= floor:
        lo -= 1
    while hi < len(pts) - 1 and pts[hi + 1][1] >= floor:
        hi += 1
    flat = pts[lo:hi + 1]
    if len(flat) < MIN_PLATEAU_POINTS:
        return None
    n = len(flat)
    mean = sum(m for _, m, _ in flat) / n
    # the mean's 1-sigma: the readings' own, or their scatter when larger
    sd = math.sqrt(sum(s * s for _, _, s in flat if math.isfinite(s)) / n) if flat else 0.0
    spread = math.sqrt(sum((m - mean) ** 2 for _, m, _ in flat) / (n - 1))
    return ReferenceReading(orientation, mean, max(sd, spread) / math.sqrt(n), 1.0)


def target_contrast(setting: TargetSetting, series: Sequence[tuple[str, Sequence[Point]]],
                    what: str, index: int = 0) -> TargetContrast:
    """A target's contrast: the certificate's (``index``: the radial pattern's place), else
    measured on the plateaus of the reference set's ``series`` ((orientation, points) each)."""
    if setting.values is not None:
        return certificate(setting, index)
    refs = [r for o, pts in series if (r := plateau(pts, o)) is not None]
    if not refs:
        return TargetContrast(None, None, f"not measured: {what} has no plateau through focus "
                              f"({MIN_PLATEAU_POINTS} distances within "
                              f"{PLATEAU_TOLERANCE:.0%} of its highest reading)")
    return from_reference(refs, what, where=PLATEAU_WHERE)
