"""The ONE place where a tracking frame's ``confidence`` is computed.

Definition (the meaning ``localize``'s confidence has, :mod:`service.localization.confidence`):
the probability that the returned ``world_from_camera`` is within 10 cm
(``TOLERANCE_POSITION_M``) AND 5 degrees (``TOLERANCE_ROTATION_DEG``) of the truth. For a
session it is evaluated under the pose's Gaussian posterior: tangent error
``xi = [omega, v] ~ N(0, s^2 Sigma)`` (``Sigma`` the frame's 6x6 marginal covariance from the
smoother, GTSAM order, body frame; ``s`` = :data:`COVARIANCE_SCALE`), with
:func:`service.localization.confidence.gaussian_tolerance_probability` (the shared formula:
chi-square with 3 DoF of each block's isotropic equivalent). Unlike a single frame's, the
session's answer has no logistic evidence model: the window's odometry and many frames make the
posterior the evidence; ``bench.tracking`` reports mean confidence against the observed fraction
within tolerance (docs/results.md, section tracking).

It is 0 whenever the session is not ``tracking`` and on a tracking frame whose usable detections
are all unexplained by its pose (``reason="detections_unexplained"``): the posterior then no
longer describes the error.
"""

from __future__ import annotations

import math

import numpy as np

from service.localization.confidence import (
    TOLERANCE_POSITION_M,
    TOLERANCE_ROTATION_DEG,
    gaussian_tolerance_probability,
)

__all__ = ["COVARIANCE_SCALE", "TOLERANCE_POSITION_M", "TOLERANCE_ROTATION_DEG",
           "session_confidence"]

#: Multiplies the posterior's standard deviations (1: the smoother's marginal as it is; the
#: benchmark's tracking frames were all within tolerance, so no evidence to change it).
COVARIANCE_SCALE = 1.0


def session_confidence(state: str, covariance: np.ndarray | None,
                       contradicted: bool = False) -> float:
    """P(position error <= 10 cm and rotation error <= 5 deg) in [0, 1] (module docstring).

    Args:
        state: the session state of the frame (``"tracking"`` gives a non-zero value).
        covariance: 6x6 covariance ``[omega (rad), v (m)]``, body frame, or None (-> 0).
        contradicted: the frame's detections are all unexplained at the pose (-> 0).
    """
    if state != "tracking" or covariance is None or contradicted:
        return 0.0
    p = gaussian_tolerance_probability(np.asarray(covariance, float) * COVARIANCE_SCALE ** 2)
    return float(min(1.0, max(0.0, p))) if math.isfinite(p) else 0.0
