"""Ellipsoids from multi-view ellipses with known camera poses (Rubino et al.), then LM refinement.

Method (docs/design/maps.md, "Reconstruction"): a linear estimate of the dual quadric by SVD
(Rubino, Crocco, Del Bue, TPAMI 2018), refined by Levenberg-Marquardt with the level-set factor
of :func:`quadloc.factors.ellipsoid_factors.ellipsoid_views_factor` from the linear estimate and
from a sphere at the triangulated centre; the best valid result wins (in front of every camera,
:func:`degenerate_shape_reason`, RMS level residual at most ``MAX_RMS_LEVEL_RESIDUAL``).

Conventions: poses are ``world_from_camera`` 4x4 (camera axes OpenCV), ellipses in pixels,
semi-axes in metres, output rotations ellipsoid frame -> world.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.camera import Camera, Ellipsoid, ellipsoid_depth_margins
from quadloc.factors.conics import Ellipse
from quadloc.factors.ellipsoid_factors import ellipsoid_views_factor
from quadloc.factors.ellipsoid_residuals import (
    LevelSetSamples,
    dual_quadric,
    dual_quadric_jacobians,
    observation_residual,
    stack_samples,
)
from quadloc.factors.rotations import (
    ORTHONORMAL_TOLERANCE,
    invert_pose,
    pose_matrix,
    rotation_angle,
)
from quadloc.maps.model import LIMITS, MapObject, SceneMap

__all__ = [
    "FrameObservations",
    "LabelledEllipse",
    "MapBuildReport",
    "ReconstructionError",
    "ReconstructionResult",
    "build_scene_map",
    "canonical_ellipsoid",
    "contour_samples",
    "degenerate_shape_reason",
    "dual_quadric_jacobians",
    "ellipsoid_errors",
    "ellipsoid_from_dual_quadric",
    "linear_dual_quadric",
    "max_ray_angle_deg",
    "reconstruct_ellipsoid",
    "refine_ellipsoid",
    "triangulate",
    "view_residuals",
]

#: Default smallest accepted angle (degrees) between the most divergent pair of viewing rays.
MIN_RAY_ANGLE_DEG = 2.0
#: Default number of points sampled on each observed ellipse for the refinement residual.
SAMPLES_PER_VIEW = 16
#: Smallest accepted ratio of the smallest to the largest semi-axis (1:100; the flattest Chess
#: object is 1:3.5): flatter results are ``degenerate_shape``.
MIN_AXIS_RATIO = 0.01
#: Largest accepted RMS of the (unweighted) level residual ``Phi_pred - 1`` at the observed
#: contours, else ``inconsistent_views`` (noisy views of one object stay below 0.2 on the bench).
MAX_RMS_LEVEL_RESIDUAL = 1.0

_TRIU4 = np.triu_indices(4)
_TRIU3 = np.triu_indices(3)
_W4 = np.where(_TRIU4[0] == _TRIU4[1], 1.0, math.sqrt(2.0))
_W3 = np.where(_TRIU3[0] == _TRIU3[1], 1.0, math.sqrt(2.0))
# Symmetric basis of 4x4 matrices matching vech order: Q = sum_k q_k B_k / w_k.
_BASIS4 = np.zeros((10, 4, 4))
for _k, (_i, _j) in enumerate(zip(*_TRIU4, strict=True)):
    _BASIS4[_k, _i, _j] = _BASIS4[_k, _j, _i] = 1.0 / _W4[_k]

class ReconstructionError(ValueError):
    """The views do not determine an ellipsoid. ``reason`` is a machine-readable code:

    ``too_few_views``, ``bad_input``, ``near_parallel_rays``, ``not_an_ellipsoid``,
    ``not_in_front`` (the estimate is not in front of every camera), ``refinement_failed``,
    ``degenerate_shape`` (semi-axes outside the map limits or flatter than ``MIN_AXIS_RATIO``:
    the shape is not constrained) or ``inconsistent_views`` (no ellipsoid reproduces the
    views: RMS level residual above ``MAX_RMS_LEVEL_RESIDUAL``).
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class ReconstructionResult:
    """An ellipsoid reconstructed from ``n_views`` views.

    ``ellipsoid`` is the refined estimate (or the linear one if ``refine=False``);
    ``linear_ellipsoid`` the closed-form estimate (None if it was not a valid ellipsoid in front
    of every camera); ``initialization`` the start of the refinement that won (``"linear"`` or
    ``"sphere"``: a sphere at the triangulated centre); ``rms_level_residual`` the RMS of
    ``Phi_pred - 1`` over the sampled observed contour points (dimensionless; each view's
    divided by its sigma when ``sigmas`` are given) after refinement,
    ``linear_rms_level_residual`` the same for the linear estimate (inf if invalid);
    ``max_ray_angle_deg`` the largest angle between two viewing rays through the ellipse
    centres; ``iterations`` LM iterations of the winning refinement (0 without refinement).
    """

    ellipsoid: Ellipsoid
    linear_ellipsoid: Ellipsoid | None
    n_views: int
    rms_level_residual: float
    linear_rms_level_residual: float
    max_ray_angle_deg: float
    iterations: int
    initialization: str


