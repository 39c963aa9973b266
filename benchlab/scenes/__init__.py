"""What the simulated camera sees on the simulated bench.

Each scene is a frozen dataclass of parameters (so a test can set a known truth) and a callable
``scene(state) -> e-/ms image`` (:class:`benchlab.drivers.sensor.Scene`). Renders are cached per
geometry: the irradiance does not depend on exposure or gain, which the camera applies.
"""

from benchlab.scenes.led import LedFalloff, LedScene
from benchlab.scenes.optics import FORWARD_BLUR, RADIAL_BLUR, BlurProfile
from benchlab.scenes.radial import RADIAL_TARGETS_LP_PER_MM, RadialScene, radial_truth_table
from benchlab.scenes.usaf import UsafScene
from benchlab.scenes.world import SimWorld, parse_target

__all__ = [
    "FORWARD_BLUR",
    "RADIAL_BLUR",
    "RADIAL_TARGETS_LP_PER_MM",
    "BlurProfile",
    "LedFalloff",
    "LedScene",
    "RadialScene",
    "SimWorld",
    "UsafScene",
    "parse_target",
    "radial_truth_table",
]
