"""The scenes through the camera simulator's sensor model: the levels land where promised."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.analysis.chart.layout import RADIAL_ROI_BOX
from benchlab.drivers.sensor import AcquisitionState, rate_for_dn8
from benchlab.scenes import SimWorld

sim_sensor = pytest.importorskip("benchlab.drivers.mightex.sim_sensor")
H, W = 1024, 1280


def _dn8(
    world: SimWorld, *, noise: bool, exposure_ms: float = 300.0, **bench: object
) -> np.ndarray:
    sensor = sim_sensor.SensorModel(seed=1, noise=noise)
    state = AcquisitionState(exposure_ms, 1.0, 8, W, H, 0.0, 0, dict(bench))
    return (sensor.render_dn12(world, state).reshape(H, W) >> 4).astype(np.uint8)


def test_usaf_levels_through_the_sensor_model() -> None:
    world = SimWorld("usaf")
    img = _dn8(world, noise=False)
    bars = world.usaf.bar_group(1, 5, "sagittal")
    r, c = (round(v) for v in bars.centre_rc)
    expected = world.usaf.render(H, W)[r, c] / float(rate_for_dn8(1.0, 300.0))
    assert abs(int(img[r, c]) - expected) <= 1  # the 12 -> 8 bit shift truncates
    assert expected < 40  # on a dark bar
    assert abs(int(img[r - 120, c + 100]) - 190) <= 1  # clear glass inside the disc
    assert img[5, 5] == 0


def test_radial_roi_histogram_has_the_thesis_like_peaks() -> None:
    world = SimWorld(("radial", 0.5, "sagittal"))
    r0, c0, r1, c1 = RADIAL_ROI_BOX
    roi = _dn8(world, noise=True)[r0:r1, c0:c1].astype(float)
    dark_peak = np.median(roi[roi < 105])
    bright_peak = np.median(roi[roi >= 105])
    assert dark_peak == pytest.approx(20, abs=3)
    assert bright_peak == pytest.approx(190, abs=3)


def test_led_gain_5_mask_saturates_and_gain_1_reads_the_plateau() -> None:
    world = SimWorld("led")
    bench = {"led_current_ma": {"1": 20.0}, "stage_position_mm": 18.0}
    sensor = sim_sensor.SensorModel(seed=1, noise=False)
    mask_state = AcquisitionState(375.0, 5.0, 8, W, H, 0.0, 0, bench)
    meas_state = AcquisitionState(375.0, 1.0, 8, W, H, 0.0, 1, bench)
    mask = (sensor.render_dn12(world, mask_state).reshape(H, W) >> 4) > 128
    meas = (sensor.render_dn12(world, meas_state).reshape(H, W) >> 4).astype(float)
    r, c = (round(v) for v in world.led.centre_rc(18.0))
    assert meas[r, c] == pytest.approx(world.led.expected_plateau_dn8(18.0, 20.0, 375.0), abs=1)
    expected = world.led.expected_mean_dn8(mask, 18.0, 20.0, 375.0)
    assert meas[mask].mean() == pytest.approx(expected, abs=0.6)