# --------------------------------------------------------------------------- input handling


def _as_ellipse(value: Any, index: int) -> Ellipse:
    if isinstance(value, Ellipse):
        return value
    try:
        box = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        box = None
    if box is None or box.shape != (4,) or not np.all(np.isfinite(box)):
        raise ReconstructionError(
            "bad_input", f"ellipses[{index}] must be an Ellipse or a box [xmin, ymin, xmax, ymax]"
        )
    return Ellipse.from_bbox(*box)


def _prepare(
    ellipses: Sequence[Any], world_from_camera: Sequence[FloatArray],
    camera: Camera | Sequence[Camera], min_views: int,
) -> tuple[list[Ellipse], FloatArray, list[Camera], FloatArray]:
    """Validate inputs; returns ellipses, camera_from_world (n,4,4), cameras, P (n,3,4)."""
    ells = [_as_ellipse(e, i) for i, e in enumerate(ellipses)]
    n = len(ells)
    if len(world_from_camera) != n:
        raise ReconstructionError("bad_input", f"world_from_camera has {len(world_from_camera)} "
                                               f"poses for {n} ellipses")
    if n < max(3, min_views):
        raise ReconstructionError("too_few_views", f"need at least {max(3, min_views)} views of "
                                                   f"the object, got {n}")
    cams = [camera] * n if isinstance(camera, Camera) else list(camera)
    if len(cams) != n or not all(isinstance(c, Camera) for c in cams):
        raise ReconstructionError("bad_input", "camera must be a Camera or one Camera per view")
    poses = np.asarray(world_from_camera, dtype=float)
    if poses.shape != (n, 4, 4) or not np.all(np.isfinite(poses)):
        raise ReconstructionError("bad_input", "world_from_camera must be finite 4x4 matrices")
    R = poses[:, :3, :3]
    if np.max(np.abs(np.einsum("nij,nkj->nik", R, R) - np.eye(3))) > ORTHONORMAL_TOLERANCE \
            or np.any(np.linalg.det(R) <= 0):
        raise ReconstructionError("bad_input", "world_from_camera rotations must be orthonormal "
                                               "with det +1 (snap them with "
                                               "quadloc.factors.rotations.snap_to_rotation)")
    cfw = np.array([invert_pose(T) for T in poses])
    P = np.array([c.projection_matrix(T) for c, T in zip(cams, cfw, strict=True)])
    return ells, cfw, cams, P


def _rays(ells: Sequence[Ellipse], cams: Sequence[Camera], cfw: FloatArray) -> FloatArray:
    """Unit world directions (n, 3) of the rays through the ellipse centres."""
    d = np.array([[(e.cx - c.cx) / c.fx, (e.cy - c.cy) / c.fy, 1.0]
                  for e, c in zip(ells, cams, strict=True)])
    d = np.einsum("nji,nj->ni", cfw[:, :3, :3], d)  # R_cw^T d: camera -> world
    rays: FloatArray = d / np.linalg.norm(d, axis=1, keepdims=True)
    return rays


def max_ray_angle_deg(rays: FloatArray) -> float:
    """Largest angle (deg) between two of the unit rays (n, 3): the spread of the views."""
    cos = np.clip(rays @ rays.T, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos.min())))


