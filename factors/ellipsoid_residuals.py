"""The level-set residual as a function of BOTH the camera pose and the ellipsoid (pure numpy).

Localization (:mod:`quadloc.factors.pose_residuals`, metric ``level_set``) moves only the camera;
map building moves the ellipsoids (and optionally the cameras). Both minimise the same residual at
the same samples of the detection (``quadloc.factors.metrics.level_set_sample_points``,
non-adaptive; equality with :class:`quadloc.factors.pose_residuals.PoseResidualModel` is tested):
``r(x) = Phi_det(x) - Phi_proj(x)``, ``Phi_proj(x) = 1 - s n^T A^-1 n`` with ``n = K^-1 (x,
y, 1)``, ``A = [R|t]_camera_from_world Q* [R|t]^T`` (3x3; ``C* = K A K^T``), ``s = A[2, 2]``.
Its gradient w.r.t. ``A`` is contracted with ``dA`` along the camera's Pose3 tangent (right
perturbation of ``world_from_camera``) and the ellipsoid's ``[omega, v, d log axes]``
(derivation: ``docs/design/factors.md``, "Ellipsoid residuals"). Residuals are dimensionless
(``Phi`` units).
"""

from __future__ import annotations

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.conics import Ellipse, level_values
from quadloc.factors.metrics import LevelSetOptions, level_set_sample_points
from quadloc.factors.rotations import skew

__all__ = [
    "LevelSetSamples",
    "dual_quadric",
    "dual_quadric_jacobians",
    "level_set_residual_and_gradient",
    "level_set_samples",
    "observation_residual",
    "stack_samples",
]

_SKEW = skew(np.eye(3)) + 0.0  # [e_k]x, k = 0, 1, 2 (+ 0.0: no -0.0 entries)


class LevelSetSamples:
    """Fixed samples of one detection: normalised rays ``n`` (3, M) and ``Phi_det - 1`` (M,)
    (and its ``points`` (M, 2) px; None for a :func:`stack_samples` stack).

    Built by :func:`level_set_samples` from ``quadloc.factors.metrics.level_set_sample_points`` (the
    localization layout, ``adaptive=False``) so both problems sample identically.
    """

    __slots__ = ("n", "phi_det_minus_1", "points")

    def __init__(self, points: FloatArray | None, n: FloatArray, phi_det_minus_1: FloatArray
                 ) -> None:
        self.points = points
        self.n = n
        self.phi_det_minus_1 = phi_det_minus_1


def level_set_samples(detection: Ellipse, camera: Camera,
                      metric_options: LevelSetOptions | None = None) -> LevelSetSamples:
    """The level-set samples of ``detection`` (px) for ``camera``; ``metric_options`` as for the
    ``level_set`` metric (``n_azimuths``, ``n_levels``, ``scale``; ``adaptive`` is forced off:
    without a pose there is no misalignment to adapt to)."""
    options: LevelSetOptions = {**(metric_options or {}), "adaptive": False}
    pts = level_set_sample_points(detection, None, **options)
    n = np.ones((3, len(pts)))
    n[0] = (pts[:, 0] - camera.cx) / camera.fx
    n[1] = (pts[:, 1] - camera.cy) / camera.fy
    phi = level_values(np.array([detection.params()]), pts[None])[0] - 1.0
    return LevelSetSamples(pts, n, phi)


def dual_quadric(rotation: FloatArray, center: FloatArray, axes: FloatArray) -> FloatArray:
    """``Q* = T diag(a^2, b^2, c^2, -1) T^T`` (4x4) of an ellipsoid (rotation ellipsoid ->
    world, centre m, semi-axes m). Batched: ``rotation`` (..., 3, 3), ``center`` and ``axes``
    (..., 3) give (..., 4, 4)."""
    R = np.asarray(rotation, dtype=float)
    c = np.asarray(center, dtype=float)
    a2 = np.asarray(axes, dtype=float) ** 2
    Q = np.empty((*R.shape[:-2], 4, 4))
    Q[..., :3, :3] = (R * a2[..., None, :]) @ np.swapaxes(R, -1, -2) \
        - c[..., :, None] * c[..., None, :]
    Q[..., :3, 3] = -c
    Q[..., 3, :3] = -c
    Q[..., 3, 3] = -1.0
    return Q


