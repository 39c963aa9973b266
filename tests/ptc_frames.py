"""Synthetic photon-transfer sweeps from the simulated camera's sensor model (no bench, fast).

Shared by the photon-transfer tests and the emva1288 cross-check.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from benchlab.analysis.camera.photon_transfer import (
    SweepPoint,
    msb_aligned,
    native_codes,
    pair_statistics,
    photon_transfer,
    spatial_nonuniformity,
)
from benchlab.drivers.mightex.sim_sensor import FlatFieldScene, SensorModel, SensorTruth
from benchlab.drivers.sensor import AcquisitionState

TRUTH = SensorTruth(dark_offset_dn12=64.0, dark_current_e_per_s=500.0, dsnu_dn12=2.0,
                    prnu_fraction=0.01)
RATE_E_PER_MS = 400.0


@dataclass
class Sweep:
    exposures_ms: list[float]
    lit: list[tuple[Any, Any]]
    dark: list[tuple[Any, Any]]
    stack_lit: Any
    stack_dark: Any
    stack_exposure_ms: float


_SCENES: dict[float, FlatFieldScene] = {}


def grab(model: SensorModel, rate: float, exposure_ms: float, gain: float, bits: int,
         size: int) -> Any:
    # One scene object per rate: the sensor model caches renders by scene identity.
    scene = _SCENES.setdefault(rate, FlatFieldScene(rate))
    state = AcquisitionState(exposure_ms=exposure_ms, gain=gain, bits=bits, width=size,
                             height=size, time_s=0.0, frame_index=0)
    dn12 = model.render_dn12(scene, state).reshape(size, size).copy()
    return dn12 if bits == 12 else (dn12 >> 4).astype(np.uint8)


def saturation_exposure_ms(truth: SensorTruth, gain: float, rate: float) -> float:
    k12 = truth.dn12_per_e * gain
    return (truth.ceiling_dn12(gain) - truth.dark_offset_dn12) / k12 / rate


def make_sweep(truth: SensorTruth = TRUTH, *, gain: float = 1.0, bits: int = 12,
               size: int = 64, rate: float = RATE_E_PER_MS, top: float = 1.15,
               stack: int = 8, seed: int = 3, steps: int = 40) -> Sweep:
    """Exposures from near dark to ``top`` x the saturation exposure (dense near the top)."""
    model = SensorModel(seed, truth=truth)
    t_sat = saturation_exposure_ms(truth, gain, rate)
    exposures = sorted({round(float(t), 2) for t in np.concatenate([
        np.geomspace(0.05, 0.05 * t_sat, 5),
        np.linspace(0.08 * t_sat, min(0.85, top) * t_sat, steps // 2),
        np.linspace(min(0.87, top) * t_sat, top * t_sat, steps // 2),
    ]) if t > 0})
    lit, dark = [], []
    for t in exposures:
        lit.append((grab(model, rate, t, gain, bits, size), grab(model, rate, t, gain, bits, size)))
        dark.append((grab(model, 0.0, t, gain, bits, size), grab(model, 0.0, t, gain, bits, size)))
    t_stack = 0.5 * t_sat
    stack_lit = np.stack([grab(model, rate, t_stack, gain, bits, size) for _ in range(stack)])
    stack_dark = np.stack([grab(model, 0.0, t_stack, gain, bits, size) for _ in range(stack)])
    return Sweep(exposures, lit, dark, stack_lit, stack_dark, t_stack)


def analyse(sweep: Sweep, bits: int = 12, transform=lambda a: a):
    """Photon transfer of a sweep, the way the characterisation analysis pairs its frames."""
    every = [transform(f) for pair in sweep.lit + sweep.dark for f in pair]
    aligned = msb_aligned(every, bits)

    def codes(frame):
        return native_codes(transform(frame), bits, aligned)

    spatial, defects = spatial_nonuniformity(np.stack([codes(f) for f in sweep.stack_lit]),
                                             np.stack([codes(f) for f in sweep.stack_dark]))
    valid = ~defects
    points = []
    for t, (a, b), (c, d) in zip(sweep.exposures_ms, sweep.lit, sweep.dark, strict=True):
        m, v = pair_statistics(codes(a), codes(b), valid)
        dm, dv = pair_statistics(codes(c), codes(d), valid)
        points.append(SweepPoint(t, m, v, dm, dv))
    return points, photon_transfer(points, spatial=spatial)
