"""numpy array types of the localization and tracking code, by element type.

Shapes, units and frames are stated where an array is used (docstrings); these aliases only
name the element type, e.g. ``FloatArray`` for a (4, 4) pose or an (H, P) IoU matrix.
"""

from __future__ import annotations

from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

__all__ = ["BoolArray", "FloatArray", "IndexArray", "Int32Array"]

#: Real numbers (poses, ellipse parameters, IoUs, covariances).
FloatArray: TypeAlias = NDArray[np.float64]
#: Indices and counts (``np.intp``: what ``np.flatnonzero`` / ``np.argsort`` return).
IndexArray: TypeAlias = NDArray[np.intp]
#: Compact indices (the scorer's (detection, object) pair index: 4 bytes per entry).
Int32Array: TypeAlias = NDArray[np.int32]
#: Masks.
BoolArray: TypeAlias = NDArray[np.bool_]
