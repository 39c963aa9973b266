"""Bootstrap uncertainty of a modulation estimate (measurement-notes section 7.1).

Lines **along the bars** are resampled with replacement: each resampled line still crosses the
same bars, so the spatial profile survives (pixel-wise resampling would destroy it for the
sine fit). The spread of the re-estimated modulation gives the standard uncertainty and a
percentile interval. A ROI only one line thick keeps its analytic uncertainty.

The bootstrap sees the noise only: the estimator's model and sampling-phase term (the
``uncertainty_model`` of its diagnostics, when it reports one) is added in quadrature and
widens the interval. Lines of an image axis only run along the bars when the bars are
axis-aligned: on oblique bars a resampled line lands at another row with another bar phase,
which smears the profile the estimator sees, so oblique bars keep the analytic uncertainty.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.result import ModulationResult
from benchlab.analysis.bars.roi import PreparedROI

#: Bars more than this far (deg) off the image axis of the resampled lines are "oblique".
OBLIQUE_LIMIT_DEG = 1.0


def bootstrap_result(
    prep: PreparedROI,
    result: ModulationResult,
    estimator: Callable[[PreparedROI], ModulationResult],
    n_resamples: int = 200,
    seed: int | None = 0,
) -> ModulationResult:
    """``result`` with bootstrap uncertainty and a 95 % percentile interval.

    Unresolved resamples count as modulation 0, so a marginal ROI gets a wide interval.
    """
    if n_resamples < 2:
        raise ValueError(f"need at least 2 bootstrap resamples, got {n_resamples}")
    prep = prep.measured()  # the resamples share the ROI's own axis and noise
    lines_axis = 1 - prep.axis  # lines along the bars are indexed along this axis
    n_lines = prep.pixels.shape[lines_axis]
    if n_lines < 2:
        return result.with_updates(
            warnings=(*result.warnings, "one line along the bars: analytic uncertainty kept")
        )
    angle = result.diagnostics.bar_angle_deg
    if angle is not None:
        # The direction in which the intensity varies: along columns (axis 1) is 0 deg.
        axis_angle = 0.0 if prep.axis == 1 else 90.0
        off = abs((angle - axis_angle + 90.0) % 180.0 - 90.0)
        if off > OBLIQUE_LIMIT_DEG:
            return result.with_updates(warnings=(
                *result.warnings,
                f"bars {off:.1f} deg off the image axis: resampled lines would shift their "
                "bar phase, analytic uncertainty kept",
            ))
    rng = np.random.default_rng(seed)
    mods: list[float] = []
    for _ in range(n_resamples):
        pick = rng.integers(0, n_lines, n_lines)
        pixels: npt.NDArray[np.float64] = np.take(prep.pixels, pick, axis=lines_axis)
        mods.append(estimator(replace(prep, pixels=pixels)).modulation)
    arr = np.asarray(mods)
    low, high = (float(v) for v in np.percentile(arr, [2.5, 97.5]))
    model_sd = result.diagnostics.uncertainty_model or 0.0
    spread = float(arr.std(ddof=1))
    # Widen each side of the percentile interval by the model term (in quadrature).
    centre = result.modulation
    low = centre - math.hypot(centre - low, 1.96 * model_sd)
    high = centre + math.hypot(high - centre, 1.96 * model_sd)
    return result.with_updates(
        uncertainty=math.hypot(spread, model_sd),
        interval=(max(low, 0.0), min(high, 1.0)),
        uncertainty_method="bootstrap",
    )
