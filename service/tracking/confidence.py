"""The ONE place where a tracking frame's ``confidence`` is computed: P(within 10 cm and 5 deg of
the truth) = P(the committed place is the right one) x P(within tolerance | that place), the
first the place posterior (:mod:`quadloc.service.tracking.places`), the second under the
pose's Gaussian posterior (the answered 6x6 ``[omega, v]`` covariance, body frame: the
smoother's marginal plus the systematic odometry drift,
:meth:`quadloc.service.tracking.session.DriftModel.systematic_covariance`; scaled by
:data:`COVARIANCE_SCALE`), with
:func:`quadloc.service.localization.confidence.gaussian_tolerance_probability`; 0 unless
``tracking`` and on a ``detections_unexplained`` frame. Rationale:
docs/design/service.md#tracking-confidence.
"""

from __future__ import annotations

import math

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.service.localization.confidence import (
    TOLERANCE_POSITION_M,
    TOLERANCE_ROTATION_DEG,
    gaussian_tolerance_probability,
)

__all__ = ["COVARIANCE_SCALE", "TOLERANCE_POSITION_M", "TOLERANCE_ROTATION_DEG",
           "session_confidence"]

#: Multiplies the posterior's standard deviations (1: the smoother's marginal as it is; the
#: benchmark's tracking frames were all within tolerance, so no evidence to change it).
COVARIANCE_SCALE = 1.0


def session_confidence(state: str, covariance: FloatArray | None,
                       contradicted: bool = False, place_probability: float = 1.0) -> float:
    """P(position error <= 10 cm and rotation error <= 5 deg) in [0, 1] (module docstring).

    Args:
        state: the session state of the frame (``"tracking"`` gives a non-zero value).
        covariance: 6x6 covariance ``[omega (rad), v (m)]``, body frame, or None (-> 0).
        contradicted: the frame's detections are all unexplained at the pose (-> 0).
        place_probability: posterior of the session's committed place, in [0, 1].
    """
    if state != "tracking" or covariance is None or contradicted:
        return 0.0
    p = gaussian_tolerance_probability(np.asarray(covariance, float) * COVARIANCE_SCALE ** 2)
    p *= min(1.0, max(0.0, place_probability))
    return float(min(1.0, max(0.0, p))) if math.isfinite(p) else 0.0
