"""The localization pipeline: RANSAC initialisation, metric refinement, result types."""

from service.localization.pipeline import localize
from service.localization.refine import RefinementResult, refine
from service.localization.types import (
    Detection,
    InlierMatch,
    LocalizationInputError,
    LocalizationOptions,
    LocalizationResult,
    PosePrior,
)

__all__ = [
    "Detection",
    "InlierMatch",
    "LocalizationInputError",
    "LocalizationOptions",
    "LocalizationResult",
    "PosePrior",
    "RefinementResult",
    "localize",
    "refine",
]
