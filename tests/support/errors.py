"""Pose errors of the tests and benchmarks: position / rotation error of an estimate against
the truth (both ``world_from_camera``, 4x4, OpenCV camera axes), the error as a GTSAM tangent
vector in the frame of the reported covariance, and the NEES."""

from __future__ import annotations

import math

import gtsam
import numpy as np

from quadloc.factors.rotations import rotation_angle

__all__ = ["nees", "pose_error_tangent", "pose_errors"]


def pose_error_tangent(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``Logmap(estimate^-1 truth)``: GTSAM Pose3 tangent ``[omega, v]`` of the truth in the
    estimate's body frame (right perturbation), the frame of the reported covariance."""
    e, t = gtsam.Pose3(estimate), gtsam.Pose3(truth)
    return np.asarray(gtsam.Pose3.Logmap(e.between(t)))


def nees(estimate: np.ndarray, truth: np.ndarray, covariance: np.ndarray) -> float:
    """Normalised estimation error squared ``xi^T Cov^-1 xi`` of :func:`pose_error_tangent`
    (``covariance``: 6x6, ``[omega, v]``, the estimate's body frame)."""
    xi = pose_error_tangent(estimate, truth)
    return float(xi @ np.linalg.solve(covariance, xi))


def pose_errors(estimate: np.ndarray | None, truth: np.ndarray) -> tuple[float, float]:
    """(camera position error m, rotation error deg) of two ``world_from_camera`` poses (4x4);
    (inf, inf) when there is no estimate. The rotation error is
    :func:`quadloc.factors.rotations.rotation_angle`."""
    if estimate is None:
        return math.inf, math.inf
    pos = float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))
    return pos, math.degrees(float(rotation_angle(estimate[:3, :3], truth[:3, :3])))
