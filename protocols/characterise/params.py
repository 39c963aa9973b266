"""Parameters of the camera characterisation (EMVA 1288-style photon transfer), checked in full.

Read by :func:`benchlab.protocols.params.parse_params` like the other procedures' files; every
problem is listed at once, naming the file and the dotted field.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from benchlab.checks import CAMERA_BIT_DEPTHS
from benchlab.drivers.mightex.characteristics import SensorCharacteristics
from benchlab.protocols.camera_limits import EXPOSURE_RANGE_MS as _EXPOSURE_RANGE_MS
from benchlab.protocols.camera_limits import GAIN_RANGE as _GAIN_RANGE


@dataclass(frozen=True)
class CharacteriseParams:
    """Parameters of ``benchlab run characterise``.

    The sweep for each (gain, bits) configuration: a probe finds the exposure that saturates
    the sensor (``t_sat``), then ``log_steps`` log-spaced exposures from the shortest up to 5 %
    of ``t_sat``, ``linear_steps`` up to 85 % and ``near_saturation_steps`` from 87 % to
    ``beyond_saturation`` x ``t_sat``; at each, two lit frames and two dark frames. Then
    ``stack_frames`` lit and dark frames at ``stack_fraction`` x ``t_sat`` for DSNU / PRNU.

    ``vary = "led_current"`` sweeps the LED current instead (0.1 mA steps up to
    ``led_current_ma``) at the fixed ``exposure_ms``: the exposure quantity is then current x
    exposure, which assumes the LED's output is proportional to its current, and the dark
    current is not measured (one exposure).
    """

    gains: tuple[float, ...] = (1.0, 4.0)
    bits: tuple[int, ...] = (12, 8)
    width: int = 128
    height: int = 128
    led_channel: int = 1
    led_current_ma: float = 20.0
    log_steps: int = 6
    linear_steps: int = 14
    near_saturation_steps: int = 10
    beyond_saturation: float = 1.15
    max_exposure_ms: float = 750.0
    probe_start_ms: float = 0.5
    vary: str = "exposure"
    exposure_ms: float = 40.0
    probe_start_ma: float = 0.5
    stack_frames: int = 8
    stack_fraction: float = 0.5
    reference_range: tuple[float, float] = (0.05, 0.4)
    simulator: Mapping[str, Any] = field(default_factory=dict)
    raw: Mapping[str, Any] = field(default_factory=dict)

    @property
    def configs(self) -> list[tuple[float, int]]:
        """Every (gain, bits) pair measured, in order."""
        return [(g, b) for g in self.gains for b in self.bits]

    def sensor_truth(self) -> SensorCharacteristics:
        """The simulated sensor's truth from ``[simulator]`` (simulated bench only)."""
        return SensorCharacteristics.from_mapping(self.simulator)


