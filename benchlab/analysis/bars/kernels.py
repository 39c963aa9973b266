"""Which path the histogram-peak method runs: the compiled kernels or the numpy reference.

``benchlab.analysis.bars._histkernels`` (C, built by ``pip install`` when a compiler is present; see
``setup.py``) fuses the per-pixel numpy passes of the method's bar geometry and bar-centre
selection into single loops, with numpy's own summation order and rounding, so both paths read
the same numbers. Without it (no compiler at install, or ``BENCHLAB_NUMPY_KERNELS=1`` in the
environment, or a build of another version of the C source) the numpy code runs: same
readings, about 2.5 times the time at 40x50.

On large inputs (``RELEASE_MIN_PIXELS`` pixels, ``RELEASE_MIN_BINS`` histogram bins) the
kernels release the GIL while they run, as numpy's loops do: other threads (the TUI, the
acquisition) keep running beside the analysis of a 2048 x 2048 ROI. ``_histkernels.c`` says why
that is safe.
"""

from __future__ import annotations

import os
import warnings
from types import ModuleType

import numpy as np
import numpy.typing as npt

#: Set to 1 to run the numpy reference even when the compiled kernels are built.
DISABLE_ENV = "BENCHLAB_NUMPY_KERNELS"
#: The version of ``_histkernels.c`` this code calls (its ``KERNELS_VERSION``).
VERSION = 1


def _load() -> ModuleType | None:
    if os.environ.get(DISABLE_ENV, "") not in ("", "0"):
        return None
    try:
        from benchlab.analysis.bars import _histkernels
    except ImportError:
        return None
    if getattr(_histkernels, "VERSION", None) != VERSION:
        # A build of another version of the C source (rebuild: pip install -e .): its
        # functions may not be these; the numpy path is always right.
        warnings.warn(f"benchlab: stale compiled kernels ({_histkernels.__file__}): numpy "
                      "path used; rebuild with 'pip install -e .'", RuntimeWarning, stacklevel=2)
        return None
    return _histkernels


def _numpy_fuses_complex_products() -> bool:
    """Whether numpy's complex product rounds like a fused multiply-add on this CPU (its AVX2
    and AVX-512 loops do, its baseline loop does not): the kernels must do as numpy does."""
    a = complex(1 + 2**-27, 1 + 2**-26)
    b = complex(1 + 2**-28, 1 - 2**-27)
    product = complex((np.array([a]) * np.array([b]))[0])
    return product != a * b  # Python's complex product is never fused


#: The compiled module, or ``None``: the numpy reference runs.
compiled: ModuleType | None = _load()
#: Passed to the kernels: numpy's complex products are fused here.
FUSED_COMPLEX = _numpy_fuses_complex_products()


def row_major(img: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``img`` itself when numpy traverses it row by row as the kernels do (C-contiguous, or a
    view such as a crop whose strides fall from the first axis to the last), else its
    C-contiguous copy (Fortran order, transposed or reversed views).

    numpy sums an array in its memory order, the kernels in row-major order: on a Fortran-order
    ROI the two paths would round differently (1e-15), and the same pixels in another layout
    would read differently. Both paths read this array instead.

    Parameters
    ----------
    img : ndarray
        Any array (any number of dimensions, any dtype).

    Returns
    -------
    ndarray
        ``img`` or its copy in C order (same dtype and values).
    """
    strides = [s for s, n in zip(img.strides, img.shape, strict=True) if n > 1]
    if all(s > 0 for s in strides) and strides == sorted(strides, reverse=True):
        return img
    return np.ascontiguousarray(img)


def describe() -> str:
    """``"compiled kernels"`` or ``"numpy fallback"``: the histogram method's path here."""
    return "compiled kernels" if compiled is not None else "numpy fallback"
