"""Names and limits of the service, in ONE dependency-free module (stdlib only).

``quadloc.service.settings`` (bounds of its fields), the wire schemas
(``quadloc.service.schemas``) and the in-process API (``quadloc.service.localization.types``)
all import these, so reading the settings loads neither gtsam, numpy nor OpenCV
(``tests/test_layers.py`` checks it).
"""

from __future__ import annotations

from quadloc.factors.names import METRIC_NAMES, ROBUST_KERNELS

__all__ = [
    "AMBIGUITY_POLICIES",
    "COVARIANCE_ORDER",
    "GRAVITY_DEFAULT_SIGMA_DEG",
    "GRAVITY_MAX_SIGMA_DEG",
    "MAX_BATCH_FRAMES",
    "MAX_DETECTIONS",
    "MAX_PIXELS",
    "METRICS",
    "NO_REFINEMENT",
    "POSE_SOURCES",
    "REASONS",
    "ROBUST_KERNELS",
    "UNKNOWN_LABEL_POLICIES",
]

#: Static upper bounds published in the schema; the server's settings may be lower.
MAX_DETECTIONS = 256
MAX_BATCH_FRAMES = 64
#: Largest |coordinate| in pixels accepted anywhere (keeps the solver's numbers sane).
MAX_PIXELS = 1e6
#: Order of the 6x6 pose covariances (GTSAM Pose3 tangent).
COVARIANCE_ORDER: tuple[str, ...] = ("omega_x", "omega_y", "omega_z", "v_x", "v_y", "v_z")

#: The nine refinement metrics (``quadloc.factors.names.METRIC_NAMES``).
METRICS: tuple[str, ...] = METRIC_NAMES
#: ``LocalizationOptions.metric`` value that skips refinement (the RANSAC/P3P/P2E pose is
#: returned as is; useful for evaluation).
NO_REFINEMENT = "none"
#: ``LocalizationOptions.unknown_label_policy`` values.
UNKNOWN_LABEL_POLICIES: tuple[str, ...] = ("ignore", "error")
#: ``LocalizationOptions.on_ambiguity`` values.
AMBIGUITY_POLICIES: tuple[str, ...] = ("not_localized", "best")
#: ``LocalizationResult.pose_source`` values: the refined client prior or the RANSAC search.
POSE_SOURCES: tuple[str, ...] = ("prior", "ransac")
#: Largest accepted gravity ``sigma_deg`` (a coarser direction does not separate poses).
GRAVITY_MAX_SIGMA_DEG = 30.0
#: Default gravity ``sigma_deg``: an AR framework's gravity (IMU, filtered) is better than ~1 deg.
GRAVITY_DEFAULT_SIGMA_DEG = 2.0
#: Every ``LocalizationResult.reason`` when ``localized`` is false.
REASONS: tuple[str, ...] = (
    "too_few_detections",
    "no_label_match",
    "no_hypothesis_above_inlier_threshold",
    "refinement_diverged",
    "ambiguous",
    "low_confidence",
    "time_budget_exceeded",
    "gravity_mismatch",
)
