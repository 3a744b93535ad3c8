"""Residuals and Jacobians of the ellipse metrics w.r.t. the camera pose, batched over objects.

Pure numpy (no GTSAM): for ONE camera pose and ALL detection/ellipsoid pairs of a refinement
at once, the metric residual of every pair and its Jacobian with respect to the pose;
:mod:`quadloc.factors.pose_factors` wraps it in GTSAM factors. Derivations and the reasons behind
the penalty's constants: ``docs/design/factors.md`` ("Pose residuals").

:class:`PoseResidualModel` is the one entry point. It validates the inputs, evaluates the
metric's residual family at a pose, replaces the rows of invalid projections by the penalty,
saturates the valid ones for the factors, and memoises the result on the pose value (its
arrays are read-only, shared by the factors that slice them). The parts, one module each:

========================================  ===================================================
:mod:`quadloc.factors.pose_frame`         conventions (pose, tangent ``xi = [omega, v]``,
                                          right perturbation); the ellipsoids in the camera
                                          frame at a pose, their depth margins, the
                                          projections' normalised dual conics ``Cn`` and
                                          their pose derivatives
:mod:`quadloc.factors.pose_level_set`     ``level_set``: its sample layout and one compiled
                                          kernel for residuals and analytic Jacobians
:mod:`quadloc.factors.pose_conic_metrics` ``algebraic``, ``frobenius``, ``wasserstein``,
                                          ``bhattacharyya``, ``bbox``: analytic, through ``Cn``
:mod:`quadloc.factors.pose_overlap_metrics` ``iou``, ``giou``: exact areas and their
                                          gradients, through ``Cn``
:mod:`quadloc.factors.pose_numeric_metrics` ``qbbox``: ``quadloc.factors.metrics.residual``
                                          and central differences (step
                                          :data:`DEFAULT_NUMERIC_STEP`)
:mod:`quadloc.factors.pose_penalty`       the bounded penalty of invalid projections (depth
                                          margin ``<= min_depth_margin``) and the saturation
                                          of valid costs below it
========================================  ===================================================

The pose is the camera's ``world_from_camera`` 4x4 matrix (OpenCV camera axes); Jacobians are
``d r / d xi`` (``(dim, 6)`` per pair) for GTSAM's Pose3 tangent ``xi = [omega (rad), v (m)]``,
right perturbation ``world_from_camera @ Exp(xi)`` (:func:`expmap_pose3`).

Reported residuals and costs (:attr:`PoseEvaluation.residuals`, :meth:`PoseResidualModel.costs`)
are the metric's own (the penalty where the projection is invalid); the factors use
:attr:`PoseEvaluation.factor_residuals` (the valid rows saturated above half the penalty). A
robust kernel (``quadloc.factors.pose_factors``) flattens the penalty too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple, TypedDict

import numpy as np

from quadloc.factors import metrics
from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.camera import Camera, Ellipsoid, projected_gaussians
from quadloc.factors.conics import Ellipse
from quadloc.factors.metrics import METRIC_NAMES
from quadloc.factors.names import GeometryError
from quadloc.factors.pose_conic_metrics import ConicMetricResiduals
from quadloc.factors.pose_frame import EllipsoidArrays, PairRows, PoseResidualFamily
from quadloc.factors.pose_level_set import LevelSetResiduals
from quadloc.factors.pose_numeric_metrics import CentralDifferenceResiduals
from quadloc.factors.pose_overlap_metrics import OverlapResiduals
from quadloc.factors.pose_penalty import DepthMarginPenalty, penalty_costs
from quadloc.factors.rotations import check_pose, skew, so3_exp

__all__ = [
    "ANALYTIC_METRICS",
    "DEFAULT_MIN_DEPTH_MARGIN",
    "DEFAULT_NUMERIC_STEP",
    "DEFAULT_PENALTY_COST",
    "ModelOptions",
    "PoseEvaluation",
    "PoseResidualModel",
    "compile_kernels",
    "expmap_pose3",
]

#: Invalid-projection penalty cost per pair, in units of the pair's reference cost ``rho_j^2``
#: (:mod:`quadloc.factors.pose_penalty`); the penalty's cost lies in ``[1x, 4x) penalty_cost
#: rho_j^2``.
DEFAULT_PENALTY_COST = 1e8
#: A projection counts as valid while the ellipsoid's smallest camera depth exceeds this (m).
DEFAULT_MIN_DEPTH_MARGIN = 1e-3
#: Central-difference step on each tangent coordinate (rad or m) for numerical Jacobians.
DEFAULT_NUMERIC_STEP: dict[str, float] = dict.fromkeys(METRIC_NAMES, 1e-6)
#: Metrics whose pose Jacobian is analytic (the others use central differences).
ANALYTIC_METRICS: tuple[str, ...] = (
    "level_set", "algebraic", "frobenius", "wasserstein", "bhattacharyya", "bbox", "iou",
    "giou")


def expmap_pose3(xi: FloatArray) -> FloatArray:
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


class ModelOptions(TypedDict, total=False):
    """:class:`PoseResidualModel`'s tuning keywords (forwarded by
    :func:`quadloc.factors.pose_factors.pose_factors`)."""

    min_depth_margin: float
    penalty_cost: float
    numeric_step: float | None
    eager_jacobian: bool | None


class PoseEvaluation(NamedTuple):
    """Residuals of all pairs at one pose (read-only arrays).

    ``residuals`` (N, dim): the metric's residuals (rows of invalid pairs hold the penalty);
    ``jacobians`` (N, dim, 6) or None (w.r.t. ``xi = [omega, v]``, right perturbation of
    ``world_from_camera``); ``valid`` (N,) bool: projection is an ellipse (else the row holds
    the penalty); ``depth_margins`` (N,) metres; ``factor_residuals`` / ``factor_jacobians``:
    what the GTSAM factors minimise, the valid rows saturated (the same arrays as
    ``residuals`` / ``jacobians`` unless a row saturates, :mod:`quadloc.factors.pose_penalty`;
    equal to them to ``c / (2 P_j)`` relative near the optimum).
    """

    residuals: FloatArray
    jacobians: FloatArray | None
    valid: BoolArray
    depth_margins: FloatArray
    factor_residuals: FloatArray
    factor_jacobians: FloatArray | None


def _check_inputs(metric: str, detections: Sequence[object], ellipsoids: Sequence[object],
                  camera: object, penalty_cost: float, min_depth_margin: float) -> None:
    """:class:`PoseResidualModel`'s argument checks: ``ValueError`` (metric, lengths, penalty
    constants) or ``GeometryError`` (types)."""
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
        See :mod:`quadloc.factors.pose_penalty` (invalid projections).
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
        initial_world_from_camera: FloatArray | None = None,
        metric_options: Mapping[str, object] | None = None,
        min_depth_margin: float = DEFAULT_MIN_DEPTH_MARGIN,
        penalty_cost: float = DEFAULT_PENALTY_COST,
        numeric_step: float | None = None,
        eager_jacobian: bool | None = None,
    ) -> None:
        _check_inputs(metric, detections, ellipsoids, camera, penalty_cost, min_depth_margin)
        self.metric = metric
        self.detections = tuple(detections)
        self.ellipsoids = tuple(ellipsoids)
        self.camera = camera
        self.options: dict[str, object] = dict(metric_options or {})
        if metric == "qbbox" and "image_size" not in self.options:
            self.options["image_size"] = (camera.width, camera.height)
        self.min_depth_margin = float(min_depth_margin)
        self.penalty_cost = float(penalty_cost)
        self.numeric_step = float(numeric_step or DEFAULT_NUMERIC_STEP.get(metric, 1e-6))
        # analytic Jacobians are cheap: compute them with every residual evaluation, since
        # LM linearises next at (almost) every pose whose error it evaluates
        self.eager_jacobian = (metric in ANALYTIC_METRICS) if eager_jacobian is None \
            else bool(eager_jacobian)
        self.analytic = metric in ANALYTIC_METRICS
        self.n = len(self.detections)
        self._ellipsoid_arrays = EllipsoidArrays(self.ellipsoids)
        self._detection_params: FloatArray = np.array(
            [(d.cx, d.cy, d.a, d.b, d.angle) for d in self.detections])
        self._memo: tuple[bytes, bool, PoseEvaluation] | None = None
        T0 = None if initial_world_from_camera is None else check_pose(
            initial_world_from_camera, "initial_world_from_camera")
        #: the level-set family (its samples: relayout, sampling_scale), None for other metrics
        self._level_set = None if metric != "level_set" else LevelSetResiduals(
            self._detection_params, self._ellipsoid_arrays, camera, self.options,
            self.min_depth_margin, T0)
        self._family: PoseResidualFamily = self._level_set if self._level_set is not None \
            else self._make_family()
        self.dim = self._family.dim
        self._penalty = self._make_penalty()

    def _make_family(self) -> PoseResidualFamily:
        """The residual family of a metric other than the level set."""
        args = (self._ellipsoid_arrays, self.camera, self.options, self.min_depth_margin)
        if not self.analytic:
            return CentralDifferenceResiduals(self.metric, self.detections, *args,
                                              self.numeric_step, expmap_pose3)
        if self.metric in ("iou", "giou"):
            return OverlapResiduals(self.metric, self._detection_params, *args)
        return ConicMetricResiduals(self.metric, self._detection_params, *args)

    def _make_penalty(self) -> DepthMarginPenalty:
        """The penalty and saturation of the current sample layout (level_set's penalty costs
        depend on its sampling scales)."""
        costs = penalty_costs(
            self.metric, self.penalty_cost, self._detection_params, self.camera,
            None if self._level_set is None else self._level_set.sampling_scale)
        return DepthMarginPenalty(costs, self._ellipsoid_arrays.largest_semi_axes,
                                  self.min_depth_margin, self.dim)

    # ------------------------------------------------------------------ level-set layout
    def relayout(self, world_from_camera: FloatArray) -> None:
        """Level set: lay the samples out again for the misalignment at ``world_from_camera``
        (4x4, e.g. an LM result; not re-validated) and forget the memoised evaluation. The
        residual size is unchanged, so factors built on this model stay valid."""
        if self._level_set is None:
            raise ValueError(f"relayout applies to the level_set metric, not {self.metric!r}")
        self._level_set.lay_out(np.asarray(world_from_camera, dtype=float))
        self._penalty = self._make_penalty()
        self._memo = None

    @property
    def sampling_scale(self) -> FloatArray:
        """Level set only: the outermost sampled level radius per detection (N,), in detection
        radii (``AttributeError`` for the other metrics)."""
        if self._level_set is None:
            raise AttributeError(f"sampling_scale: the {self.metric!r} metric has no samples")
        return self._level_set.sampling_scale

    @property
    def sampling_grown(self) -> bool:
        """Level set: some detection's sampled area was grown for the misalignment at the
        initial pose (see :meth:`relayout`); always False for the other metrics."""
        return self._level_set is not None and self._level_set.sampling_grown

    @property
    def sample_points(self) -> FloatArray:
        """Level set only: the fixed sample points (N, M, 2), pixels."""
        if self._level_set is None:
            raise AttributeError(f"sample_points: the {self.metric!r} metric has no samples")
        return self._level_set.sample_points

    @property
    def penalty_costs(self) -> FloatArray:
        """Per-pair penalty cost ``P_j`` (N,), read-only (:mod:`quadloc.factors.pose_penalty`)."""
        return self._penalty.costs

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, world_from_camera: FloatArray, jacobian: bool = True) -> PoseEvaluation:
        """Residuals (and Jacobians if ``jacobian``) of all pairs at ``world_from_camera`` (4x4).

        Memoised on the pose value: repeated calls at the same pose cost one comparison.
        """
        T = np.asarray(world_from_camera, dtype=float)
        key = T.tobytes()
        memo = self._memo
        if memo is not None and key == memo[0] and (memo[1] or not jacobian):
            return memo[2]
        jacobian = jacobian or self.eager_jacobian
        rows = self._family.rows(T, jacobian)
        if rows.sum_squares is None and not rows.valid.all():
            frame = self._ellipsoid_arrays.camera_frame(T) if rows.frame is None else rows.frame
            self._penalty.replace_invalid(rows.residuals, rows.jacobians, ~rows.valid, frame,
                                          rows.depth_margins)
        ev = self._saturate(rows)
        # the family's arrays are read-only already when it gave sum_squares (PairRows)
        arrays = [] if rows.sum_squares is not None else \
            [ev.residuals, ev.jacobians, ev.valid, ev.depth_margins]
        if ev.factor_residuals is not ev.residuals:  # saturated rows (else the same arrays)
            arrays += [ev.factor_residuals, ev.factor_jacobians]
        for arr in arrays:
            if arr is not None:
                arr.setflags(write=False)
        self._memo = (key, jacobian, ev)
        return ev

    def _saturate(self, rows: PairRows) -> PoseEvaluation:
        """The evaluation of ``rows`` (penalty applied) with the factors' residuals: the valid
        rows saturated (:meth:`quadloc.factors.pose_penalty.DepthMarginPenalty.saturate`)."""
        r, J = self._penalty.saturate(rows.residuals, rows.jacobians, rows.valid,
                                      rows.sum_squares)
        return PoseEvaluation(rows.residuals, rows.jacobians, rows.valid, rows.depth_margins,
                              r, J)

    # ------------------------------------------------------------------ reporting
    def costs(self, world_from_camera: FloatArray) -> FloatArray:
        """The metric's unweighted cost ``||r_j||^2`` of each pair at a pose (N,), unsaturated;
        the penalty's cost where the projection is invalid."""
        ev = self.evaluate(world_from_camera, jacobian=False)
        costs: FloatArray = np.einsum("nm,nm->n", ev.residuals, ev.residuals)
        return costs


def compile_kernels() -> None:
    """Compile the numeric kernels (level set, camera frame and dual conics, exact areas and
    iou / giou rows, the batched projection of :func:`quadloc.factors.camera.projected_gaussians`;
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
