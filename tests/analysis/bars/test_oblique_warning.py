"""sinefit and variance warn when the bars lie off the pixel axes (issue 9, review 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.bars.estimators import estimate_modulation


def bars(angle_deg: float, period_px: float = 8.0, seed: int = 0) -> np.ndarray:
    """60 x 60 px of blurred-ish square-wave bars at ``angle_deg`` from the column axis."""
    yy, xx = np.mgrid[0:60, 0:60].astype(float)
    t = math.radians(angle_deg)
    u = xx * math.cos(t) + yy * math.sin(t)
    wave = np.tanh(3.0 * np.sin(2 * np.pi * u / period_px))
    rng = np.random.default_rng(seed)
    return np.clip(100 + 60 * wave + rng.normal(0, 1.5, wave.shape), 0, 255).round()


@pytest.mark.parametrize("name", ["sinefit", "variance"])
@pytest.mark.parametrize("angle", [12.0, 30.0])
def test_oblique_bars_get_a_warning(name: str, angle: float) -> None:
    r = estimate_modulation(bars(angle), estimator=name, freq_cycles_per_px=1 / 8)
    assert any(f"deg off the pixel axes: {name}" in w for w in r.warnings), r.warnings
    (note,) = [w for w in r.warnings if "off the pixel axes" in w]
    assert abs(float(note.split()[1]) - angle) <= 1.0  # the measured angle


@pytest.mark.parametrize("name", ["sinefit", "variance"])
@pytest.mark.parametrize("angle", [0.0, 90.0, 0.5])
def test_bars_on_a_pixel_axis_get_none(name: str, angle: float) -> None:
    r = estimate_modulation(bars(angle), estimator=name, freq_cycles_per_px=1 / 8)
    assert not any("off the pixel axes" in w for w in r.warnings), r.warnings


def test_profilefit_measures_the_direction_and_needs_no_warning() -> None:
    r = estimate_modulation(bars(30.0), estimator="profilefit", freq_cycles_per_px=1 / 8)
    assert not any("off the pixel axes" in w for w in r.warnings)


def test_a_subnormal_frequency_gives_an_answer_not_an_overflow() -> None:
    # hypothesis found it: int(inf) in the harmonic count (tiny-ROI path of profilefit)
    r = estimate_modulation(np.array([[0]], np.uint8), estimator="profilefit",
                            freq_cycles_per_px=5e-324, orientation="horizontal")
    assert not r.resolved
