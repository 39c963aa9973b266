"""The numpy/OpenCV hole fill and erosion equal scipy.ndimage's, which analysis no longer
imports (start-up time)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from benchlab.analysis.geometry import _erode, fill_holes


def _masks() -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    out = [rng.random((40, 55)) > p for p in (0.2, 0.5, 0.8)]
    ring = np.zeros((30, 30), bool)
    ring[5:25, 5:25] = True
    ring[10:20, 10:20] = False  # one enclosed hole
    ring[12, 12] = True  # an island inside the hole
    edge = ring.copy()
    edge[0:3, :] = True  # touching the border
    diagonal = np.eye(12, dtype=bool) | np.eye(12, k=1, dtype=bool)  # 4- vs 8-connectivity
    return [*out, ring, edge, diagonal, np.zeros((5, 5), bool), np.ones((5, 5), bool)]


@pytest.mark.parametrize("mask", _masks())
def test_fill_holes_matches_scipy(mask: np.ndarray) -> None:
    assert np.array_equal(fill_holes(mask), ndimage.binary_fill_holes(mask))


@pytest.mark.parametrize("mask", _masks())
def test_erode_matches_scipy_with_border_set(mask: np.ndarray) -> None:
    assert np.array_equal(_erode(mask), ndimage.binary_erosion(mask, border_value=1))


def test_fill_holes_refuses_non_2d() -> None:
    with pytest.raises(ValueError, match="2-D"):
        fill_holes(np.zeros(5, bool))