def triangulate(origins: FloatArray, rays: FloatArray) -> FloatArray:
    """Least-squares point closest to the rays ``origins + t rays`` (n, 3)."""
    proj = np.eye(3) - rays[:, :, None] * rays[:, None, :]
    point: FloatArray = np.linalg.solve(proj.sum(0), np.einsum("nij,nj->i", proj, origins))
    return point


# --------------------------------------------------------------------------- linear estimate


def _vech_design(P: FloatArray) -> FloatArray:
    """``G`` (n, 6, 10): weighted ``vech(P B_k P^T)`` for the weighted vech basis ``B_k``."""
    PBP: FloatArray = np.einsum("nai,kij,nbj->nkab", P, _BASIS4, P)
    return (PBP[:, :, _TRIU3[0], _TRIU3[1]] * _W3).transpose(0, 2, 1)


def linear_dual_quadric(dual_conics: FloatArray, projections: FloatArray) -> FloatArray:
    """Least-squares dual quadric (4x4, scale arbitrary) from dual conics ``C*_i`` (n, 3, 3) and
    projection matrices ``P_i`` (n, 3, 4), solving ``s_i vech(C*_i) = G_i vech(Q*)`` by SVD.

    Inputs should already be conditioned (see :func:`reconstruct_ellipsoid`). The returned
    matrix is normalised to unit Frobenius norm.
    """
    C = np.asarray(dual_conics, dtype=float)
    P = np.asarray(projections, dtype=float)
    n = C.shape[0]
    c = C[:, _TRIU3[0], _TRIU3[1]] * _W3
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    A = np.zeros((n, 6, 10 + n))
    A[:, :, :10] = _vech_design(P)
    A[np.arange(n), :, 10 + np.arange(n)] = -c
    _, _, Vt = np.linalg.svd(A.reshape(6 * n, 10 + n), full_matrices=False)
    q = Vt[-1, :10] / _W4
    Q = np.zeros((4, 4))
    Q[_TRIU4] = q
    Q = Q + Q.T - np.diag(np.diag(Q))
    return Q / np.linalg.norm(Q)


def ellipsoid_from_dual_quadric(dual_quadric: FloatArray) -> Ellipsoid:
    """Ellipsoid (centre, semi-axes descending, proper rotation) of a dual quadric of any scale.

    Raises ``ReconstructionError("not_an_ellipsoid")`` if ``Q*[3, 3] = 0`` or the shape matrix
    ``M = Q*[:3, :3] / -Q*[3,3] + c c^T`` is not positive definite.
    """
    Q = np.asarray(dual_quadric, dtype=float)
    Q = 0.5 * (Q + Q.T)
    w = Q[3, 3]
    if not abs(w) > 1e-12 * np.abs(Q).max():
        raise ReconstructionError("not_an_ellipsoid", "dual quadric with Q*[3, 3] = 0 "
                                                      "(a paraboloid or degenerate quadric)")
    Qn = Q / -w
    center = -Qn[:3, 3]
    M = Qn[:3, :3] + np.outer(center, center)
    lam, vec = np.linalg.eigh(0.5 * (M + M.T))
    if not lam[0] > 0:
        raise ReconstructionError(
            "not_an_ellipsoid", f"the estimated quadric is not an ellipsoid (shape eigenvalues "
                                f"{np.array2string(lam, precision=3)} m^2 are not all positive)")
    return canonical_ellipsoid(vec, center, np.sqrt(lam))


def canonical_ellipsoid(rotation: FloatArray, center: FloatArray, axes: FloatArray
                        ) -> Ellipsoid:
    """The ellipsoid with its semi-axes (m) in descending order, the rotation's columns
    permuted alike and the last one negated if needed for det +1. Semi-axes that underflowed
    are kept tiny (1e-300), not zero: callers check them against the map limits."""
    order = np.argsort(axes)[::-1]
    R = rotation[:, order]
    if np.linalg.det(R) < 0:
        R[:, 2] = -R[:, 2]
    return Ellipsoid(center, np.maximum(axes[order], 1e-300), R)


# --------------------------------------------------------------------------- refinement


