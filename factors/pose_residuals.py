"""Residuals and Jacobians of the ellipse metrics w.r.t. the camera pose, batched over objects.

Pure numpy (no GTSAM): for ONE camera pose and ALL detection/ellipsoid pairs of a refinement
at once, the metric residual of every pair and its Jacobian with respect to the pose;
:mod:`quadloc.factors.pose_factors` wraps it in GTSAM factors. Derivations and the reasons behind
the penalty's constants: ``docs/design/factors.md`` ("Pose residuals").

Conventions
-----------
* The pose is the camera's ``world_from_camera`` 4x4 matrix (OpenCV camera axes). Its tangent
  vector is GTSAM's Pose3 order ``xi = [omega (3, rad), v (3, m)]`` with RIGHT perturbation:
  ``world_from_camera(xi) = world_from_camera @ Exp(xi)`` (``Pose3.retract``). Jacobians are
  ``d r / d xi`` at ``xi = 0``, shape ``(m, 6)`` per pair.
* In the camera frame a world point moves as ``X_c(xi) = X_c - omega x X_c - v`` (first order).
* The projected dual conic is ``C* = K A K^T`` with ``A = S_c - c_c c_c^T`` (3x3), ``c_c`` the
  ellipsoid centre and ``S_c = R S R^T`` its shape matrix (``S = R_e diag(axes^2) R_e^T``), both in
  the camera frame (``C* = P Q* P^T`` exactly). Its first-order change is
  ``dA = -[w]x A - A [w]x^T + v c_c^T + c_c v^T``.

Metrics
-------
* ``level_set`` (analytic): ``r = Phi_det(x) - Phi_proj(x) = (Phi_det(x) - 1) + s n^T A^-1 n``
  at the detection's samples ``x`` (rays ``n = K^-1 (x, y, 1)``, ``s = A[2,2]``), fixed at the
  initial pose (the layout of ``quadloc.factors.metrics.level_set_sample_points``); residuals and
  Jacobians of all pairs by one compiled kernel (:func:`_level_set_kernel`).
* ``algebraic``, ``frobenius``, ``wasserstein``, ``bhattacharyya``, ``bbox`` (analytic):
  :func:`quadloc.factors.metrics.conic_residuals` of the normalised dual conic
  ``Cn = C* / (-C*[2,2])``, differentiated through ``dC* = K dA K^T``,
  ``dCn = (dC* + Cn dC*[2,2]) / (-C*[2,2])``.
* ``iou``, ``giou`` (analytic): :func:`quadloc.factors.metrics.overlap_residual` of all pairs in one
  call (exact area gradients w.r.t. the projection's ``(mu, Sigma)``, chained through ``dCn``),
  with ``disjoint_hull`` (disjoint pairs get the giou rows).
* ``qbbox``: ``quadloc.factors.metrics.residual`` and central differences on ``retract`` (step
  :data:`DEFAULT_NUMERIC_STEP`), one-sided where a side is invalid.

Evaluations are memoised on the pose value and their arrays are read-only (shared by the
factors that slice them).

Invalid projections (penalty) and saturation
--------------------------------------------
A projection is valid while the whole ellipsoid is in front of the camera: depth margin
``m = z_c - sqrt(S_c[2,2]) > min_depth_margin`` (m; as
:func:`quadloc.factors.camera.ellipsoid_depth_margins`). Otherwise the pair's ``dim`` residual
components all equal ``sqrt(P_j / dim) * (1 + d / (d + d_s))``, ``d = min_depth_margin - m``,
``d_s`` the ellipsoid's largest semi-axis (m): cost in ``[P_j, 4 P_j)``, Jacobian
``-sqrt(P_j/dim) d_s / (d + d_s)^2 dm/dxi`` (``dm/dw = e3 x c_c - (e3 x S_c e3) /
sqrt(S_c[2,2])``, ``dm/dv = -e3``).

``P_j = penalty_cost * rho_j^2`` (:attr:`PoseResidualModel.penalty_costs`), ``rho_j`` the
pair's reference residual magnitude: ``L_j`` px for bbox / qbbox / wasserstein / algebraic /
frobenius, ``max(1, s_max_j)^2`` for level_set (``s_max_j`` its sampling scale), 1 for iou /
giou / bhattacharyya; ``L_j = max(image diagonal, |c_D| + max(a_D, b_D))`` px.

The GTSAM factors see each VALID pair's residual saturated above half the penalty (``c =
||r||^2``, ``c_0 = P_j / 2``): ``h(c) = c`` for ``c <= c_0``, else ``c_0 + w (1 - exp(-(c -
c_0) / w))`` with ``w = 0.4 P_j`` (C^1, ``h < 0.9 P_j``), ``r_sat = r sqrt(h(c) / c)``; so every
valid cost is below every penalty. Reported residuals and costs
(:attr:`PoseEvaluation.residuals`, :meth:`PoseResidualModel.costs`) are the metric's own; the
factors use :attr:`PoseEvaluation.factor_residuals`. A robust kernel
(``quadloc.factors.pose_factors``) flattens the penalty too.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from quadloc.factors import metrics
from quadloc.factors.camera import Camera, Ellipsoid, depth_margin, projected_gaussians
from quadloc.factors.conics import (
    DegenerateProjectionError,
    Ellipse,
    ellipse_params_and_validity,
    gaussian_derivatives_from_dual_conics,
    gaussians_from_dual_conics,
)
from quadloc.factors.jit import jit
from quadloc.factors.metrics import METRIC_NAMES
from quadloc.factors.names import GeometryError
from quadloc.factors.overlap import HULL_DIRECTIONS
from quadloc.factors.rotations import check_pose, skew, so3_exp

__all__ = [
    "ANALYTIC_METRICS",
    "DEFAULT_MIN_DEPTH_MARGIN",
    "DEFAULT_NUMERIC_STEP",
    "DEFAULT_PENALTY_COST",
    "PoseEvaluation",
    "PoseResidualModel",
    "compile_kernels",
    "expmap_pose3",
]

#: Invalid-projection penalty cost per pair, in units of the pair's reference cost ``rho_j^2``
#: (see the module docstring); the penalty's cost lies in ``[1x, 4x) penalty_cost rho_j^2``.
DEFAULT_PENALTY_COST = 1e8
#: A projection counts as valid while the ellipsoid's smallest camera depth exceeds this (m).
DEFAULT_MIN_DEPTH_MARGIN = 1e-3
#: Central-difference step on each tangent coordinate (rad or m) for numerical Jacobians.
DEFAULT_NUMERIC_STEP: dict[str, float] = dict.fromkeys(METRIC_NAMES, 1e-6)
#: Metrics whose pose Jacobian is analytic (the others use central differences).
ANALYTIC_METRICS: tuple[str, ...] = (
    "level_set", "algebraic", "frobenius", "wasserstein", "bhattacharyya", "bbox", "iou",
    "giou")
#: Power of the reference length ``L_j`` (px) in the metric's residual: the penalty's
#: reference residual ``rho_j = L_j ** power`` (level_set: ``max(1, s_max_j)^2`` instead).
_PENALTY_PIXEL_POWER: dict[str, int] = {
    "iou": 0, "giou": 0, "bhattacharyya": 0, "level_set": 0, "bbox": 1, "qbbox": 1,
    "wasserstein": 1, "algebraic": 1, "frobenius": 1}
assert set(_PENALTY_PIXEL_POWER) == set(METRIC_NAMES)
# tangent generators: d(A)/d(omega_k) = G + G^T with G = -[e_k]x A; d(A)/d(v_k) = G + G^T with
# G = e_k c^T
_SKEW_BASIS = skew(np.eye(3)) + 0.0  # [e_k]x, k = 0, 1, 2


@jit
def _level_set_kernel(
    T: np.ndarray, centers: np.ndarray, S_world: np.ndarray, S_world_inv: np.ndarray,
    rays: np.ndarray, phi0: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Level-set residuals (N, M) and Jacobians (N, M, 6) of all pairs at ``T``
    (``world_from_camera`` 4x4), and per object its centre's depth ``z_c`` (N,) m and ``S_c[2,
    2]`` (N,) m^2 (for :func:`quadloc.factors.camera.depth_margin`; the rows of an invalid pair
    are garbage, replaced by the penalty). Docs: docs/design/factors.md, "Level-set residual".

    Per object, ``A^-1`` by Sherman-Morrison from the world frame, ``A_w = S_w - d d^T`` (``d``
    the centre seen from the camera, world axes): ``A_w^-1 = S_w^-1 + e e^T / (1 - d . e)``,
    ``e = S_w^-1 d``, ``A^-1 = R^T A_w^-1 R``; then per sample ray ``n`` (``rays`` (N, 3, M)),
    with ``u = A^-1 n``, ``g = n . u``, ``s = A[2, 2]``::

        r      = phi0 + s g                       (phi0 = Phi_det(x) - 1, (N, M))
        dr/dw  = 2 g (e3 x A e3) + 2 s (n x u)
        dr/dv  = 2 g z_c e3 - 2 (s A^-1 c_c . n) u
    """
    n_obj, m = phi0.shape
    r = np.empty((n_obj, m))
    J = np.empty((n_obj, m, 6))
    z_out = np.empty(n_obj)
    v_out = np.empty(n_obj)
    Ai_w = np.empty((3, 3))
    Ai = np.empty((3, 3))
    for j in range(n_obj):
        d0, d1, d2 = centers[j, 0] - T[0, 3], centers[j, 1] - T[1, 3], centers[j, 2] - T[2, 3]
        z = d0 * T[0, 2] + d1 * T[1, 2] + d2 * T[2, 2]
        # S_w R e3, and A e3 = R^T (S_w R e3 - d z) in camera axes
        w0 = S_world[j, 0, 0] * T[0, 2] + S_world[j, 0, 1] * T[1, 2] + S_world[j, 0, 2] * T[2, 2]
        w1 = S_world[j, 1, 0] * T[0, 2] + S_world[j, 1, 1] * T[1, 2] + S_world[j, 1, 2] * T[2, 2]
        w2 = S_world[j, 2, 0] * T[0, 2] + S_world[j, 2, 1] * T[1, 2] + S_world[j, 2, 2] * T[2, 2]
        z_out[j] = z
        v_out[j] = w0 * T[0, 2] + w1 * T[1, 2] + w2 * T[2, 2]
        w0, w1, w2 = w0 - d0 * z, w1 - d1 * z, w2 - d2 * z
        a0 = T[0, 0] * w0 + T[1, 0] * w1 + T[2, 0] * w2
        a1 = T[0, 1] * w0 + T[1, 1] * w1 + T[2, 1] * w2
        s = T[0, 2] * w0 + T[1, 2] * w1 + T[2, 2] * w2
        # e = S_w^-1 d, A_w^-1 = S_w^-1 + e e^T / den
        e0 = S_world_inv[j, 0, 0] * d0 + S_world_inv[j, 0, 1] * d1 + S_world_inv[j, 0, 2] * d2
        e1 = S_world_inv[j, 1, 0] * d0 + S_world_inv[j, 1, 1] * d1 + S_world_inv[j, 1, 2] * d2
        e2 = S_world_inv[j, 2, 0] * d0 + S_world_inv[j, 2, 1] * d1 + S_world_inv[j, 2, 2] * d2
        den = 1.0 - (d0 * e0 + d1 * e1 + d2 * e2)
        e0, e1, e2 = e0 / den, e1 / den, e2 / den  # now A_w^-1 d; e e^T / den = den e' e'^T
        for a in range(3):
            ea = e0 if a == 0 else (e1 if a == 1 else e2)
            for b in range(3):
                eb = e0 if b == 0 else (e1 if b == 1 else e2)
                Ai_w[a, b] = S_world_inv[j, a, b] + ea * eb * den
        # A^-1 = R^T A_w^-1 R
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for p in range(3):
                    for q in range(3):
                        acc += T[p, a] * Ai_w[p, q] * T[q, b]
                Ai[a, b] = acc
        # s A^-1 c_c = s R^T A_w^-1 d
        sw0 = s * (T[0, 0] * e0 + T[1, 0] * e1 + T[2, 0] * e2)
        sw1 = s * (T[0, 1] * e0 + T[1, 1] * e1 + T[2, 1] * e2)
        sw2 = s * (T[0, 2] * e0 + T[1, 2] * e1 + T[2, 2] * e2)
        for i in range(m):
            n0, n1, n2 = rays[j, 0, i], rays[j, 1, i], rays[j, 2, i]
            u0 = Ai[0, 0] * n0 + Ai[0, 1] * n1 + Ai[0, 2] * n2
            u1 = Ai[1, 0] * n0 + Ai[1, 1] * n1 + Ai[1, 2] * n2
            u2 = Ai[2, 0] * n0 + Ai[2, 1] * n1 + Ai[2, 2] * n2
            g = n0 * u0 + n1 * u1 + n2 * u2
            p = sw0 * n0 + sw1 * n1 + sw2 * n2
            r[j, i] = phi0[j, i] + s * g
            # (n x u) = -(u x n)
            J[j, i, 0] = -2.0 * a1 * g - 2.0 * s * (u1 * n2 - u2 * n1)
            J[j, i, 1] = 2.0 * a0 * g - 2.0 * s * (u2 * n0 - u0 * n2)
            J[j, i, 2] = -2.0 * s * (u0 * n1 - u1 * n0)
            J[j, i, 3] = -2.0 * p * u0
            J[j, i, 4] = -2.0 * p * u1
            J[j, i, 5] = -2.0 * p * u2 + 2.0 * z * g
    return r, J, z_out, v_out


