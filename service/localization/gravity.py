"""A client's measured gravity direction: the tilt test of candidate poses.

A pose ``camera_from_world = [R | t]`` predicts the map's up axis in the camera as ``R up``;
the client measures gravity ``g`` (pointing down, OpenCV camera axes), so the camera's measured
up is ``-g``. Their angle is the pose's **tilt error** (roll and pitch; the rotation about the
vertical is not observed). A candidate is ruled out when its tilt error exceeds
``confidence.TOLERANCE_ROTATION_DEG + GRAVITY_GATE_SIGMAS * sigma``: the tilt error is at most
the rotation error, and an answer is correct (what ``confidence`` is the probability of) only
within that rotation tolerance, so beyond the gate it is not a correct answer whatever its fit.

How ``localize`` uses gravity: every refinement has it as a factor on the pose's tilt
(:mod:`quadloc.factors.gravity_factor`), the ambiguity check weighs its chi2 with the detections',
the candidates it rules out are dropped while another is left, an answer it rules out is
``gravity_mismatch``, and the confidence model has a ``gravity`` feature (fitted on solves with
a simulated IMU, ``bench.trust``). The RANSAC hypotheses are not gated: a tilted minimal-sample
pose often refines, with the factor, to the correct one.

Rationale and measurements: ``docs/design/localization.md`` ("Gravity").
"""

from __future__ import annotations

import math

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.gravity_factor import GravityMeasurement
from quadloc.service.localization.confidence import TOLERANCE_ROTATION_DEG
from quadloc.service.localization.types import Gravity

__all__ = ["GRAVITY_GATE_SIGMAS", "answer_gate_deg", "gravity_measurement", "tilt_errors_deg"]

#: Sensor sigmas of the gate (per tilt axis).
GRAVITY_GATE_SIGMAS = 3.0


def tilt_errors_deg(camera_from_world: FloatArray, up_world: FloatArray,
                    gravity: Gravity) -> FloatArray:
    """Angles (degrees, shape ``(...)``) between the camera's up predicted by poses
    ``camera_from_world`` (..., 4, 4) (or rotations (..., 3, 3)) from the map's ``up_world``
    (3,) and the measured up ``-gravity.direction_camera``."""
    R = np.asarray(camera_from_world, dtype=float)[..., :3, :3]
    up = np.asarray(up_world, dtype=float)
    predicted = R @ (up / np.linalg.norm(up))
    cos = -(predicted @ gravity.direction_camera)
    angles: FloatArray = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return angles


def answer_gate_deg(gravity: Gravity) -> float:
    """Largest tilt error (degrees) of a localized answer (module docstring)."""
    return TOLERANCE_ROTATION_DEG + GRAVITY_GATE_SIGMAS * gravity.sigma_deg


def gravity_measurement(gravity: Gravity, up_world: FloatArray) -> GravityMeasurement:
    """The client's gravity as the refinement's factor input: its down in the camera, the
    map's down (minus ``up_world``, (3,), any length) and its sigma in radians."""
    return GravityMeasurement(gravity.direction_camera, -np.asarray(up_world, dtype=float),
                              math.radians(gravity.sigma_deg))
