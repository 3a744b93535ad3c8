"""Camera pose refinement: the metric factors + Levenberg-Marquardt (the paper's section V).

:func:`refine` takes matched detections and map ellipsoids (same order), the camera
intrinsics and an initial ``world_from_camera`` pose (4x4, OpenCV camera axes) and minimises
the paper's equation 8, ``sum_j sigma_j^-1 Delta_j``, over the pose with
``gtsam.LevenbergMarquardtOptimizer`` on the factors of
:func:`quadloc.factors.pose_factors.pose_factors` (one batched factor without robust kernel, one per
detection with one), plus an optional ``PriorFactorPose3`` and a measured gravity direction
(:func:`quadloc.factors.gravity_factor.gravity_factor`). Adaptive level-set samples grown at the
start are re-laid once at the result and solved again (``iterations`` counts both solves; skipped
past the ``deadline``: ``RefinementResult.resample_skipped``).

``covariance``: 6x6, order ``[omega_x, omega_y, omega_z, v_x, v_y, v_z]`` (rad, m), right
perturbation, CAMERA (body) frame: the inverse of the Gauss-Newton information ``J^T W J`` at
the solution (None with ``covariance_reason`` when singular or ill conditioned). Why the
stopping tolerances are what they are, and how the covariance is computed:
``docs/design/localization.md``.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.gravity_factor import GravityMeasurement, gravity_factor
from quadloc.factors.names import GeometryError, check_robust
from quadloc.factors.pose_factors import pose3, pose_factors
from quadloc.factors.pose_residuals import PoseResidualModel
from quadloc.factors.rotations import check_pose
from quadloc.service.localization.types import (
    Detection,
    check_covariance,
    check_detections,
    check_options,
)

__all__ = [
    "ABSOLUTE_ERROR_TOL",
    "DEFAULT_MAX_ITERATIONS",
    "ERROR_TOL",
    "INFORMATION_CONDITION_LIMIT",
    "LAMBDA_UPPER_BOUND",
    "OVERLAP_NIELSEN_DAMPING",
    "OVERLAP_RELATIVE_ERROR_TOL",
    "RELATIVE_ERROR_TOL",
    "STAGES",
    "STATUSES",
    "RefinementResult",
    "refine",
]

#: LM's iteration cap when the caller gives none (both solves together).
DEFAULT_MAX_ITERATIONS = 50
ERROR_TOL = 1e-20
RELATIVE_ERROR_TOL = 1e-6
#: iou / giou: their residual is not smooth at the optimum of noisy detections (areas of
#: symmetric differences), so LM creeps there, by < 1e-3 of the error per iteration, for
#: hundreds of iterations (module docstring).
OVERLAP_RELATIVE_ERROR_TOL = 1e-3
ABSOLUTE_ERROR_TOL = 0.0
#: iou / giou: LM's lambda follows Nielsen's gain-ratio update (``_lm_params``) instead of
#: GTSAM's fixed factor 10 (lambda / 10 after every accepted step, x 10 after every rejected
#: one), which at their kinked noisy optimum (areas of symmetric differences) falls to ~1e-8
#: and then climbs back through ~10 rejected trials: ~1.7 model evaluations per LM iteration
#: instead of ~2.6 (``bench.overlap_refinement``, docs/results.md). The damping stays
#: ``lambda I``: Marquardt's ``lambda diag(J^T J)`` barely damps the directions that few
#: overlapping pairs leave weak, and from starts 0.2 m / 10 deg off its first steps jumped
#: metres away (within 10 cm: iou 71-73 % against 80-82 % with ``lambda I``, 108 frames x 2
#: seeds of ``bench.chess_eval``'s convergence experiment).
OVERLAP_NIELSEN_DAMPING = True


#: LM gives up an iteration when lambda exceeds this (GTSAM default 1e5 is too low for the
#: sqrt-of-area residuals of iou/giou, whose Jacobians are ~1e4 near the optimum).
LAMBDA_UPPER_BOUND = 1e10
#: The covariance is reported only if cond(information) is below this.
INFORMATION_CONDITION_LIMIT = 1e12
#: Possible ``RefinementResult.status`` values.
STATUSES = ("converged", "max_iterations", "time_budget", "diverged", "invalid_projection")

_POSE_KEY = 0


@dataclass(frozen=True)
class RefinementResult:
    """Outcome of :func:`refine`.

    Attributes:
        world_from_camera: refined 4x4 camera pose in the map (OpenCV camera axes).
        covariance: 6x6 pose covariance, order ``[omega, v]`` (rad, m), right perturbation,
            camera (body) frame; None when the information matrix is singular.
        covariance_reason: why ``covariance`` is None (else None).
        per_detection_cost: (N,) the metric's unweighted cost ``Delta_j = ||r_j||^2`` at the
            final pose (level set: on the sample points fixed at the start; iou: a pair whose
            ellipses are disjoint has the giou rows, ``Delta_j`` > 1); ``inf`` where the
            projection is not an ellipse.
        valid_projection: (N,) bool, the projection of pair ``j`` is an ellipse at the final pose.
        initial_error, total_error: GTSAM's weighted error ``0.5 sum_j ||r_j||^2 / sigma_j``
            (plus the prior's) at the initial and final pose, each with the level-set sample
            layout of its own solve: after a re-lay they are costs of different functions and
            need not decrease.
        iterations: LM iterations performed.
        converged: ``status == "converged"``.
        status: one of :data:`STATUSES`: ``converged`` (LM met a stopping tolerance),
            ``max_iterations`` (the cap was reached first), ``time_budget`` (the ``deadline``
            passed first; the pose is the last accepted LM step), ``invalid_projection`` (some
            ellipsoid's projection is not an ellipse at the final pose: behind the camera,
            crossing its principal plane or containing it), ``diverged`` (GTSAM failed or
            the result is not finite; the initial pose is returned).
        time_ms: wall time of the whole call (graph build, LM, covariance), milliseconds.
        resample_skipped: the first solve grew adaptive level-set samples but the
            ``deadline`` had passed, so the re-laid second solve was not run (the status is
            the first solve's).
        chi2: ``sum_j ||r_j||^2 / w_j`` at the final pose over the pairs with a valid
            projection (``w_j = sigma_j`` with sigma weighting, else 1; no robust kernel, no
            prior): the weighted residual sum of squares ``r^T W r`` of the metric factors.
        n_residuals: number of scalar residuals of the metric factors (N x the metric's
            residual size), the ``m`` of ``s^2 = chi2 / (m - 6)``.
        fixed_information: (6, 6) the information the prior and gravity factors contribute
            at the final pose (``A^T A`` of their whitened linearisations; same order and frame
            as ``covariance``), None without them: the part of ``covariance^-1`` that is not
            the detections' (``confidence.calibrated_covariance`` rescales only the rest).
        gravity_chi2: the gravity factor's whitened squared error at the final pose (0 without
            gravity): with ``chi2``, how well a pose explains everything measured.
        stages_ms: wall time of each stage of the call, milliseconds, keys :data:`STAGES`
            (``validate``: the argument checks; ``build``: the residual model, its factors and
            the graph; ``solve``: the LM solve(s); ``relayout``: the level-set samples laid out
            again between them; ``covariance``: covariance and fixed factors' information;
            ``finish``: costs, chi2, the result): where a refinement's time goes
            (``bench.peer_refine`` reports them).
    """

    world_from_camera: FloatArray
    covariance: FloatArray | None
    covariance_reason: str | None
    per_detection_cost: FloatArray
    valid_projection: BoolArray
    initial_error: float
    total_error: float
    iterations: int
    converged: bool
    status: str
    time_ms: float
    resample_skipped: bool = False
    chi2: float = math.nan
    n_residuals: int = 0
    fixed_information: FloatArray | None = None
    gravity_chi2: float = 0.0
    stages_ms: Mapping[str, float] = field(default_factory=dict)


#: The stages of :attr:`RefinementResult.stages_ms`, in their order.
STAGES = ("validate", "build", "solve", "relayout", "covariance", "finish")


def _lm_params(max_iterations: int, metric: str = "level_set") -> gtsam.LevenbergMarquardtParams:
    """LM parameters of a solve of ``metric`` (shared: do not modify; the optimizer copies
    them). :data:`OVERLAP_NIELSEN_DAMPING` is read at every call (part of the cache key)."""
    return _shared_lm_params(max_iterations,
                             metric in ("iou", "giou") and OVERLAP_NIELSEN_DAMPING)


@functools.lru_cache(maxsize=64)
def _shared_lm_params(max_iterations: int, nielsen: bool) -> gtsam.LevenbergMarquardtParams:
    """:func:`_lm_params`, cached per ``(max_iterations, nielsen)``: ``nielsen``, Nielsen's
    lambda update instead of GTSAM's fixed factor."""
    params = gtsam.LevenbergMarquardtParams()
    # one pose variable: sequential elimination solves the same dense 6x6 Cholesky as the
    # default multifrontal one (bit-identical steps, tested) without building a junction
    # tree: ~2 us less per LM iteration (measured with GTSAM 4.3.0)
    params.setLinearSolverType("SEQUENTIAL_CHOLESKY")
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(RELATIVE_ERROR_TOL)
    params.setAbsoluteErrorTol(ABSOLUTE_ERROR_TOL)
    params.setErrorTol(ERROR_TOL)
    params.setlambdaUpperBound(LAMBDA_UPPER_BOUND)
    if nielsen:
        params.setUseFixedLambdaFactor(False)
    return params


def refine(
    detections: Sequence[Detection],
    ellipsoids: Sequence[Ellipsoid],
    camera: Camera,
    initial_world_from_camera: FloatArray,
    metric: str = "level_set",
    *,
    use_sigma: bool = True,
    robust: str | None = None,
    robust_scale: float | None = None,
    prior_world_from_camera: FloatArray | None = None,
    prior_covariance: FloatArray | None = None,
    gravity: GravityMeasurement | None = None,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    metric_options: Mapping[str, Any] | None = None,
    deadline: Deadline | None = None,
) -> RefinementResult:
    """Refine the camera pose by minimising ``sum_j sigma_j^-1 Delta_j`` (paper eq. 8) with LM.

    Args:
        detections: N matched detections (ellipse in pixels, optional ``sigma``).
        ellipsoids: the N map ellipsoids (world frame), ``ellipsoids[j]`` matched to
            ``detections[j]``.
        camera: pinhole intrinsics of the image.
        initial_world_from_camera: 4x4 starting pose (camera in the map, OpenCV axes).
        metric: one of ``quadloc.factors.metrics.METRIC_NAMES``.
        use_sigma: weight detection ``j`` by ``sigma_j^-1`` when it has a sigma (else weight 1).
        robust: None or a kernel in ``quadloc.factors.pose_factors.ROBUST_KERNELS``, per detection.
        robust_scale: kernel threshold on the whitened residual norm (default per metric,
            ``quadloc.factors.pose_factors.DEFAULT_ROBUST_SCALE``).
        prior_world_from_camera, prior_covariance: optional pose prior (4x4) and its 6x6
            covariance in GTSAM's Pose3 tangent order ``[omega, v]``, body frame; both or neither.
        gravity: optional measured gravity direction, a factor on the pose's roll and pitch.
        max_iterations: LM iteration cap (>= 1).
        metric_options: options of the metric (e.g. level-set sampling), see
            ``quadloc.factors.metrics``.
        deadline: optional stop after which no further LM iteration starts (the per-request
            solve budget of the service: CPU time of this thread with a wall-clock hard limit,
            :meth:`quadloc.factors.budget.Deadline.cpu_budget`); None = no limit.

    Returns:
        :class:`RefinementResult`.

    Raises:
        ValueError (``GeometryError``): bad input, the message names the field.
    """
    t_start = time.perf_counter()
    check_detections(detections, GeometryError)
    if len(ellipsoids) != len(detections):
        raise GeometryError(f"ellipsoids must match detections one to one: got "
                            f"{len(ellipsoids)} ellipsoids for {len(detections)} detections")
    T0 = check_pose(initial_world_from_camera, "initial_world_from_camera")
    check_options({"max_iterations": max_iterations, "use_sigma": use_sigma}, GeometryError, "")
    max_iterations = int(max_iterations)
    check_robust(robust, robust_scale, error=GeometryError)
    if (prior_world_from_camera is None) != (prior_covariance is None):
        raise GeometryError("prior_world_from_camera and prior_covariance must be given together")
    prior = None if prior_covariance is None else (
        check_pose(prior_world_from_camera, "prior_world_from_camera"),
        check_covariance("prior_covariance", prior_covariance, GeometryError))

    sigmas = [d.sigma if use_sigma else None for d in detections]
    resample = metric == "level_set" and bool((metric_options or {}).get("adaptive", True))
    if gravity is not None and not isinstance(gravity, GravityMeasurement):
        raise GeometryError(f"gravity: must be a GravityMeasurement or None, got "
                            f"{type(gravity).__name__}")
    stages = dict.fromkeys(STAGES, 0.0)
    t = time.perf_counter()
    stages["validate"] = t - t_start
    graph, model, n_metric_factors = _build_graph(
        detections, ellipsoids, camera, T0, metric, sigmas, robust, robust_scale, prior,
        gravity, metric_options)
    t, t_prev = time.perf_counter(), t
    stages["build"] = t - t_prev
    T_start, total_iterations, initial_error = T0, 0, math.nan
    start_pose: gtsam.Pose3 | None = None
    relaid_skipped = False
    for pass_ in range(2 if resample else 1):
        outcome = _solve(graph, model, T_start, max_iterations - total_iterations, deadline,
                         start_pose)
        t, t_prev = time.perf_counter(), t
        stages["solve"] += t - t_prev
        total_iterations += outcome.iterations
        if pass_ == 0:
            initial_error = outcome.initial_error
        if pass_ == 1 or outcome.status in ("diverged", "invalid_projection", "time_budget") \
                or total_iterations >= max_iterations or not model.sampling_grown:
            break
        if deadline_passed(deadline):
            # no time for the re-laid solve: keep the first solve and its status, and say the
            # re-lay was skipped
            relaid_skipped = True
            break
        # Some adaptive level-set sample areas were grown for the misalignment at T_start
        # (quadloc.factors.metrics.level_set_sampling_scale); re-lay them at the result and solve
        # again (same factors: the model's samples change in place).
        T_start = outcome.T
        start_pose = outcome.result.atPose3(_POSE_KEY)
        model.relayout(T_start)
        t, t_prev = time.perf_counter(), t
        stages["relayout"] += t - t_prev
    status = outcome.status
    if status == "converged" and total_iterations >= max_iterations:
        status = "max_iterations"
    weights = np.array([s if s is not None else 1.0 for s in sigmas])
    covariance: FloatArray | None
    reason: str | None
    if status == "diverged":
        covariance, reason = None, "refinement diverged"
    elif status == "invalid_projection":
        covariance, reason = None, "a projection is not an ellipse at the final pose"
    elif robust is None and graph.size() == n_metric_factors:
        covariance, reason = _batched_covariance(model, outcome.T, weights)
    else:
        covariance, reason = _covariance(graph, outcome.result)
    fixed_information, gravity_chi2 = _fixed_factors(graph, n_metric_factors, outcome.result,
                                                     gravity is not None)
    t, t_prev = time.perf_counter(), t
    stages["covariance"] = t - t_prev
    ok = outcome.valid
    if ok.all():  # the usual case, without the masked copies
        chi2 = float(np.sum(outcome.costs / weights))
    else:
        chi2 = float(np.sum(outcome.costs[ok] / weights[ok])) if ok.any() else math.inf
    t_end = time.perf_counter()
    stages["finish"] = t_end - t
    return RefinementResult(
        world_from_camera=outcome.T, covariance=covariance, covariance_reason=reason,
        per_detection_cost=outcome.costs, valid_projection=outcome.valid,
        initial_error=initial_error,
        total_error=outcome.total_error, iterations=total_iterations,
        converged=status == "converged", status=status,
        time_ms=(t_end - t_start) * 1e3,
        resample_skipped=relaid_skipped, chi2=chi2, n_residuals=len(detections) * model.dim,
        fixed_information=fixed_information, gravity_chi2=gravity_chi2,
        stages_ms={k: v * 1e3 for k, v in stages.items()},
    )


@dataclass(frozen=True)
class _SolveOutcome:
    T: FloatArray
    result: gtsam.Values
    costs: FloatArray
    valid: BoolArray
    initial_error: float
    total_error: float
    iterations: int
    status: str


def _build_graph(
    detections: Sequence[Detection], ellipsoids: Sequence[Ellipsoid], camera: Camera,
    T0: FloatArray, metric: str, sigmas: list[float | None], robust: str | None,
    robust_scale: float | None, prior: tuple[FloatArray, FloatArray] | None,
    gravity: GravityMeasurement | None, metric_options: Mapping[str, Any] | None,
) -> tuple[gtsam.NonlinearFactorGraph, PoseResidualModel, int]:
    """The factor graph of one refinement, its shared residual model (level-set samples
    laid out at ``T0``) and the number of metric factors (first in the graph; then the prior's
    and the gravity's)."""
    # without robust kernels one batched factor (Diagonal noise = the same per-detection
    # weights) saves N-1 Python round trips per evaluation; with them, one factor per
    # detection, all slicing one shared evaluation (see quadloc.factors.pose_factors)
    factors, model = pose_factors(
        metric, _POSE_KEY, [d.ellipse for d in detections], list(ellipsoids), camera,
        sigmas=sigmas, robust=robust, robust_scale=robust_scale,
        initial_world_from_camera=T0, metric_options=metric_options, batched=robust is None,
    )
    graph = gtsam.NonlinearFactorGraph()
    for f in factors:
        graph.add(f)
    if prior is not None:
        graph.add(gtsam.PriorFactorPose3(_POSE_KEY, pose3(prior[0]),
                                         gtsam.noiseModel.Gaussian.Covariance(prior[1])))
    if gravity is not None:
        graph.add(gravity_factor(_POSE_KEY, gravity))  # last (_fixed_factors)
    return graph, model, len(factors)


def _fixed_factors(graph: gtsam.NonlinearFactorGraph, n_metric_factors: int,
                   values: gtsam.Values, with_gravity: bool) -> tuple[FloatArray | None, float]:
    """(information (6, 6) of the factors after the metric ones at ``values``, or None
    without; the gravity factor's whitened squared error, 0 without)."""
    if graph.size() == n_metric_factors:
        return None, 0.0
    info = np.zeros((6, 6))
    for i in range(n_metric_factors, graph.size()):
        A, _ = graph.at(i).linearize(values).jacobian()
        info += A.T @ A
    gravity_chi2 = 2.0 * float(graph.at(graph.size() - 1).error(values)) if with_gravity \
        else 0.0
    return info, gravity_chi2


def _solve(
    graph: gtsam.NonlinearFactorGraph, model: PoseResidualModel, T0: FloatArray,
    max_iterations: int, deadline: Deadline | None = None,
    start_pose: gtsam.Pose3 | None = None,
) -> _SolveOutcome:
    """One LM solve of ``graph`` from ``T0`` (``start_pose``: the same pose as a ``Pose3``, e.g.
    a previous solve's result, which saves re-snapping its rotation); final costs from
    ``model``."""
    initial = gtsam.Values()
    initial.insert(_POSE_KEY, start_pose if start_pose is not None else pose3(T0))

    status = "converged"
    initial_error = math.nan
    try:
        params = _lm_params(max_iterations, model.metric)
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        initial_error = float(optimizer.error())  # the graph's error at ``initial``
        if initial_error <= ERROR_TOL:
            # what GTSAM's optimize() does first (no iteration below errorTol), e.g. the
            # re-laid solve of exact detections
            result, iterations, T, total_error = initial, 0, T0, initial_error
        else:
            accepted_tol = OVERLAP_RELATIVE_ERROR_TOL if model.metric in ("iou", "giou") \
                else None
            if deadline is None and accepted_tol is None:
                result = optimizer.optimize()
            elif _optimize_until(optimizer, params, deadline, accepted_tol):
                result = optimizer.values()
            else:
                result, status = optimizer.values(), "time_budget"
            iterations = int(optimizer.iterations())
            T = result.atPose3(_POSE_KEY).matrix()
            total_error = float(optimizer.error())  # the error of ``result``
    except (RuntimeError, np.linalg.LinAlgError):  # e.g. an indeterminant linear system
        if math.isnan(initial_error):
            try:
                initial_error = float(graph.error(initial))
            except (RuntimeError, np.linalg.LinAlgError):  # the start itself cannot be scored
                initial_error = math.inf
        result, iterations, T, total_error = initial, 0, T0, initial_error
        status = "diverged"
    if not (math.isfinite(total_error) and np.isfinite(T).all()):
        result, T, total_error, status = initial, T0, initial_error, "diverged"

    ev = model.evaluate(T, jacobian=False)
    valid = ev.valid.copy()
    costs = (ev.residuals * ev.residuals).sum(axis=1)
    if not valid.all():
        costs[~valid] = np.inf
        if status != "diverged":
            status = "invalid_projection"
    return _SolveOutcome(T, result, costs, valid, initial_error, total_error, iterations,
                         status)


def _optimize_until(
    optimizer: gtsam.LevenbergMarquardtOptimizer, params: gtsam.LevenbergMarquardtParams,
    deadline: Deadline | None, accepted_relative_tol: float | None = None,
) -> bool:
    """GTSAM's ``optimize()`` loop (same stopping rules), stepped from Python so that no
    iteration starts after ``deadline`` (None: no deadline). With ``accepted_relative_tol`` it
    also stops after an iteration that was ACCEPTED (the error decreased) but decreased it by
    less than that fraction (:data:`OVERLAP_RELATIVE_ERROR_TOL`; not GTSAM's own
    ``relativeErrorTol``, which also ends the lambda search of a REJECTED step whose cost
    change is below it, leaving the pose where it was). True if it stopped by itself, False at
    the deadline."""
    current = optimizer.error()
    if current <= params.getErrorTol():
        return True
    while optimizer.iterations() < params.getMaxIterations():
        if deadline_passed(deadline):
            return False
        optimizer.iterate()
        new = optimizer.error()
        if not math.isfinite(new) or optimizer.lambda_() > params.getlambdaUpperBound() \
                or gtsam.checkConvergence(params, current, new):
            return True
        if accepted_relative_tol is not None and new < current \
                and current - new < accepted_relative_tol * current:
            return True
        current = new
    return True


def _batched_covariance(
    model: PoseResidualModel, T: FloatArray, weights: FloatArray
) -> tuple[FloatArray | None, str | None]:
    """Covariance of the pose from the batched factor alone (no robust kernel, no prior):
    ``(J^T W J)^-1`` with ``J`` (N*m, 6) the factor's Jacobian at ``T`` (the memoised
    evaluation LM ended with) and ``W`` the rows' weights ``1 / w_j`` (``weights`` (N,)), which
    is what ``gtsam.Marginals`` computes for that graph (tested), without linearising it."""
    J = model.evaluate(T, jacobian=True).factor_jacobians
    assert J is not None  # evaluated with jacobian=True
    Jw = J / weights[:, None, None]
    info = Jw.reshape(-1, 6).T @ J.reshape(-1, 6)
    if not np.isfinite(info).all():
        return None, "information matrix is not finite"
    eig, V = np.linalg.eigh(0.5 * (info + info.T))
    reason = _singular_reason(eig)
    if reason is not None:
        return None, reason
    return (V / eig) @ V.T, None


def _singular_reason(info_eigenvalues: FloatArray) -> str | None:
    """Why an information matrix with these eigenvalues (ascending) gives no covariance (not
    finite, not positive definite, or condition number >= ``INFORMATION_CONDITION_LIMIT``),
    else None."""
    eig = info_eigenvalues
    if np.isfinite(eig).all() and eig[0] > 0.0 \
            and eig[-1] < eig[0] * INFORMATION_CONDITION_LIMIT:
        return None
    pos = eig[np.isfinite(eig) & (eig > 0)]
    rank = int(np.sum(pos > pos.max() / INFORMATION_CONDITION_LIMIT)) if pos.size else 0
    return (f"information matrix is singular (numerical rank {rank} < 6): the "
            f"detections do not constrain all 6 DoF")


def _covariance(
    graph: gtsam.NonlinearFactorGraph, values: gtsam.Values
) -> tuple[FloatArray | None, str | None]:
    """Marginal covariance of the pose (``gtsam.Marginals``: robust kernels, prior), or None
    and the reason."""
    try:
        cov = np.asarray(gtsam.Marginals(graph, values).marginalCovariance(_POSE_KEY))
    except RuntimeError as exc:  # indeterminant linear system
        return None, f"information matrix is singular: {exc}".strip()
    eig = np.linalg.eigvalsh(0.5 * (cov + cov.T))
    # the information's eigenvalues are the covariance's inverses (non-positive ones kept)
    pos = eig > 0
    reason = _singular_reason(np.sort(np.where(pos, 1.0 / np.where(pos, eig, 1.0), eig)))
    if reason is not None:
        return None, reason
    return cov, None
