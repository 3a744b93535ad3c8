"""The ONE place where a tracking frame's ``confidence`` is computed.

Definition (the meaning issue 12 gives ``localize``'s confidence): the probability that the
returned ``world_from_camera`` is within :data:`POSITION_TOLERANCE_M` (10 cm) of the truth AND
within :data:`ROTATION_TOLERANCE_RAD` (5 degrees) of it. Here it is evaluated under the pose's
Gaussian posterior: tangent error ``xi = [omega, v] ~ N(0, s^2 * Sigma)`` (``Sigma`` the 6x6
marginal covariance of the frame's pose, GTSAM order, body frame; ``s`` =
:data:`COVARIANCE_SCALE`, a calibration factor fitted with ``bench.tracking`` on tuning seeds and
checked on held-out seeds), probability estimated from :data:`N_SAMPLES` fixed quasi-random
normal draws (deterministic). It is 0 whenever the session is not ``tracking`` and on a tracking
frame whose usable detections are all unexplained by the pose (``detections_unexplained``).

When ``service.localization.confidence`` (issue 12) lands, :func:`session_confidence` is the one
function to point at it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["COVARIANCE_SCALE", "N_SAMPLES", "POSITION_TOLERANCE_M", "ROTATION_TOLERANCE_RAD",
           "session_confidence"]

POSITION_TOLERANCE_M = 0.10
ROTATION_TOLERANCE_RAD = math.radians(5.0)
#: Multiplies the posterior's standard deviations (see ``docs/results.md``, section tracking).
COVARIANCE_SCALE = 1.0
N_SAMPLES = 512
_DRAWS = np.random.default_rng(20261123).standard_normal((N_SAMPLES, 6))
_DRAWS.setflags(write=False)


def session_confidence(state: str, covariance: np.ndarray | None,
                       contradicted: bool = False) -> float:
    """P(position error <= 10 cm and rotation error <= 5 deg) in [0, 1] (module docstring).

    Args:
        state: the session state of the frame (``"tracking"`` gives a non-zero value).
        covariance: 6x6 covariance ``[omega (rad), v (m)]``, body frame, or None (-> 0).
        contradicted: the frame's detections are all unexplained at the pose (-> 0: the
            Gaussian posterior no longer describes the error).
    """
    if state != "tracking" or covariance is None or contradicted:
        return 0.0
    S = 0.5 * (np.asarray(covariance, dtype=float) + np.asarray(covariance, dtype=float).T)
    try:
        L = np.linalg.cholesky(S * COVARIANCE_SCALE ** 2)
    except np.linalg.LinAlgError:
        return 0.0
    xi = _DRAWS @ L.T
    rot = np.linalg.norm(xi[:, :3], axis=1)
    pos = np.linalg.norm(xi[:, 3:], axis=1)
    return float(np.mean((rot <= ROTATION_TOLERANCE_RAD) & (pos <= POSITION_TOLERANCE_M)))
