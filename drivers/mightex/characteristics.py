"""The characteristics of the bench camera's sensor (MT9M001, MCE-B013-U) in the EMVA 1288
model: system gain, read noise, full well, black level, dark current, DSNU, PRNU, hot pixels
and the response's compression near full well.

A production type: the characterisation (``benchlab.protocols.characterise``) checks a
``[simulator]`` table against it and says what such a sensor should read, and the simulated
camera (:mod:`benchlab.drivers.mightex.sim_sensor`) is built from one, never the other way.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from benchlab.drivers.mightex.profile import SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX

#: Sensor constants of the MT9M001 (MCE-B013-U); the geometry is the camera profile's.
FULL_WELL_E = 20000.0
READ_NOISE_E = 8.0
ADC_BITS = 12
#: Digital numbers (12-bit) per electron at unity gain: full well maps to full scale.
DN12_PER_E = (2**ADC_BITS - 1) / FULL_WELL_E
#: The highest 12-bit code (the ADC range).
ADC_MAX_DN12 = 2**ADC_BITS - 1


@dataclass(frozen=True)
class SensorCharacteristics:
    """A sensor's characteristics in the EMVA 1288 model (what ``benchlab run characterise``
    measures): the simulated camera is built from one (its truth), and the characterisation
    states what a sensor with these characteristics should read.

    The defaults are the plain MT9M001 model every other simulation uses: linear, no offset,
    no dark current, uniform pixels. All DN values are 12-bit codes at gain 1; 8-bit frames are
    the 12-bit code shifted right by 4 (so K, noise and offsets in 8-bit DN are /16).

    Parameters
    ----------
    dn12_per_e : float
        System gain K at gain 1 in 12-bit DN per electron (scales with the gain setting).
    read_noise_e : float
        Temporal dark (read) noise, electrons RMS.
    full_well_e : float
        Electrons a pixel holds; the code clips at ``offset + response(full well) * K`` or the
        ADC range, whichever is lower.
    dark_offset_dn12 : float
        Black level added after the gain (12-bit DN).
    dark_current_e_per_s : float
        Mean dark current (electrons per second of exposure; shot noise included).
    dsnu_dn12 : float
        Spatial RMS of the black level (a seeded fixed pattern), 12-bit DN.
    prnu_fraction : float
        Spatial RMS of the pixel sensitivity, as a fraction (seeded fixed pattern).
    hot_pixel_fraction, hot_pixel_dark_current_e_per_s : float
        Share of pixels (seeded) with an extra dark current of the given rate.
    compression_at_full_well : float
        Response non-linearity: linear up to ``compression_knee`` x full well, then quadratic
        compression reaching this fraction at full well (0.03: 3 % fewer DN than linear).
    compression_knee : float
        Fraction of the full well where the compression starts.
    map_seed : int
        Seed of the DSNU / PRNU / hot-pixel maps (fixed per sensor, unlike the frame noise).
    """

    dn12_per_e: float = DN12_PER_E
    read_noise_e: float = READ_NOISE_E
    full_well_e: float = FULL_WELL_E
    dark_offset_dn12: float = 0.0
    dark_current_e_per_s: float = 0.0
    dsnu_dn12: float = 0.0
    prnu_fraction: float = 0.0
    hot_pixel_fraction: float = 0.0
    hot_pixel_dark_current_e_per_s: float = 0.0
    compression_at_full_well: float = 0.0
    compression_knee: float = 0.5
    map_seed: int = 1288

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"sensor truth {f.name} must be finite and >= 0, got {value}")
        if self.dn12_per_e <= 0 or self.full_well_e <= 0:
            raise ValueError("sensor truth dn12_per_e and full_well_e must be > 0")
        if not 0 <= self.compression_knee < 1 or self.compression_at_full_well >= 0.5:
            raise ValueError("sensor truth compression_knee must be in [0, 1) and "
                             "compression_at_full_well < 0.5")
        if self.prnu_fraction >= 0.3 or self.hot_pixel_fraction > 0.1:
            raise ValueError("sensor truth prnu_fraction must be < 0.3, hot_pixel_fraction <= 0.1")

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> SensorCharacteristics:
        """Build from a mapping of field names (unknown names raise ``ValueError``)."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"unknown sensor truth field(s): {', '.join(unknown)}")
        values: dict[str, Any] = {k: (int(v) if k == "map_seed" else float(v))
                                  for k, v in data.items()}
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def response_e(self, electrons: Any) -> Any:
        """Electrons as the ADC sees them after the (optional) compression near full well."""
        e = np.asarray(electrons, dtype=np.float64)
        if self.compression_at_full_well == 0:
            return e
        knee = self.compression_knee
        u = np.clip(e / self.full_well_e - knee, 0.0, None) / (1.0 - knee)
        return e - self.compression_at_full_well * self.full_well_e * u**2

    def response_slope(self, electrons: Any) -> Any:
        """d response / d electrons (scales the temporal noise through the compression)."""
        e = np.asarray(electrons, dtype=np.float64)
        if self.compression_at_full_well == 0:
            return np.ones_like(e)
        knee = self.compression_knee
        u = np.clip(e / self.full_well_e - knee, 0.0, None) / (1.0 - knee)
        return np.clip(1.0 - 2.0 * self.compression_at_full_well * u / (1.0 - knee), 0.0, None)

    def output_variance_e2(self, electrons: Any, out: Any = None) -> Any:
        """Temporal variance at the output, in electrons^2 before the gain: shot + read noise,
        scaled through the compression. With compression on, a pixel at full well holds exactly
        the full well (the excess spills), so only the read noise remains. ``out``: an array
        of the result's shape to write it into (returned)."""
        e = np.asarray(electrons, dtype=np.float64)
        if self.compression_at_full_well == 0:
            return np.add(e, self.read_noise_e**2, out=out)
        held = np.minimum(e, self.full_well_e)
        var = (held + self.read_noise_e**2) * self.response_slope(held) ** 2
        result = np.where(e >= self.full_well_e, self.read_noise_e**2, var)
        if out is None:
            return result
        np.copyto(out, result)
        return out

    def ceiling_dn12(self, gain: float) -> float:
        """The code a saturated pixel reads (12-bit): full well or ADC range, lower first."""
        full = self.dark_offset_dn12 + float(self.response_e(self.full_well_e)) * (
            self.dn12_per_e * gain)
        return float(min(math.floor(full + 1e-6), ADC_MAX_DN12))

    def maps(self, height: int, width: int) -> tuple[Any, Any, Any]:
        """Fixed patterns of the top-left ``height x width`` window of the full sensor.

        Returns ``(offset_dn12, sensitivity, dark_current_e_per_s)``; each is a scalar when
        the pattern is uniform, so the default sensor costs nothing extra.
        """
        offset: Any = self.dark_offset_dn12
        gain_map: Any = 1.0
        dark: Any = self.dark_current_e_per_s
        if self.dsnu_dn12 or self.prnu_fraction or self.hot_pixel_fraction:
            rng = np.random.default_rng(self.map_seed)
            shape = (SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX)
            z_offset = rng.standard_normal(shape)[:height, :width]
            z_gain = rng.standard_normal(shape)[:height, :width]
            hot = (rng.random(shape) < self.hot_pixel_fraction)[:height, :width]
            if self.dsnu_dn12:
                offset = self.dark_offset_dn12 + self.dsnu_dn12 * z_offset
            if self.prnu_fraction:
                gain_map = 1.0 + self.prnu_fraction * z_gain
            if self.hot_pixel_fraction:
                dark = self.dark_current_e_per_s + self.hot_pixel_dark_current_e_per_s * hot
        return offset, gain_map, dark
