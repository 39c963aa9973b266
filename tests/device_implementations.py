"""Every implementation of each device kind, for the contract suites (tests/test_contract_*.py).

The simulators are always in the list, and one real device of each kind: it runs when the
user names the bench, ``pytest --hardware bench.toml tests/drivers/test_contract_*.py``
(tests/conftest.py turns the bench file into the variables below, which also work alone),
and is skipped, saying so, otherwise:

    BENCHLAB_HW_CAMERA_SERIAL=13-000123 (or "any")   a Mightex camera on USB
    BENCHLAB_HW_CAMERA_MODEL=MCE-B013-U               its profile (default: by module number)
    BENCHLAB_HW_LED_PORT=/dev/ttyUSB0                 a Mightex SLC; channel 1 is lit at
    BENCHLAB_HW_LED_CEILING_MA=10                     most this many mA (default 10)
    BENCHLAB_HW_STAGE_PORT=/dev/ttyUSB1               a Thorlabs APT cube; it is homed and
    BENCHLAB_HW_STAGE_TRAVEL_MM=0,25                  moved inside this travel (default 0,25)
    BENCHLAB_HW_STAGE_COUNTS_PER_MM=34554.96          its scale (default: the Z8 table value)
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import pytest

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

    with MightexCamera.open(serial=None if serial == "any" else serial,
                            model=os.environ.get("BENCHLAB_HW_CAMERA_MODEL") or None) as cam:
        yield cam


NO_HARDWARE = "real device: give pytest --hardware bench.toml (tests/device_implementations.py)"


@contextlib.contextmanager
def _not_named() -> Iterator[None]:
    pytest.skip(NO_HARDWARE)
    yield


def _hardware(kind: str, variable: str, opener: Callable[[str], Any]) -> Implementation[Any]:
    value = os.environ.get(variable)
    if not value:
        return Implementation(f"hw-{kind}", _not_named, False)
    return Implementation(f"hw-{kind}-{value}", lambda: opener(value), False)


CAMERAS: list[Implementation[Camera]] = [
    Implementation("sim-mightex", _sim_camera, True),
    _hardware("mightex", "BENCHLAB_HW_CAMERA_SERIAL", _hw_camera)]


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
    Implementation("sim-slc", _sim_led, True), _hardware("slc", "BENCHLAB_HW_LED_PORT", _hw_led)]


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

    counts = float(os.environ.get("BENCHLAB_HW_STAGE_COUNTS_PER_MM", "34554.96"))
    with AptStage(port, travel_mm=stage_travel_mm(), counts_per_mm=counts) as stage:
        yield stage


STAGES: list[Implementation[LinearStage]] = [
    Implementation("sim-apt", _sim_stage, True),
    _hardware("apt", "BENCHLAB_HW_STAGE_PORT", _hw_stage)]
