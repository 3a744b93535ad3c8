"""The localization pipeline: RANSAC initialisation, metric refinement, result types.

``refine()`` is not re-exported here: ``quadloc.service.localization.refine`` is its module (its
constants, e.g. ``OVERLAP_NIELSEN_DAMPING``, are set there), not the function.
"""

from quadloc.service.localization.pipeline import localize
from quadloc.service.localization.types import (
    Detection,
    InlierMatch,
    LocalizationInputError,
    LocalizationOptions,
    LocalizationResult,
    PlaceHint,
    PosePrior,
)

__all__ = [
    "Detection",
    "InlierMatch",
    "LocalizationInputError",
    "LocalizationOptions",
    "LocalizationResult",
    "PlaceHint",
    "PosePrior",
    "localize",
]