def contour_samples(ellipse: Ellipse, n: int) -> LevelSetSamples:
    """``n`` points on the observed ellipse as level-set samples in homogeneous pixels
    (``Phi_det = 1`` there), for a camera given by its projection ``K [R|t]`` (see
    :func:`quadloc.factors.ellipsoid_factors.ellipsoid_views_factor`)."""
    pts = ellipse.contour_points(n)
    return LevelSetSamples(pts, np.vstack([pts.T, np.ones((1, n))]), np.zeros(n))


def _projection_rows(projections: FloatArray) -> FloatArray:
    """``K [R|t]`` (n, 3, 4) padded to (n, 4, 4): the factor's ``camera_from_world`` for
    samples in homogeneous pixels."""
    P = np.asarray(projections, dtype=float)
    out = np.zeros((P.shape[0], 4, 4))
    out[:, :3, :] = P
    out[:, 3, 3] = 1.0
    return out


def view_residuals(
    ellipsoid: Ellipsoid, ellipses: Sequence[Ellipse], projections: FloatArray,
    samples_per_view: int = SAMPLES_PER_VIEW,
) -> FloatArray:
    """Level residuals ``Phi_pred - 1`` (n, samples) of ``ellipsoid`` against observed ellipses,
    with ``projections`` the views' ``P = K [R|t]_camera_from_world`` (n, 3, 4): minus the
    shared level-set residual (:func:`quadloc.factors.ellipsoid_residuals.observation_residual`) at
    ``samples_per_view`` contour points of each observed ellipse."""
    samples = stack_samples([contour_samples(e, samples_per_view) for e in ellipses])
    r, _, _ = observation_residual(_projection_rows(projections), ellipsoid.rotation,
                                   ellipsoid.center, ellipsoid.axes, samples, False)
    return -r


def refine_ellipsoid(
    initial: Ellipsoid, ellipses: Sequence[Ellipse], projections: FloatArray, *,
    sigmas: Sequence[float] | None = None, samples_per_view: int = SAMPLES_PER_VIEW,
    max_iterations: int = 100, log_axes_prior: tuple[FloatArray, float] | None = None,
) -> tuple[Ellipsoid, int]:
    """Levenberg-Marquardt refinement (GTSAM) of ``initial`` against the observed ellipses.

    ``projections``: ``P_i = K_i [R|t]_camera_from_world`` (n, 3, 4). ``sigmas``: optional
    per-view standard deviation of the level residual (default 1). ``log_axes_prior``:
    optional ``(mean (3,), sigma)`` Gaussian prior on the log semi-axes (log metres), a weak
    regulariser for narrow baselines (it biases exact data; off by default). Returns the refined
    ellipsoid (semi-axes descending) and the number of LM iterations.
    """
    pose_key, axes_key = gtsam.symbol("e", 0), gtsam.symbol("a", 0)
    graph = gtsam.NonlinearFactorGraph()
    sig = [1.0] * len(ellipses) if sigmas is None else list(sigmas)
    graph.add(ellipsoid_views_factor(
        stack_samples([contour_samples(e, samples_per_view) for e in ellipses]),
        1.0 / np.asarray(sig, dtype=float), [(pose_key, axes_key)],
        np.zeros(len(ellipses), int), camera_from_world=_projection_rows(projections)))
    if log_axes_prior is not None:
        mean, prior_sigma = log_axes_prior
        graph.add(gtsam.PriorFactorVector(
            axes_key, np.asarray(mean, dtype=float).reshape(3),
            gtsam.noiseModel.Isotropic.Sigma(3, float(prior_sigma))))
    values = gtsam.Values()
    values.insert(pose_key, gtsam.Pose3(gtsam.Rot3(initial.rotation), initial.center))
    values.insert(axes_key, np.log(initial.axes))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-20)
    params.setErrorTol(0.0)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    result = optimizer.optimize()
    pose = result.atPose3(pose_key)
    axes = np.exp(result.atVector(axes_key))
    if not np.all(np.isfinite(axes)) or not np.all(np.isfinite(pose.matrix())):
        raise ReconstructionError("refinement_failed", "refinement diverged (non-finite result)")
    refined = ellipsoid_from_dual_quadric(
        dual_quadric(pose.rotation().matrix(), np.asarray(pose.translation()), axes))
    return refined, int(optimizer.iterations())


# --------------------------------------------------------------------------- one object


