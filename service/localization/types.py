"""Inputs and outputs of the localization pipeline (owned by the relocalization issue).

Frames: ``world_from_camera`` is the camera's pose in the map (4x4, camera axes OpenCV:
+X right, +Y down, +Z forward). Covariances are 6x6 in GTSAM's Pose3 tangent order
``[omega_x, omega_y, omega_z, v_x, v_y, v_z]`` (radians, metres), right perturbation, expressed
in the camera (body) frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from factors.geometry import Ellipse, GeometryError


@dataclass(frozen=True)
class Detection:
    """One detected object: its ellipse (px), category label, optional predicted ``sigma``
    (the paper's per-detection uncertainty, > 0, unitless: it scales the metric's cost as
    ``sigma^-1 * Delta``) and optional detector ``score`` in [0, 1]."""

    ellipse: Ellipse
    label: str
    sigma: float | None = None
    score: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.ellipse, Ellipse):
            raise GeometryError("Detection.ellipse must be an Ellipse")
        if not isinstance(self.label, str) or not self.label:
            raise GeometryError("Detection.label must be a non-empty string")
        if self.sigma is not None and not (math.isfinite(self.sigma) and self.sigma > 0):
            raise GeometryError(f"Detection.sigma must be finite and > 0, got {self.sigma}")
        if self.score is not None and not (math.isfinite(self.score) and 0 <= self.score <= 1):
            raise GeometryError(f"Detection.score must be in [0, 1], got {self.score}")
