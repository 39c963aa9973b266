"""Sharpness figure for focusing: the variance of the Laplacian.

A sharper image has stronger second derivatives at its edges, so the variance of the Laplacian
rises to a maximum at best focus (Pech-Pacheco et al., ICPR 2000). The figure depends on the
scene and exposure, so it is only compared between frames of the same scene: the operator
turns the back focus to maximise it (Table 4.10 step 3).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt


def sharpness(pixels: npt.NDArray[Any], roi: tuple[int, int, int, int] | None = None) -> float:
    """Variance of the Laplacian of a frame (or of ``roi`` = row0, col0, row1, col1).

    Parameters
    ----------
    pixels : ndarray
        2-D monochrome frame, any integer or float dtype.
    roi : tuple of int, optional
        0-based, end-exclusive rows/columns; the whole frame by default.

    Returns
    -------
    float
        Non-negative sharpness figure in (gray units)^2; 0 for a uniform image.

    Raises
    ------
    ValueError
        If the frame is not 2-D or the ROI is empty or off the frame.
    """
    arr = np.asarray(pixels)
    if arr.ndim != 2:
        raise ValueError(f"sharpness needs a 2-D frame, got shape {arr.shape}")
    if roi is not None:
        r0, c0, r1, c1 = roi
        if not (0 <= r0 < r1 <= arr.shape[0] and 0 <= c0 < c1 <= arr.shape[1]):
            raise ValueError(f"ROI {roi} is empty or off the {arr.shape} frame")
        arr = arr[r0:r1, c0:c1]
    if arr.size < 9:
        raise ValueError("sharpness needs at least 3 x 3 pixels")
    # here: OpenCV costs ~50 ms to import, and the depth analysis imports this package for
    # its through-focus modules without ever asking for a sharpness figure
    import cv2

    lap = cv2.Laplacian(arr.astype(np.float32), cv2.CV_32F, ksize=3)
    return float(np.var(lap, dtype=np.float64))
