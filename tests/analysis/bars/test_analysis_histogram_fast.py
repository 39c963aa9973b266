"""The histogram-peak estimator's speed-ups give exactly what the straightforward code gives:
scipy's peak finder, np.convolve smoothing, and counting pixels below the valley."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.signal import find_peaks

from benchlab.analysis.bars import histogram
from benchlab.analysis.bars.histogram import _find_peaks, _kernel, histogram_peak
from benchlab.analysis.bars.roi import PreparedROI, prepare_roi


@settings(max_examples=200, deadline=None)
@given(
    y=arrays(np.float64, st.integers(3, 60), elements=st.sampled_from([0.0, 1.0, 2.0, 3.0])),
    height=st.floats(0.0, 3.0),
)
def test_find_peaks_matches_scipy(y: np.ndarray, height: float) -> None:
    padded = np.pad(y, 1)
    peaks, heights = _find_peaks(padded, height)
    assert peaks == find_peaks(padded, height=height)[0].tolist()
    assert heights == padded[peaks].tolist()


def _random_rois(n: int, seed: int) -> list[tuple[np.ndarray, dict[str, object]]]:
    """Bar ROIs of many kinds: 8-bit, 12-bit MSB-aligned, float, integer-valued float,
    averaged frames, noisy, blurred, shaded."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        shape = (int(rng.integers(2, 50)), int(rng.integers(2, 60)))
        period = float(rng.uniform(2.2, 30.0))
        x = np.arange(shape[1])
        bars = np.where(np.sin(2 * np.pi * x / period + rng.uniform(0, 6)) > 0, 1.0, -1.0)
        mean, amp = rng.uniform(20, 200), rng.uniform(0, 80)
        noise = rng.uniform(0.05, 12.0)
        img = mean + amp * bars[None, :] + rng.normal(0, noise, shape)
        img += rng.uniform(0, 0.3) * mean * np.linspace(-0.5, 0.5, shape[0])[:, None]
        kind = i % 5
        if kind == 0:
            roi: np.ndarray = np.clip(np.round(img), 0, 255).astype(np.uint8)
        elif kind == 1:
            roi = (np.clip(np.round(img * 8), 0, 4095).astype(np.uint16) * 16).astype(np.uint16)
        elif kind == 2:
            roi = img
        elif kind == 3:
            roi = np.round(img)
        else:
            frames = img[None] + rng.normal(0, noise, (int(rng.integers(2, 5)), *shape))
            roi = np.clip(np.round(frames), 0, 255).astype(np.uint8)
        out.append((roi, {"orientation": "horizontal", "freq_cycles_per_px": 1.0 / period}))
    return out


def _reference_binned(prep: PreparedROI) -> tuple[np.ndarray, float, bool]:
    """The histogram without the integer shortcut: pixels below the valley are counted."""
    counts, width, _ = _original_binned(prep)
    return counts, width, False


_original_binned = histogram._binned


def _convolve_smoothed(
    prep: PreparedROI, counts: np.ndarray, width: float, scale: float
) -> tuple[np.ndarray, float, int]:
    n_half = max(prep.pixels.size / 2.0, 1.0)
    sigma_gray = 1.06 * prep.noise_sigma * n_half ** (-0.2)
    sigma_bins = round(max(scale * sigma_gray / width, 0.7 * scale), 2)
    kernel = _kernel(sigma_bins)
    return np.convolve(counts, kernel, mode="full"), sigma_bins * width, (kernel.size - 1) // 2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_histogram_peak_identical_to_straightforward_path(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Same results, bit for bit, as np.convolve + counting pixels."""
    rois = _random_rois(300, seed)
    preps = [prepare_roi(roi, **kw) for roi, kw in rois]  # type: ignore[arg-type]
    fast = [histogram_peak(p) for p in preps]
    monkeypatch.setattr(histogram, "_binned", _reference_binned)
    monkeypatch.setattr(histogram, "_smoothed", _convolve_smoothed)
    slow = [histogram_peak(p) for p in preps]
    assert fast == slow
    assert sum(r.resolved for r in fast) > 50  # the comparison covers real readings


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(y=arrays(np.float64, st.integers(1, 40), elements=st.sampled_from([0.0, 1.0, 2.0, 3.0])))
def test_rises_maximum_is_the_array_maximum(y: np.ndarray) -> None:
    """The maximum read off the candidate tops is max(y), ends and plateaus included."""
    from benchlab.analysis.bars.histogram import _rises

    starts, heights, top = _rises(y)
    assert top == float(y.max())
    assert heights == [float(y[i]) for i in starts]
