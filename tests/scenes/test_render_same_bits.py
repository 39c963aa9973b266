"""The simulated camera's fast paths (issue 39) give the bits of the plain expressions they
replace: the sensor model's in-place mean and noise width, the chart's cached lit disc and
in-place composition, an unrotated bar evaluated along its own axes, and the forward view
composed without a copy. Each reference below is the plain expression the code used before.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from benchlab.drivers.mightex.sim_sensor import SensorModel, SensorTruth
from benchlab.drivers.sensor import AcquisitionState
from benchlab.scenes import usaf
from benchlab.scenes.focus import ThroughFocusLens, scenes_at
from benchlab.scenes.usaf import UsafScene
from benchlab.scenes.world import SimWorld

H, W = 48, 64


def plain_sensor(truth: SensorTruth, rate: npt.NDArray[np.float64], state: AcquisitionState
                 ) -> tuple[Any, Any, Any, float]:
    """(noise-free codes, float32 mean + 0.5, float32 sigma, ceiling) as written before."""
    offset, sensitivity, dark = truth.maps(state.height, state.width)
    electrons = np.clip(rate * state.exposure_ms, 0.0, None) * sensitivity
    if np.any(dark):
        electrons = electrons + dark * (state.exposure_ms / 1e3)
    dn_per_e = truth.dn12_per_e * state.gain
    ceiling = truth.ceiling_dn12(state.gain)
    held = (np.minimum(electrons, truth.full_well_e) if truth.compression_at_full_well
            else electrons)
    mean = offset + truth.response_e(held) * dn_per_e
    exact = np.clip(np.floor(mean + 0.5), 0, ceiling).astype(np.uint16).ravel()
    mean32 = np.broadcast_to(mean + 0.5, rate.shape).astype(np.float32).ravel()
    sigma = np.sqrt(truth.output_variance_e2(electrons)) * dn_per_e
    sigma32 = np.broadcast_to(sigma, rate.shape).astype(np.float32).ravel()
    return exact, mean32, sigma32, ceiling


TRUTHS = {
    "linear": SensorTruth(),
    "maps and compression": SensorTruth(dark_offset_dn12=30.0, dsnu_dn12=2.0,
                                        prnu_fraction=0.02, hot_pixel_fraction=0.01,
                                        hot_pixel_dark_current_e_per_s=5e4,
                                        dark_current_e_per_s=20.0,
                                        compression_at_full_well=0.03),
}


@pytest.mark.parametrize("name", sorted(TRUTHS))
def test_sensor_frames_are_the_plain_expressions(name: str) -> None:
    truth = TRUTHS[name]
    rng = np.random.default_rng(3)
    # negative rates (clipped), dark, mid and past full well at 300 ms
    rate = rng.uniform(-5.0, 90.0, (H, W))
    state = AcquisitionState(300.0, 1.5, 12, W, H, 0.0, 0)
    exact, mean32, sigma32, ceiling = plain_sensor(truth, rate, state)

    quiet = SensorModel(5, noise=False, truth=truth)
    assert np.array_equal(quiet.render_dn12(lambda _s: rate, state), exact)
    # a second state (another exposure), then back: nothing left over from the first
    other = AcquisitionState(120.0, 1.0, 12, W, H, 0.0, 1)
    assert np.array_equal(quiet.render_dn12(lambda _s: rate, other),
                          plain_sensor(truth, rate, other)[0])
    assert np.array_equal(quiet.render_dn12(lambda _s: rate, state), exact)

    noisy = SensorModel(5, truth=truth)
    got = [noisy.render_dn12(lambda _s: rate, state).copy() for _ in range(3)]
    draws = np.random.default_rng(5)  # the model's draws: the bank, then one offset a frame
    bank = draws.standard_normal(2 * 1280 * 1024, dtype=np.float32)
    n = H * W
    for frame in got:
        start = int(draws.integers(0, bank.size - n + 1))
        x = bank[start:start + n] * sigma32 + mean32
        want = np.clip(x, 0.0, ceiling).astype(np.uint16)
        assert np.array_equal(frame, want)
    # noise switched off on a prepared model: the noise-free frame of that state
    noisy.noise = False
    assert np.array_equal(noisy.render_dn12(lambda _s: rate, state), exact)


@pytest.mark.parametrize("theta_deg", [0.0, 90.0, 17.0])
def test_an_unrotated_bar_is_the_plain_patch(theta_deg: float) -> None:
    rows = np.arange(100.0, 140.0)[:, None]
    cols = np.arange(200.0, 236.0)[None, :]
    centre, half_len, half_w, sig_r, sig_c = (119.3, 217.8), 12.5, 2.5, 1.7, 2.2
    t = math.radians(theta_deg)
    ct, st = math.cos(t), math.sin(t)
    dy, dx = rows - centre[0], cols - centre[1]
    across, along = dx * ct + dy * st, -dx * st + dy * ct
    sig_across = math.sqrt((sig_c * ct) ** 2 + (sig_r * st) ** 2)
    sig_along = math.sqrt((sig_c * st) ** 2 + (sig_r * ct) ** 2)
    p, q = max(abs(ct), abs(st)), min(abs(ct), abs(st))
    step = usaf._smoothed_step
    want = ((step(across + half_w, sig_across, p, q) - step(across - half_w, sig_across, p, q))
            * (step(along + half_len, sig_along, p, q) - step(along - half_len, sig_along, p, q)))
    got = usaf._rotated_bar(rows, cols, centre, half_len, half_w, theta_deg, sig_r, sig_c)
    assert got.shape == want.shape == (40, 36)
    assert np.array_equal(got, want)


def _plain_posed(scene: UsafScene, height: int, width: int) -> npt.NDArray[np.float64]:
    """The posed chart as rendered before: a fresh disc, then ``bright x disc - depth x sum``."""
    bar_sum = np.zeros((height, width))
    for g, e in scene.layout.elements:
        for orientation in ("sagittal", "tangential"):
            posed = scene.bar_set(g, e, orientation)  # type: ignore[arg-type]
            usaf._add_bars(bar_sum, posed, *scene.sigmas_px(posed))
    rows = np.arange(height, dtype=np.float64)[:, None]
    cols = np.arange(width, dtype=np.float64)[None, :]
    disc = scene._disc(rows, cols)
    img = scene.bright_rate * disc - (scene.bright_rate - scene.dark_rate) * bar_sum
    return np.maximum(img, 0.0)


def test_the_forward_view_through_focus_is_the_plain_composition() -> None:
    lens = ThroughFocusLens()
    world = SimWorld("usaf", through_focus=lens)
    for stage_mm in (3.0, 17.5):
        state = AcquisitionState(300.0, 1.0, 8, 1280, 1024, 0.0, 0,
                                 {"target": "usaf", "object_offset_mm": 39.0,
                                  "stage_position_mm": stage_mm})
        chart, edges = scenes_at(lens, 39.0 + stage_mm, world.usaf, world.edges)
        plain = _plain_posed(chart, 1024, 1280)
        assert np.array_equal(chart.rendered(state), plain)
        plain -= edges.darkening(state) * (plain / edges.bright_rate)
        got = world(state)
        assert np.array_equal(got, plain)
        assert got.flags.writeable  # the caller's own array
    # the nominal chart (no pose): the lit disc's cache serves it too
    nominal = UsafScene()
    rows = np.arange(1024, dtype=np.float64)[:, None]
    cols = np.arange(1280, dtype=np.float64)[None, :]
    assert np.array_equal(nominal.bright_rate * nominal._disc(rows, cols),
                          usaf._frame_lit(nominal, 1024, 1280))