def reconstruct_ellipsoid(
    ellipses: Sequence[Ellipse | Sequence[float]],
    world_from_camera: Sequence[FloatArray],
    camera: Camera | Sequence[Camera],
    *,
    refine: bool = True,
    min_views: int = 3,
    min_ray_angle_deg: float = MIN_RAY_ANGLE_DEG,
    sigmas: Sequence[float] | None = None,
    samples_per_view: int = SAMPLES_PER_VIEW,
    log_axes_prior_sigma: float | None = None,
) -> ReconstructionResult:
    """Ellipsoid of one object from its ellipses (or boxes ``[xmin, ymin, xmax, ymax]`` px,
    replaced by their inscribed axis-aligned ellipses) in ``>= 3`` views.

    Args:
        ellipses: one observation per view, pixels.
        world_from_camera: the views' camera poses (4x4, camera axes OpenCV).
        camera: intrinsics, shared or one per view.
        refine: run the LM refinement after the linear estimate.
        min_views: minimum number of views (never less than 3).
        min_ray_angle_deg: refuse view sets whose rays through the ellipse centres are all
            within this angle of each other (the depth is then unobservable).
        sigmas: optional per-view standard deviation of the level residual for the refinement.
        samples_per_view: contour points per observed ellipse in the refinement residual.
        log_axes_prior_sigma: if given, a Gaussian prior (this sigma, in log metres) pulls the
            log semi-axes towards the apparent size ``median(depth * sqrt(ab) / f)``: keeps
            narrow-baseline reconstructions from collapsing to flat ellipsoids (biased, opt-in).

    Raises ``ReconstructionError`` (``reason`` in ``too_few_views``, ``bad_input``,
    ``near_parallel_rays``, ``not_an_ellipsoid``, ``not_in_front``, ``refinement_failed``,
    ``degenerate_shape``, ``inconsistent_views``).
    """
    ells, cfw, cams, P = _prepare(ellipses, world_from_camera, camera, min_views)
    if sigmas is not None:
        sig = np.asarray(sigmas, dtype=float)
        if sig.shape != (len(ells),) or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise ReconstructionError("bad_input", f"sigmas must be {len(ells)} finite numbers "
                                                   f"> 0 (one per view)")
    if not (isinstance(samples_per_view, int) and samples_per_view >= 5):
        raise ReconstructionError("bad_input", f"samples_per_view must be an integer >= 5 (a "
                                               f"conic needs 5 points), got {samples_per_view!r}")
    if log_axes_prior_sigma is not None and not (math.isfinite(log_axes_prior_sigma)
                                                 and log_axes_prior_sigma > 0):
        raise ReconstructionError("bad_input", f"log_axes_prior_sigma must be finite and > 0, "
                                               f"got {log_axes_prior_sigma!r}")
    rays = _rays(ells, cams, cfw)
    spread = max_ray_angle_deg(rays)
    if spread < min_ray_angle_deg:
        raise ReconstructionError(
            "near_parallel_rays", f"the {len(ells)} viewing rays are nearly parallel (largest "
                                  f"angle {spread:.3g} deg < {min_ray_angle_deg:g} deg): the "
                                  f"object's depth is not observable")
    origins = -np.einsum("nji,nj->ni", cfw[:, :3, :3], cfw[:, :3, 3])  # camera centres
    X0 = triangulate(origins, rays)
    depth = np.einsum("nj,nj->n", cfw[:, 2, :3], np.broadcast_to(X0, origins.shape)) + cfw[:, 2, 3]
    if np.any(depth <= 0):
        raise ReconstructionError("not_in_front", "the viewing rays meet behind a camera")
    size = np.array([math.sqrt(e.a * e.b) for e in ells])
    focal = np.array([math.sqrt(c.fx * c.fy) for c in cams])
    scale = float(np.median(depth * size / focal))
    # Conditioning: world X = scale * X' + X0; image x' = (x - c_e) / sqrt(ab).
    T = pose_matrix(scale * np.eye(3), X0)
    H = np.zeros((len(ells), 3, 3))
    H[:, 0, 0] = H[:, 1, 1] = 1.0 / size
    H[:, :2, 2] = -np.array([[e.cx, e.cy] for e in ells]) / size[:, None]
    H[:, 2, 2] = 1.0
    C = np.array([e.dual_conic() for e in ells])
    Cn = np.einsum("nij,njk,nlk->nil", H, C, H)
    Pn = np.einsum("nij,njk,kl->nil", H, P, T)
    Qn = linear_dual_quadric(Cn, Pn)
    linear: Ellipsoid | None = None
    linear_problem = ""
    try:
        linear = ellipsoid_from_dual_quadric(T @ Qn @ T.T)
        _check_in_front(linear, cfw)
    except (ReconstructionError, ValueError) as exc:
        linear, linear_problem = None, str(exc)
    weights = (np.ones(len(ells)) if sigmas is None
               else 1.0 / np.asarray(sigmas, dtype=float).reshape(len(ells)))

    def rms_of(ellipsoid: Ellipsoid) -> float:
        """RMS of the level residuals, each view's divided by its sigma."""
        r = view_residuals(ellipsoid, ells, P, samples_per_view) * weights[:, None]
        return float(np.sqrt(np.mean(r**2)))

    lin_rms = rms_of(linear) if linear is not None else math.inf
    if not refine:
        if linear is None:
            raise ReconstructionError("not_an_ellipsoid", f"linear estimate: {linear_problem}")
        _check_result(linear, ells, P, samples_per_view)
        return ReconstructionResult(linear, linear, len(ells), lin_rms, lin_rms, spread, 0,
                                    "linear")
    # Refine from the linear estimate and from a sphere at the triangulated centre (radius from
    # the apparent sizes): the linear estimate is fragile with narrow baselines or noise.
    starts: list[tuple[str, Ellipsoid]] = [("sphere", Ellipsoid(X0, np.full(3, scale)))]
    if linear is not None:
        starts.insert(0, ("linear", linear))
    prior = (None if log_axes_prior_sigma is None
             else (np.full(3, math.log(scale)), float(log_axes_prior_sigma)))
    best: tuple[float, Ellipsoid, int, str] | None = None
    problems = [f"linear: {linear_problem}"] if linear is None else []
    reasons: set[str] = set()
    for label, start in starts:
        try:
            refined, iters = refine_ellipsoid(start, ells, P, sigmas=sigmas,
                                              samples_per_view=samples_per_view,
                                              log_axes_prior=prior)
            _check_in_front(refined, cfw)
            _check_result(refined, ells, P, samples_per_view)
        except (ReconstructionError, ValueError, RuntimeError) as exc:  # RuntimeError: GTSAM
            problems.append(f"{label}: {exc}")
            reasons.add(getattr(exc, "reason", "refinement_failed"))
            continue
        rms = rms_of(refined)
        if label == "linear" and rms > lin_rms:
            # only at round-off level (LM never accepts an increase): keep the linear estimate
            refined, rms = start, lin_rms  # the "linear" start is the linear estimate
        if best is None or rms < best[0]:
            best = (rms, refined, iters, label)
    if best is None and linear is not None:
        # Every refinement collapsed (e.g. a flat object under noise): keep the linear estimate
        # if it is a valid shape.
        try:
            _check_result(linear, ells, P, samples_per_view)
            best = (lin_rms, linear, 0, "linear")
        except ReconstructionError as exc:
            problems.append(f"linear: {exc}")
    if best is None:
        reason = next((r for r in ("degenerate_shape", "inconsistent_views") if r in reasons),
                      "refinement_failed")
        raise ReconstructionError(reason, "no valid ellipsoid: " + "; ".join(problems))
    rms, refined, iters, label = best
    return ReconstructionResult(refined, linear, len(ells), rms, lin_rms, spread, iters, label)


