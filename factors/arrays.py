"""The array types of the annotations: what a numpy array holds, for mypy and the reader.

``numpy.typing.NDArray`` of the element type; shapes and units are not types, the docstrings
state them (e.g. "(N, 3) m"). Every module of ``quadloc.factors`` and ``quadloc.maps`` annotates
its arrays with these names, and so does the rest of the code base.
"""

from __future__ import annotations

from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

__all__ = ["BoolArray", "FloatArray", "Int32Array", "IntArray"]

#: float64 array (coordinates, residuals, Jacobians, poses ...).
FloatArray: TypeAlias = NDArray[np.float64]
#: bool array (masks: valid pairs, inliers ...).
BoolArray: TypeAlias = NDArray[np.bool_]
#: platform-integer array (indices, counts: what ``np.flatnonzero`` / ``np.argsort`` return).
IntArray: TypeAlias = NDArray[np.intp]
#: compact indices (e.g. the localization scorer's (detection, object) pair index: 4 bytes).
Int32Array: TypeAlias = NDArray[np.int32]
