"""The pose layout shared by the metric residual families: the ellipsoids in the camera frame
at a pose, and their projections' normalised dual conics with their pose derivatives.

Pure numpy and compiled kernels (:mod:`quadloc.factors.jit`), batched over the N pairs of one
refinement; :mod:`quadloc.factors.pose_residuals` assembles the families on top of it.

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
* A projection is valid while the whole ellipsoid is in front of the camera: depth margin
  ``m = z_c - sqrt(S_c[2,2]) > min_depth_margin`` (m; :func:`quadloc.factors.camera.depth_margin`).
  A family reports the margins and which pairs are valid; the rows of invalid pairs are
  replaced by :mod:`quadloc.factors.pose_penalty`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numpy as np

from quadloc.factors import camera as _camera
from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.jit import jit
from quadloc.factors.rotations import skew

__all__ = [
    "CameraFrame",
    "EllipsoidArrays",
    "PairRows",
    "PoseResidualFamily",
    "ProjectionConics",
]

# tangent generators: d(A)/d(omega_k) = G + G^T with G = -[e_k]x A; d(A)/d(v_k) = G + G^T with
# G = e_k c^T
_SKEW_BASIS = skew(np.eye(3)) + 0.0  # [e_k]x, k = 0, 1, 2


class CameraFrame(NamedTuple):
    """The N ellipsoids in the camera frame at one pose (rows of ONE pose, read by the
    families and the penalty)."""

    #: ``A = S_c - c_c c_c^T`` (N, 3, 3) m^2 (``C* = K A K^T``)
    A: FloatArray
    #: centres ``c_c`` (N, 3) m, camera frame
    centers: FloatArray
    #: shape matrices ``S_c`` (N, 3, 3) m^2, camera frame
    shapes: FloatArray
    #: smallest depths ``z_c - sqrt(S_c[2,2])`` (N,) m
    depth_margins: FloatArray


class PairRows(NamedTuple):
    """One family's evaluation of all N pairs at one pose, before the penalty and the
    saturation (:class:`quadloc.factors.pose_residuals.PoseResidualModel` applies them)."""

    #: metric residuals (N, dim); rows of invalid pairs are stand-ins (writable, for the penalty)
    residuals: FloatArray
    #: ``d r / d xi`` (N, dim, 6), or None when not asked for (writable)
    jacobians: FloatArray | None
    #: (N,) whether the pair's projection is an ellipse the metric can use
    valid: BoolArray
    #: (N,) m, as in :class:`CameraFrame`
    depth_margins: FloatArray
    #: the frame the family computed at this pose, or None (the penalty then computes it)
    frame: CameraFrame | None
    #: ``sum(residuals**2)`` when the family computed it and every pair is valid, else None;
    #: when given, ``residuals``, ``jacobians``, ``valid`` and ``depth_margins`` are read-only
    sum_squares: float | None = None


class PoseResidualFamily(Protocol):
    """A metric's residuals of all pairs as functions of ``world_from_camera``."""

    #: residual components per pair
    dim: int

    def rows(self, world_from_camera: FloatArray, jacobian: bool) -> PairRows:
        """All pairs at ``world_from_camera`` (4x4 float64); Jacobians if ``jacobian``."""
        ...


@jit
def _camera_frame_kernel(T: FloatArray, centers: FloatArray, L: FloatArray) -> FloatArray:
    """At ``T`` (``world_from_camera`` 4x4), per object in the camera frame: ``A = S_c - c_c
    c_c^T`` (N, 3, 3), the centre ``c_c = R^T (c_w - t)`` (N, 3) m and the shape matrix ``S_c =
    (R^T L)(R^T L)^T`` (N, 3, 3) m^2 (``L = R_e diag(axes)`` (N, 3, 3), world) and the depth
    margin (N,) m (:func:`quadloc.factors.camera.depth_margin`'s compiled form, called from
    here), in ONE flat array of ``22 N`` values in that order (one boxed array instead of four:
    ~2 us a call, and no numpy calls for the margins)."""
    n = centers.shape[0]
    out = np.empty(22 * n)
    A = out[:9 * n].reshape((n, 3, 3))
    c = out[9 * n:12 * n].reshape((n, 3))
    S = out[12 * n:21 * n].reshape((n, 3, 3))
    margins = out[21 * n:]
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
        margins[j] = _camera.depth_margin_kernel(c[j, 2], S[j, 2, 2])
    return out


