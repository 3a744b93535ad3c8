"""The smooth conic metrics' residuals of all pairs as functions of the camera pose, with
analytic Jacobians: ``algebraic``, ``frobenius``, ``wasserstein``, ``bhattacharyya``, ``bbox``.

Each is a smooth function of the projection's normalised dual conic ``Cn = C* / (-C*[2,2])``:
:func:`quadloc.factors.metrics.conic_residuals` (batched over pairs, the one implementation of
these metrics), differentiated through ``dC* = K dA K^T``, ``dCn = (dC* + Cn dC*[2,2]) /
(-C*[2,2])`` (:class:`quadloc.factors.pose_frame.ProjectionConics`). Residuals (N, 4 or 5) in
the metric's units, Jacobians (N, dim, 6) w.r.t. the pose tangent of
:mod:`quadloc.factors.pose_frame`.

``bbox`` on this path is one compiled kernel (:func:`_bbox_kernel`, the same operations in the
same order as ``quadloc.factors.metrics``' centre, ``Sigma`` and box rows, tested equal): its
numpy form cost ~7 small-array operations per evaluation, most of a refinement's time (issue 33).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from quadloc.factors import metrics
from quadloc.factors.arrays import FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.jit import jit
from quadloc.factors.pose_frame import EllipsoidArrays, PairRows, ProjectionConics

__all__ = ["ConicMetricResiduals"]


@jit
def _bbox_kernel(box_d: FloatArray, Cn: FloatArray, dCn: FloatArray) -> FloatArray:
    """The bbox rows of :func:`quadloc.factors.metrics.conic_residuals` from the detections' boxes
    ``box_d`` (N, 4) px and the projections' normalised dual conics ``Cn`` (N, 3, 3) with their
    derivatives ``dCn`` (N, K, 3, 3) (K = 0: no Jacobian): ``mu = -Cn[:2, 2]``, ``h_i =
    sqrt(Cn[i, i] + mu_i mu_i)``, ``r = box_d - [mu - h, mu + h]``; ``dmu = -dCn[:2, 2]``,
    ``dh_i = (dCn[i, i] + dmu_i mu_i + mu_i dmu_i) / (2 h_i)``, ``dr = [dh - dmu, -dmu - dh]``.
    One flat array: ``r`` (N, 4) then ``dr`` (N, 4, K)."""
    n, k = Cn.shape[0], dCn.shape[1]
    out = np.empty(4 * n + 4 * n * k)
    r = out[:4 * n].reshape((n, 4))
    J = out[4 * n:].reshape((n, 4, k))
    for j in range(n):
        m0, m1 = -Cn[j, 0, 2], -Cn[j, 1, 2]
        h0 = np.sqrt(Cn[j, 0, 0] + m0 * m0)
        h1 = np.sqrt(Cn[j, 1, 1] + m1 * m1)
        r[j, 0] = box_d[j, 0] - (m0 - h0)
        r[j, 1] = box_d[j, 1] - (m1 - h1)
        r[j, 2] = box_d[j, 2] - (m0 + h0)
        r[j, 3] = box_d[j, 3] - (m1 + h1)
        for c in range(k):
            d0, d1 = -dCn[j, c, 0, 2], -dCn[j, c, 1, 2]
            e0 = (dCn[j, c, 0, 0] + d0 * m0 + m0 * d0) / (2.0 * h0)
            e1 = (dCn[j, c, 1, 1] + d1 * m1 + m1 * d1) / (2.0 * h1)
            J[j, 0, c] = e0 - d0
            J[j, 1, c] = e1 - d1
            J[j, 2, c] = -d0 - e0
            J[j, 3, c] = -d1 - e1
    return out


#: ``dCn`` with no direction (K = 0): :func:`_bbox_kernel` without Jacobian (writable, the
#: same array type as a ``dCn``: no second compilation)
_NO_DERIVATIVE = np.empty((0, 0, 3, 3))


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
        if self._metric == "bbox":
            n = len(Cn)
            out = _bbox_kernel(self._detection_terms[0], Cn,
                               _NO_DERIVATIVE if dCn is None else dCn)
            return PairRows(out[:4 * n].reshape(n, 4),
                            None if dCn is None else out[4 * n:].reshape(n, 4, 6), valid,
                            frame.depth_margins, frame)
        r, J = metrics.conic_residuals(self._metric, self._detection_params, Cn, dCn,
                                       detection_terms=self._detection_terms)
        return PairRows(r, None if J is None else np.ascontiguousarray(J), valid,
                        frame.depth_margins, frame)