def degenerate_shape_reason(ellipsoid: Ellipsoid) -> str | None:
    """Why ``ellipsoid`` is not an object's shape, or None: semi-axes outside the map limits
    (``LIMITS``), or flatter than ``MIN_AXIS_RATIO`` (smallest / largest semi-axis: a
    reconstruction collapsed along an axis the views do not constrain, not a real object)."""
    lo, hi = LIMITS["min_semi_axis_m"], LIMITS["max_semi_axis_m"]
    axes = np.asarray(ellipsoid.axes, dtype=float)
    if not (axes.min() >= lo and axes.max() <= hi):
        return (f"semi-axes {np.array2string(axes, precision=4)} m outside [{lo:g}, {hi:g}] m")
    if axes.min() < MIN_AXIS_RATIO * axes.max():
        return (f"semi-axes {np.array2string(axes, precision=4)} m: smallest below "
                f"{MIN_AXIS_RATIO:g} x the largest (collapsed along an unconstrained axis)")
    return None


def _check_result(ellipsoid: Ellipsoid, ells: Sequence[Ellipse], P: FloatArray,
                  samples_per_view: int) -> None:
    """``degenerate_shape`` unless :func:`degenerate_shape_reason` is None; then
    ``inconsistent_views`` if the unweighted RMS level residual exceeds
    ``MAX_RMS_LEVEL_RESIDUAL`` (the views are not of one ellipsoid, e.g. mixed objects: a tiny
    ellipsoid that fits none of them may be all LM finds)."""
    problem = degenerate_shape_reason(ellipsoid)
    if problem is not None:
        raise ReconstructionError(
            "degenerate_shape", f"the views do not constrain the shape: {problem} (narrow "
                                f"baseline? try more spread views or log_axes_prior_sigma)")
    rms = float(np.sqrt(np.mean(view_residuals(ellipsoid, ells, P, samples_per_view) ** 2)))
    if not rms <= MAX_RMS_LEVEL_RESIDUAL:
        raise ReconstructionError(
            "inconsistent_views", f"the best ellipsoid (semi-axes "
                                  f"{np.array2string(ellipsoid.axes, precision=4)} m) misses "
                                  f"the observed ellipses: RMS level residual {rms:.3g} > "
                                  f"{MAX_RMS_LEVEL_RESIDUAL:g} (views of different objects?)")


