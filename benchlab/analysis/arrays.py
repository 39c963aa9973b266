"""The array types every layer above the drivers annotates with (one definition each)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

#: A float64 array of any shape: pixels, profiles, curves.
FloatArray = npt.NDArray[np.float64]
