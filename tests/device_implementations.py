"""Every implementation of each device kind, for the contract suites (tests/test_contract_*.py).

The simulators are always in the list. Real hardware joins when the user names it:

    BENCHLAB_HW_CAMERA_SERIAL=13-000123 (or "any")   a Mightex camera on USB
    BENCHLAB_HW_LED_PORT=/dev/ttyUSB0                 a Mightex SLC; channel 1 is lit at
    BENCHLAB_HW_LED_CEILING_MA=10                     most this many mA (default 10)
    BENCHLAB_HW_STAGE_PORT=/dev/ttyUSB1               a Thorlabs APT cube; it is homed and
    BENCHLAB_HW_STAGE_TRAVEL_MM=0,25                  moved inside this travel (default 0,25)

Without these variables the hardware cases are not generated at all (never skipped).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Generic, TypeVar

from benchlab.drivers.interfaces import Camera, LightSource, LinearStage

D = TypeVar("D")


@dataclass(frozen=True)
class Implementation(Generic[D]):
    """One way to get an open device of a kind; ``opener`` is a context manager factory."""

    name: str
    opener: Callable[[], contextlib.AbstractContextManager[D]]
    simulated: bool

    def __str__(self) -> str:  # the pytest id
        return self.name


# ---- cameras -------------------------------------------------------------------------------
@contextlib.contextmanager
def _sim_camera() -> Iterator[Camera]:
    from benchlab.drivers.mightex.camera import MightexCamera
    from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera

    sim = SimulatedCamera(noise=False)
    with MightexCamera.open(backend=SimCameraBackend([sim]), pid=sim.pid) as cam:
        yield cam


@contextlib.contextmanager
def _hw_camera(serial: str) -> Iterator[Camera]:
    from benchlab.drivers.mightex.camera import MightexCamera

    with MightexCamera.open(serial=None if serial == "any" else serial) as cam:
        yield cam


CAMERAS: list[Implementation[Camera]] = [Implementation("sim-mightex", _sim_camera, True)]
if os.environ.get("BENCHLAB_HW_CAMERA_SERIAL"):
    _serial = os.environ["BENCHLAB_HW_CAMERA_SERIAL"]
    CAMERAS.append(Implementation(f"hw-mightex-{_serial}", lambda: _hw_camera(_serial), False))


# ---- light sources -------------------------------------------------------------------------
#: Channel 1 may be lit up to this current in the contract suite; channel 2 has no ceiling.
LED_CEILING_MA = float(os.environ.get("BENCHLAB_HW_LED_CEILING_MA", "10"))


@contextlib.contextmanager
def _sim_led() -> Iterator[LightSource]:
    from benchlab.drivers.slc.controller import SlcController
    from benchlab.drivers.slc.sim import SimulatedSlc

    with SimulatedSlc(channels=4) as sim, \
            SlcController(sim.port, ceilings_ma={1: LED_CEILING_MA}) as led:
        yield led


@contextlib.contextmanager
def _hw_led(port: str) -> Iterator[LightSource]:
    from benchlab.drivers.slc.controller import SlcController

    with SlcController(port, ceilings_ma={1: LED_CEILING_MA}) as led:
        yield led


LIGHT_SOURCES: list[Implementation[LightSource]] = [
    Implementation("sim-slc", _sim_led, True)]
if os.environ.get("BENCHLAB_HW_LED_PORT"):
    _led_port = os.environ["BENCHLAB_HW_LED_PORT"]
    LIGHT_SOURCES.append(Implementation(f"hw-slc-{_led_port}", lambda: _hw_led(_led_port), False))


# ---- linear stages -------------------------------------------------------------------------
def stage_travel_mm() -> tuple[float, float]:
    lo, hi = (float(v) for v in os.environ.get("BENCHLAB_HW_STAGE_TRAVEL_MM", "0,25").split(","))
    return lo, hi


@contextlib.contextmanager
def _sim_stage() -> Iterator[LinearStage]:
    from benchlab.drivers.apt.sim import SimulatedAptStage
    from benchlab.drivers.apt.stage import AptStage

    travel = stage_travel_mm()
    with SimulatedAptStage(travel_mm=travel, time_scale=200.0, initial_position_mm=3.0) as sim, \
            AptStage(sim.port, travel_mm=travel) as stage:
        yield stage


@contextlib.contextmanager
def _hw_stage(port: str) -> Iterator[LinearStage]:
    from benchlab.drivers.apt.stage import AptStage

    with AptStage(port, travel_mm=stage_travel_mm()) as stage:
        yield stage


STAGES: list[Implementation[LinearStage]] = [Implementation("sim-apt", _sim_stage, True)]
if os.environ.get("BENCHLAB_HW_STAGE_PORT"):
    _stage_port = os.environ["BENCHLAB_HW_STAGE_PORT"]
    STAGES.append(Implementation(f"hw-apt-{_stage_port}", lambda: _hw_stage(_stage_port), False))