def _check_in_front(ellipsoid: Ellipsoid, cfw: FloatArray) -> None:
    margins = ellipsoid_depth_margins(cfw, ellipsoid.center[None],
                                      ellipsoid.shape_matrix()[None])[:, 0]
    if np.any(margins <= 0):
        bad = int(np.argmin(margins))
        raise ReconstructionError(
            "not_in_front", f"the estimated ellipsoid is not entirely in front of camera {bad} "
                            f"(smallest depth {margins[bad]:.3g} m): inconsistent views")


# --------------------------------------------------------------------------- evaluation


#: The 24 proper signed permutation matrices (symmetries of an ellipsoid's frame): column k is
#: ``signs[k] e_perm[k]``.
_SYMMETRIES = np.array([S for perm in itertools.permutations(range(3))
                        for signs in itertools.product((1.0, -1.0), repeat=3)
                        if np.linalg.det(S := np.eye(3)[:, list(perm)] * signs) > 0])


def ellipsoid_errors(estimate: Ellipsoid, truth: Ellipsoid) -> dict[str, float]:
    """Errors of ``estimate`` against ``truth``, independent of axis order and signs.

    The estimate's frame is matched to the truth's over the 24 proper signed permutations of its
    axes (minimum rotation angle). Returns ``center_m`` (Euclidean, m), ``axes_m`` (largest
    absolute semi-axis error after matching, m), ``axes_rel`` (largest relative one),
    ``orientation_deg`` (rotation angle between the matched frames; ill-defined for nearly
    equal semi-axes) and ``shape_rel`` (``|M_est - M_true|_F / |M_true|_F``, frame-free).
    """
    frames = np.einsum("ij,sjk->sik", estimate.rotation, _SYMMETRIES)  # R_est S
    angles = rotation_angle(truth.rotation, frames)  # (24,) rad
    best = int(np.argmin(angles))
    angle = float(angles[best])
    axes = np.abs(_SYMMETRIES[best]).T @ estimate.axes  # axes permuted like the columns
    m_true = truth.shape_matrix()
    return {
        "center_m": float(np.linalg.norm(estimate.center - truth.center)),
        "axes_m": float(np.max(np.abs(axes - truth.axes))),
        "axes_rel": float(np.max(np.abs(axes - truth.axes) / truth.axes)),
        "orientation_deg": math.degrees(angle),
        "shape_rel": float(np.linalg.norm(estimate.shape_matrix() - m_true)
                           / np.linalg.norm(m_true)),
    }


# --------------------------------------------------------------------------- whole map


