"""The smooth conic metrics' residuals of all pairs as functions of the camera pose, with
analytic Jacobians: ``algebraic``, ``frobenius``, ``wasserstein``, ``bhattacharyya``, ``bbox``.

Each is a smooth function of the projection's normalised dual conic ``Cn = C* / (-C*[2,2])``:
:func:`quadloc.factors.metrics.conic_residuals` (batched over pairs, the one implementation of
these metrics), differentiated through ``dC* = K dA K^T``, ``dCn = (dC* + Cn dC*[2,2]) /
(-C*[2,2])`` (:class:`quadloc.factors.pose_frame.ProjectionConics`). Residuals (N, 4 or 5) in
the metric's units, Jacobians (N, dim, 6) w.r.t. the pose tangent of
:mod:`quadloc.factors.pose_frame`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from quadloc.factors import metrics
from quadloc.factors.arrays import FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.pose_frame import EllipsoidArrays, PairRows, ProjectionConics

__all__ = ["ConicMetricResiduals"]


class ConicMetricResiduals:
    """Residuals of the smooth metric ``metric`` (one of
    ``quadloc.factors.metrics.CONIC_METRICS``) of N pairs (:class:`PoseResidualFamily
    <quadloc.factors.pose_frame.PoseResidualFamily>`); ``detection_params`` (N, 5) px / rad."""

    def __init__(self, metric: str, detection_params: FloatArray, ellipsoids: EllipsoidArrays,
                 camera: Camera, options: Mapping[str, object], min_depth_margin: float) -> None:
        self._metric = metric
        self._detection_params = detection_params
        self._ellipsoids = ellipsoids
        self._min_depth_margin = min_depth_margin
        self._conics = ProjectionConics(camera)
        #: what the metric needs of the (fixed) detections, computed once
        self._detection_terms = metrics.conic_detection_terms(metric, detection_params)
        #: residual components per pair
        self.dim = int(metrics.residual_size(metric, **options))

    def rows(self, world_from_camera: FloatArray, jacobian: bool) -> PairRows:
        """All pairs at ``world_from_camera`` (4x4): the metric of the projections' ``Cn``,
        chained through ``dCn`` if ``jacobian``."""
        frame = self._ellipsoids.camera_frame(world_from_camera)
        valid = frame.depth_margins > self._min_depth_margin
        Cn, dCn = self._conics.normalised(frame, valid, jacobian)
        r, J = metrics.conic_residuals(self._metric, self._detection_params, Cn, dCn,
                                       detection_terms=self._detection_terms)
        return PairRows(r, None if J is None else np.ascontiguousarray(J), valid,
                        frame.depth_margins, frame)
