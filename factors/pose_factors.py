"""The nine ellipse metrics as GTSAM factors on the camera pose.

Every factor is a ``gtsam.CustomFactor`` on ONE ``Pose3`` key holding the camera's
``world_from_camera`` pose (OpenCV camera axes), for ONE detection/ellipsoid pair. Its
unwhitened error is the metric residual ``r_j`` (``quadloc.factors.metrics.residual``: cost
``Delta_j = ||r_j||^2``) between the detected ellipse and the projection ``C* = P Q*_j P^T``.
Jacobians are w.r.t. GTSAM's tangent ``xi = [omega, v]`` with right perturbation
(``pose.retract(xi) = pose.compose(Pose3.Expmap(xi))``).

Noise: isotropic std ``s_j = sqrt(sigma_j)`` (``sigma_j`` the detector's predicted
uncertainty; unit without it), so GTSAM minimises ``0.5 sum_j sigma_j^-1 Delta_j``, the argmin of
the paper's equation 8. An optional robust kernel (:data:`ROBUST_KERNELS`) wraps it per
detection (``gtsam.noiseModel.Robust``), threshold ``k`` on the WHITENED residual norm
``sqrt(Delta_j / sigma_j)``, defaults in :data:`DEFAULT_ROBUST_SCALE`.

All the factors of one solve share ONE memoised
:class:`quadloc.factors.pose_residuals.PoseResidualModel` (every pair evaluated at once per pose,
the factors slice their rows). :func:`pose_factors` returns one factor per pair (default; needed for
per-detection robust kernels), or with ``batched=True`` ONE factor over all pairs with a
Diagonal noise model (the same weighted error, one Python round trip). Jacobians:
:mod:`quadloc.factors.pose_residuals` and its metric families; invalid projections (a bounded
penalty) and the saturation: :mod:`quadloc.factors.pose_penalty`. Why and measurements:
``docs/design/factors.md`` ("Pose factors").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Unpack

import gtsam
import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.names import ROBUST_KERNELS, check_robust, is_real
from quadloc.factors.pose_residuals import ModelOptions, PoseResidualModel
from quadloc.factors.rotations import snap_to_rotation

__all__ = [
    "DEFAULT_ROBUST_SCALE",
    "ROBUST_KERNELS",
    "batched_pose_factor",
    "make_noise_model",
    "pose3",
    "pose_factor",
    "pose_factors",
    "shared_pose_factor",
]


def pose3(T: FloatArray) -> gtsam.Pose3:
    """A 4x4 rigid transform (any direction: ``world_from_camera``, ``odom_from_camera``...) as
    a ``gtsam.Pose3`` of the same direction; the rotation block is snapped to the nearest
    rotation (:func:`quadloc.factors.rotations.snap_to_rotation`: unchanged when already
    orthonormal)."""
    return gtsam.Pose3(gtsam.Rot3(snap_to_rotation(T[:3, :3])), np.ascontiguousarray(T[:3, 3]))


#: Default robust threshold ``k`` per metric, on the whitened residual norm
#: ``sqrt(Delta_j / sigma_j)`` (units: those of the metric's residual); about twice to three
#: times the inliers' 90th percentile (calibration: ``docs/design/factors.md``).
DEFAULT_ROBUST_SCALE: dict[str, float] = {
    "level_set": 2.0,
    "iou": 0.6,
    "giou": 0.6,
    "bbox": 10.0,
    "qbbox": 10.0,
    "wasserstein": 8.0,
    "bhattacharyya": 0.1,
    "algebraic": 4000.0,
    "frobenius": 5000.0,
}


def _std(sigma: float | None, name: str = "sigma") -> float:
    """The noise std ``sqrt(sigma)`` (1 for None); ``sigma`` must be finite and > 0."""
    if sigma is None:
        return 1.0
    if not (is_real(sigma) and math.isfinite(sigma) and sigma > 0):
        raise ValueError(f"{name} must be finite and > 0, got {sigma!r}")
    return math.sqrt(float(sigma))


def _check_sigmas(sigmas: Sequence[float | None], n: int) -> FloatArray:
    """The stds (n,) of ``sigmas`` (one per detection)."""
    if len(sigmas) != n:
        raise ValueError(f"sigmas must have one entry per detection ({n}), got {len(sigmas)}")
    return np.array([_std(s, f"sigmas[{j}]") for j, s in enumerate(sigmas)])


def make_noise_model(
    dim: int,
    sigma: float | None = None,
    robust: str | None = None,
    robust_scale: float | None = None,
    metric: str = "level_set",
) -> gtsam.noiseModel.Base:
    """Noise model of one pair's factor: isotropic std ``sqrt(sigma)`` (unit if ``sigma`` None).

    ``robust`` in :data:`ROBUST_KERNELS` (or None) wraps it in ``gtsam.noiseModel.Robust`` with
    threshold ``robust_scale`` (default ``DEFAULT_ROBUST_SCALE[metric]``).
    """
    std = _std(sigma)
    check_robust(robust, robust_scale)
    base = gtsam.noiseModel.Isotropic.Sigma(int(dim), std)
    if robust is None:
        return base
    k = DEFAULT_ROBUST_SCALE.get(metric, 1.0) if robust_scale is None else robust_scale
    create: dict[str, Callable[[float], gtsam.noiseModel.mEstimator.Base]] = {
        "huber": gtsam.noiseModel.mEstimator.Huber.Create,
        "cauchy": gtsam.noiseModel.mEstimator.Cauchy.Create,
        "geman_mcclure": gtsam.noiseModel.mEstimator.GemanMcClure.Create,
    }
    est = create[robust](float(k))
    return gtsam.noiseModel.Robust.Create(est, base)


def shared_pose_factor(
    key: int, model: PoseResidualModel, index: int, noise_model: gtsam.noiseModel.Base
) -> gtsam.CustomFactor:
    """Factor for pair ``index`` of ``model`` (whose evaluation is shared and memoised)."""
    if not 0 <= index < model.n:
        raise IndexError(f"index {index} out of range for a model of {model.n} pairs")
    if noise_model.dim() != model.dim:
        raise ValueError(f"noise_model dim {noise_model.dim()} != residual dim {model.dim}")
    return _model_factor(key, model, noise_model, lambda a: a[index])


def pose_factors(
    metric: str,
    key: int,
    detections: Sequence[Ellipse],
    ellipsoids: Sequence[Ellipsoid],
    camera: Camera,
    *,
    sigmas: Sequence[float | None] | None = None,
    robust: str | None = None,
    robust_scale: float | None = None,
    initial_world_from_camera: FloatArray | None = None,
    metric_options: Mapping[str, object] | None = None,
    batched: bool = False,
    **model_options: Unpack[ModelOptions],
) -> tuple[list[gtsam.CustomFactor], PoseResidualModel]:
    """Factors for N detection/ellipsoid pairs, all sharing one memoised evaluation.

    ``sigmas[j]`` (or None) sets pair ``j``'s noise (std ``sqrt(sigma_j)``). By default one
    factor per pair, in the pairs' order (each with its own robust kernel if ``robust``). With
    ``batched=True`` (only without a robust kernel) a single factor with a Diagonal noise model
    holding every pair's std: the same weighted error, one GTSAM callback instead of N.
    Returns the factors and the shared :class:`PoseResidualModel` (e.g. for per-pair costs).
    ``model_options`` go to :class:`PoseResidualModel` (``min_depth_margin``, ``penalty_cost``,
    ``numeric_step``, ``eager_jacobian``).
    """
    model = PoseResidualModel(metric, detections, ellipsoids, camera,
                              initial_world_from_camera=initial_world_from_camera,
                              metric_options=metric_options, **model_options)
    if sigmas is None:
        sigmas = [None] * model.n
    stds = _check_sigmas(sigmas, model.n)
    check_robust(robust, robust_scale)
    if batched:
        if robust is not None:
            raise ValueError("batched=True cannot carry per-detection robust kernels; "
                             "use batched=False with robust")
        return [_batched_factor(key, model, stds)], model
    factors = [
        shared_pose_factor(key, model, j,
                           make_noise_model(model.dim, s, robust, robust_scale, metric))
        for j, s in enumerate(sigmas)
    ]
    return factors, model


def pose_factor(
    metric: str,
    key: int,
    detection: Ellipse,
    ellipsoid: Ellipsoid,
    camera: Camera,
    *,
    sigma: float | None = None,
    robust: str | None = None,
    robust_scale: float | None = None,
    initial_world_from_camera: FloatArray | None = None,
    metric_options: Mapping[str, object] | None = None,
    **model_options: Unpack[ModelOptions],
) -> gtsam.CustomFactor:
    """A ``gtsam.CustomFactor`` on the ``world_from_camera`` Pose3 ``key`` for one pair.

    Residual: ``metric``'s residual between ``detection`` and the projection of ``ellipsoid``;
    noise std ``sqrt(sigma)`` (unit if None), optional robust kernel. For several pairs of one
    solve prefer :func:`pose_factors` (shared evaluation, much faster).
    """
    factors, _ = pose_factors(metric, key, [detection], [ellipsoid], camera,
                              sigmas=[sigma], robust=robust, robust_scale=robust_scale,
                              initial_world_from_camera=initial_world_from_camera,
                              metric_options=metric_options, **model_options)
    return factors[0]


def batched_pose_factor(
    key: int, model: PoseResidualModel, sigmas: Sequence[float | None] | None = None
) -> gtsam.CustomFactor:
    """ONE factor over all pairs of ``model`` (Diagonal noise: pair ``j`` rows std
    ``sqrt(sigma_j)``, unit where ``sigmas[j]`` is None).

    The same weighted error as one factor per pair with one GTSAM callback instead of N:
    :func:`pose_factors` returns it for ``batched=True``, which the refinement uses whenever no
    robust kernel is asked for (a per-detection robust kernel is impossible in this form);
    ``bench.refine_speed`` measures both designs. ``sigmas`` are validated as in
    :func:`pose_factors` (one per pair, finite and > 0, or None)."""
    return _batched_factor(key, model,
                           np.ones(model.n) if sigmas is None else _check_sigmas(sigmas, model.n))


def _batched_factor(key: int, model: PoseResidualModel, stds: FloatArray) -> gtsam.CustomFactor:
    """:func:`batched_pose_factor` with the pairs' stds (N,) already validated (one check per
    refinement)."""
    n, m = model.n, model.dim
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.repeat(stds, m))
    return _model_factor(key, model, noise, lambda a: a.reshape(n * m, *a.shape[2:]))


def _model_factor(key: int, model: PoseResidualModel, noise: gtsam.noiseModel.Base,
                  rows: Callable[[FloatArray], FloatArray]) -> gtsam.CustomFactor:
    """A ``CustomFactor`` on ``key`` whose error and Jacobian are ``rows`` of the model's
    memoised (N, dim) factor residuals and (N, dim, 6) factor Jacobians."""
    evaluate = model.evaluate

    def error_fn(this: gtsam.CustomFactor, values: gtsam.Values,
                 H: gtsam.JacobianVector | None) -> FloatArray:
        T = values.atPose3(key).matrix()
        if H is None:
            return rows(evaluate(T, False).factor_residuals)
        ev = evaluate(T, True)
        assert ev.factor_jacobians is not None  # asked for
        H[0] = rows(ev.factor_jacobians)
        return rows(ev.factor_residuals)

    return gtsam.CustomFactor(noise, [key], error_fn)
