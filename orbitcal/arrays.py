"""Array type aliases shared by every module (shapes and units are in each docstring)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["BoolArray", "FloatArray", "IntArray"]

#: Float64 array of any shape.
FloatArray = npt.NDArray[np.float64]
#: Boolean array (masks) of any shape.
BoolArray = npt.NDArray[np.bool_]
#: Int64 array of any shape.
IntArray = npt.NDArray[np.int64]
