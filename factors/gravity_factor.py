"""A measured gravity direction as a GTSAM factor on the camera pose.

An AR framework's IMU measures the direction gravity pulls in the camera; the map knows its own
down (minus its up axis). A pose ``world_from_camera = [R | t]`` predicts the camera's down in
the map as ``R down_camera``; the factor's error is the 2-D tangent-plane difference between
that and ``down_world`` (GTSAM's ``Unit3.error``: norm ``sin(angle)``, the angle in radians for
small angles),
with an isotropic noise of ``sigma_rad`` per tilt axis. It constrains roll and pitch only: the
rotation about the vertical and the position are not observed. (The tilt angle itself, for
testing candidates: ``quadloc.service.localization.gravity.tilt_errors_deg``.)

GTSAM's own C++ ``AttitudeFactorPose3`` (navigation frame = the map, body frame = the camera):
no Python round trip per evaluation. Its error and Jacobian are checked against the tilt angle
and central differences in ``tests/service/localization/test_gravity.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np

from quadloc.factors.arrays import FloatArray

__all__ = ["GravityMeasurement", "gravity_factor"]


@dataclass(frozen=True)
class GravityMeasurement:
    """A gravity direction measured in the camera, with the map's down.

    Attributes:
        down_camera: (3,) unit vector, the direction gravity pulls in the camera's axes
            (OpenCV: +X right, +Y down, +Z forward).
        down_world: (3,) unit vector, the direction gravity pulls in the map (minus its up
            axis).
        sigma_rad: 1-sigma angular noise per tilt axis (radians), > 0.
    """

    down_camera: FloatArray
    down_world: FloatArray
    sigma_rad: float

    def __post_init__(self) -> None:
        for name in ("down_camera", "down_world"):
            v = np.asarray(getattr(self, name), dtype=float)
            n = float(np.linalg.norm(v)) if v.shape == (3,) else math.nan
            if not (np.all(np.isfinite(v)) and n > 1e-9):
                raise ValueError(f"{name}: must be a non-zero finite 3-vector, got {v.tolist()}")
            object.__setattr__(self, name, v / n)
        if not (math.isfinite(self.sigma_rad) and self.sigma_rad > 0):
            raise ValueError(f"sigma_rad: must be > 0, got {self.sigma_rad!r}")


def gravity_factor(key: int, measurement: GravityMeasurement) -> gtsam.NonlinearFactor:
    """The factor on the ``world_from_camera`` ``Pose3`` at ``key`` (2 residuals, radians)."""
    return gtsam.AttitudeFactorPose3(
        key, gtsam.Unit3(measurement.down_world),
        gtsam.noiseModel.Isotropic.Sigma(2, measurement.sigma_rad),
        gtsam.Unit3(measurement.down_camera))