class EllipsoidArrays:
    """The N map ellipsoids of one refinement as world-frame arrays (fixed during the solve).

    ``centers`` (N, 3) m, semi-``axes`` (N, 3) m, ``rotations`` (N, 3, 3) ellipsoid -> world,
    ``shape_factors`` ``L = R_e diag(axes)`` (N, 3, 3) m (``S = L L^T``), ``largest_semi_axes``
    (N,) m."""

    def __init__(self, ellipsoids: Sequence[Ellipsoid]) -> None:
        self.centers: FloatArray = np.array([q.center for q in ellipsoids])
        self.axes: FloatArray = np.array([q.axes for q in ellipsoids])
        self.rotations: FloatArray = np.array([q.rotation for q in ellipsoids])
        # S = R diag(axes^2) R^T = L L^T with L = R diag(axes)
        self.shape_factors: FloatArray = self.rotations * self.axes[:, None, :]
        self.largest_semi_axes: FloatArray = self.axes.max(axis=1)

    def camera_frame(self, world_from_camera: FloatArray) -> CameraFrame:
        """The ellipsoids in the camera frame at ``world_from_camera`` (4x4)
        (:func:`_camera_frame_kernel`, then the depth margins)."""
        # a fresh C-ordered copy of the pose: the kernels are compiled for that one type
        out = _camera_frame_kernel(np.array(world_from_camera, float, order="C"),
                                   self.centers, self.shape_factors)
        n = len(self.centers)
        c, S = out[9 * n:12 * n].reshape(n, 3), out[12 * n:21 * n].reshape(n, 3, 3)
        return CameraFrame(out[:9 * n].reshape(n, 3, 3), c, S, out[21 * n:])


@functools.lru_cache(maxsize=64)
def _camera_constants(camera: Camera) -> tuple[FloatArray, FloatArray]:
    """What the dual-conic metrics need of the intrinsics, read-only: ``K`` (3, 3) and ``-K
    [e_k]x K^-1`` (3, 3, 3), so that ``K (-[e_k]x A) K^T = this_k @ C*`` (``C* = K A K^T``).
    Cached per camera (one per image size and calibration)."""
    K = np.ascontiguousarray(camera.K)
    neg_KSKinv: FloatArray = -(K @ _SKEW_BASIS @ np.linalg.inv(K))
    for arr in (K, neg_KSKinv):
        arr.setflags(write=False)
    return K, neg_KSKinv


@jit
def _dual_conic_kernel(A: FloatArray, c: FloatArray, K: FloatArray, neg_KSKinv: FloatArray,
                       jacobian: bool) -> FloatArray:
    """``Cn = C* / (-C*[2,2])`` (N, 3, 3), ``C* = K A K^T``, and if ``jacobian`` its derivative
    (N, 6, 3, 3) along the tangents ``[omega, v]``, in ONE flat array (``Cn`` then ``dCn``):
    ``dC* = K dA K^T = G + G^T`` with ``G = K G_k K^T`` for the generators of the module
    docstring, ``-[e_k]x A`` (rotation k) -> ``-K [e_k]x K^-1 C*``, ``e_k c^T`` (translation
    k) -> ``K e_k (K c)^T``;
    ``dCn = (dC* + Cn dC*[2,2]) / (-C*[2,2])``."""
    n = A.shape[0]
    out = np.empty(9 * n + (54 * n if jacobian else 0))
    Cn = out[:9 * n].reshape((n, 3, 3))
    dCn = out[9 * n:].reshape((n if jacobian else 0, 6, 3, 3))
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
    return out


class ProjectionConics:
    """The projections' normalised dual conics ``Cn = C* / (-C*[2,2])`` (``C* = K A K^T``) and
    their derivatives along the pose tangents, for one camera (pixels)."""

    def __init__(self, camera: Camera) -> None:
        #: the intrinsic matrix (3, 3) px, read-only
        self.K: FloatArray
        self.K, self._neg_KSKinv = _camera_constants(camera)

    def normalised(self, frame: CameraFrame, valid: BoolArray, jacobian: bool
                   ) -> tuple[FloatArray, FloatArray | None]:
        """``Cn`` (N, 3, 3) of the projections and, if ``jacobian``, its derivative (N, 6, 3, 3)
        along the 6 tangent directions ``[omega, v]`` (:func:`_dual_conic_kernel`). Invalid rows
        (``~valid``) hold a stand-in ellipse, to be replaced by the penalty."""
        A = frame.A
        if not valid.all():
            A = A.copy()
            A[~valid] = np.diag([1.0, 1.0, -1.0])
        out = _dual_conic_kernel(A, frame.centers, self.K, self._neg_KSKinv, jacobian)
        n = len(A)
        return out[:9 * n].reshape(n, 3, 3), out[9 * n:].reshape(n, 6, 3, 3) if jacobian \
            else None
