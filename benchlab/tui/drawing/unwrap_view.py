"""The live view's unwrapped radial view (the ``u`` key): maps built once, remapped per frame.

The centre comes from the first frame's field-of-view mask (the chart's nominal centre when
no annulus is lit); the maps are rebuilt only when the frame size changes or the view is
switched on again. At 8 px/mm the full circle is about 1000 x 220 px, a few ms per frame.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.chart.layout import IMAGE_CENTRE_RC
from benchlab.analysis.views.raytrace import REFERENCE_OBJECT_RADIUS_MM, read_raytrace_table
from benchlab.analysis.views.synthesis import ViewMaps, apply_maps, fov_centre_of_frame, unwrap_maps
from benchlab.tui.services import LiveReading, preview_of

#: Live unwrapped view scale, px per object mm.
LIVE_PX_PER_MM = 8.0


class UnwrapPreview:
    """Turns a live reading's preview into the unwrapped radial view."""

    def __init__(self, object_radius_mm: float = REFERENCE_OBJECT_RADIUS_MM) -> None:
        self.object_radius_mm = object_radius_mm
        self._maps: ViewMaps | None = None
        self.centre_method = ""

    def reset(self) -> None:
        """Forget the maps (the next frame refits the centre)."""
        self._maps = None

    def maps_for(self, pixels: npt.NDArray[Any]) -> ViewMaps:
        if self._maps is None or tuple(self._maps.meta["frame_shape"]) != pixels.shape[:2]:
            try:
                centre, self.centre_method = fov_centre_of_frame(pixels)
            except ValueError:
                centre, self.centre_method = IMAGE_CENTRE_RC, "nominal"
            self._maps = unwrap_maps(read_raytrace_table(None), pixels.shape[:2], centre,
                                     object_radius_mm=self.object_radius_mm,
                                     px_per_mm=LIVE_PX_PER_MM)
        return self._maps

    def apply(self, reading: LiveReading, pixels: npt.NDArray[Any],
              max_side: int = 640) -> LiveReading:
        """The reading with its preview replaced by the unwrapped frame (a note on failure)."""
        try:
            view = apply_maps(np.asarray(pixels), self.maps_for(pixels))
        except (ValueError, OSError) as exc:
            return dataclasses.replace(reading, note=f"unwrap: {exc}")
        return dataclasses.replace(
            reading, preview=preview_of(view, max_side=max_side),
            note=f"unwrapped at {self.object_radius_mm:g} mm (centre {self.centre_method})"
            + (f"; ROI: {reading.note}" if reading.note else ""),
        )
