"""The blur model's closed forms against brute-force numerics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from benchlab.scenes.optics import (
    FORWARD_BLUR,
    RADIAL_BLUR,
    BlurProfile,
    blurred_square_wave,
    box_blurred_rect,
)

FINE = 200  # samples per px in the brute-force references


def _brute_rect(x_px: np.ndarray, a: float, b: float, sigma: float) -> np.ndarray:
    """Indicator of [a, b] on a fine grid, Gaussian-blurred, then averaged over each pixel."""
    lo, hi = x_px.min() - 1, x_px.max() + 2
    grid = np.arange(lo * FINE, hi * FINE) / FINE + 0.5 / FINE
    ind = ((grid >= a) & (grid < b)).astype(float)
    blurred = gaussian_filter1d(ind, sigma * FINE, mode="constant", truncate=8) if sigma else ind
    out = []
    for x in x_px:
        sel = (grid >= x - 0.5) & (grid < x + 0.5)
        out.append(blurred[sel].mean())
    return np.array(out)


@pytest.mark.parametrize("sigma", [0.0, 0.3, 1.7])
def test_box_blurred_rect_matches_brute_force(sigma: float) -> None:
    x = np.arange(0, 12, dtype=float)
    exact = box_blurred_rect(x, 3.3, 7.9, sigma)
    assert exact == pytest.approx(_brute_rect(x, 3.3, 7.9, sigma), abs=3e-3)
    # the pixel aperture and the blur conserve the bar's area
    wide = np.arange(-20, 40, dtype=float)
    assert box_blurred_rect(wide, 3.3, 7.9, sigma).sum() == pytest.approx(4.6, abs=1e-9)


@pytest.mark.parametrize(
    "period,sigma", [(22.0, 0.4), (5.5, 1.6), (1.83, 0.3), (1.83, 2.0), (3.7, 0.9)]
)
def test_blurred_square_wave_matches_brute_force(period: float, sigma: float) -> None:
    step = period / 2000
    idx = np.arange(-40000, 40000)  # 40 whole periods: circular convolution by FFT is exact
    u = idx * step
    square = (np.mod(idx, 2000) < 1000).astype(float)  # exact edges, no float rounding
    freq = np.fft.rfftfreq(idx.size, d=step)
    ref = np.fft.irfft(np.fft.rfft(square) * np.exp(-2 * (np.pi * sigma * freq) ** 2), idx.size)
    mid = slice(len(u) // 2, len(u) // 2 + 4000)
    # the sampled square wave's edges sit half a sample before the continuous ones
    got = blurred_square_wave(u[mid] + step / 2, period, sigma)
    assert got == pytest.approx(ref[mid], abs=5e-4)


def test_square_wave_per_sample_sigma_and_both_branches_agree() -> None:
    u = np.linspace(0, 10, 101)
    sig = np.linspace(0.2, 2.0, 101)
    mixed = blurred_square_wave(u, 4.0, sig)
    one_by_one = np.array([blurred_square_wave(ui, 4.0, si) for ui, si in zip(u, sig, strict=True)])
    assert mixed == pytest.approx(one_by_one.ravel(), abs=1e-6)


def test_profiles_interpolate_and_defaults_are_like_the_thesis() -> None:
    prof = BlurProfile((1.0, 2.0), (0.2, 0.4), (1.0, 3.0))
    assert float(prof.sagittal_px(1.5)) == pytest.approx(0.3)
    assert float(prof.tangential_px(5.0)) == pytest.approx(3.0)  # flat beyond the table
    heights = np.linspace(1.7, 2.7, 6)
    assert np.all(RADIAL_BLUR.tangential_px(heights) > 3 * RADIAL_BLUR.sagittal_px(heights))
    assert np.all(np.diff(FORWARD_BLUR.sagittal_px(np.linspace(0, 1.2, 7))) > 0)
    with pytest.raises(ValueError):
        BlurProfile((2.0, 1.0), (0.1, 0.1), (0.1, 0.1))
