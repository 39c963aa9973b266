""":func:`benchlab.analysis.arrays.mean_of_frames` is the plain float64 mean of the stacked
frames, bit for bit (issue 39: the depth and FOV positions' averaged frames)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from benchlab.analysis.arrays import mean_of_frames


def _plain(frames: list[npt.NDArray[Any]]) -> npt.NDArray[np.float64]:
    return np.asarray(np.mean(np.stack(frames).astype(np.float64), axis=0))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16, np.int8, np.float32,
                                   np.float64, np.int64, np.uint32])
def test_the_plain_mean_bit_for_bit(dtype: Any) -> None:
    rng = np.random.default_rng(39)
    info = np.iinfo(dtype) if np.dtype(dtype).kind in "ui" else None
    for n in (1, 2, 3, 5, 7, 10, 16):
        for shape in [(256, 320), (3, 5), (1, 1), (17,)]:
            if info is not None:
                frames = [rng.integers(info.min, info.max, shape, endpoint=True).astype(dtype)
                          for _ in range(n)]
            else:
                frames = [(rng.normal(0, 1e3, shape)).astype(dtype) for _ in range(n)]
            got, want = mean_of_frames(frames), _plain(frames)
            assert got.dtype == want.dtype == np.float64 and got.shape == want.shape
            assert got.tobytes() == want.tobytes(), (dtype, n, shape)


def test_codes_at_the_top_of_the_range_and_mixed_depths() -> None:
    top = [np.full((4, 6), 65535, np.uint16)] * 300 + [np.full((4, 6), 255, np.uint8)]
    assert mean_of_frames(top).tobytes() == _plain(top).tobytes()
    many = [np.full((2, 3), 65535, np.uint16)] * 32767  # the largest int32 sum taken
    assert mean_of_frames(many).tobytes() == _plain(many).tobytes()


def test_no_frames_or_different_shapes_are_refused() -> None:
    with pytest.raises(ValueError, match="at least one"):
        mean_of_frames([])
    with pytest.raises(ValueError, match="same shape"):
        mean_of_frames([np.zeros((2, 3), np.uint8), np.zeros((3, 2), np.uint8)])
    with pytest.raises(ValueError):
        mean_of_frames([np.zeros((2, 3)), np.zeros((3, 2))])
