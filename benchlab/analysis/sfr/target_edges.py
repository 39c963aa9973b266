"""Each nominal edge of the slanted-edge target (:mod:`.target`) read in a whole frame: its
SFR, or the reason there is no clean edge in its ROI. Used by every procedure that images the
target (the Table 4.10 MTF test, the depth-of-field sweep)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy.typing as npt

from benchlab.analysis.sfr.measure import SfrRefused, SfrResult, measure_sfr
from benchlab.analysis.sfr.target import EdgeSpec, edge_specs


def measure_edges(
    pixels: npt.NDArray[Any], specs: Sequence[EdgeSpec] | None = None, *,
    full_scale: float | None = None,
) -> list[tuple[EdgeSpec, SfrResult | str]]:
    """Each nominal edge's SFR, or the reason there is no clean edge in its ROI.
    ``full_scale``: the camera's ceiling (:func:`benchlab.analysis.sfr.measure.full_scale_of_frame`
    from the frame's metadata); None infers it from each ROI's codes."""
    return [(spec, measure_edge(pixels, spec, full_scale))
            for spec in (specs if specs is not None else edge_specs())]


def measure_edge(pixels: npt.NDArray[Any], spec: EdgeSpec,
                 full_scale: float | None = None) -> SfrResult | str:
    """One nominal edge's SFR, or the reason there is no clean edge in its ROI (clipping
    judged against ``full_scale``, see :func:`measure_edges`)."""
    r0, c0, r1, c1 = spec.roi
    if r0 < 0 or c0 < 0 or r1 > pixels.shape[0] or c1 > pixels.shape[1]:
        return f"ROI {spec.roi} is off the {pixels.shape} frame"
    try:
        return measure_sfr(pixels[r0:r1, c0:c1], full_scale=full_scale)
    except SfrRefused as exc:
        return "; ".join(exc.reasons)
