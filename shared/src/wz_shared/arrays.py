"""The numpy array types used across the project, under one name each.

``F64`` is an array of float64 of any shape; the shape and units of a particular array are
said where it is used (``x_m: F64  # (N,) [m]``). Import them from here rather than defining
local aliases, so one name always means one dtype.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]
I64 = npt.NDArray[np.int64]
I32 = npt.NDArray[np.int32]
I16 = npt.NDArray[np.int16]
IntP = npt.NDArray[np.intp]
U8 = npt.NDArray[np.uint8]
U64 = npt.NDArray[np.uint64]
Bool = npt.NDArray[np.bool_]

__all__ = ["F32", "F64", "I16", "I32", "I64", "U8", "U64", "Bool", "IntP"]
