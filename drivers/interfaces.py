"""The three device kinds the bench uses, as typed interfaces every driver implements.

- :class:`Camera` - grabs frames at a set exposure and gain (Mightex USB camera).
- :class:`LightSource` - current-driven LED channels with per-channel ceilings (Mightex SLC).
- :class:`LinearStage` - one axis in mm with travel limits, homing and stop (Thorlabs APT).

Template methods, as in python-microscope's ``abc.py``: the public method checks its arguments
against the interface's rules (finite numbers, existing channels, ceilings, travel) and only
then calls the driver's ``_do_*`` method, which talks to the device. A bad value therefore
never reaches the wire, whatever the driver. Model-specific limits (exposure steps, camera
geometry) stay with the driver's protocol module and are checked there, before any byte.

``tests/test_contract_*.py`` run one contract suite per kind against every implementation.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

import numpy as np
import numpy.typing as npt

from benchlab.drivers.errors import DeviceError, SafetyLimitError, SettingOutOfRangeError
from benchlab.drivers.safety import SafeInstrument

__all__ = ["Camera", "DeviceIdentity", "Frame", "FrameMetadata", "LightSource", "LinearStage"]


@dataclass(frozen=True)
class DeviceIdentity:
    """Who a device is, for ``session.json`` and the devices panel."""

    model: str
    serial: str
    firmware: str
    #: Serial port path or URL; ``None`` for USB devices.
    port: str | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"model": self.model, "serial": self.serial,
                               "firmware": self.firmware}
        if self.port is not None:
            out["port"] = self.port
        return out


def _finite(name: str, value: object) -> float:
    """``value`` as a float, or :class:`SettingOutOfRangeError` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SettingOutOfRangeError(f"{name} must be a finite number, got {value!r}; nothing sent")
    return float(value)


def _timeout(value: float | None) -> float | None:
    if value is None:
        return None
    if _finite("timeout_s", value) < 0:
        raise SettingOutOfRangeError(f"timeout_s must be >= 0, got {value!r}")
    return float(value)


