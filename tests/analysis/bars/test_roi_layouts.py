"""The same pixels in any memory layout read the same: numpy sums an array in its memory
order, so a Fortran-order, transposed or reversed ROI would round a few ulps apart (1e-15) from
its C-order copy; :func:`benchlab.analysis.bars.roi.row_major` makes every estimator read the
C-order array, and copies nothing that is already row by row."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchlab.analysis.bars import geometry as bargeometry
from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.bars.roi import prepare_roi, row_major

LAYOUTS = ("fortran", "transposed", "reversed", "fortran-crop")


@st.composite
def rois(draw: st.DrawFn) -> tuple[np.ndarray, float]:
    """A bar pattern (any angle, period, phase, duty, shading) or an extreme (flat, all-zero,
    saturated), 1x1 to 120x120, as float64, uint8 or uint16, and its frequency."""
    rows = draw(st.integers(1, 120))
    cols = draw(st.integers(1, 120))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kind = draw(st.sampled_from(["bars", "bars", "bars", "flat", "zero", "saturated"]))
    dtype = draw(st.sampled_from([np.float64, np.uint8, np.uint16]))
    period = draw(st.floats(2.2, 40.0))
    y, x = np.mgrid[0:rows, 0:cols].astype(np.float64)
    if kind == "bars":
        theta = draw(st.floats(0.0, math.pi))
        wave = np.cos(2 * math.pi * (x * math.cos(theta) + y * math.sin(theta)) / period
                      + draw(st.floats(0.0, 6.3)))
        wave = np.where(wave > draw(st.floats(-0.3, 0.3)), 1.0, 0.0)
        img = 40 + 150 * wave * (1 + draw(st.floats(0.0, 0.3)) * x / max(cols, 1))
        img += rng.normal(0, draw(st.floats(0.0, 20.0)), img.shape)
    elif kind == "flat":
        img = np.full((rows, cols), 77.0)
    elif kind == "zero":
        img = np.zeros((rows, cols))
    else:
        img = np.full((rows, cols), 255.0)
    if dtype == np.uint8:
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    elif dtype == np.uint16:
        img = np.clip(np.rint(img * 16), 0, 65535).astype(np.uint16)
    return img, 1.0 / period


def _layout(img: np.ndarray, layout: str) -> np.ndarray:
    """The same pixels in another memory layout."""
    views = {
        "fortran": lambda: np.asfortranarray(img),
        "transposed": lambda: np.ascontiguousarray(img.T).T,
        "reversed": lambda: np.ascontiguousarray(img[::-1, ::-1])[::-1, ::-1],
        "fortran-crop": lambda: np.asfortranarray(np.pad(img, 3))[3:-3, 3:-3],
    }
    out = views[layout]()
    assert np.array_equal(out, img)
    return out


def _reading(roi: np.ndarray, freq: float) -> tuple[object, ...]:
    r = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=freq)
    return (r.modulation, r.resolved, r.interval, r.dark, r.bright, r.warnings,
            r.diagnostics.noise_sigma)


@settings(max_examples=40, deadline=None)
@given(case=rois(), layout=st.sampled_from(LAYOUTS))
def test_any_layout_reads_as_its_c_order_copy(case: tuple[np.ndarray, float],
                                               layout: str) -> None:
    """The bars' fundamental and the histogram reading of a Fortran-order (transposed,
    reversed) ROI: bit for bit those of the C-order ROI."""
    roi, freq = case
    img = np.ascontiguousarray(roi, dtype=np.float64)
    other = _layout(img, layout)
    assert (bargeometry.quick_fundamental(other, None, freq, None, None)
            == bargeometry.quick_fundamental(img, None, freq, None, None))
    assert _reading(other, freq) == _reading(img, freq)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_row_major_copies_only_other_layouts(layout: str) -> None:
    """A crop or stride of a C-order frame (already row by row) is read in place; any other
    layout through its C-order copy, which prepare_roi hands to the estimators."""
    frame = np.arange(30 * 40, dtype=np.float64).reshape(30, 40)
    for view in (frame[5:25, 3:33], frame[:, ::2], frame[::3, 1:2], frame[2:3, :]):
        assert row_major(view) is view
    other = _layout(frame, layout)
    assert not other.flags.c_contiguous
    assert row_major(other).flags.c_contiguous
    assert np.array_equal(row_major(other), frame)
    assert prepare_roi(other).pixels.flags.c_contiguous
