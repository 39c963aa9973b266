"""The histogram path's later speed-ups (issue 9: 100 us per 2,000-px ROI) change no number:
each shortcut is checked against the straightforward code it replaces."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.bars.histogram import _find_peaks, _massive_modes, histogram_peak
from benchlab.analysis.bars.roi import _profile_var, detect_axis, detect_plateau, prepare_roi
from benchlab.synthetic.bars import BarCase, render


@settings(max_examples=200, deadline=None)
@given(
    img=arrays(
        np.float64,
        st.tuples(st.integers(1, 40), st.integers(1, 40)),
        elements=st.floats(-1e6, 1e6, allow_nan=False),
    )
)
def test_profile_var_is_numpys_var_of_the_mean(img: np.ndarray) -> None:
    """Bit for bit ``np.var(img.mean(axis))``, so ``detect_axis`` picks the same axis."""
    for ax in (0, 1):
        assert _profile_var(img, ax) == float(np.var(img.mean(axis=ax)))
    if min(img.shape) >= 2:
        expected = 1 if np.var(img.mean(axis=0)) >= np.var(img.mean(axis=1)) else 0
        assert detect_axis(img) == expected


def _reference_massive_modes(smooth: np.ndarray, peaks: list[int]) -> list[int]:
    """The mode merging as first written: masses from a cumulative sum with a leading 0, and
    always the merge loop."""
    if len(peaks) < 2:
        return peaks
    total = float(smooth.sum())
    pairs = zip(peaks[:-1], peaks[1:], strict=True)
    cuts = [p + int(np.argmin(smooth[p : q + 1])) for p, q in pairs]
    cum = np.concatenate([[0.0], np.cumsum(smooth)])
    edges = [0, *[c + 1 for c in cuts], smooth.size]
    modes = [(p, float(cum[edges[i + 1]] - cum[edges[i]])) for i, p in enumerate(peaks)]
    valleys = [float(smooth[c]) for c in cuts]
    limit = 0.04 * total
    while len(modes) > 1:
        light = min(range(len(modes)), key=lambda i: modes[i][1])
        if modes[light][1] >= limit:
            break
        left = valleys[light - 1] if light > 0 else -math.inf
        right = valleys[light] if light < len(valleys) else -math.inf
        j = light - 1 if left >= right else light + 1
        keep = j if smooth[modes[j][0]] >= smooth[modes[light][0]] else light
        lo = min(light, j)
        modes[lo : lo + 2] = [(modes[keep][0], modes[light][1] + modes[j][1])]
        del valleys[lo]
    return [int(m[0]) for m in modes if m[1] >= limit]


@pytest.mark.slow
@settings(max_examples=400, deadline=None)
@given(y=arrays(np.float64, st.integers(3, 80), elements=st.floats(0.0, 50.0)))
def test_massive_modes_match_the_merge_loop(y: np.ndarray) -> None:
    """Same modes as the general merge; the valley handed back is the lowest bin between two
    neighbouring modes (what the reading would search for)."""
    smooth = np.convolve(y, [0.25, 0.5, 0.25])
    peaks, _ = _find_peaks(smooth, 0.0)
    modes, valley = _massive_modes(smooth, peaks)
    assert modes == _reference_massive_modes(smooth, peaks)
    if valley is not None:
        assert len(modes) == 2
        assert valley == modes[0] + int(np.argmin(smooth[modes[0] : modes[1] + 1]))


def test_massive_modes_two_clear_modes_take_the_short_path() -> None:
    """Two heavy modes: both kept and their valley returned; one light bump: merged away."""
    x = np.arange(100.0)
    two = 50 * np.exp(-0.5 * ((x - 30) / 4) ** 2) + 40 * np.exp(-0.5 * ((x - 70) / 5) ** 2)
    peaks, _ = _find_peaks(two, 0.0)
    modes, valley = _massive_modes(two, peaks)
    assert modes == peaks and len(modes) == 2
    assert valley == 30 + int(np.argmin(two[30:71]))
    bump = two + 0.3 * np.exp(-0.5 * ((x - 90) / 1.0) ** 2)
    peaks, _ = _find_peaks(bump, 0.0)
    assert len(peaks) == 3
    modes, valley = _massive_modes(bump, peaks)
    assert len(modes) == 2 and valley is None
    assert modes == _reference_massive_modes(bump, peaks)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int32, np.float32, np.float64])
def test_detect_plateau_with_the_maximum_given(dtype: type) -> None:
    """Passing the known maximum gives the same verdict as letting it be found, clipped or
    not, in the data's own precision."""
    rng = np.random.default_rng(3)
    for top in (200.0, 200.3):
        values: np.ndarray = np.minimum(rng.normal(190, 8, 4000), top).astype(dtype)
        for step in (0.0, 1.0, 16.0):
            assert detect_plateau(values, step, values.max()) == detect_plateau(values, step)
    assert detect_plateau(np.minimum(np.arange(1000), 900).astype(np.uint16), 1.0) == 900.0


def test_selected_keeps_every_other_fact() -> None:
    prep = prepare_roi(np.arange(64, dtype=np.uint8).reshape(8, 8) % 7 * 30,
                       freq_cycles_per_px=0.2, orientation="horizontal", noise_sigma=1.5)
    pixels = prep.pixels[prep.pixels > 50][None, :]
    sub = prep.selected(pixels, 0.7, 60.0, 180.0)
    assert sub.pixels is pixels
    assert (sub.noise_sigma, sub.vmin, sub.vmax) == (0.7, 60.0, 180.0)
    same = {"pixels", "known_noise", "vmin", "vmax", "source"}
    for f in dataclasses.fields(prep):
        if f.name not in same:
            assert getattr(sub, f.name) == getattr(prep, f.name), f.name
    assert sub.source is prep and sub.selected(pixels, 0.7, 60.0, 180.0).source is prep
    # A 1 x N selection of horizontal stripes still has the ROI's axis (0), measured on the
    # ROI's own pixels when first asked for.
    stripes = prepare_roi(np.repeat([[10], [90], [10], [90]], 6, axis=1).repeat(2, axis=0))
    centre_px = stripes.selected(stripes.pixels[2:4].reshape(1, -1), 1.0, 10.0, 90.0)
    assert centre_px.known_axis is None and centre_px.axis == 0 == stripes.known_axis
    assert sub.diagnostics().n_pixels == pixels.size
    assert sub.diagnostics(n_pixels=64).n_pixels == 64
    assert sub.diagnostics(n_pixels=64, bimodality=0.5).bimodality == 0.5


@pytest.mark.parametrize("angle", [0.0, 25.0])
def test_histogram_diagnostics_count_the_whole_roi(angle: float) -> None:
    """The reading uses the bar and space centres, but reports the ROI's pixel count."""
    bar = BarCase(shape=(40, 50), px_per_period=8.0, angle_deg=angle, noise_sigma=2.0)
    roi = render(bar, np.random.default_rng(1))
    r = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=0.125)
    assert r.resolved
    assert r.diagnostics.n_pixels == roi.size
    # The whole-ROI fallback (bars rotated against the given orientation) reports it too.
    prep = prepare_roi(roi, freq_cycles_per_px=0.125, orientation="vertical")
    assert histogram_peak(prep).diagnostics.n_pixels == roi.size
    flat = np.full((20, 30), 77, np.uint8)
    assert estimate_modulation(flat, estimator="histogram").diagnostics.n_pixels == 600
