"""One full-scale code per frame: the live view, radiometry and the edge analysis judge clipping
against the same code (before, the live view said 65535 where the analysis said 65520)."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.analysis.sfr.measure import full_scale_of_frame
from benchlab.protocols.radiometry import saturation_code_of
from benchlab.tui.services import max_code_of

RNG = np.random.default_rng(3)


@pytest.mark.parametrize(("frame", "bits", "want"), [
    (RNG.integers(0, 256, (16, 16)).astype(np.uint8), 8, 255.0),
    (RNG.integers(0, 4096, (16, 16)).astype(np.uint16), 12, 4095.0),
    ((RNG.integers(0, 4096, (16, 16)) << 4).astype(np.uint16), 12, 65520.0),  # MSB-aligned
    ((RNG.integers(0, 1024, (16, 16)) << 6).astype(np.uint16), 10, 65472.0),
    (RNG.integers(0, 1024, (16, 16)).astype(np.uint16), 10, 1023.0),
])
def test_live_view_radiometry_and_analysis_agree(frame: np.ndarray, bits: int,
                                                 want: float) -> None:
    assert full_scale_of_frame(frame, {"bits": bits}) == want
    assert max_code_of(frame, {"bits": bits}) == want
    assert saturation_code_of(frame, bits) == want


def test_without_a_bit_depth_the_dtype_and_code_grid_decide() -> None:
    frame = (RNG.integers(0, 4096, (16, 16)) << 4).astype(np.uint16)
    assert max_code_of(frame, {}) == 65520.0
    assert max_code_of(np.zeros((4, 4), np.uint8), {}) == 255.0
    assert max_code_of(np.full((2, 2), 0.5), {}) == 0.5  # float data: its maximum