@dataclass(frozen=True)
class LabelledEllipse:
    """One detection with known data association: the map ``object_id`` it belongs to, its
    category ``label`` and its ``ellipse`` (px) — or a ``box`` ``[xmin, ymin, xmax, ymax]``."""

    object_id: str
    label: str
    ellipse: Ellipse | None = None
    box: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        if (self.ellipse is None) == (self.box is None):
            raise ValueError(f"LabelledEllipse {self.object_id!r}: give exactly one of "
                             f"ellipse or box")

    def as_ellipse(self) -> Ellipse:
        """The ellipse, or the one inscribed in the box (px)."""
        if self.ellipse is not None:
            return self.ellipse
        assert self.box is not None  # exactly one of the two (__post_init__)
        return Ellipse.from_bbox(*self.box)


@dataclass(frozen=True)
class FrameObservations:
    """The detections of one image with its known ``world_from_camera`` pose (4x4) and camera."""

    world_from_camera: FloatArray
    camera: Camera
    detections: Sequence[LabelledEllipse]


@dataclass(frozen=True)
class MapBuildReport:
    """Per-object outcome of :func:`build_scene_map`: results of the reconstructed objects,
    failures ``object_id -> (reason, message)``, and label votes that were not unanimous."""

    results: dict[str, ReconstructionResult] = field(default_factory=dict)
    failures: dict[str, tuple[str, str]] = field(default_factory=dict)
    label_disagreements: dict[str, dict[str, int]] = field(default_factory=dict)


def build_scene_map(
    frames: Sequence[FrameObservations], *, map_id: str, name: str,
    up_axis: tuple[float, float, float] = (0.0, 0.0, 1.0),
    categories: Sequence[str] | None = None, on_failure: str = "raise",
    metadata: Mapping[str, Any] | None = None, **reconstruct_options: Any,
) -> tuple[SceneMap, MapBuildReport]:
    """Build a :class:`SceneMap` from per-frame labelled detections with known association.

    Each object's views are gathered across frames and reconstructed with
    :func:`reconstruct_ellipsoid` (``reconstruct_options`` are passed on). The category of an
    object is the majority label of its detections (ties: first seen). ``categories`` defaults
    to the labels in order of first appearance. ``on_failure``: ``"raise"`` (the first
    ``ReconstructionError``, its message prefixed with the object id) or ``"skip"`` (the object
    is left out and listed in ``report.failures``).
    """
    if on_failure not in ("raise", "skip"):
        raise ValueError(f"on_failure must be 'raise' or 'skip', got {on_failure!r}")
    views: dict[str, list[tuple[Ellipse, FloatArray, Camera]]] = {}
    labels: dict[str, Counter[str]] = {}
    label_order: dict[str, None] = {}
    for fi, frame in enumerate(frames):
        seen: set[str] = set()
        for det in frame.detections:
            if det.object_id in seen:
                raise ValueError(f"frames[{fi}]: object {det.object_id!r} detected twice")
            seen.add(det.object_id)
            views.setdefault(det.object_id, []).append(
                (det.as_ellipse(), np.asarray(frame.world_from_camera, float), frame.camera))
            labels.setdefault(det.object_id, Counter())[det.label] += 1
            label_order.setdefault(det.label, None)
    report = MapBuildReport()
    objects = []
    for object_id, obs in views.items():
        votes = labels[object_id]
        label = votes.most_common(1)[0][0]  # ties: the label seen first
        if len(votes) > 1:
            report.label_disagreements[object_id] = dict(votes)
        try:
            result = reconstruct_ellipsoid([o[0] for o in obs], [o[1] for o in obs],
                                           [o[2] for o in obs], **reconstruct_options)
        except ReconstructionError as exc:
            if on_failure == "raise":
                raise ReconstructionError(exc.reason, f"object {object_id!r}: {exc}") from exc
            report.failures[object_id] = (exc.reason, str(exc))
            continue
        report.results[object_id] = result
        objects.append(MapObject(object_id, label, result.ellipsoid))
    cats = tuple(categories) if categories is not None else tuple(label_order)
    meta = {"built_by": "quadloc.maps.reconstruct.build_scene_map", "n_frames": len(frames)}
    meta.update(metadata or {})
    scene = SceneMap(map_id=map_id, name=name, up_axis=up_axis, categories=cats,
                     objects=tuple(objects), metadata=meta)
    return scene, report
