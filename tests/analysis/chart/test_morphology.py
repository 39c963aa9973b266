"""benchlab.analysis.chart.morphology gives exactly OpenCV's results (which the analysis no longer
imports: start-up, issue 11) on random images and on the edge cases: empty, all set, one
pixel, one row or column, boxes larger than the image, components on the borders, 4- vs
8-connectivity and long serpentine components."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from benchlab.analysis.chart.finder import WINDOW_BLOCK_PX, _block_max
from benchlab.analysis.chart.morphology import (
    box_close,
    box_dilate,
    box_erode,
    fill_holes,
    label_components,
)

_SIZES = st.sampled_from([1, 3, 5, 7, 9, 15, 23, 41])


def _box(size: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))


@settings(max_examples=80, deadline=None)
@given(rows=st.integers(1, 45), cols=st.integers(1, 45), size=_SIZES, seed=st.integers(0, 9999),
       wide=st.booleans())
def test_box_morphology_equals_opencv(rows: int, cols: int, size: int, seed: int,
                                      wide: bool) -> None:
    rng = np.random.default_rng(seed)
    img = (rng.normal(size=(rows, cols)).astype(np.float32) if wide
           else rng.integers(0, 256, (rows, cols), dtype=np.uint8))
    assert np.array_equal(box_dilate(img, size), cv2.dilate(img, _box(size)))
    assert np.array_equal(box_erode(img, size), cv2.erode(img, _box(size)))
    closed = box_close(img, size)
    assert closed.dtype == img.dtype
    assert np.array_equal(closed, cv2.morphologyEx(img, cv2.MORPH_CLOSE, _box(size)))


def test_box_morphology_refuses_what_it_cannot_mean() -> None:
    with pytest.raises(ValueError, match="odd"):
        box_close(np.zeros((4, 4), np.float32), 4)
    with pytest.raises(ValueError, match="2-D"):
        box_dilate(np.zeros(4, np.float32), 3)
    with pytest.raises(ValueError, match="numbers"):
        box_erode(np.zeros((4, 4), bool), 3)


def _cv2_labels(mask: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8),
                                                           connectivity=4)
    return n, labels, stats[:, cv2.CC_STAT_AREA]


def _assert_labels_equal(mask: np.ndarray) -> None:
    n, labels, areas = label_components(mask)
    ref_n, ref_labels, ref_areas = _cv2_labels(mask)
    assert n == ref_n
    assert labels.dtype == np.int32 and np.array_equal(labels, ref_labels)
    assert np.array_equal(areas, ref_areas)


@settings(max_examples=120, deadline=None)
@given(rows=st.integers(1, 40), cols=st.integers(1, 40), density=st.floats(0.0, 1.0),
       seed=st.integers(0, 9999))
def test_labels_equal_opencv_on_random_masks(rows: int, cols: int, density: float,
                                             seed: int) -> None:
    mask = np.random.default_rng(seed).random((rows, cols)) < density
    _assert_labels_equal(mask)
    assert np.array_equal(fill_holes(mask), ndimage.binary_fill_holes(mask))


def _serpentine(n: int) -> np.ndarray:
    """One 4-connected path folded back and forth: the longest chain of runs there is."""
    mask = np.zeros((2 * n + 1, 2 * n + 1), bool)
    mask[::2, 1:-1] = True
    for k, row in enumerate(range(1, 2 * n, 2)):
        mask[row, -2 if k % 2 == 0 else 1] = True
    return mask


def _edge_masks() -> dict[str, np.ndarray]:
    checker = (np.indices((9, 11)).sum(axis=0) % 2).astype(bool)  # touching only diagonally
    ring = np.zeros((30, 30), bool)
    ring[3:27, 3:27] = True
    ring[8:22, 8:22] = False
    ring[14, 14] = True  # island in the hole
    borders = np.zeros((12, 17), bool)
    borders[0, :5] = borders[-1, -4:] = borders[5:, 0] = borders[:3, -1] = True
    comb = np.zeros((20, 20), bool)
    comb[:, ::3] = True  # columns joined only through the last row
    comb[:-1, 1::3] = False
    comb[-1, :] = True
    return {
        "empty": np.zeros((7, 9), bool), "all set": np.ones((7, 9), bool),
        "one pixel on": np.ones((1, 1), bool), "one pixel off": np.zeros((1, 1), bool),
        "one row": np.array([[1, 1, 0, 1, 0, 0, 1]], bool),
        "one column": np.array([[1], [0], [1], [1]], bool),
        "checkerboard": checker, "ring": ring, "borders": borders, "comb": comb,
        "serpentine": _serpentine(40), "anti-serpentine": ~_serpentine(40),
    }


@pytest.mark.parametrize("name", list(_edge_masks()))
def test_labels_and_hole_fill_on_edge_cases(name: str) -> None:
    mask = _edge_masks()[name]
    _assert_labels_equal(mask)
    assert np.array_equal(fill_holes(mask), ndimage.binary_fill_holes(mask))


def test_serpentine_is_one_component() -> None:
    n, labels, areas = label_components(_serpentine(60))
    assert n == 2 and areas[1] == _serpentine(60).sum()


def test_block_max_is_the_sampled_opencv_dilation_it_replaced() -> None:
    """``_search_window`` read a WINDOW_BLOCK_PX box dilation at the block centres."""
    step = WINDOW_BLOCK_PX
    rng = np.random.default_rng(5)
    for shape in ((32, 32), (37, 45), (1024, 1280), (8 * 4 + 7, 8 * 5)):
        img = rng.normal(size=shape).astype(np.float32)
        hb, wb = shape[0] // step, shape[1] // step
        near_max = cv2.dilate(img, np.ones((step, step), np.uint8))
        sampled = near_max[step // 2: hb * step: step, step // 2: wb * step: step]
        assert np.array_equal(_block_max(img, step), sampled)


def test_empty_shapes() -> None:
    for shape in ((0, 5), (5, 0), (0, 0)):
        n, labels, areas = label_components(np.zeros(shape, bool))
        assert n == 1 and labels.shape == shape and areas.tolist() == [0]
        assert fill_holes(np.zeros(shape, bool)).shape == shape
