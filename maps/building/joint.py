"""Joint refinement of all ellipsoids (and optionally the camera poses) in ONE GTSAM graph.

Variables: per object ``E_k`` (``Pose3``: ellipsoid frame -> world, translation = centre) and
``L_k`` (``Vector3``: log semi-axes, metres); with ``refine_cameras`` also per frame ``X_f``
(``Pose3`` ``world_from_camera``, OpenCV camera axes).

Factors (docs/design/maps.md, "Joint refinement"): the level-set views factor of localization
(:func:`quadloc.factors.ellipsoid_factors.ellipsoid_views_factor`, Huber kernel per view, truncated
detections down-weighted); ``size_priors`` or a weak prior on the semi-axes the views leave
unconstrained; a one-sided floor on every semi-axis; with ``refine_cameras`` a gauge prior and
odometry between factors. :class:`ObjectQuality` reports each object's views, spread, residual
and the marginal std of its log semi-axes and centre.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import gtsam
import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import (
    TRUNCATED_WEIGHT,
    Camera,
    Ellipsoid,
    touches_border,
    truncation_sigma,
)
from quadloc.factors.ellipsoid_factors import ellipsoid_views_factor, valid_views
from quadloc.factors.ellipsoid_residuals import (
    LevelSetSamples,
    level_set_samples,
    observation_residual,
    stack_samples,
)
from quadloc.factors.pose_factors import DEFAULT_ROBUST_SCALE, pose3
from quadloc.factors.pose_residuals import DEFAULT_MIN_DEPTH_MARGIN
from quadloc.factors.rotations import invert_pose, pose_matrix
from quadloc.maps.building.recording import Observation, OdometryNoise, SizePrior
from quadloc.maps.reconstruct import canonical_ellipsoid, max_ray_angle_deg

__all__ = ["JointResult", "ObjectQuality", "refine_jointly"]

#: Marginal std of a log semi-axis above which the axis is reported unconstrained.
UNCONSTRAINED_LOG_STD = 0.3
#: Std (log metres) of the prior on the log semi-axes that the views leave unconstrained at the
#: initial estimate (towards the object's mean log semi-axis); None disables it (tuning: design
#: doc).
UNCONSTRAINED_PRIOR_SIGMA: float | None = 0.5
#: ``sigma`` assumed for detections without one in the quality report's axis uncertainty (a
#: level-set residual std of ``sqrt(2.5e-3) = 0.05``, typical of a fine-tuned detector; the
#: optimisation itself weights them 1, as localization does).
QUALITY_DEFAULT_SIGMA = 2.5e-3
#: Floor of every semi-axis, as a fraction of the object's initial mean semi-axis (geometric),
#: held by a one-sided prior (zero cost above it, std ``AXIS_FLOOR_LOG_SIGMA`` in log below;
#: None: no floor; why: design doc).
AXIS_FLOOR_FRACTION: float | None = 0.05
AXIS_FLOOR_LOG_SIGMA = 0.1
#: With ``refine_cameras``: consecutive frames whose views share one factor.
FRAMES_PER_FACTOR = 3


@dataclass(frozen=True)
class ObjectQuality:
    """Per-object quality (see the module docstring); angles in degrees."""

    n_views: int
    view_spread_deg: float
    residual_cost: float
    rms_level_residual: float
    log_axis_std: tuple[float, float, float]
    unconstrained_axes: tuple[int, ...]
    center_std_m: float = math.nan


@dataclass(frozen=True)
class JointResult:
    ellipsoids: list[Ellipsoid]
    quality: list[ObjectQuality]
    world_from_camera: FloatArray
    iterations: int
    initial_error: float
    final_error: float
    stopped_early: bool



def _log_axis_std(T_cw: FloatArray, R: FloatArray, center: FloatArray, axes: FloatArray,
                  samples: LevelSetSamples, info_weights: FloatArray
                  ) -> tuple[FloatArray, FloatArray, BoolArray, float]:
    """Marginal std (3,) of the log semi-axes (in the order of ``axes``) from the views'
    Gauss-Newton information on ``[omega, v, log axes]`` (cameras fixed), each view weighted by
    ``info_weights`` (1/sigma); also the residuals (V', M) of the views in front, their mask and
    the largest std (m) of the centre along any direction.
    Views that are not valid (:func:`quadloc.factors.ellipsoid_factors.valid_views`) are
    skipped."""
    ok = valid_views(T_cw, R, center, axes, DEFAULT_MIN_DEPTH_MARGIN)
    if not ok.any():
        return np.full(3, np.inf), np.zeros((0, samples.n.shape[-1])), ok, math.inf
    sub = LevelSetSamples(None, samples.n[ok], samples.phi_det_minus_1[ok])
    r, J, _ = observation_residual(T_cw[ok], R, center, axes, sub)
    assert J is not None  # jacobians asked for (the default)
    H = np.einsum("v,vmi,vmj->ij", info_weights[ok], J, J)
    try:
        cov = np.linalg.inv(H + 1e-12 * np.trace(H) * np.eye(9))
        std: FloatArray = np.sqrt(np.maximum(np.diag(cov)[6:], 0.0))
        # centre: c -> c + R v, so its covariance is R cov_v R^T; largest std of any direction
        center_std = float(np.sqrt(max(np.linalg.eigvalsh(R @ cov[3:6, 3:6] @ R.T).max(), 0)))
    except np.linalg.LinAlgError:
        std, center_std = np.full(3, np.inf), math.inf
    return std, r, ok, center_std


def _floor_factor(key: int, floor: float, sigma: float) -> gtsam.CustomFactor:
    """One-sided prior on a ``Vector3`` (log semi-axes): residual ``max(0, floor - x_i)``,
    std ``sigma``: no cost at or above ``floor``."""

    def error_fn(this: gtsam.CustomFactor, values: gtsam.Values,
                 H: gtsam.JacobianVector | None) -> FloatArray:
        x = values.atVector(key)
        below = x < floor
        if H is not None:
            H[0] = np.diag(np.where(below, -1.0, 0.0))
        return np.where(below, floor - x, 0.0)

    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(3, sigma), [key], error_fn)


@dataclass
class _Ticker:
    """Counts factor evaluations and reports fractional LM progress at most every
    ``interval_s`` from inside an iteration (one iteration of a large graph, e.g. with camera
    poses, can take seconds): ``progress(iteration + fraction, last error)`` with ``fraction``
    the evaluations so far over about three per factor and iteration (a linearisation and two
    error evaluations), capped below 1."""

    progress: Callable[[float, float], None] | None
    interval_s: float = 0.5
    n_factors: int = 1
    iteration: int = 0
    error: float = math.nan
    count: int = 0
    last: float = field(default_factory=time.monotonic)

    def new_iteration(self, iteration: int, error: float) -> None:
        self.iteration, self.error, self.count = iteration, error, 0
        self.last = time.monotonic()

    def __call__(self) -> None:
        self.count += 1
        if self.progress is None:
            return
        now = time.monotonic()
        if now - self.last >= self.interval_s:
            self.last = now
            frac = min(0.95, self.count / (3.0 * self.n_factors))
            self.progress(self.iteration + frac, self.error)


def refine_jointly(
    camera: Camera, world_from_camera: FloatArray, observations: Sequence[Observation],
    objects: Sequence[tuple[str, Sequence[int], Ellipsoid]], *,
    size_priors: Mapping[str, SizePrior] | None = None, refine_cameras: bool = False,
    odometry: OdometryNoise | None = None, max_iterations: int = 30,
    deadline: Deadline | None = None,
    progress: Callable[[float, float], None] | None = None,
    unconstrained_log_std: float = UNCONSTRAINED_LOG_STD,
    truncated_weight: float = TRUNCATED_WEIGHT,
    unconstrained_prior_sigma: float | None = UNCONSTRAINED_PRIOR_SIGMA,
    frames_per_factor: int = FRAMES_PER_FACTOR,
    axis_floor_fraction: float | None = AXIS_FLOOR_FRACTION,
    initial_world_from_camera: FloatArray | None = None,
) -> JointResult:
    """Refine ``objects`` = ``(label, observation indices, initial ellipsoid)`` jointly.

    ``world_from_camera`` (F, 4, 4): the frames' poses (app's world frame). ``deadline``: the
    :class:`quadloc.factors.budget.Deadline` after which LM stops (the result so far is kept;
    ``stopped_early``). ``progress(iteration, error)`` after each LM iteration, and with a
    fractional iteration at least every 0.5 s during one (see ``_Ticker``).
    ``initial_world_from_camera`` (F, 4, 4): where the frames' poses start (e.g. after loop
    closures, :func:`quadloc.maps.building.loops.corrected_poses`; default the app's poses);
    the odometry between factors stay the app's relative poses.
    """
    T_app = np.asarray(world_from_camera, dtype=float)
    T_wc = T_app if initial_world_from_camera is None else np.asarray(
        initial_world_from_camera, dtype=float)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    E = [gtsam.symbol("e", k) for k in range(len(objects))]
    L = [gtsam.symbol("l", k) for k in range(len(objects))]
    used_frames = sorted({observations[i].frame for _, idx, _ in objects for i in idx})
    X = {f: gtsam.symbol("x", f) for f in used_frames} if refine_cameras else {}
    samples: dict[int, LevelSetSamples] = {}
    info_w: list[FloatArray] = []
    view_rows: list[tuple[int, int, int, float]] = []  # (frame, object, observation, weight)
    sigmas: list[FloatArray] = []  # per object: its views' sigma, NaN where none is given
    robust = DEFAULT_ROBUST_SCALE["level_set"]
    ticker = _Ticker(progress)
    T_cw = np.array([invert_pose(T) for T in T_wc])
    for k, (label, idx, ell) in enumerate(objects):
        values.insert(E[k], pose3(pose_matrix(ell.rotation, ell.center)))
        values.insert(L[k], np.log(ell.axes))
        for i in idx:
            samples[i] = level_set_samples(observations[i].ellipse, camera)
        stacked = stack_samples([samples[i] for i in idx])
        sigma = np.array([np.nan if observations[i].sigma is None else observations[i].sigma
                          for i in idx], dtype=float)
        sigmas.append(sigma)
        truncated = np.array([touches_border(observations[i].ellipse, camera) for i in idx])
        weights = 1.0 / np.sqrt(truncation_sigma(np.where(np.isnan(sigma), 1.0, sigma),
                                                 truncated, truncated_weight))
        frames_k = [observations[i].frame for i in idx]
        info_w.append(1.0 / truncation_sigma(
            np.where(np.isnan(sigma), QUALITY_DEFAULT_SIGMA, sigma), truncated, truncated_weight))
        if not refine_cameras:  # one factor per object over all its views
            graph.add(ellipsoid_views_factor(
                stacked, weights, [(E[k], L[k])], np.zeros(len(idx), int),
                camera_from_world=T_cw[frames_k], robust_scale=robust, on_evaluate=ticker))
        else:
            for v, i in enumerate(idx):
                view_rows.append((observations[i].frame, k, i, weights[v]))
        prior = (size_priors or {}).get(label)
        if prior is not None:
            graph.add(gtsam.PriorFactorVector(
                L[k], np.full(3, math.log(prior.semi_axis_m)),
                gtsam.noiseModel.Isotropic.Sigma(3, prior.log_sigma)))
        elif unconstrained_prior_sigma is not None:
            # axes the views do not constrain at the initial estimate: a weak prior towards the
            # object's mean log semi-axis keeps them from collapsing (module doc)
            std, _, _, _ = _log_axis_std(T_cw[frames_k], ell.rotation, ell.center, ell.axes,
                                         stacked, info_w[k])
            loose = ~(std <= unconstrained_log_std)
            if loose.any():
                sig = np.where(loose, unconstrained_prior_sigma, 1e6)
                graph.add(gtsam.PriorFactorVector(
                    L[k], np.full(3, float(np.mean(np.log(ell.axes)))),
                    gtsam.noiseModel.Diagonal.Sigmas(sig)))
        if axis_floor_fraction is not None:
            graph.add(_floor_factor(L[k], float(np.mean(np.log(ell.axes)))
                                    + math.log(axis_floor_fraction), AXIS_FLOOR_LOG_SIGMA))
    if refine_cameras and used_frames:
        for f in used_frames:
            values.insert(X[f], pose3(T_wc[f]))
        # one factor per run of `frames_per_factor` consecutive used frames, over their views
        # of every object: few Python round trips, small dense Jacobian blocks
        by_frame: dict[int, list[tuple[int, int, float]]] = {}
        for f, k, i, wv in view_rows:
            by_frame.setdefault(f, []).append((k, i, wv))
        chunk = max(1, int(frames_per_factor))
        for start in range(0, len(used_frames), chunk):
            fs = used_frames[start:start + chunk]
            rows = [(fi, k, i, wv) for fi, f in enumerate(fs) for k, i, wv in by_frame[f]]
            objs = sorted({k for _, k, _, _ in rows})
            slot = {k: s for s, k in enumerate(objs)}
            graph.add(ellipsoid_views_factor(
                stack_samples([samples[i] for _, _, i, _ in rows]),
                np.array([wv for *_, wv in rows]), [(E[k], L[k]) for k in objs],
                [slot[k] for _, k, _, _ in rows], camera_keys=[X[f] for f in fs],
                view_cameras=[fi for fi, _, _, _ in rows], robust_scale=robust,
                on_evaluate=ticker))
        graph.add(gtsam.PriorFactorPose3(X[used_frames[0]], pose3(T_wc[used_frames[0]]),
                                         gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
        noise = odometry or OdometryNoise()
        path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(
            np.diff(T_app[:, :3, 3], axis=0), axis=1))])  # app's path length to each frame (m)
        for a, b in itertools.pairwise(used_frames):
            rel = invert_pose(T_app[a]) @ T_app[b]
            sig = noise.sigmas(float(path[b] - path[a]), b - a)
            graph.add(gtsam.BetweenFactorPose3(X[a], X[b], pose3(rel),
                                               gtsam.noiseModel.Diagonal.Sigmas(sig)))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(1e-5)
    params.setAbsoluteErrorTol(1e-9)
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    initial_error = float(graph.error(values))
    ticker.n_factors = max(1, graph.size())
    err = initial_error
    it = 0
    stopped = False
    while it < max_iterations:
        if deadline_passed(deadline):
            stopped = True
            break
        ticker.new_iteration(it, err)
        opt.iterate()
        it += 1
        new_err = float(opt.error())
        if progress is not None:
            progress(it, new_err)
        converged = err - new_err <= max(1e-5 * err, 1e-9)
        err = new_err
        if converged:
            break
    result = opt.values()
    ells: list[Ellipsoid] = []
    T_out = T_wc.copy()
    for f, key in X.items():
        T_out[f] = result.atPose3(key).matrix()
    quality = []
    T_cw_out = np.array([invert_pose(T) for T in T_out])
    for k, (_label, idx, _ell) in enumerate(objects):
        pose = result.atPose3(E[k])
        R = pose.rotation().matrix()
        c = np.asarray(pose.translation(), dtype=float)
        axes = np.exp(result.atVector(L[k]))
        ell = canonical_ellipsoid(R, c, axes)
        ells.append(ell)
        frames_k = [observations[i].frame for i in idx]
        stacked = stack_samples([samples[i] for i in idx])
        std, r_ok, ok, center_std = _log_axis_std(T_cw_out[frames_k], R, c, axes, stacked,
                                                  info_w[k])
        w_cost = np.where(np.isnan(sigmas[k]), 1.0, 1.0 / sigmas[k])[ok]
        cost = 0.5 * float(np.sum(w_cost[:, None] * r_ok**2))
        rays = c - T_out[frames_k, :3, 3]
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        allr = r_ok.reshape(-1) if r_ok.size else np.zeros(1)
        # std per axis of the refined frame; report in the canonical (descending) order
        order = np.argsort(axes)[::-1]
        std_c = std[order]
        quality.append(ObjectQuality(
            n_views=len(idx), view_spread_deg=max_ray_angle_deg(rays), residual_cost=cost,
            rms_level_residual=float(np.sqrt(np.mean(allr**2))),
            log_axis_std=(float(std_c[0]), float(std_c[1]), float(std_c[2])),
            center_std_m=center_std,
            unconstrained_axes=tuple(int(a) for a in np.flatnonzero(
                ~(std_c <= unconstrained_log_std)))))
    return JointResult(ells, quality, T_out, it, initial_error, err, stopped)