def check_characterise(c: Any, limits: Any = None) -> CharacteriseParams:
    """Read a ``characterise`` parameter mapping with the params checker ``c``."""
    d = CharacteriseParams()
    gains = c.numbers("camera.gains", d.gains, *_GAIN_RANGE)
    found, raw_bits = c._get("camera.bits", list(d.bits))
    settled = getattr(limits, "camera_bit_depths", None)
    # Default: the depths the doctor found to decode on this bench, deepest first.
    bits = tuple(sorted(settled, reverse=True)) if settled else d.bits
    if found:
        if (not isinstance(raw_bits, list) or not raw_bits
                or any(b not in CAMERA_BIT_DEPTHS or isinstance(b, bool) for b in raw_bits)
                or len(set(raw_bits)) != len(raw_bits)):
            c.fail("camera.bits", "must be a list of distinct "
                   f"{' / '.join(map(str, CAMERA_BIT_DEPTHS))}, got {raw_bits!r}")
        else:
            bits = tuple(int(b) for b in raw_bits)
            for b in bits:
                problem = limits.bits_problem(b) if limits is not None else None
                if problem:
                    c.fail("camera.bits", problem)
    width = c.integer("camera.width", d.width, 8, 1280)
    height = c.integer("camera.height", d.height, 8, 1024)
    for name, value in (("camera.width", width), ("camera.height", height)):
        if value % 4:
            c.fail(name, f"must be a multiple of 4, got {value}")
    channel = c.integer("led.channel", d.led_channel, 1, 16)
    current = c.number("led.current_ma", d.led_current_ma, 0.0, 5000.0, lo_open=True)
    if limits is not None and limits.led_ceilings_ma is not None:
        ceiling = limits.led_ceilings_ma.get(channel)
        if ceiling is None:
            c.fail("led.channel", f"channel {channel} has no current ceiling in the bench "
                   "configuration")
        elif current > ceiling:
            c.fail("led.current_ma", f"{current:g} mA exceeds the bench ceiling {ceiling:g} mA "
                   f"of channel {channel}")
    log_steps = c.integer("sweep.log_steps", d.log_steps, 2, 50)
    linear_steps = c.integer("sweep.linear_steps", d.linear_steps, 3, 500)
    near_sat = c.integer("sweep.near_saturation_steps", d.near_saturation_steps, 2, 200)
    beyond = c.number("sweep.beyond_saturation", d.beyond_saturation, 1.0, 4.0, lo_open=True)
    max_exp = c.number("sweep.max_exposure_ms", d.max_exposure_ms, *_EXPOSURE_RANGE_MS)
    probe = c.number("sweep.probe_start_ms", d.probe_start_ms, *_EXPOSURE_RANGE_MS)
    if probe > max_exp:
        c.fail("sweep.probe_start_ms", f"{probe:g} ms is above sweep.max_exposure_ms {max_exp:g}")
    vary = c.choice("sweep.vary", d.vary, ("exposure", "led_current"))
    fixed_exposure = c.number("sweep.exposure_ms", d.exposure_ms, *_EXPOSURE_RANGE_MS)
    probe_ma = c.number("sweep.probe_start_ma", d.probe_start_ma, 0.1, 5000.0)
    if vary == "led_current" and probe_ma > current:
        c.fail("sweep.probe_start_ma", f"{probe_ma:g} mA is above led.current_ma {current:g}")
    stack = c.integer("spatial.stack_frames", d.stack_frames, 2, 400)
    stack_fraction = c.number("spatial.stack_fraction", d.stack_fraction, 0.05, 0.9)
    ref = c.numbers("calibration.reference_range", d.reference_range, 0.0, 1.0)
    if len(ref) != 2 or not ref[0] < ref[1]:
        c.fail("calibration.reference_range", f"must be [low, high] fractions with low < high, "
               f"got {list(ref)}")
        ref = d.reference_range
    found, sim = c._get("simulator", {})
    simulator: dict[str, Any] = {}
    if found:
        if not isinstance(sim, Mapping):
            c.fail("simulator", "must be a table of sensor truth values")
        else:
            for key, value in sim.items():
                c.seen.add(f"simulator.{key}")
                if isinstance(value, bool) or not isinstance(value, int | float):
                    c.fail(f"simulator.{key}", f"must be a number, got {value!r}")
                else:
                    simulator[str(key)] = value
            try:
                SensorCharacteristics.from_mapping(simulator)
            except ValueError as exc:
                c.fail("simulator", str(exc))
    return CharacteriseParams(
        gains=gains, bits=bits, width=width, height=height, led_channel=channel,
        led_current_ma=current, log_steps=log_steps, linear_steps=linear_steps,
        near_saturation_steps=near_sat, beyond_saturation=beyond, max_exposure_ms=max_exp,
        probe_start_ms=probe, vary=vary, exposure_ms=fixed_exposure, probe_start_ma=probe_ma,
        stack_frames=stack, stack_fraction=stack_fraction,
        reference_range=(ref[0], ref[1]), simulator=simulator, raw=c.data,
    )


def characterise_to_dict(p: CharacteriseParams) -> dict[str, Any]:
    """The effective parameters in the file's layout (what a session records)."""
    return {
        "procedure": "characterise",
        "camera": {"gains": list(p.gains), "bits": list(p.bits), "width": p.width,
                   "height": p.height},
        "led": {"channel": p.led_channel, "current_ma": p.led_current_ma},
        "sweep": {"log_steps": p.log_steps, "linear_steps": p.linear_steps,
                  "near_saturation_steps": p.near_saturation_steps,
                  "beyond_saturation": p.beyond_saturation,
                  "max_exposure_ms": p.max_exposure_ms, "probe_start_ms": p.probe_start_ms,
                  "vary": p.vary, "exposure_ms": p.exposure_ms,
                  "probe_start_ma": p.probe_start_ma},
        "spatial": {"stack_frames": p.stack_frames, "stack_fraction": p.stack_fraction},
        "calibration": {"reference_range": list(p.reference_range)},
        "simulator": dict(p.simulator),
    }
