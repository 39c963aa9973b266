"""What the characterisation should find on the simulated bench: the sensor truth expressed in
the measured quantities (same keys as the results), per gain and bit depth.

Quantities the standard defines through a procedure rather than a sensor constant are evaluated
with that definition on the noise-free model: saturation is the mean signal where the expected
temporal variance of the clipped signal peaks (not the clip code, which a noisy sensor's mean
never reaches), and the linearity error is the EMVA 5-95 % fit applied to the model's expected
means at the sweep's exposures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchlab.analysis.camera.photon_transfer import (
    LINEARITY_RANGE,
    QUANTISATION_VAR_DN2,
    linearity_deviation,
)
from benchlab.drivers.mightex.characteristics import SensorCharacteristics

_Z, _W = np.polynomial.hermite_e.hermegauss(21)
_W = _W / _W.sum()


def _clipped(mu: Any, sd: Any, ceiling: float) -> tuple[Any, Any]:
    """Mean and variance of N(mu, sd) clipped above at ``ceiling``."""
    from scipy.stats import norm  # here: importing every procedure must stay fast

    a = (ceiling - mu) / sd
    cdf, pdf = norm.cdf(a), norm.pdf(a)
    mean = mu * cdf - sd * pdf + ceiling * (1 - cdf)
    ex2 = (mu**2 + sd**2) * cdf - sd * (mu + ceiling) * pdf + ceiling**2 * (1 - cdf)
    return mean, ex2 - mean**2


def expected_signal(truth: SensorCharacteristics, gain: float, electrons: Any) -> tuple[Any, Any]:
    """Expected pixel mean (12-bit DN, offset included) and temporal variance for mean light
    ``electrons`` (dark electrons included), averaged over the PRNU spread."""
    e0 = np.asarray(electrons, dtype=np.float64)
    k = truth.dn12_per_e * gain
    ceiling = truth.ceiling_dn12(gain)
    mean = np.zeros_like(e0)
    var = np.zeros_like(e0)
    for z, w in zip(_Z, _W, strict=True):
        e = e0 * max(1.0 + truth.prnu_fraction * z, 0.0)
        held = np.minimum(e, truth.full_well_e)
        mu = truth.dark_offset_dn12 + truth.response_e(held) * k
        sd = np.sqrt(truth.output_variance_e2(e)) * k
        m, v = _clipped(mu, np.maximum(sd, 1e-9), ceiling)
        mean += w * m
        var += w * v
    return mean, var


def truth_for(
    truth: SensorCharacteristics, *, gain: float, bits: int, width: int, height: int,
    exposures_ms: Sequence[float] = (), light_e: Sequence[float] = (),
) -> dict[str, Any]:
    """The truth of one configuration in the result keys (DN at the frame's bit depth).

    ``exposures_ms`` and ``light_e`` (mean light electrons per pixel) of the sweep's steps give
    the linearity error; without them it is None.
    """
    scale = 1.0 if bits == 12 else 1.0 / 16.0
    k12 = truth.dn12_per_e * gain
    k = k12 * scale
    ceiling = truth.ceiling_dn12(gain)
    e_clip = min((ceiling - truth.dark_offset_dn12) / k12, truth.full_well_e * 1.5)
    grid = np.linspace(0.6, 1.4, 4001) * e_clip
    mean, var = expected_signal(truth, gain, grid)
    i_sat = int(np.argmax(var))
    sat12 = float(mean[i_sat] - truth.dark_offset_dn12)
    offset, sensitivity, dark = truth.maps(height, width)
    hot = np.broadcast_to(np.asarray(dark) > truth.dark_current_e_per_s, (height, width))
    good = ~hot
    dsnu12 = float(np.std(np.broadcast_to(offset, (height, width))[good], ddof=1))
    sens = np.broadcast_to(sensitivity, (height, width))[good]
    out: dict[str, Any] = {
        "system_gain_dn_per_e": k,
        "read_noise_e": truth.read_noise_e,
        "read_noise_dn": math.sqrt((k * truth.read_noise_e) ** 2 + QUANTISATION_VAR_DN2),
        "saturation_dn": sat12 * scale,
        "saturation_e": sat12 / k12,
        "saturation_clip_dn": (ceiling - truth.dark_offset_dn12) * scale,
        "dark_current_e_per_s": truth.dark_current_e_per_s,
        "dsnu_dn": dsnu12 * scale,
        "prnu_pct": 100.0 * float(np.std(sens, ddof=1) / np.mean(sens)),
        "hot_pixels": int(hot.sum()),
        "linearity_error_pct": None,
    }
    if len(exposures_ms) >= 3 and len(light_e) == len(exposures_ms):
        order = np.argsort(light_e)
        t = np.asarray(exposures_ms, dtype=np.float64)[order]
        light = np.asarray(light_e, dtype=np.float64)[order]
        dark_e = truth.dark_current_e_per_s * t / 1e3
        lit, _ = expected_signal(truth, gain, light + dark_e)
        unlit, _ = expected_signal(truth, gain, dark_e)
        y = lit - unlit
        lo, hi = LINEARITY_RANGE
        idx = np.flatnonzero((y >= lo * sat12) & (y <= hi * sat12))
        if idx.size >= 2:
            _, _, dev = linearity_deviation(light, y, idx)
            out["linearity_error_pct"] = [float(dev[idx].min()), float(dev[idx].max())]
    return out
