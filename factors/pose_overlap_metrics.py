"""The overlap metrics' residuals of all pairs as functions of the camera pose, with analytic
Jacobians: ``iou``, ``giou``.

:func:`quadloc.factors.metrics.overlap_residual` of all pairs in one call (exact areas of
:mod:`quadloc.factors.overlap` and their exact gradients w.r.t. the projection's ``(mu,
Sigma)``), chained through ``dCn`` (:class:`quadloc.factors.pose_frame.ProjectionConics`), with
``disjoint_hull`` (disjoint pairs get the giou rows). Residuals (N, 4) dimensionless,
Jacobians (N, 4, 6) w.r.t. the pose tangent of :mod:`quadloc.factors.pose_frame`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from quadloc.factors import metrics
from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.conics import (
    ellipse_params_and_validity,
    gaussian_derivatives_from_dual_conics,
    gaussians_from_dual_conics,
)
from quadloc.factors.pose_frame import EllipsoidArrays, PairRows, ProjectionConics

__all__ = ["OverlapResiduals"]


def _dg_dxi(mu: FloatArray, dCn: FloatArray) -> FloatArray:
    """``d g / d xi`` (n, 5, 6) of the projections' ``g = (mu_x, mu_y, s00, s01, s11)``
    along the 6 pose tangents, from ``mu`` (n, 2) and ``dCn`` (n, 6, 3, 3)."""
    dmu, dsig = gaussian_derivatives_from_dual_conics(mu, dCn)
    dg = np.concatenate([dmu, dsig[..., 0, 0, None], dsig[..., 0, 1, None],
                         dsig[..., 1, 1, None]], axis=-1)  # (n, 6, 5)
    return dg.transpose(0, 2, 1)


class OverlapResiduals:
    """iou / giou residuals of N pairs (:class:`PoseResidualFamily
    <quadloc.factors.pose_frame.PoseResidualFamily>`); ``detection_params`` (N, 5) px / rad,
    ``options`` the metric's (``hull_directions``: accepted, unused by the exact areas)."""

    def __init__(self, metric: str, detection_params: FloatArray, ellipsoids: EllipsoidArrays,
                 camera: Camera, options: Mapping[str, object], min_depth_margin: float) -> None:
        self._metric = metric
        self._detection_params = detection_params
        self._ellipsoids = ellipsoids
        self._min_depth_margin = min_depth_margin
        self._conics = ProjectionConics(camera)
        #: residual components per pair
        self.dim = int(metrics.residual_size(metric, **options))

    def rows(self, world_from_camera: FloatArray, jacobian: bool) -> PairRows:
        """All pairs at ``world_from_camera`` (4x4). A projection whose Sigma is not positive
        definite is invalid too (its rows stay 0, for the penalty)."""
        frame = self._ellipsoids.camera_frame(world_from_camera)
        valid = frame.depth_margins > self._min_depth_margin
        Cn, dCn = self._conics.normalised(frame, valid, jacobian)
        r, J = self._overlap_rows(Cn, dCn, valid)
        return PairRows(r, J, valid, frame.depth_margins, frame)

    def _overlap_rows(self, Cn: FloatArray, dCn: FloatArray | None, valid: BoolArray
                      ) -> tuple[FloatArray, FloatArray | None]:
        """iou / giou rows (N, 4) of :func:`quadloc.factors.metrics.overlap_residual` (all pairs in
        one call, ``disjoint_hull``) and their pose Jacobian: the exact area gradients w.r.t. the
        projection's ``g = (mu_x, mu_y, s00, s01, s11)`` chained through ``dg / dxi``. A
        projection whose Sigma is not positive definite is invalid: ``valid`` is updated in
        place."""
        mu, sigma = gaussians_from_dual_conics(Cn)
        params, ellipse = ellipse_params_and_validity(mu, sigma)
        valid &= ellipse
        if valid.all():  # the usual case: no scatter into zero-filled rows
            r, grad = metrics.overlap_residual(self._metric, self._detection_params, params,
                                               gradient=dCn is not None, disjoint_hull=True)
            return r, None if dCn is None or grad is None else grad @ _dg_dxi(mu, dCn)
        n = len(valid)
        r = np.zeros((n, self.dim))
        J = None if dCn is None else np.zeros((n, self.dim, 6))
        idx = np.flatnonzero(valid)
        if idx.size:
            rows, grad = metrics.overlap_residual(
                self._metric, self._detection_params[idx], params[idx],
                gradient=J is not None, disjoint_hull=True)
            r[idx] = rows
            if J is not None and dCn is not None and grad is not None:
                J[idx] = grad @ _dg_dxi(mu[idx], dCn[idx])
        return r, J
