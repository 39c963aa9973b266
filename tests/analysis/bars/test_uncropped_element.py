"""A 26 x 26 px ROI over a whole three-bar element and its ground (issue 37, point 6): the bar
structure and the ground are not noise, and the element reads its contrast."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.synthetic.threebar import element_with_ground

#: Ground and bar levels (8-bit): contrast (180 - 20) / 200 = 0.8, as a real G5E4.
GROUND, BAR = 180.0, 20.0
NOISE = 3.0


def _element(theta_deg: float, seed: int) -> npt.NDArray[np.uint8]:
    return element_with_ground(4.0, theta_deg, GROUND, BAR, 26, NOISE,
                               np.random.default_rng(seed))


@pytest.mark.parametrize("theta_deg", [0.0, 3.0, 10.0, 20.0, 30.0, 45.0])
@pytest.mark.parametrize("freq", [None, 1.0 / 8.0])
def test_an_uncropped_element_reads_resolved_and_its_noise_is_the_pixels(
    theta_deg: float, freq: float | None,
) -> None:
    # Before: 0.46-0.53 (its ground averaged into the bars), "fit residual 43 is 10 x the
    # pixel noise"; in the issue's real capture, noise 581 DN and "not resolved".
    r = estimate_modulation(_element(theta_deg, seed=int(theta_deg)), freq_cycles_per_px=freq)
    assert r.resolved and not r.lower_bound
    assert r.modulation == pytest.approx(0.8, abs=0.02)
    assert r.interval[0] <= 0.8 <= r.interval[1]
    assert NOISE * 0.8 <= r.diagnostics.noise_sigma <= 3.0 * NOISE
    assert any("off the bar pattern" in w for w in r.warnings)


@pytest.mark.slow
def test_uncropped_elements_at_any_angle_read_their_contrast() -> None:
    # 56 seeded ROIs at 0-45 deg, each with and without the frequency: 110 of 112 readings
    # within 0.02 of 0.8 holding it in their interval (the two others: one ROI whose noisy
    # ground piles 5 pixels on its top code, taken for saturation: a bound, not a value).
    good = 0
    for theta in (0.0, 3.0, 7.0, 15.0, 20.0, 30.0, 40.0, 45.0):
        for k in range(7):
            roi = _element(theta, seed=k * 7 + int(theta))
            for freq in (None, 1.0 / 8.0):
                r = estimate_modulation(roi, freq_cycles_per_px=freq)
                good += (r.resolved and not r.lower_bound and abs(r.modulation - 0.8) <= 0.02
                         and r.interval[0] <= 0.8 <= r.interval[1]
                         and r.diagnostics.noise_sigma <= 3.0 * NOISE)
    assert good >= 108
