"""Bootstrap uncertainty of a modulation estimate (measurement-notes section 7.1).

Lines **along the bars** are resampled with replacement: each resampled line still crosses the
same bars, so the spatial profile survives (pixel-wise resampling would destroy it for the
sine fit). The spread of the re-estimated modulation gives the standard uncertainty and a
percentile interval. A ROI only one line thick keeps its analytic uncertainty.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from benchlab.analysis.result import ModulationResult
from benchlab.analysis.roi import PreparedROI


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
    lines_axis = 1 - prep.axis  # lines along the bars are indexed along this axis
    n_lines = prep.pixels.shape[lines_axis]
    if n_lines < 2:
        return result.with_updates(
            warnings=(*result.warnings, "one line along the bars: analytic uncertainty kept")
        )
    rng = np.random.default_rng(seed)
    mods: list[float] = []
    for _ in range(n_resamples):
        pick = rng.integers(0, n_lines, n_lines)
        pixels: npt.NDArray[np.float64] = np.take(prep.pixels, pick, axis=lines_axis)
        mods.append(estimator(replace(prep, pixels=pixels)).modulation)
    arr = np.asarray(mods)
    low, high = (float(v) for v in np.percentile(arr, [2.5, 97.5]))
    return result.with_updates(
        uncertainty=float(arr.std(ddof=1)),
        interval=(low, high),
        uncertainty_method="bootstrap",
    )