def dual_quadric_jacobians(rotation: FloatArray, center: FloatArray,
                           axes: FloatArray) -> FloatArray:
    """``dQ*/d theta`` (9, 4, 4) for ``theta = [omega (3), v (3), d log axes (3)]``.

    ``omega, v``: the Pose3 right perturbation of the ellipsoid pose (rotation ellipsoid ->
    world, translation = centre): ``R -> R Exp(omega)``, ``center -> center + R v``.
    Batched like :func:`dual_quadric`: (..., 9, 4, 4).
    """
    R = np.asarray(rotation, dtype=float)
    c = np.asarray(center, dtype=float)
    a2 = np.asarray(axes, dtype=float) ** 2
    lead = R.shape[:-2]
    dQ = np.zeros((*lead, 9, 4, 4))
    # d(R D R^T) along omega_k = R ([e_k]x D - D [e_k]x) R^T, D = diag(a^2)
    inner = _SKEW * a2[..., None, None, :] - a2[..., None, :, None] * _SKEW  # (..., 3, 3, 3)
    dQ[..., 0:3, :3, :3] = np.einsum("...ij,...kjl,...ml->...kim", R, inner, R)
    Rt = np.swapaxes(R, -1, -2)  # rows: the columns r_k of R
    rc = Rt[..., :, :, None] * c[..., None, None, :]  # (..., 3, 3, 3): r_k c^T
    dQ[..., 3:6, :3, :3] = -(rc + np.swapaxes(rc, -1, -2))
    dQ[..., 3:6, :3, 3] = -Rt
    dQ[..., 3:6, 3, :3] = -Rt
    dQ[..., 6:9, :3, :3] = 2.0 * a2[..., :, None, None] * (
        Rt[..., :, :, None] * Rt[..., :, None, :])
    return dQ


def level_set_residual_and_gradient(
    A: FloatArray, samples: LevelSetSamples, gradient: bool = True,
) -> tuple[FloatArray, FloatArray | None]:
    """Residuals ``r`` (M,) and gradients ``dr/dA`` (M, 3, 3) (None if not ``gradient``).

    Batched: ``A`` (V, 3, 3) with ``samples.n`` (V, 3, M) and ``samples.phi_det_minus_1``
    (V, M) give ``r`` (V, M) and gradients (V, M, 3, 3)."""
    u = np.linalg.solve(A, samples.n)  # (..., 3, M)
    g = np.einsum("...km,...km->...m", samples.n, u)
    s = A[..., 2, 2]
    r = samples.phi_det_minus_1 + s[..., None] * g
    if not gradient:
        return r, None
    G = -s[..., None, None, None] * np.einsum("...im,...jm->...mij", u, u)
    G[..., 2, 2] += g
    return r, G


def stack_samples(samples: list[LevelSetSamples]) -> LevelSetSamples:
    """Samples of V detections with the same layout stacked for the batched evaluation."""
    return LevelSetSamples(None, np.stack([s.n for s in samples]),
                           np.stack([s.phi_det_minus_1 for s in samples]))


def observation_residual(
    camera_from_world: FloatArray, rotation: FloatArray, center: FloatArray, axes: FloatArray,
    samples: LevelSetSamples, jacobians: bool = True,
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """Residual (M,) of one detection against one ellipsoid seen from one camera, with the
    Jacobians w.r.t. the ellipsoid ``[omega, v, d log axes]`` (M, 9) and w.r.t. the camera's
    ``world_from_camera`` Pose3 tangent ``[omega, v]`` (M, 6) when ``jacobians``.

    Batched over V views: ``camera_from_world`` (V, 4, 4) with :func:`stack_samples` give
    (V, M), (V, M, 9), (V, M, 6); the ellipsoid is shared (``rotation`` (3, 3)) or one per view
    (``rotation`` (V, 3, 3), ``center`` and ``axes`` (V, 3)).

    The caller must ensure the views are valid
    (:func:`quadloc.factors.ellipsoid_factors.valid_views`: the ellipsoid in front of the camera
    and not degenerate): otherwise ``A`` is no ellipse's conic, or singular (LinAlgError).
    """
    Q = dual_quadric(rotation, center, axes)
    P = np.asarray(camera_from_world, dtype=float)[..., :3, :]
    A = P @ Q @ np.swapaxes(P, -1, -2)
    r, G = level_set_residual_and_gradient(A, samples, jacobians)
    if G is None:  # not jacobians
        return r, None, None
    dQ = dual_quadric_jacobians(rotation, center, axes)
    dA = np.einsum("...ai,...kij,...bj->...kab", P, dQ, P)  # (..., 9, 3, 3)
    J_ell = np.einsum("...mab,...kab->...mk", G, dA)
    # camera: dA = -[w]x A - A [w]x^T + v c^T + c v^T, c = centre in the camera frame
    c = np.einsum("...ij,...j->...i", P[..., :3], np.asarray(center, dtype=float)) + P[..., 3]
    SA = np.einsum("kij,...jl->...kil", _SKEW, A)  # (..., 3, 3, 3)
    dAc = np.empty((*A.shape[:-2], 6, 3, 3))
    dAc[..., :3, :, :] = -SA - np.swapaxes(SA, -1, -2)
    E = np.eye(3)
    dAc[..., 3:, :, :] = (E[:, :, None] * c[..., None, None, :]
                          + c[..., None, :, None] * E[:, None, :])
    J_cam = np.einsum("...mab,...kab->...mk", G, dAc)
    return r, J_ell, J_cam
