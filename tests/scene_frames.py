"""Simulated camera frames of a scene, for the tests that need the procedure's own frames."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from benchlab.drivers.mightex.sim_sensor import SensorModel
from benchlab.drivers.sensor import AcquisitionState
from benchlab.scenes.radial import RadialScene
from benchlab.scenes.usaf import UsafScene

H, W = 1024, 1280


def frame(scene: UsafScene, bits: int = 8, seed: int = 0,
          transmission: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.uint16]:
    """A noisy camera frame of the scene (Poisson + read noise, 12-bit ADC)."""
    rate = scene.render(H, W) if transmission is None else scene.render(H, W) * transmission
    state = AcquisitionState(300.0, 1.0, bits, W, H, 0.0, 0)
    dn = SensorModel(seed).render_dn12(lambda _s: rate, state).reshape(H, W)
    return (dn >> 4).astype(np.uint8) if bits == 8 else dn.copy()


def camera_frame(scene: UsafScene | RadialScene, seed: int | None) -> npt.NDArray[np.uint8]:
    """The procedure's 8-bit forward frame (300 ms, unity gain); ``seed`` None: no noise."""
    rate = scene.render(H, W)
    state = AcquisitionState(300.0, 1.0, 8, W, H, 0.0, 0)
    sensor = SensorModel(seed, noise=seed is not None)
    return (sensor.render_dn12(lambda _s: rate, state).reshape(H, W) >> 4).astype(np.uint8)
