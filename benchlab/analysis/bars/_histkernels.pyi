"""Types of the compiled kernels (``_histkernels.c``); see :mod:`benchlab.analysis.bars.kernels`."""

import numpy as np
import numpy.typing as npt

VERSION: int
#: The GIL is released for images of at least this many pixels ...
RELEASE_MIN_PIXELS: int
#: ... and histograms of at least this many bins.
RELEASE_MIN_BINS: int

def quick_core(
    img: npt.NDArray[np.float64], freq: float, min_periods: float, settled_cycles: float,
    iterations: int, coarse_min_px: int, fused: bool, /,
) -> tuple[float, float, float, float, float] | None: ...
def phase_select(
    img: npt.NDArray[np.float64], kx_bins: float, ky_bins: float, centre: float,
    inner_limit: float, near: bytes, wide: bytes, min_pixels: int,
    out: npt.NDArray[np.float64], /,
) -> tuple[float, int, float, float]: ...
def modes(
    smooth: npt.NDArray[np.float64], min_fraction: float, /,
) -> tuple[list[int], int | None, bool]: ...
