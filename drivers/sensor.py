"""What a simulated camera asks a scene for, and the sensor model that turns light into codes.

A *scene* is any callable ``scene(state) -> ndarray`` that returns the photo-electron rate
(e-/ms per pixel, float, shape ``(state.height, state.width)``) reaching the sensor for the
given :class:`AcquisitionState`. The camera simulator multiplies by exposure, adds shot and
read noise, applies gain, clips at full well / ADC range and quantises to 12 bits (8-bit
output is the 12-bit code shifted right by 4, as the MT9M001 delivers it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

# The simulated MT9M001's sensor constants and geometry, read from the production descriptions
# of its sensor and of the camera (:data:`benchlab.drivers.mightex.profile.BENCH_CAMERA`).
from benchlab.drivers.mightex.characteristics import (  # noqa: F401 (the simulator's sensor)
    ADC_BITS,
    DN12_PER_E,
    FULL_WELL_E,
    READ_NOISE_E,
)
from benchlab.drivers.mightex.profile import (  # noqa: F401 (the simulator's geometry)
    PIXEL_PITCH_UM,
    SENSOR_HEIGHT_PX,
    SENSOR_WIDTH_PX,
)


@dataclass(frozen=True)
class AcquisitionState:
    """The camera settings at the moment a frame is exposed.

    ``bench`` carries whatever the bench assembly knows about the rest of the set-up
    (stage position, LED currents, which target is mounted); the camera never reads it.
    """

    exposure_ms: float
    gain: float
    bits: int
    width: int
    height: int
    time_s: float
    frame_index: int
    bench: Mapping[str, Any] = field(default_factory=dict)


class Scene(Protocol):
    """The light reaching the sensor, in photo-electrons per millisecond per pixel."""

    def __call__(self, state: AcquisitionState) -> npt.NDArray[np.float64]: ...


def rate_for_dn8(dn8: float | npt.ArrayLike, exposure_ms: float, gain: float = 1.0) -> Any:
    """Electron rate (e-/ms) that yields the mean 8-bit code ``dn8`` at this exposure and gain.

    Scenes use it to place their dark and bright levels where a test wants them.
    """
    dn12 = np.asarray(dn8, dtype=np.float64) * 16.0
    return dn12 / (DN12_PER_E * gain * exposure_ms)
