"""The ONE place where a tracking frame's ``confidence`` is computed: P(within 10 cm and 5 deg of
the truth) = P(the committed place is the right one) x P(within tolerance | that place), the
first the place posterior (:mod:`quadloc.service.tracking.places`), the second under the
pose's Gaussian posterior (the answered 6x6 ``[omega, v]`` covariance, body frame: the
smoother's marginal plus the systematic odometry drift,
:meth:`quadloc.service.tracking.session.DriftModel.systematic_covariance`; scaled by
:data:`COVARIANCE_SCALE`), with
:func:`quadloc.service.localization.confidence.gaussian_tolerance_probability`; 0 unless
``tracking``. On a ``detections_unexplained`` frame (its usable detections all unexplained at
the pose): 0 when two or more are unexplained; one unexplained detection is weak evidence
against the pose (a spurious detection or a wrong label explains it as well), weighed by Bayes'
rule with :data:`LONE_UNEXPLAINED_LIKELIHOOD_RATIO`. Rationale:
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

__all__ = ["COVARIANCE_SCALE", "LONE_UNEXPLAINED_LIKELIHOOD_RATIO", "TOLERANCE_POSITION_M",
           "TOLERANCE_ROTATION_DEG", "session_confidence"]

#: Multiplies the posterior's standard deviations (1: the smoother's marginal as it is; the
#: benchmark's tracking frames were all within tolerance, so no evidence to change it).
COVARIANCE_SCALE = 1.0
#: P(one usable detection, unexplained | pose within tolerance) / P(the same | pose off): a
#: lone unexplained detection is ten times likelier when the pose is off (weak evidence: a
#: detector's false positive or wrong label leaves one unexplained at a right pose; the same
#: rule as the place scoring's, where a lone detection is no evidence for another place).
#: Not fitted: on building walks (tuning seeds 0-2, 10 and 50 rooms, perturbed and twins)
#: 97 % of such frames (91 of 6,586 tracking frames) were within tolerance, where 0 was
#: answered before.
LONE_UNEXPLAINED_LIKELIHOOD_RATIO = 0.1


def session_confidence(state: str, covariance: FloatArray | None,
                       unexplained: int = 0, place_probability: float = 1.0) -> float:
    """P(position error <= 10 cm and rotation error <= 5 deg) in [0, 1] (module docstring).

    Args:
        state: the session state of the frame (``"tracking"`` gives a non-zero value).
        covariance: 6x6 covariance ``[omega (rad), v (m)]``, body frame, or None (-> 0).
        unexplained: on a frame whose usable detections are all unexplained at the pose, how
            many there are (0: not such a frame; 1: weighed with
            :data:`LONE_UNEXPLAINED_LIKELIHOOD_RATIO`; 2 or more: -> 0).
        place_probability: posterior of the session's committed place, in [0, 1].
    """
    if state != "tracking" or covariance is None or unexplained >= 2:
        return 0.0
    p = gaussian_tolerance_probability(np.asarray(covariance, float) * COVARIANCE_SCALE ** 2)
    p *= min(1.0, max(0.0, place_probability))
    if not math.isfinite(p):
        return 0.0
    p = min(1.0, max(0.0, p))
    if unexplained == 1:
        lam = LONE_UNEXPLAINED_LIKELIHOOD_RATIO
        p = p * lam / (p * lam + (1.0 - p))
    return float(p)
