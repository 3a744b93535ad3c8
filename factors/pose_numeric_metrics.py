"""A metric's residuals of all pairs as functions of the camera pose with central-difference
Jacobians: the metrics without an analytic pose Jacobian (``qbbox``: piecewise, clipped at the
image border).

Residuals by ``quadloc.factors.metrics.residual`` on the projected ellipses, one pair at a time;
Jacobian column ``k`` by central differences along tangent ``k`` of the pose (right
perturbation, :mod:`quadloc.factors.pose_frame`), one-sided where a side is invalid.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from quadloc.factors import metrics
from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.conics import (
    DegenerateProjectionError,
    Ellipse,
    ellipse_params_and_validity,
    gaussians_from_dual_conics,
)
from quadloc.factors.names import GeometryError
from quadloc.factors.pose_frame import EllipsoidArrays, PairRows, ProjectionConics

__all__ = ["CentralDifferenceResiduals"]


class CentralDifferenceResiduals:
    """Residuals of ``metric`` for N pairs (:class:`PoseResidualFamily
    <quadloc.factors.pose_frame.PoseResidualFamily>`) with ``options`` the metric's.

    Jacobian column ``k`` is ``(r(T Exp(h e_k)) - r(T Exp(-h e_k))) / (2 h)`` with ``h`` the
    ``step`` (rad or m) and ``exp`` the SE(3) exponential of a tangent ``[omega, v]`` (6,) as a
    4x4 matrix (:func:`quadloc.factors.pose_residuals.expmap_pose3`)."""

    def __init__(self, metric: str, detections: Sequence[Ellipse], ellipsoids: EllipsoidArrays,
                 camera: Camera, options: Mapping[str, object], min_depth_margin: float,
                 step: float, exp: Callable[[FloatArray], FloatArray]) -> None:
        self._metric = metric
        self._detections = tuple(detections)
        self._ellipsoids = ellipsoids
        self._options = dict(options)
        self._min_depth_margin = min_depth_margin
        self._K = ProjectionConics(camera).K
        self._step = step
        # the 6 pairs (Exp(h e_k), Exp(-h e_k)), fixed for the model's life
        self._tangent_steps: list[tuple[FloatArray, FloatArray]] = []
        for k in range(6):
            e = np.zeros(6)
            e[k] = step
            self._tangent_steps.append((exp(e), exp(-e)))
        #: residual components per pair
        self.dim = int(metrics.residual_size(metric, **options))

    def _projections(self, world_from_camera: FloatArray) -> list[Ellipse | None]:
        """Projected ellipses at a pose (None where the projection is not an ellipse)."""
        frame = self._ellipsoids.camera_frame(world_from_camera)
        A = frame.A
        C = self._K @ A @ self._K.T
        with np.errstate(divide="ignore", invalid="ignore"):  # invalid rows: not used
            params, ellipse = ellipse_params_and_validity(
                *gaussians_from_dual_conics(C / -C[:, 2:, 2:]))
        ok = (frame.depth_margins > self._min_depth_margin) & ellipse
        return [Ellipse(*params[j]) if ok[j] else None for j in range(len(ok))]

    def _metric_rows(self, world_from_camera: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Residual rows (N, dim) via quadloc.factors.metrics.residual, and validity (N,)."""
        projs = self._projections(world_from_camera)
        n = len(projs)
        r = np.empty((n, self.dim))
        valid = np.zeros(n, dtype=bool)
        for j, p in enumerate(projs):
            if p is None:
                continue
            try:
                rj = np.asarray(metrics.residual(self._metric, self._detections[j], p,
                                                 **self._options), dtype=float)
            except (DegenerateProjectionError, GeometryError):
                continue
            if rj.shape != (self.dim,) or not np.all(np.isfinite(rj)):
                continue
            r[j] = rj
            valid[j] = True
        return r, valid

    def rows(self, world_from_camera: FloatArray, jacobian: bool) -> PairRows:
        """All pairs at ``world_from_camera`` (4x4); with ``jacobian``, 12 more evaluations."""
        T = world_from_camera
        frame = self._ellipsoids.camera_frame(T)
        r, valid = self._metric_rows(T)
        J = None
        if jacobian:
            h = self._step
            J = np.zeros((len(valid), self.dim, 6))
            for k, (forward, backward) in enumerate(self._tangent_steps):
                rp, vp = self._metric_rows(T @ forward)
                rm, vm = self._metric_rows(T @ backward)
                both = vp & vm
                J[both, :, k] = (rp[both] - rm[both]) / (2 * h)
                only_p = vp & ~vm & valid
                J[only_p, :, k] = (rp[only_p] - r[only_p]) / h
                only_m = vm & ~vp & valid
                J[only_m, :, k] = (r[only_m] - rm[only_m]) / h
        return PairRows(r, J, valid, frame.depth_margins, frame)