@functools.lru_cache(maxsize=32)
def _unit_level_set_layout(n_azimuths: int, n_levels: int) -> tuple[np.ndarray, np.ndarray]:
    """``quadloc.factors.metrics``' level-set layout for a unit circle, s_max = 1: the homogeneous
    points ``(u, v, 1)`` as columns (3, M) and ``u^2 + v^2`` (1, M), read-only."""
    uv = metrics.level_set_sample_points(Ellipse(0.0, 0.0, 1.0, 1.0, 0.0), None,
                                         n_azimuths=n_azimuths, n_levels=n_levels, scale=1.0,
                                         adaptive=False)
    uv1 = np.ones((3, len(uv)))
    uv1[:2] = uv.T
    uv2 = (uv * uv).sum(axis=1)[None, :]
    for arr in (uv1, uv2):
        arr.setflags(write=False)
    return uv1, uv2


@functools.lru_cache(maxsize=64)
def _camera_constants(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """What the dual-conic metrics need of the intrinsics, read-only: ``K`` (3, 3) and ``-K
    [e_k]x K^-1`` (3, 3, 3), so that ``K (-[e_k]x A) K^T = this_k @ C*`` (``C* = K A K^T``).
    Cached per camera (one per image size and calibration)."""
    K = np.ascontiguousarray(camera.K)
    neg_KSKinv = -(K @ _SKEW_BASIS @ np.linalg.inv(K))
    for arr in (K, neg_KSKinv):
        arr.setflags(write=False)
    return K, neg_KSKinv


@jit
def _camera_frame_kernel(T: np.ndarray, centers: np.ndarray, L: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At ``T`` (``world_from_camera`` 4x4), per object in the camera frame: ``A = S_c - c_c
    c_c^T`` (N, 3, 3), the centre ``c_c = R^T (c_w - t)`` (N, 3) m and the shape matrix ``S_c =
    (R^T L)(R^T L)^T`` (N, 3, 3) m^2 (``L = R_e diag(axes)`` (N, 3, 3), world)."""
    n = centers.shape[0]
    A = np.empty((n, 3, 3))
    c = np.empty((n, 3))
    S = np.empty((n, 3, 3))
    RL = np.empty((3, 3))
    for j in range(n):
        for k in range(3):
            c[j, k] = ((centers[j, 0] - T[0, 3]) * T[0, k] + (centers[j, 1] - T[1, 3]) * T[1, k]
                       + (centers[j, 2] - T[2, 3]) * T[2, k])
            for m in range(3):
                RL[k, m] = T[0, k] * L[j, 0, m] + T[1, k] * L[j, 1, m] + T[2, k] * L[j, 2, m]
        for a in range(3):
            for b in range(a, 3):
                v = RL[a, 0] * RL[b, 0] + RL[a, 1] * RL[b, 1] + RL[a, 2] * RL[b, 2]
                S[j, a, b] = S[j, b, a] = v
                A[j, a, b] = A[j, b, a] = v - c[j, a] * c[j, b]
    return A, c, S


@jit
def _dual_conic_kernel(A: np.ndarray, c: np.ndarray, K: np.ndarray, neg_KSKinv: np.ndarray,
                       jacobian: bool) -> tuple[np.ndarray, np.ndarray]:
    """``Cn = C* / (-C*[2,2])`` (N, 3, 3), ``C* = K A K^T``, and if ``jacobian`` its derivative
    (N, 6, 3, 3) along the tangents ``[omega, v]`` (else (0, 6, 3, 3)): ``dC* = K dA K^T = G +
    G^T`` with ``G = K G_k K^T`` for the generators of the module docstring, ``-[e_k]x A``
    (rotation k) -> ``-K [e_k]x K^-1 C*``, ``e_k c^T`` (translation k) -> ``K e_k (K c)^T``;
    ``dCn = (dC* + Cn dC*[2,2]) / (-C*[2,2])``."""
    n = A.shape[0]
    Cn = np.empty((n, 3, 3))
    dCn = np.empty((n if jacobian else 0, 6, 3, 3))
    Cs = np.empty((3, 3))
    KA = np.empty((3, 3))
    G = np.empty((3, 3))
    Kc = np.empty(3)
    for j in range(n):
        for a in range(3):
            for b in range(3):
                KA[a, b] = K[a, 0] * A[j, 0, b] + K[a, 1] * A[j, 1, b] + K[a, 2] * A[j, 2, b]
        for a in range(3):
            for b in range(3):
                Cs[a, b] = KA[a, 0] * K[b, 0] + KA[a, 1] * K[b, 1] + KA[a, 2] * K[b, 2]
        w = -Cs[2, 2]
        for a in range(3):
            for b in range(3):
                Cn[j, a, b] = Cs[a, b] / w
        if not jacobian:
            continue
        for a in range(3):
            Kc[a] = K[a, 0] * c[j, 0] + K[a, 1] * c[j, 1] + K[a, 2] * c[j, 2]
        for k in range(6):
            for a in range(3):
                for b in range(3):
                    if k < 3:
                        G[a, b] = (neg_KSKinv[k, a, 0] * Cs[0, b] + neg_KSKinv[k, a, 1] * Cs[1, b]
                                   + neg_KSKinv[k, a, 2] * Cs[2, b])
                    else:
                        G[a, b] = K[a, k - 3] * Kc[b]
            d22 = 2.0 * G[2, 2]
            for a in range(3):
                for b in range(3):
                    dCn[j, k, a, b] = (G[a, b] + G[b, a] + Cn[j, a, b] * d22) / w
    return Cn, dCn


def expmap_pose3(xi: np.ndarray) -> np.ndarray:
    """4x4 matrix of GTSAM's ``Pose3.Expmap(xi)``, ``xi = [omega (rad), v (m)]`` (SE(3) exp:
    rotation :func:`quadloc.factors.rotations.so3_exp`, translation ``V v``)."""
    xi = np.asarray(xi, dtype=float)
    w, v = xi[:3], xi[3:]
    th = float(np.linalg.norm(w))
    W = skew(w)
    if th < 1e-8:
        V = np.eye(3) + 0.5 * W + W @ W / 6.0
    else:
        V = np.eye(3) + (1.0 - math.cos(th)) / th**2 * W + (th - math.sin(th)) / th**3 * W @ W
    T = np.eye(4)
    T[:3, :3] = so3_exp(w)
    T[:3, 3] = V @ v
    return T


@dataclass(frozen=True)
class PoseEvaluation:
    """Residuals of all pairs at one pose.

    ``residuals`` (N, dim): the metric's residuals (rows of invalid pairs hold the penalty);
    ``jacobians`` (N, dim, 6) or None (w.r.t. ``xi = [omega, v]``, right perturbation of
    ``world_from_camera``); ``valid`` (N,) bool: projection is an ellipse (else the row holds
    the penalty); ``depth_margins`` (N,) metres; ``factor_residuals`` / ``factor_jacobians``:
    what the GTSAM factors minimise, the valid rows saturated (module docstring; equal to
    ``residuals`` / ``jacobians`` to ``c / (2 P_j)`` relative near the optimum).
    """

    residuals: np.ndarray
    jacobians: np.ndarray | None
    valid: np.ndarray
    depth_margins: np.ndarray
    factor_residuals: np.ndarray | None = None
    factor_jacobians: np.ndarray | None = None


class PoseResidualModel:
    """Metric residuals of N detection/ellipsoid pairs as functions of ``world_from_camera``.

    Parameters
    ----------
    metric:
        One of ``quadloc.factors.metrics.METRIC_NAMES``.
    detections, ellipsoids:
        Same length N >= 1, pair ``j`` = (detected ellipse in pixels, map ellipsoid in world m).
    camera:
        Pinhole intrinsics (pixels).
    initial_world_from_camera:
        4x4 pose used ONLY to fix the level-set sample points when the sampling is adaptive
        (the sampling area depends on the distance between detection and projection). The
        samples are then frozen for the whole solve, so LM minimises one fixed function.
    metric_options:
        Passed to ``quadloc.factors.metrics.residual`` / ``level_set_sample_points``.
    min_depth_margin, penalty_cost:
        See the module docstring (invalid projections).
    numeric_step:
        Central-difference step for metrics without analytic Jacobian (default per metric in
        :data:`DEFAULT_NUMERIC_STEP`).
    eager_jacobian:
        Compute the Jacobians with every evaluation (default: for the analytic metrics, where
        they are cheap; LM linearises at nearly every pose it evaluates).

    :meth:`evaluate` memoises the last pose (one full evaluation per pose, shared by all the
    per-detection GTSAM factors that slice it).
    """

    def __init__(
        self,
        metric: str,
        detections: Sequence[Ellipse],
        ellipsoids: Sequence[Ellipsoid],
        camera: Camera,
        *,
        initial_world_from_camera: np.ndarray | None = None,
        metric_options: Mapping[str, Any] | None = None,
        min_depth_margin: float = DEFAULT_MIN_DEPTH_MARGIN,
        penalty_cost: float = DEFAULT_PENALTY_COST,
        numeric_step: float | None = None,
        eager_jacobian: bool | None = None,
    ) -> None:
        if metric not in metrics.METRIC_NAMES:
            raise ValueError(
                f"metric must be one of {', '.join(metrics.METRIC_NAMES)}; got {metric!r}"
            )
        if len(detections) != len(ellipsoids):
            raise ValueError(
                f"detections and ellipsoids must have the same length, got {len(detections)} "
                f"and {len(ellipsoids)}"
            )
        if len(detections) == 0:
            raise ValueError("detections must not be empty")
        for what, items, kind in (("detections", detections, Ellipse),
                                  ("ellipsoids", ellipsoids, Ellipsoid)):
            for j, v in enumerate(items):
                if not isinstance(v, kind):
                    raise GeometryError(
                        f"{what}[{j}] must be an {kind.__name__}, got {type(v).__name__}")
        if not isinstance(camera, Camera):
            raise GeometryError(f"camera must be a Camera, got {type(camera).__name__}")
        if not (math.isfinite(penalty_cost) and penalty_cost > 0):
            raise ValueError(f"penalty_cost must be finite and > 0, got {penalty_cost}")
        if not (math.isfinite(min_depth_margin) and min_depth_margin >= 0):
            raise ValueError(f"min_depth_margin must be finite and >= 0, got {min_depth_margin}")
        self.metric = metric
        self.detections = tuple(detections)
        self.ellipsoids = tuple(ellipsoids)
        self.camera = camera
        self.options: dict[str, Any] = dict(metric_options or {})
        if metric == "qbbox" and "image_size" not in self.options:
            self.options["image_size"] = (camera.width, camera.height)
        self.min_depth_margin = float(min_depth_margin)
        self.penalty_cost = float(penalty_cost)
        self.numeric_step = float(numeric_step or DEFAULT_NUMERIC_STEP.get(metric, 1e-6))
        # analytic Jacobians are cheap: compute them with every residual evaluation, since
        # LM linearises next at (almost) every pose whose error it evaluates
        self.eager_jacobian = (metric in ANALYTIC_METRICS) if eager_jacobian is None \
            else bool(eager_jacobian)
        self.n = len(self.detections)
        if metric != "level_set":  # the dual-conic metrics (and _projections)
            self._K, self._neg_KSKinv = _camera_constants(camera)
        # per-object constants (world frame)
        self._centers = np.array([q.center for q in self.ellipsoids])  # (N, 3) m
        axes = np.array([q.axes for q in self.ellipsoids])  # (N, 3) m
        # S = R diag(axes^2) R^T = L L^T with L = R diag(axes)
        rot = np.array([q.rotation for q in self.ellipsoids])  # (N, 3, 3) object -> world
        self._L = rot * axes[:, None, :]
        self._d_scale = axes.max(axis=1)  # (N,) m, penalty length scale
        if metric == "level_set":
            # world-frame shape matrix S_w = L L^T and its inverse R diag(axes^-2) R^T
            self._S_world = self._L @ self._L.transpose(0, 2, 1)
            self._S_world_inv = (rot / (axes * axes)[:, None, :]) @ rot.transpose(0, 2, 1)
        self._det_params = np.array([(d.cx, d.cy, d.a, d.b, d.angle) for d in self.detections])
        #: what the smooth metric needs of the (fixed) detections, computed once
        self._det_terms = metrics.conic_detection_terms(metric, self._det_params) \
            if metric in metrics.CONIC_METRICS else None
        self._cache_key: bytes | None = None
        self._cache_jac = False
        self._cache: PoseEvaluation | None = None
        #: level set: some detection's sampled area was grown for the misalignment at the
        #: initial pose (see :meth:`relayout`); always False for the other metrics
        self.sampling_grown = False
        T0 = None if initial_world_from_camera is None else check_pose(
            initial_world_from_camera, "initial_world_from_camera")
        if metric == "level_set":
            self._init_level_set(T0)
            self.dim = self._M
        else:
            self.dim = int(metrics.residual_size(self.metric, **self.options))
        self._set_layout_dependents()
        self.analytic = metric in ANALYTIC_METRICS

    def relayout(self, world_from_camera: np.ndarray) -> None:
        """Level set: lay the samples out again for the misalignment at ``world_from_camera``
        (4x4, e.g. an LM result; not re-validated) and forget the memoised evaluation. The
        residual size is unchanged, so factors built on this model stay valid."""
        if self.metric != "level_set":
            raise ValueError(f"relayout applies to the level_set metric, not {self.metric!r}")
        self._init_level_set(np.asarray(world_from_camera, dtype=float))
        self._set_layout_dependents()
        self._cache_key, self._cache_jac, self._cache = None, False, None

    def _set_layout_dependents(self) -> None:
        """The penalty costs, which depend on the level-set layout."""
        self.penalty_costs = self._penalty_costs()
        self.penalty_costs.setflags(write=False)
        self._half_penalty = 0.5 * self.penalty_costs  # where the saturation starts
        self._saturation_floor = float(self._half_penalty.min())

    # ------------------------------------------------------------------ set-up
    def _penalty_costs(self) -> np.ndarray:
        """Per-pair penalty cost ``P_j = penalty_cost * rho_j^2`` (N,), see the module doc."""
        if self.metric == "level_set":
            rho = np.maximum(1.0, self.sampling_scale) ** 2
        else:
            P = self._det_params
            diag = math.hypot(self.camera.width, self.camera.height)
            L = np.maximum(diag, np.hypot(P[:, 0], P[:, 1]) + np.maximum(P[:, 2], P[:, 3]))
            rho = L ** _PENALTY_PIXEL_POWER[self.metric]
        return self.penalty_cost * rho * rho

    def _projections(self, world_from_camera: np.ndarray) -> list[Ellipse | None]:
        """Projected ellipses at a pose (None where the projection is not an ellipse)."""
        A, _, _, margins = self._camera_frame(np.asarray(world_from_camera, dtype=float))
        C = self._K @ A @ self._K.T
        with np.errstate(divide="ignore", invalid="ignore"):  # invalid rows: not used
            params, ellipse = ellipse_params_and_validity(
                *gaussians_from_dual_conics(C / -C[:, 2:, 2:]))
        ok = (margins > self.min_depth_margin) & ellipse
        return [Ellipse(*params[j]) if ok[j] else None for j in range(self.n)]

    def _init_level_set(self, T0: np.ndarray | None) -> None:
        """Fix the level-set samples: ``quadloc.factors.metrics.level_set_sample_points``' layout,
        computed for all detections at once (equality with it is tested). The parts that do
        not depend on ``T0`` (validated options, unit layout, detection axes) are computed on
        the first call only and reused by :meth:`relayout`.

        Sample ``m`` of detection ``j`` is the affine image ``x = c_D + R_D diag(a, b) s_max
        (u_m, v_m)`` of the unit layout ``(u_m, v_m)``, so its normalised ray ``n = K^-1 (x,
        y, 1) = H_j (u_m, v_m, 1)`` with a per-object 3x3 ``H_j``: one matmul lays out all."""
        if not hasattr(self, "_ls_const"):
            M = int(metrics.residual_size("level_set", **self.options))  # validates options
            scale = metrics._positive_float(  # validated as by the metric
                "scale", self.options.get("scale", metrics.DEFAULT_LEVEL_SET_SCALE))
            uv1, uv2 = _unit_level_set_layout(self.options.get("n_azimuths", 6),
                                              self.options.get("n_levels", 4))
            # canonical axes a >= b (the metric's layout does not depend on axis labelling)
            axes_angle = metrics.canonical_axes(self._det_params)
            ca, sa = np.cos(axes_angle[:, 2]), np.sin(axes_angle[:, 2])
            cam = self.camera
            focal = np.array([cam.fx, cam.fy])
            # H without s_max: columns 0, 1 (R(angle) diag(a, b) over the focal lengths) scale
            # with s_max, column 2 is K^-1 (c_D, 1)
            H = np.zeros((self.n, 3, 3))
            H[:, :2, :2] = (np.stack((ca, -sa, sa, ca), axis=1).reshape(self.n, 2, 2)
                            * axes_angle[:, None, :2] / focal[:, None])
            H[:, :2, 2] = (self._det_params[:, :2] - (cam.cx, cam.cy)) / focal
            H[:, 2, 2] = 1.0
            self._ls_const = (M, float(scale), uv1, uv2, H, np.linalg.inv(H))
        self._M, scale, uv1, uv2, H, H_inv = self._ls_const
        adaptive = bool(self.options.get("adaptive", True))
        if adaptive and T0 is not None:
            A, _, _, margins = self._camera_frame(T0)
            a3 = A[:, :, 2]  # A e3, camera axes
            ok = margins > self.min_depth_margin
            # The projected centre c_P is the point of C* e3 = K A K^T e3 = K A e3, so its ray is
            # n = A e3 / s, and H^-1 n = (u, v, 1) are its coordinates in the detection's
            # axes over its semi-axes: Phi_D(c_P) = u^2 + v^2 = |(H^-1 A e3)[:2]|^2 / s^2
            # (quadloc.factors.conics.level_values; the same layout as quadloc.factors.metrics,
            # tested).
            p = (H_inv @ a3[:, :, None])[:, :, 0]
            all_ok = bool(ok.all())  # the usual case: no masking
            w = p[:, 2] if all_ok else np.where(ok, p[:, 2], 1.0)
            phi = (p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1]) / (w * w)
            s_max = np.maximum(scale, metrics.LEVEL_SET_ADAPTIVE_GAIN * np.sqrt(phi))
            if not all_ok:
                s_max = np.where(ok, s_max, scale)
        else:
            s_max = np.full(self.n, scale)
        self.sampling_scale = s_max  # (N,) outermost level radius per detection
        self.sampling_grown = bool((s_max > scale).any())
        self._phi0 = uv2 * (s_max**2)[:, None] - 1.0
        Hs = H.copy()
        Hs[:, :, :2] *= s_max[:, None, None]
        self._nT = Hs @ uv1  # (N, 3, M) normalised camera coordinates K^-1 (x, y, 1)

    @property
    def sample_points(self) -> np.ndarray:
        """Level set: the fixed sample points (N, M, 2), pixels (``K n``)."""
        cam = self.camera
        return np.stack([cam.fx * self._nT[:, 0] + cam.cx, cam.fy * self._nT[:, 1] + cam.cy],
                        axis=-1)

    # ------------------------------------------------------------------ evaluation
    def _camera_frame(
        self, world_from_camera: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``A`` (N,3,3), centres ``c_c`` (N,3) m, ``S_c`` (N,3,3), depth margins (N,) m
        (:func:`_camera_frame_kernel`)."""
        A, c, S = _camera_frame_kernel(np.array(world_from_camera, float, order="C"),
                                       self._centers, self._L)
        return A, c, S, depth_margin(c[:, 2], S[:, 2, 2])

    def evaluate(self, world_from_camera: np.ndarray, jacobian: bool = True) -> PoseEvaluation:
        """Residuals (and Jacobians if ``jacobian``) of all pairs at ``world_from_camera`` (4x4).

        Memoised on the pose value: repeated calls at the same pose cost one comparison.
        """
        T = np.asarray(world_from_camera, dtype=float)
        key = T.tobytes()
        if key == self._cache_key and (self._cache_jac or not jacobian):
            return self._cache  # type: ignore[return-value]
        jacobian = jacobian or self.eager_jacobian
        if not self.analytic:
            ev = self._evaluate_numeric(T, jacobian)
        elif self.metric == "level_set":
            ev = self._evaluate_level_set(T, jacobian)
        else:
            ev = self._evaluate_conic(T, jacobian)
        ev = self._saturate(ev)
        arrays = [ev.residuals, ev.jacobians, ev.valid, ev.depth_margins]
        if ev.factor_residuals is not ev.residuals:  # saturated rows (else the same arrays)
            arrays += [ev.factor_residuals, ev.factor_jacobians]
        for arr in arrays:
            if arr is not None:
                arr.setflags(write=False)
        self._cache_key, self._cache_jac, self._cache = key, jacobian, ev
        return ev

    def _saturate(self, ev: PoseEvaluation) -> PoseEvaluation:
        """Add the factors' residuals: the valid rows saturated (``r / sqrt(1 + c / P_j)``,
        module docstring)."""
        r = ev.residuals
        # fast path: the total cost is below every pair's c_0, so none can reach it
        c = None if float(np.vdot(r, r)) <= self._saturation_floor else (r * r).sum(axis=1)
        big = None if c is None else (c > self._half_penalty) & ev.valid
        if big is None or not big.any():
            return PoseEvaluation(r, ev.jacobians, ev.valid, ev.depth_margins, r, ev.jacobians)
        P = self.penalty_costs
        c0 = self._half_penalty
        span = 0.4 * P  # h < c0 + span = 0.9 P
        e = np.exp(-np.where(big, c - c0, 0.0) / span)
        h = np.where(big, c0 + span * (1.0 - e), c)
        g = np.sqrt(h / np.where(big, c, 1.0))
        rs = np.where(big[:, None], r * g[:, None], r)
        J = ev.jacobians
        if J is not None:
            # d g / d c = (h' c - h) / (2 c^2 g), h' = e; dc = 2 r^T dr
            dg = np.where(big, (e * c - h) / (2.0 * np.where(big, c, 1.0) ** 2 * g), 0.0)
            rJ = np.einsum("nm,nmk->nk", r, J)
            Js = J * g[:, None, None] + (2.0 * dg[:, None] * r)[:, :, None] * rJ[:, None, :]
            J = np.where(big[:, None, None], Js, J)
        return PoseEvaluation(r, ev.jacobians, ev.valid, ev.depth_margins, rs, J)

    def _evaluate_level_set(self, T: np.ndarray, jacobian: bool) -> PoseEvaluation:
        """Level-set residuals and Jacobians of all pairs (:func:`_level_set_kernel`; the
        Jacobian is always computed with the residual)."""
        # a fresh C-ordered copy of the pose: the kernels are compiled for that one type
        r, J, z, v = _level_set_kernel(np.array(T, float, order="C"), self._centers,
                                       self._S_world, self._S_world_inv, self._nT, self._phi0)
        margins = depth_margin(z, v)
        valid = margins > self.min_depth_margin
        if not valid.all():
            _, c, S, _ = self._camera_frame(T)
            self._apply_penalty(r, J, ~valid, c, S, margins)
        return PoseEvaluation(r, J, valid, margins)

    def _apply_penalty(
        self, r: np.ndarray, J: np.ndarray | None, bad: np.ndarray, c: np.ndarray,
        S: np.ndarray, margins: np.ndarray,
    ) -> None:
        """Overwrite rows ``bad`` of ``r`` (N, dim) / ``J`` (N, dim, 6) with the penalty."""
        idx = np.flatnonzero(bad)
        d = self.min_depth_margin - margins[idx]
        ds = self._d_scale[idx]
        amp = np.sqrt(self.penalty_costs[idx] / self.dim)  # residual amplitude sqrt(P_j / dim)
        r[idx] = (amp * (1.0 + d / (d + ds)))[:, None]
        if J is not None:
            cb = c[idx]
            s3 = S[idx, :, 2]
            ext = np.sqrt(S[idx, 2, 2])
            dm = np.zeros((idx.size, 6))
            dm[:, 0] = -cb[:, 1] + s3[:, 1] / ext
            dm[:, 1] = cb[:, 0] - s3[:, 0] / ext
            dm[:, 5] = -1.0
            coef = -amp * ds / (d + ds) ** 2
            J[idx] = (coef[:, None] * dm)[:, None, :]

    def _normalised_dual_conics(
        self, A: np.ndarray, c: np.ndarray, valid: np.ndarray, jacobian: bool,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """``Cn = C* / (-C*[2,2])`` (N, 3, 3) of the projections and, if ``jacobian``, its
        derivative (N, 6, 3, 3) along the 6 tangent directions ``[omega, v]``
        (:func:`_dual_conic_kernel`). Invalid rows (``~valid``) hold a stand-in ellipse, to be
        replaced by the penalty."""
        if not valid.all():
            A = A.copy()
            A[~valid] = np.diag([1.0, 1.0, -1.0])
        Cn, dCn = _dual_conic_kernel(A, c, self._K, self._neg_KSKinv, jacobian)
        return Cn, dCn if jacobian else None

    def _evaluate_conic(self, T: np.ndarray, jacobian: bool) -> PoseEvaluation:
        """The metrics of the projections' normalised dual conics ``Cn`` (with their
        derivatives ``dCn`` along the 6 tangents): :func:`quadloc.factors.metrics.conic_residuals`,
        or for iou / giou :meth:`_overlap_rows`."""
        A, c, S, margins = self._camera_frame(T)
        valid = margins > self.min_depth_margin
        Cn, dCn = self._normalised_dual_conics(A, c, valid, jacobian)
        if self.metric in ("iou", "giou"):
            r, J = self._overlap_rows(Cn, dCn, valid)
        else:
            r, J = metrics.conic_residuals(self.metric, self._det_params, Cn, dCn,
                                           detection_terms=self._det_terms)
            J = None if J is None else np.ascontiguousarray(J)
        if not valid.all():
            self._apply_penalty(r, J, ~valid, c, S, margins)
        return PoseEvaluation(r, J, valid, margins)

    def _overlap_rows(self, Cn: np.ndarray, dCn: np.ndarray | None, valid: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray | None]:
        """iou / giou rows (N, 4) of :func:`quadloc.factors.metrics.overlap_residual` (all pairs in
        one call, ``disjoint_hull``) and their pose Jacobian: the exact area gradients w.r.t. the
        projection's ``g = (mu_x, mu_y, s00, s01, s11)`` chained through ``dg / dxi``. A
        projection whose Sigma is not positive definite is invalid: ``valid`` is updated in
        place (its rows stay 0 for the penalty)."""
        mu, sigma = gaussians_from_dual_conics(Cn)
        params, ellipse = ellipse_params_and_validity(mu, sigma)
        valid &= ellipse
        hull_directions = self.options.get("hull_directions", HULL_DIRECTIONS)
        if valid.all():  # the usual case: no scatter into zero-filled rows
            r, grad = metrics.overlap_residual(self.metric, self._det_params, params,
                                               hull_directions, gradient=dCn is not None,
                                               disjoint_hull=True)
            return r, None if dCn is None else grad @ self._dg_dxi(mu, dCn)
        r = np.zeros((self.n, self.dim))
        J = None if dCn is None else np.zeros((self.n, self.dim, 6))
        idx = np.flatnonzero(valid)
        if idx.size:
            rows, grad = metrics.overlap_residual(
                self.metric, self._det_params[idx], params[idx], hull_directions,
                gradient=J is not None, disjoint_hull=True)
            r[idx] = rows
            if J is not None:
                J[idx] = grad @ self._dg_dxi(mu[idx], dCn[idx])
        return r, J

    @staticmethod
    def _dg_dxi(mu: np.ndarray, dCn: np.ndarray) -> np.ndarray:
        """``d g / d xi`` (n, 5, 6) of the projections' ``g = (mu_x, mu_y, s00, s01, s11)``
        along the 6 pose tangents, from ``mu`` (n, 2) and ``dCn`` (n, 6, 3, 3)."""
        dmu, dsig = gaussian_derivatives_from_dual_conics(mu, dCn)
        dg = np.concatenate([dmu, dsig[..., 0, 0, None], dsig[..., 0, 1, None],
                             dsig[..., 1, 1, None]], axis=-1)  # (n, 6, 5)
        return dg.transpose(0, 2, 1)

    # ------------------------------------------------------------------ generic metrics
    def _metric_rows(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual rows (N, dim) via quadloc.factors.metrics.residual, and validity (N,)."""
        projs = self._projections(T)
        r = np.empty((self.n, self.dim))
        valid = np.zeros(self.n, dtype=bool)
        for j, p in enumerate(projs):
            if p is None:
                continue
            try:
                rj = np.asarray(metrics.residual(self.metric, self.detections[j], p,
                                                 **self.options), dtype=float)
            except (DegenerateProjectionError, GeometryError):
                continue
            if rj.shape != (self.dim,) or not np.all(np.isfinite(rj)):
                continue
            r[j] = rj
            valid[j] = True
        return r, valid

    def _evaluate_numeric(self, T: np.ndarray, jacobian: bool) -> PoseEvaluation:
        _, c, S, margins = self._camera_frame(T)
        r, valid = self._metric_rows(T)
        J = None
        if jacobian:
            h = self.numeric_step
            J = np.zeros((self.n, self.dim, 6))
            for k in range(6):
                e = np.zeros(6)
                e[k] = h
                rp, vp = self._metric_rows(T @ expmap_pose3(e))
                rm, vm = self._metric_rows(T @ expmap_pose3(-e))
                both = vp & vm
                J[both, :, k] = (rp[both] - rm[both]) / (2 * h)
                only_p = vp & ~vm & valid
                J[only_p, :, k] = (rp[only_p] - r[only_p]) / h
                only_m = vm & ~vp & valid
                J[only_m, :, k] = (r[only_m] - rm[only_m]) / h
        if not valid.all():
            self._apply_penalty(r, J, ~valid, c, S, margins)
        return PoseEvaluation(r, J, valid, margins)

    # ------------------------------------------------------------------ reporting
    def costs(self, world_from_camera: np.ndarray) -> np.ndarray:
        """The metric's unweighted cost ``||r_j||^2`` of each pair at a pose (N,), unsaturated;
        the penalty's cost where the projection is invalid."""
        ev = self.evaluate(world_from_camera, jacobian=False)
        return np.einsum("nm,nm->n", ev.residuals, ev.residuals)


def compile_kernels() -> None:
    """Compile the numeric kernels (level set, dual conics, exact areas and iou / giou rows,
    the batched projection of :func:`quadloc.factors.camera.projected_gaussians`;
    :mod:`quadloc.factors.jit`) now, or load them from numba's cache: one small
    evaluation per kernel family, through the same calls as a refinement (so the same
    specialisations). The service calls this at start-up so that no request pays the
    compilation (~13 s once per machine and cache directory, well under 1 s from the cache;
    docs/deployment.md)."""
    camera = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)
    ellipsoid = Ellipsoid(np.array([0.0, 0.0, 3.0]), np.array([0.3, 0.2, 0.1]), np.eye(3))
    detection = Ellipse(330.0, 245.0, 45.0, 30.0, 0.2)
    for metric in ("level_set", "bbox", "iou", "giou"):
        model = PoseResidualModel(metric, [detection], [ellipsoid], camera,
                                  initial_world_from_camera=np.eye(4))
        model.evaluate(np.eye(4))
    projected_gaussians(camera, np.eye(4)[None], ellipsoid.center[None],
                        ellipsoid.shape_matrix()[None], ellipsoid.dual_quadric()[None])
