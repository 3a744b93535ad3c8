"""Names shared by the math layer and everything above it; dependency-free (stdlib only).

Importing this module loads neither numpy nor gtsam, so the service's settings and wire schemas
can publish the valid names without loading the solver (``service.limits`` re-exports them).
"""

from __future__ import annotations

__all__ = ["METRIC_NAMES", "ROBUST_KERNELS"]

#: The nine ellipse metrics (``factors.metrics.residual``, ``factors.pose_factors``).
METRIC_NAMES: tuple[str, ...] = (
    "iou", "giou", "bbox", "qbbox", "algebraic", "frobenius", "wasserstein", "bhattacharyya",
    "level_set",
)

#: Robust kernels accepted by name (``factors.pose_factors.make_noise_model``).
ROBUST_KERNELS: tuple[str, ...] = ("huber", "cauchy", "geman_mcclure")
