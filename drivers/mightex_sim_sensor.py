"""Sensor model of the simulated camera: scene light -> noisy 8/12-bit frame bytes, fast.

Per frame the simulator needs ``clip(round(mean + sigma * z), 0, ceiling)`` over 1.3 Mpixel.
Two things keep that cheap enough for > 60 frames/s:

* the noise-free mean and the noise sigma (both in 12-bit DN) are cached per acquisition state
  (scene, exposure, gain, geometry, bench state), so the scene runs only when something changes;
  a scene with ``time_dependent = True`` is evaluated every frame instead;
* the standard-normal draws come from one bank of ``2 x pixels`` float32 values generated once;
  each frame reads a window at a random offset. Per-pixel statistics are exact Gaussians; two
  frames are shifted copies of one another's noise (a bench simulator does not need better).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.drivers import mightex_protocol as p
from benchlab.drivers.sensor import (
    DN12_PER_E,
    FULL_WELL_E,
    READ_NOISE_E,
    AcquisitionState,
    Scene,
)

_ADC_MAX = 4095


def _freeze(value: Any) -> Any:
    """A hashable stand-in for a bench-state value (mappings and sequences included)."""
    if isinstance(value, Mapping):
        return tuple(sorted((str(k), _freeze(v)) for k, v in value.items()))
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    if isinstance(value, np.ndarray):
        return (value.shape, value.tobytes())
    try:
        hash(value)
    except TypeError:
        return repr(value)
    return value


class SensorModel:
    """Turns a scene into frame bytes for one camera (holds the caches and the noise bank).

    Parameters
    ----------
    seed : int, optional
        Seed of the noise generator (frames are reproducible for a given seed and call order).
    noise : bool
        ``False`` renders the noise-free quantised image (exact values for tests).
    read_noise_e : float
        Read noise in electrons RMS.
    """

    def __init__(self, seed: int | None = None, *, noise: bool = True,
                 read_noise_e: float = READ_NOISE_E) -> None:
        self.rng = np.random.default_rng(seed)
        self.noise = noise
        self.read_noise_e = read_noise_e
        self._bank: npt.NDArray[np.float32] | None = None
        self._key: Any = None
        self._mean: npt.NDArray[np.float32] | None = None  # DN12 + 0.5 (so truncation rounds)
        self._sigma: npt.NDArray[np.float32] | None = None  # DN12
        self._ceiling = float(_ADC_MAX)
        self._exact: npt.NDArray[np.uint16] | None = None  # noise-free DN12 when noise is off
        self._work: dict[int, tuple[npt.NDArray[np.float32], npt.NDArray[np.uint16]]] = {}
        self.scene_calls = 0

    def _noise_bank(self, n: int) -> npt.NDArray[np.float32]:
        if self._bank is None or self._bank.size < 2 * n:
            size = 2 * max(n, p.SPECS["MCE-B013-U"].max_width * p.SPECS["MCE-B013-U"].max_height)
            self._bank = self.rng.standard_normal(size, dtype=np.float32)
        return self._bank

    def _prepare(self, scene: Scene, state: AcquisitionState) -> None:
        key = (id(scene), state.exposure_ms, state.gain, state.width, state.height,
               _freeze(state.bench))
        if key == self._key and not getattr(scene, "time_dependent", False):
            return
        rate = np.asarray(scene(state), dtype=np.float64)
        self.scene_calls += 1
        if rate.shape != (state.height, state.width):
            raise ValueError(
                f"scene returned shape {rate.shape}, camera expects {(state.height, state.width)}"
            )
        electrons = np.clip(rate * state.exposure_ms, 0.0, None)
        dn_per_e = DN12_PER_E * state.gain
        # Pixels saturate at the full well (before gain) or the ADC range, whichever first.
        self._ceiling = float(min(math.floor(FULL_WELL_E * dn_per_e + 1e-6), _ADC_MAX))
        mean = electrons * dn_per_e
        self._exact = np.clip(np.floor(mean + 0.5), 0, self._ceiling).astype(np.uint16).ravel()
        self._mean = (mean + 0.5).astype(np.float32).ravel()
        self._sigma = (np.sqrt(electrons + self.read_noise_e**2) * dn_per_e).astype(
            np.float32).ravel()
        self._key = key

    def render_dn12(self, scene: Scene, state: AcquisitionState) -> npt.NDArray[np.uint16]:
        """One frame as 12-bit codes (flat uint16 view into a reused work buffer)."""
        self._prepare(scene, state)
        assert self._mean is not None and self._sigma is not None and self._exact is not None
        n = state.width * state.height
        if not self.noise:
            return self._exact
        if n not in self._work:
            self._work = {n: (np.empty(n, np.float32), np.empty(n, np.uint16))}
        x, dn = self._work[n]
        bank = self._noise_bank(n)
        offset = int(self.rng.integers(0, bank.size - n + 1))
        np.multiply(bank[offset:offset + n], self._sigma, out=x)
        np.add(x, self._mean, out=x)
        np.clip(x, 0.0, self._ceiling, out=x)
        np.copyto(dn, x, casting="unsafe")  # truncation of value + 0.5 = rounding
        return dn

    def render_into(self, payload: bytearray, scene: Scene, state: AcquisitionState) -> None:
        """Write the pixel bytes of one frame (8-bit = 12-bit >> 4, or packed 12-bit)."""
        dn = self.render_dn12(scene, state)
        n = dn.size
        if state.bits == 8:
            out8 = np.frombuffer(payload, dtype=np.uint8, count=n)
            np.right_shift(dn, np.uint16(4), out=out8, casting="unsafe")
        else:
            p.pack_12bit(dn, np.frombuffer(payload, dtype="<u2", count=n))


# --------------------------------------------------------------------------- simple scenes


class FlatFieldScene:
    """Uniform irradiance: ``rate_e_per_ms`` photo-electrons per ms in every pixel."""

    def __init__(self, rate_e_per_ms: float) -> None:
        self.rate_e_per_ms = float(rate_e_per_ms)

    def __call__(self, state: AcquisitionState) -> npt.NDArray[np.float64]:
        return np.full((state.height, state.width), self.rate_e_per_ms)


class BarTargetScene:
    """Square-wave bars: ``period_px`` pixels per line pair, half bright, half dark.

    ``orientation="vertical"`` gives vertical bars (intensity varies along a row).
    """

    def __init__(self, period_px: float, bright_e_per_ms: float, dark_e_per_ms: float,
                 orientation: str = "vertical") -> None:
        if period_px < 2:
            raise ValueError(f"bar period must be at least 2 pixels, got {period_px}")
        if orientation not in ("vertical", "horizontal"):
            raise ValueError(f"orientation must be 'vertical' or 'horizontal', got {orientation!r}")
        self.period_px = float(period_px)
        self.bright_e_per_ms = float(bright_e_per_ms)
        self.dark_e_per_ms = float(dark_e_per_ms)
        self.orientation = orientation

    def __call__(self, state: AcquisitionState) -> npt.NDArray[np.float64]:
        along = state.width if self.orientation == "vertical" else state.height
        phase = (np.arange(along) % self.period_px) < self.period_px / 2
        line = np.where(phase, self.bright_e_per_ms, self.dark_e_per_ms)
        if self.orientation == "vertical":
            return np.broadcast_to(line, (state.height, state.width)).copy()
        return np.broadcast_to(line[:, None], (state.height, state.width)).copy()


def flat_field_scene(rate_e_per_ms: float = 30.0) -> FlatFieldScene:
    """A uniform scene; 30 e-/ms gives mean 8-bit code ~115 at 300 ms, gain 1.

    Use :func:`benchlab.drivers.sensor.rate_for_dn8` to aim for a given code.
    """
    return FlatFieldScene(rate_e_per_ms)


def bar_target_scene(period_px: float = 32.0, *, bright_e_per_ms: float = 50.0,
                     dark_e_per_ms: float = 8.0, orientation: str = "vertical") -> BarTargetScene:
    """Square-wave bar target; defaults give 8-bit codes ~191 / ~30 at 300 ms, gain 1."""
    return BarTargetScene(period_px, bright_e_per_ms, dark_e_per_ms, orientation)