# ---- camera ------------------------------------------------------------------------------------
class FrameMetadata(Protocol):
    """Acquisition metadata a camera attaches to each frame."""

    @property
    def exposure_ms(self) -> float: ...

    @property
    def gain(self) -> float: ...

    @property
    def bits(self) -> int: ...

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary of every field."""
        ...


#: The metadata type a camera's frames carry (each driver has its own, with its extra fields).
M = TypeVar("M", bound=FrameMetadata, covariant=True)


@dataclass(frozen=True)
class Frame(Generic[M]):
    """Pixels (``(height, width)``, uint8, or uint16 holding ``meta.bits`` bits) and metadata."""

    pixels: npt.NDArray[np.uint8] | npt.NDArray[np.uint16]
    meta: M


class Camera(ABC, Generic[M]):
    """A camera: configure, set exposure and gain, grab frames."""

    @property
    @abstractmethod
    def identity(self) -> DeviceIdentity:
        """Model, serial number and firmware of the open camera."""

    @property
    @abstractmethod
    def exposure_ms(self) -> float:
        """Exposure as set on the camera (after the model's rounding)."""

    @property
    @abstractmethod
    def gain(self) -> float:
        """Gain multiplier as set on the camera."""

    def configure(self, *, width: int = 1280, height: int = 1024, bits: int = 8,
                  mode: str = "normal", **options: int) -> None:
        """Frame size in pixels, bit depth, acquisition mode (``"normal"`` = free running,
        ``"trigger"``) and model-specific integer ``options``; old frames are flushed.

        The model's own geometry rules (steps, maxima, which bit depths) are the driver's.
        """
        for name, value in (("width", width), ("height", height), ("bits", bits),
                            *options.items()):
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise SettingOutOfRangeError(
                    f"camera {name} must be a whole number >= 0, got {value!r}; nothing sent")
        if not isinstance(mode, str):
            raise SettingOutOfRangeError(f"camera mode must be a name, got {mode!r}")
        self._do_configure(width=width, height=height, bits=bits, mode=mode, **options)

    def set_exposure_ms(self, exposure_ms: float) -> None:
        """Exposure time in ms (the model's range and step are checked by the driver)."""
        self._do_set_exposure_ms(_finite("exposure_ms", exposure_ms))

    def set_gain(self, gain: float) -> None:
        """Gain multiplier, 1.0 = unity (the model's range is checked by the driver)."""
        self._do_set_gain(_finite("gain", gain))

    def grab(self, timeout_s: float | None = None, *, fresh: bool = True) -> Frame[M]:
        """A frame taken with the current settings: in free-running mode one exposed wholly
        after this call (``fresh``; ``fresh=False``: the newest the camera holds, for a live
        stream), in trigger mode the next in order (driver default timeout if None)."""
        return self._do_grab(_timeout(timeout_s), fresh=fresh)

    @abstractmethod
    def clear_buffer(self) -> int:
        """Drop every frame waiting in the camera; returns how many there were."""

    @abstractmethod
    def reopen(self) -> None:
        """Reconnect to the same camera (after it was lost) and restore its settings."""

    @abstractmethod
    def close(self) -> None:
        """Release the camera (safe to call twice)."""

    def __enter__(self) -> Camera[M]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @abstractmethod
    def _do_configure(self, *, width: int, height: int, bits: int, mode: str,
                      **options: int) -> None: ...

    @abstractmethod
    def _do_set_exposure_ms(self, exposure_ms: float) -> None: ...

    @abstractmethod
    def _do_set_gain(self, gain: float) -> None: ...

    @abstractmethod
    def _do_grab(self, timeout_s: float | None, *, fresh: bool = True) -> Frame[M]: ...


# ---- light source ------------------------------------------------------------------------------
class LightSource(SafeInstrument):
    """Current-driven light channels (1-based) with a configured ceiling per channel.

    A channel without a configured ceiling cannot be lit. ``close()`` (and every exit path,
    see :class:`SafeInstrument`) switches every channel off.
    """

    #: How the device and its channels are named in messages.
    NAME = "light source"
    CHANNEL_NAME = "light channel"

    @property
    @abstractmethod
    def identity(self) -> DeviceIdentity:
        """Model, serial number, firmware and port of the open controller."""

    @property
    @abstractmethod
    def channel_count(self) -> int:
        """Number of channels (known once open)."""

    @property
    @abstractmethod
    def ceilings_ma(self) -> Mapping[int, float]:
        """Configured per-channel current ceilings in mA."""

    def ceiling_ma(self, ch: int) -> float | None:
        """The highest current channel ``ch`` may be driven at (None: must stay dark)."""
        return self.ceilings_ma.get(ch)

    @abstractmethod
    def current_step_ma(self, ch: int) -> float:
        """The smallest current change channel ``ch`` can make, in mA: every current it drives
        is a whole multiple of it (known once open)."""

    def max_current_ma(self, ch: int) -> float | None:
        """The highest current channel ``ch`` can be set to: its ceiling rounded down to the
        current step (None: no ceiling, must stay dark)."""
        ceiling = self.ceiling_ma(ch)
        if ceiling is None:
            return None
        step = self.current_step_ma(ch)
        return round(math.floor(ceiling / step + 1e-9) * step, 9)

    def on(self, ch: int, current_ma: float) -> None:
        """Light channel ``ch`` at ``current_ma``; checked against its ceiling and its current
        step first (a current between two steps is refused, never rounded: see README)."""
        self._check_channel(ch)
        self._check_current(ch, current_ma)
        self._check_step(ch, current_ma)
        self._do_on(ch, float(current_ma))

    def off(self, ch: int) -> None:
        """Switch channel ``ch`` off."""
        self._check_channel(ch)
        self._do_off(ch)

    @abstractmethod
    def all_off(self) -> None:
        """Switch every channel off and confirm it; raise if any may still be lit."""

    def is_on(self, ch: int) -> bool:
        """Whether channel ``ch`` is lit (read from the device)."""
        self._check_channel(ch)
        return self._do_is_on(ch)

    def current_ma(self, ch: int) -> float:
        """The working current channel ``ch`` is set to, in mA (read from the device)."""
        self._check_channel(ch)
        return self._do_current_ma(ch)

    # ---- the checks every light source shares ------------------------------------------------
    def _check_channel(self, ch: int) -> None:
        if not self.is_open:
            raise DeviceError(f"{self.NAME} is not open")
        n = self.channel_count
        if isinstance(ch, bool) or not (isinstance(ch, int) and 1 <= ch <= n):
            raise SettingOutOfRangeError(
                f"{self.CHANNEL_NAME} {ch} does not exist (1..{n}); nothing sent")

    def _check_current(self, ch: int, current_ma: float) -> None:
        what = f"{self.CHANNEL_NAME} {ch}"
        if (isinstance(current_ma, bool) or not isinstance(current_ma, int | float)
                or not math.isfinite(current_ma)):
            raise SettingOutOfRangeError(f"{what}: current {current_ma!r} is not finite")
        if current_ma < 0:
            raise SettingOutOfRangeError(f"{what}: negative current {current_ma} mA")
        limit = self.ceiling_ma(ch)
        if limit is None:
            raise SafetyLimitError(f"{what} has no configured ceiling; nothing sent")
        if current_ma > limit:
            raise SafetyLimitError(
                f"{what}: {current_ma} mA exceeds the ceiling {limit} mA; nothing sent")

    def _check_step(self, ch: int, current_ma: float) -> None:
        """Refuse a current the hardware cannot drive (between two of its steps): rounding it
        would light another current than asked - or none at all below the first step."""
        step = self.current_step_ma(ch)
        steps = current_ma / step
        if abs(steps - round(steps)) > 1e-6:
            lo, hi = (round(k * step, 9) for k in (math.floor(steps), math.floor(steps) + 1))
            raise SettingOutOfRangeError(
                f"{self.CHANNEL_NAME} {ch}: {current_ma:g} mA cannot be set, the {self.NAME} "
                f"drives {step:g} mA steps (nearest: {lo:g} or {hi:g} mA); nothing sent")

    @abstractmethod
    def _do_on(self, ch: int, current_ma: float) -> None: ...

    @abstractmethod
    def _do_off(self, ch: int) -> None: ...

    @abstractmethod
    def _do_is_on(self, ch: int) -> bool: ...

    @abstractmethod
    def _do_current_ma(self, ch: int) -> float: ...


# ---- linear stage ------------------------------------------------------------------------------
class LinearStage(SafeInstrument):
    """One motorised axis in mm: home, move within the configured travel, stop.

    ``close()`` (and every exit path, see :class:`SafeInstrument`) stops the stage.
    """

    #: How the device is named in messages.
    NAME = "stage"

    @property
    @abstractmethod
    def identity(self) -> DeviceIdentity:
        """Model, serial number, firmware and port of the open controller."""

    @property
    @abstractmethod
    def travel_mm(self) -> tuple[float, float]:
        """Configured (low, high) travel limits in mm; no move may leave them."""

    @property
    @abstractmethod
    def position_mm(self) -> float:
        """Current position in mm (read from the device)."""

    @property
    @abstractmethod
    def is_homed(self) -> bool:
        """Whether the stage has been homed since power-up."""

    @property
    @abstractmethod
    def is_moving(self) -> bool:
        """Whether the stage is moving (read from the device)."""

    @property
    @abstractmethod
    def velocity_mm_s(self) -> float:
        """Maximum move velocity in mm/s."""

    def home(self, timeout_s: float | None = None) -> None:
        """Find the home switch, zero the position and wait until homed."""
        self._do_home(_timeout(timeout_s))

    def move_to_mm(self, position_mm: float, *, wait: bool = True,
                   timeout_s: float | None = None) -> None:
        """Absolute move; the target is checked against the travel before anything is sent."""
        target = _finite(f"{self.NAME}: target", position_mm)
        lo, hi = self.travel_mm
        if not lo <= target <= hi:
            raise SafetyLimitError(
                f"{self.NAME}: target {target:.4f} mm outside travel [{lo}, {hi}] mm; nothing sent")
        self._do_move_to_mm(target, wait=wait, timeout_s=_timeout(timeout_s))

    def stop(self, *, immediate: bool = True, wait: bool = True,
             timeout_s: float | None = None) -> None:
        """Stop now (``immediate``) or with a profiled deceleration; optionally wait."""
        self._do_stop(immediate=immediate, wait=wait, timeout_s=_timeout(timeout_s))

    def set_velocity_mm_s(self, velocity_mm_s: float) -> None:
        """Maximum move velocity in mm/s (> 0; the model's maximum is checked by the driver)."""
        if _finite(f"{self.NAME}: velocity", velocity_mm_s) <= 0:
            raise SettingOutOfRangeError(
                f"{self.NAME}: velocity must be > 0 mm/s, got {velocity_mm_s!r}")
        self._do_set_velocity_mm_s(float(velocity_mm_s))

    @abstractmethod
    def _do_home(self, timeout_s: float | None) -> None: ...

    @abstractmethod
    def _do_move_to_mm(self, position_mm: float, *, wait: bool,
                       timeout_s: float | None) -> None: ...

    @abstractmethod
    def _do_stop(self, *, immediate: bool, wait: bool, timeout_s: float | None) -> None: ...

    @abstractmethod
    def _do_set_velocity_mm_s(self, velocity_mm_s: float) -> None: ...
