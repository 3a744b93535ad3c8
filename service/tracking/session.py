"""A tracking session: camera poses of a walk in a sliding-window factor graph.

One GTSAM ``Pose3`` per frame, the camera's ``world_from_camera`` (OpenCV camera axes), key
``x<frame index>``; factors: the metric factors of the detections associated at the predicted
pose, odometry ``BetweenFactorPose3`` (noise :class:`DriftModel`), client priors with a
covariance and the device's measured gravity (:mod:`quadloc.factors.gravity_factor`, on the frame's
tilt). States :data:`STATES`; poses are returned only while ``tracking``. Factors,
smoothers and the ``lost`` rules: docs/design/service.md#tracking-session.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import gtsam
import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import (
    TRUNCATED_WEIGHT,
    Camera,
    border_touching,
    truncation_sigma,
)
from quadloc.factors.conics import ellipse_params
from quadloc.factors.gravity_factor import gravity_factor
from quadloc.factors.names import FieldError, GeometryError
from quadloc.factors.pose_factors import pose3, pose_factors
from quadloc.factors.rotations import (
    DOCUMENT_ROTATION_TOLERANCE,
    check_pose,
    invert_pose,
    skew,
    snap_to_rotation,
)
from quadloc.maps.compiled import CompiledMap
from quadloc.service.localization.calibration_fit import (
    CalibrationConstants,
    session_variance_ratio,
)
from quadloc.service.localization.confidence import (
    TOLERANCE_POSITION_M,
    TOLERANCE_ROTATION_DEG,
    calibration_key,
)
from quadloc.service.localization.copies import is_copy
from quadloc.service.localization.gravity import gravity_measurement
from quadloc.service.localization.pipeline import localize
from quadloc.service.localization.scoring import Match, MatchScorer, ScoringTimeoutError
from quadloc.service.localization.types import (
    Detection,
    Gravity,
    InlierMatch,
    LocalizationOptions,
    PosePrior,
)
from quadloc.service.tracking.association import associate
from quadloc.service.tracking.confidence import session_confidence
from quadloc.service.tracking.multiframe import InitFrame, multi_frame_ransac
from quadloc.service.tracking.places import (
    COMMIT_PROBABILITY,
    KEEP_PROBABILITY,
    MIN_COMMIT_OBJECTS,
    MIN_OBJECT_FRAMES,
    PlaceCandidate,
    PlaceHypothesis,
    PlaceSet,
    alignment,
    same_place,
    single_place,
)

__all__ = [
    "MAX_BUFFERED_DETECTIONS",
    "MAX_WINDOW_FRAMES",
    "MIN_PROPOSAL_ROUNDS",
    "SMOOTHERS",
    "STATES",
    "TIME_BUDGET_EXCEEDED",
    "DriftModel",
    "FrameInput",
    "FrameResult",
    "SessionOptions",
    "TrackingInputError",
    "TrackingSession",
    "pose_adjoint",
]

STATES = ("initializing", "tracking", "lost")
#: A tracking frame with at least this many usable detections, none of them explained by the
#: estimate (no inlier), sends the session to ``lost`` at once (fewer: after
#: ``lost_after_misses`` such frames in a row), when they contradict it: some were associated,
#: or the estimate predicts objects of the map in view (the places' shared rule,
#: :meth:`~quadloc.service.tracking.places.PlaceSet.predicts_objects_in_view`; walls hide
#: other rooms). A frame looking at no object (a corridor, a wall) has only spurious
#: detections to show, however many.
LOST_UNEXPLAINED_DETECTIONS = 3
#: A tracking frame whose estimate moved from its odometry prediction by more than this squared
#: Mahalanobis distance (6 dof, under the predicted covariance; chi-square 99.9 %) jumped. With
#: at least :data:`LOST_UNEXPLAINED_DETECTIONS` usable detections of which the jumped estimate
#: explains more (one-to-one inliers) than the prediction, the prediction was wrong: the session
#: is ``lost``. Otherwise a wrong association or a biased detection pulled the update: the
#: frame's detections are dropped (:meth:`TrackingSession._track`).
JUMP_CHI2 = 22.5
#: Standard deviations (6,) ``[omega (rad) x 3, v (m) x 3]`` added to the predicted covariance
#: when a jump to an estimate that explains more of the frame is weighed for ``lost``: the
#: tolerance of a pose (5 deg, 10 cm) over ``sqrt(JUMP_CHI2)``, so a move within the tolerance
#: is never a wrong prediction, however tight the smoother's covariance after a long tracked
#: stretch (it knows nothing of the map's centimetre errors nor of biased detections: on a
#: building walk it claimed 5 mm / 0.2 deg with the prediction 2 cm off the truth). Such an
#: estimate is kept as a correction (:meth:`TrackingSession._track`).
JUMP_TOLERANCE_STD = np.array(
    [math.radians(TOLERANCE_ROTATION_DEG)] * 3 + [TOLERANCE_POSITION_M] * 3) / math.sqrt(JUMP_CHI2)
#: A tracking frame whose detections were fused (used by the smoother) and include an inlier
#: constrains the pose when the inliers of the fused frames of the smoother's window
#: (``window_frames``, this one included) cover this many distinct objects (two
#: ellipse-ellipsoid pairs determine a pose; frames of one object each, a short odometry step
#: apart, do it jointly): the systematic drift (:meth:`DriftModel.systematic_covariance`)
#: restarts from 0 there.
CONSTRAINING_OBJECTS = 2
SMOOTHERS = ("isam2", "batch")
#: Largest ``window_frames`` of each smoother: the batch smoother re-solves its whole window at
#: every frame, so its window is what bounds a frame's CPU time (measured by
#: ``python -m bench.adversarial``; docs/tracking.md, "Limits").
MAX_WINDOW_FRAMES = {"isam2": 300, "batch": 60}
#: Most detections an initializing session keeps buffered (over all buffered frames; the
#: oldest frames are dropped first): bounds a session's memory whatever the frames hold.
MAX_BUFFERED_DETECTIONS = 2048
#: A tracking frame's smoother update starts only with this many times the previous update's
#: CPU time left in its budget.
UPDATE_COST_MARGIN = 1.5
#: ``FrameResult.reason`` of a frame not fused because its time budget ran out.
TIME_BUDGET_EXCEEDED = "time_budget_exceeded"
#: A tracking session asks single-frame ``localize`` for rival places every this many frames
#: (on a frame with >= 3 usable detections): a wrong place committed to meets its rival.
CHECK_INTERVAL_FRAMES = 30
#: Frames remembered (poses, usable detections) to score a newly proposed place on.
HISTORY_FRAMES = 45
#: A session commits to a place only after it has lived through this many proposal rounds (one
#: every ``init_interval_frames``; the round that proposed it counts): single proposals can all
#: come from one of several identical rooms (a single frame's answer may be wrong on exact
#: copies), the rounds let the copies be proposed. Counted per place, not per session: a place
#: proposed late in a long initialization (the walk entered a new room) waits its own rounds.
MIN_PROPOSAL_ROUNDS = 3
#: Below this posterior a candidate place does not make an answer ``ambiguous``.
AMBIGUOUS_PROBABILITY = 0.05
#: A place is checked for being a copy of the committed one (``_copy_of_committed``) by
#: carrying its objects by the transform between the two camera poses onto the nearest object
#: of the label within this (m: the alignments' drift since proposed; the copy itself is then
#: decided by the rigid fit's 5 cm).
COPY_SEARCH_M = 0.3

_T = TypeVar("_T")


class TrackingInputError(FieldError):
    """Bad session or frame input naming its ``field`` (a
    :class:`quadloc.factors.names.FieldError`); ``str()`` reads ``"<field>: <problem>"``, e.g.
    ``"timestamp: must be a finite number ..."``."""


@dataclass(frozen=True)
class DriftModel:
    """Odometry noise: a random walk plus a systematic part (documented in docs/tracking.md,
    "Odometry drift model").

    Random walk (:meth:`sigmas`, the odometry factors): between two frames ``d`` metres and
    ``dt`` seconds apart the relative pose has independent per-axis std
    ``sqrt(q_d d + q_t dt + floor^2)`` with, for rotation (rad) and translation (m):
    ``q_d = (x_per_sqrt_m)^2`` per metre and ``q_t = (x_per_sqrt_s)^2`` per second. So the
    defaults mean 2 cm and 0.5 deg of std after 1 m, 0.3 cm and 0.05 deg after 1 s standing.

    Systematic part (:meth:`systematic_covariance`, added to the answered covariance): a scale
    error of std ``scale_error`` (fraction of the displacement) and a constant gyro bias of std
    ``gyro_bias_rad_per_s`` per axis, both unknown but the same over the whole stretch since the
    last detection-constrained frame, so their error grows linearly with the displacement and
    the time (not with their square roots). Defaults 1.5 % and 0.03 deg/s per axis:
    ARKit/ARCore-class visual-inertial odometry.
    """

    translation_m_per_sqrt_m: float = 0.02
    translation_m_per_sqrt_s: float = 0.003
    rotation_rad_per_sqrt_m: float = math.radians(0.5)
    rotation_rad_per_sqrt_s: float = math.radians(0.05)
    translation_floor_m: float = 1e-4
    rotation_floor_rad: float = math.radians(0.01)
    scale_error: float = 0.015
    gyro_bias_rad_per_s: float = math.radians(0.03)

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise TrackingInputError("must be finite and >= 0", field=f"options.drift.{name}")

    def sigmas(self, distance_m: float, dt_s: float) -> FloatArray:
        """Per-axis stds ``[omega (3) rad, v (3) m]`` of one odometry step."""
        dt_s = max(dt_s, 0.0)
        r = math.sqrt(self.rotation_rad_per_sqrt_m ** 2 * distance_m
                      + self.rotation_rad_per_sqrt_s ** 2 * dt_s + self.rotation_floor_rad ** 2)
        t = math.sqrt(self.translation_m_per_sqrt_m ** 2 * distance_m
                      + self.translation_m_per_sqrt_s ** 2 * dt_s
                      + self.translation_floor_m ** 2)
        return np.array([r, r, r, t, t, t])

    def systematic_covariance(self, odom_from_camera: FloatArray, displacement_m: FloatArray,
                              elapsed_s: float, moment_m_s: FloatArray) -> FloatArray:
        """6x6 covariance ``[omega (rad), v (m)]`` in the body frame of the camera
        ``odom_from_camera`` (4x4) of the systematic drift accumulated since the anchor (the
        last detection-constrained frame).

        With a scale error ``s`` (std ``scale_error``) and a gyro bias ``b`` (rad/s, std
        ``gyro_bias_rad_per_s`` per axis, any direction), the odometry-frame errors are
        ``theta = b T`` (rotation) and ``e = s D + b x W`` (position), ``D`` =
        ``displacement_m`` (3,) the camera's odometry displacement since the anchor (m), ``T``
        = ``elapsed_s``, ``W`` = ``moment_m_s`` (3,) = sum over the steps of ``(t_i - t_anchor)
        dp_i`` (m s: the rotation error at step i turns that step's displacement). Hence
        ``Cov(theta) = sb^2 T^2 I``, ``Cov(e) = ss^2 D D^T + sb^2 (|W|^2 I - W W^T)``,
        ``Cov(theta, e) = sb^2 T [W]_x``, rotated into the body frame by ``R^T``.
        """
        R = np.asarray(odom_from_camera, float)[:3, :3]
        d = R.T @ np.asarray(displacement_m, float)
        w = R.T @ np.asarray(moment_m_s, float)
        b2 = self.gyro_bias_rad_per_s ** 2
        T = max(float(elapsed_s), 0.0)
        wx = skew(w)
        cov = np.zeros((6, 6))
        cov[:3, :3] = b2 * T * T * np.eye(3)
        cov[3:, 3:] = self.scale_error ** 2 * np.outer(d, d) \
            + b2 * (float(w @ w) * np.eye(3) - np.outer(w, w))
        cov[:3, 3:] = b2 * T * wx
        cov[3:, :3] = cov[:3, 3:].T
        return cov


@dataclass
class _DriftAnchor:
    """The odometry since the last detection-constrained frame (the anchor): what
    :meth:`DriftModel.systematic_covariance` needs. Positions in the odometry frame (m), times
    (s)."""

    position: FloatArray
    timestamp: float
    last_position: FloatArray
    last_timestamp: float
    moment: FloatArray  # sum over the steps of (t_i - timestamp) * dp_i (m s)

    @classmethod
    def at(cls, odom_from_camera: FloatArray, timestamp: float) -> _DriftAnchor:
        p = np.array(odom_from_camera[:3, 3], float)
        return cls(p, timestamp, p.copy(), timestamp, np.zeros(3))

    def advance(self, odom_from_camera: FloatArray, timestamp: float) -> None:
        p = np.array(odom_from_camera[:3, 3], float)
        self.moment = self.moment + (timestamp - self.timestamp) * (p - self.last_position)
        self.last_position, self.last_timestamp = p, timestamp

    def covariance(self, drift: DriftModel, odom_from_camera: FloatArray) -> FloatArray:
        """The systematic drift's 6x6 covariance at the newest frame (``odom_from_camera``)."""
        return drift.systematic_covariance(odom_from_camera, self.last_position - self.position,
                                           self.last_timestamp - self.timestamp, self.moment)


@dataclass(frozen=True)
class SessionOptions:
    """Knobs of a session (validated). ``window_frames``: poses kept in the graph;
    ``metric``/``robust``: the factors' metric and kernel; ``inlier_iou``: a detection is an
    inlier of a frame's pose when its IoU with its object's projection is >= this."""

    window_frames: int = 30
    smoother: str = "isam2"
    metric: str = "level_set"
    robust: str | None = "huber"
    use_sigma: bool = True
    inlier_iou: float = 0.2
    drift: DriftModel = field(default_factory=DriftModel)
    init_buffer_frames: int = 60
    init_max_frames: int = 8
    init_interval_frames: int = 5
    init_max_samples: int = 300
    lost_position_std_m: float = 0.5
    lost_after_misses: int = 10
    seed: int = 0

    def __post_init__(self) -> None:
        def bad(name: str, problem: str) -> TrackingInputError:
            return TrackingInputError(problem, field=f"options.{name}")
        if not (isinstance(self.window_frames, int) and 2 <= self.window_frames <= 300):
            raise bad("window_frames", f"must be an integer in [2, 300], got "
                      f"{self.window_frames!r}")
        if self.smoother not in SMOOTHERS:
            raise bad("smoother", f"must be one of {SMOOTHERS}, got {self.smoother!r}")
        if self.window_frames > MAX_WINDOW_FRAMES[self.smoother]:
            raise bad("window_frames", f"must be <= {MAX_WINDOW_FRAMES[self.smoother]} with the "
                      f"{self.smoother} smoother, got {self.window_frames}")
        if not (0 < self.inlier_iou <= 1):
            raise bad("inlier_iou", f"must be in (0, 1], got {self.inlier_iou!r}")
        if not (isinstance(self.init_max_frames, int) and 1 <= self.init_max_frames
                <= self.init_buffer_frames <= 600):
            raise bad("init_max_frames", "must satisfy 1 <= init_max_frames <= "
                      "init_buffer_frames <= 600")


@dataclass(frozen=True)
class FrameInput:
    """One frame of a session.

    Attributes:
        detections: as for ``localize``.
        odom_from_camera: 4x4 pose of the camera in the client's odometry frame, OpenCV camera
            axes (convert ARKit/ARCore with ``@ diag(1, -1, -1, 1)`` first).
        timestamp: client clock, seconds, non-decreasing within a session.
        frame_id: echoed back.
        prior: optional client prior on ``world_from_camera`` (a factor when it has a
            covariance).
        gravity: optional gravity direction measured in this frame's camera (OpenCV axes): a
            factor on the frame's tilt against the map's up axis.
    """

    detections: Sequence[Detection]
    odom_from_camera: FloatArray
    timestamp: float
    frame_id: str | None = None
    prior: PosePrior | None = None
    gravity: Gravity | None = None


@dataclass(frozen=True, eq=False)
class FrameResult:
    """A frame's answer. Poses are OpenCV camera axes; covariances 6x6 ``[omega, v]`` (rad, m),
    right perturbation, body frame of the pose they belong to (``world_from_odom``'s: the odometry
    frame). ``world_from_camera``/``world_from_odom`` are None unless ``state == "tracking"``.
    ``inliers``: detections whose IoU with their object's projection at the returned pose is >=
    ``inlier_iou`` (one-to-one). ``confidence``: :func:`quadloc.service.tracking.confidence.
    session_confidence`. ``reason``: why there is no pose (``waiting_for_constraints``,
    ``ambiguous``, ``lost``), ``detections_unexplained`` for a tracking frame whose usable
    detections are all unexplained by its (odometry-predicted) pose, else None."""

    frame_index: int
    frame_id: str | None
    timestamp: float
    state: str
    world_from_camera: FloatArray | None
    covariance: FloatArray | None
    world_from_odom: FloatArray | None
    world_from_odom_covariance: FloatArray | None
    inliers: tuple[InlierMatch, ...]
    confidence: float
    n_usable_detections: int
    reason: str | None
    timings_ms: dict[str, float]
    candidates: tuple[PlaceCandidate, ...] = ()


def pose_adjoint(T: FloatArray) -> FloatArray:
    """6x6 adjoint of a 4x4 pose in GTSAM's ``[omega, v]`` order:
    ``T Exp(xi) T^-1 = Exp(Ad_T xi)``."""
    return pose3(T).AdjointMap()


def _key(i: int) -> int:
    return gtsam.symbol("x", i)


@dataclass
class _Buffered:
    index: int
    timestamp: float
    frame: InitFrame
    detections: tuple[Detection, ...]
    prior: PosePrior | None
    gravity: Gravity | None


class TrackingSession:
    """The state of one session (not thread-safe: the store serialises calls per session)."""

    def __init__(self, compiled: CompiledMap, camera: Camera,
                 options: SessionOptions | None = None,
                 calibration: CalibrationConstants | None = None) -> None:
        """``calibration``: the map version's own calibration (``quadloc calibrate``), None:
        the shipped constants; it rescales the answers' covariances by
        :func:`~quadloc.service.localization.calibration_fit.session_variance_ratio` for the
        session's calibration key (its ``metric`` and ``use_sigma``), the same rule as
        localize's (:func:`~quadloc.service.localization.calibration_fit.
        map_calibration_applies`)."""
        self.compiled = compiled
        self.camera = camera
        self.options = options or SessionOptions()
        #: multiplies the smoother's marginals in the answers (1: the shipped constants)
        self.variance_ratio = session_variance_ratio(
            calibration, calibration_key(self.options.metric, self.options.use_sigma))
        self.state = "initializing"
        self.frame_count = 0
        self._rng = np.random.default_rng(self.options.seed)
        self._buffer: deque[_Buffered] = deque(maxlen=self.options.init_buffer_frames)
        self._last_attempt = -10 ** 9
        self._smoother: gtsam.BatchFixedLagSmoother | gtsam.IncrementalFixedLagSmoother | None \
            = None
        self._last: tuple[int, float, FloatArray, FloatArray, FloatArray] | None = None
        self._misses = 0
        self._anchor: _DriftAnchor | None = None
        #: the inlier objects of the fused tracking frames of the window (empty when not fused)
        self._recent_objects: deque[frozenset[str]] = deque(maxlen=self.options.window_frames)
        self._last_timestamp: float | None = None
        self._update_cpu_s = 0.0  # CPU time (s) of the last smoother update
        self._places = PlaceSet(compiled, camera, self.options.inlier_iou)
        self._committed: PlaceHypothesis | None = None
        # (odom_from_camera, usable ellipses (D, 5), labels) of the last frames
        self._history: deque[tuple[FloatArray, FloatArray, tuple[str, ...]]] = deque(
            maxlen=HISTORY_FRAMES)
        self._last_check = -10 ** 9
        self._evidence: tuple[FloatArray, FloatArray, tuple[str, ...]] = (
            np.eye(4), np.zeros((0, 5)), ())

    # ------------------------------------------------------------------ public
    @property
    def last_timestamp(self) -> float | None:
        """The timestamp (s, the client's clock) of the last frame fused; None before any."""
        return self._last_timestamp

    def add_frame(self, frame: FrameInput, deadline: Deadline | None = None) -> FrameResult:
        """Fuse one frame; returns its :class:`FrameResult`. Raises
        :class:`TrackingInputError` naming the field on bad input (the session is unchanged).

        ``deadline`` (e.g. :meth:`Deadline.cpu_budget`; None: no limit) is checked between the
        frame's stages: a frame past it is counted (its index and timestamp used) but not
        fused, answered with reason :data:`TIME_BUDGET_EXCEEDED` and no pose; the state stays
        (a tracking session chains the next frame's odometry from the last fused one; an
        initializing one abandons the attempt, keeping the frame in its buffer unless the
        deadline had passed before the frame started). The only stage not
        interruptible is the smoother's update, bounded by :data:`MAX_WINDOW_FRAMES`.
        Initialization draws exactly ``init_max_samples`` samples (seeded): the same frames give
        the same answer whatever the machine's load, unless the deadline passes."""
        t0 = time.perf_counter()
        T_oc = self._check(frame)
        index = self.frame_count
        usable = [i for i, d in enumerate(frame.detections)
                  if len(self.compiled.indices_for(d.label)) > 0]
        self.frame_count += 1
        self._last_timestamp = float(frame.timestamp)
        timings: dict[str, float] = {}
        dets = frame.detections
        self._evidence = (T_oc, ellipse_params([dets[i].ellipse for i in usable]) if usable
                          else np.zeros((0, 5)), tuple(dets[i].label for i in usable))
        if deadline_passed(deadline):
            result = self._no_pose(index, frame, T_oc, usable, TIME_BUDGET_EXCEEDED, timings)
        elif self.state == "tracking":
            result = self._track(index, frame, T_oc, usable, timings, deadline)
        else:
            result = self._initialize(index, frame, T_oc, usable, timings, deadline)
        timings["total"] = (time.perf_counter() - t0) * 1e3
        return result

    def reset(self, keep_places: bool = False) -> None:
        """Drop the graph; the next frames relocalize (state ``lost``). The place hypotheses
        are dropped too unless ``keep_places`` (a rival place won: they stay in competition)."""
        self._smoother = None
        self._last = None
        self._anchor = None
        self._recent_objects.clear()
        self._misses = 0
        self._buffer.clear()
        self._committed = None
        self._places.restart_rounds()  # every place waits its rounds again (as a new one)
        if not keep_places:
            self._places.clear()
            self._history.clear()
        self.state = "lost"

    # ------------------------------------------------------------------ input
    def _check(self, frame: FrameInput) -> FloatArray:
        if not isinstance(frame, FrameInput):
            raise TrackingInputError(f"must be a FrameInput, got {type(frame).__name__}",
                                     field="frame")
        for i, d in enumerate(frame.detections):
            if not isinstance(d, Detection):
                raise TrackingInputError("must be a Detection", field=f"detections[{i}]")
        try:
            T = check_pose(frame.odom_from_camera, "odom_from_camera",
                           DOCUMENT_ROTATION_TOLERANCE)
        except GeometryError as exc:
            raise TrackingInputError(f"must be a rigid transform ({exc.problem})",
                                     field="odom_from_camera") from exc
        if not isinstance(frame.gravity, (Gravity, type(None))):
            raise TrackingInputError(f"must be a Gravity or None, got "
                                     f"{type(frame.gravity).__name__}", field="gravity")
        ts = frame.timestamp
        if isinstance(ts, bool) or not isinstance(ts, (int, float)) or not math.isfinite(ts):
            raise TrackingInputError(f"must be a finite number, got {ts!r}", field="timestamp")
        if self._last_timestamp is not None and ts < self._last_timestamp:
            raise TrackingInputError(
                f"{ts} is before the previous frame's {self._last_timestamp} "
                "(frames must be sent in time order)", field="timestamp")
        T[:3, :3] = snap_to_rotation(T[:3, :3])  # T is check_pose's own copy
        return T

    # ------------------------------------------------------------------ tracking
    def _factors_for(self, key: int, T_pred: FloatArray, detections: Sequence[Detection],
                     objects: Sequence[int]) -> Sequence[gtsam.NonlinearFactor]:
        if not objects:
            return []
        opts = self.options
        sigmas: list[float | None] = [d.sigma if opts.use_sigma else None for d in detections]
        # a truncated detection's bias recurs in the next frames: weighted down (docs/tracking.md)
        truncated = border_touching(ellipse_params([d.ellipse for d in detections]),
                                    self.camera)
        if truncated.any():
            scaled = truncation_sigma(np.array([1.0 if s is None else s for s in sigmas]),
                                      truncated, TRUNCATED_WEIGHT)
            sigmas = [float(w) if cut else s
                      for s, w, cut in zip(sigmas, scaled, truncated.tolist(), strict=True)]
        factors, _ = pose_factors(
            opts.metric, key, [d.ellipse for d in detections],
            [self.compiled.ellipsoids[o] for o in objects], self.camera, sigmas=sigmas,
            robust=opts.robust, initial_world_from_camera=T_pred,
            batched=opts.robust is None)
        return factors

    def _between(self, key_a: int, key_b: int, T_oa: FloatArray, T_ob: FloatArray,
                 dt: float) -> tuple[gtsam.BetweenFactorPose3, FloatArray, FloatArray]:
        rel = invert_pose(T_oa) @ T_ob
        sig = self.options.drift.sigmas(float(np.linalg.norm(rel[:3, 3])), dt)
        noise = gtsam.noiseModel.Diagonal.Sigmas(sig)
        return gtsam.BetweenFactorPose3(key_a, key_b, pose3(rel), noise), rel, np.diag(sig ** 2)

    def _new_smoother(self) -> gtsam.BatchFixedLagSmoother | gtsam.IncrementalFixedLagSmoother:
        lag = float(self.options.window_frames - 1)
        if self.options.smoother == "batch":
            return gtsam.BatchFixedLagSmoother(lag)
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(0.01)
        params.relinearizeSkip = 1
        params.findUnusedFactorSlots = True
        return gtsam.IncrementalFixedLagSmoother(lag, params)

    def _marginal(self, key: int) -> FloatArray | None:
        """The smoother's 6x6 marginal covariance of pose ``key`` (symmetrised), None when
        it cannot be computed or is not finite."""
        sm = self._smoother
        assert sm is not None
        try:
            if isinstance(sm, gtsam.BatchFixedLagSmoother):  # options.smoother == "batch"
                marginal = gtsam.Marginals(sm.getFactors(), sm.calculateEstimate()) \
                    .marginalCovariance(key)
            else:
                marginal = sm.marginalCovariance(key)
        except RuntimeError:
            return None
        cov: FloatArray = 0.5 * (np.asarray(marginal) + np.asarray(marginal).T)
        return cov if np.all(np.isfinite(cov)) else None

    def _verify(self, detections: Sequence[Detection], usable: list[int],
                world_from_camera: FloatArray) -> list[InlierMatch]:
        if not usable:
            return []
        sc = MatchScorer(self.compiled, self.camera, [detections[i].ellipse for i in usable],
                         [detections[i].label for i in usable], usable)
        ms = sc.matches(invert_pose(world_from_camera), self.options.inlier_iou)
        return [InlierMatch(m.detection_index, self.compiled.object_ids[m.object_index],
                            float(m.iou), 1.0 - float(m.iou)) for m in ms]

    def _result(self, index: int, frame: FrameInput, T_oc: FloatArray, T: FloatArray | None,
                cov: FloatArray | None, inliers: list[InlierMatch], n_usable: int,
                reason: str | None, timings: dict[str, float],
                contradicted: bool = False) -> FrameResult:
        T_wo = cov_wo = None
        if cov is not None:
            # the smoother's marginal (random-walk drift, detections) plus the systematic drift
            # since the last detection-constrained frame (DriftModel, docs/tracking.md)
            cov = self.variance_ratio * cov
            if self._anchor is not None and self.state == "tracking":
                cov = cov + self._anchor.covariance(self.options.drift, T_oc)
        if T is not None:
            T_wo = T @ invert_pose(T_oc)
            if cov is not None:
                Ad = pose_adjoint(T_oc)
                cov_wo = Ad @ cov @ Ad.T
        committed = self._committed if self.state == "tracking" else None
        place_p = self._places.place_probability(committed) if committed is not None else 0.0
        return FrameResult(index, frame.frame_id, float(frame.timestamp), self.state, T, cov,
                           T_wo, cov_wo, tuple(inliers),
                           session_confidence(self.state, cov, n_usable if contradicted else 0,
                                              place_p),
                           n_usable, reason, timings,
                           self._places.candidates(T_oc, committed, T))

    def _no_pose(self, index: int, frame: FrameInput, T_oc: FloatArray, usable: list[int],
                 reason: str, timings: dict[str, float]) -> FrameResult:
        return self._result(index, frame, T_oc, None, None, [], len(usable), reason, timings)

    def _track(self, index: int, frame: FrameInput, T_oc: FloatArray, usable: list[int],
               timings: dict[str, float], deadline: Deadline | None = None) -> FrameResult:
        assert self._last is not None and self._smoother is not None
        t = time.perf_counter()
        last_index, last_ts, T_oc_last, T_last, cov_last = self._last
        key, key_last = _key(index), _key(last_index)
        between, rel, Q = self._between(key_last, key, T_oc_last, T_oc,
                                        float(frame.timestamp) - last_ts)
        T_pred = T_last @ rel
        Ad = pose_adjoint(invert_pose(rel))
        cov_pred = Ad @ cov_last @ Ad.T + Q
        graph = gtsam.NonlinearFactorGraph()
        graph.add(between)
        assoc = []
        if usable:
            dets = frame.detections
            assoc = associate(self.compiled, self.camera, T_pred, cov_pred,
                              ellipse_params([dets[i].ellipse for i in usable]),
                              [dets[i].label for i in usable], usable, deadline)
            if deadline_passed(deadline):
                timings["associate"] = (time.perf_counter() - t) * 1e3
                return self._no_pose(index, frame, T_oc, usable, TIME_BUDGET_EXCEEDED, timings)
            for f in self._factors_for(key, T_pred, [dets[a.detection_index] for a in assoc],
                                       [a.object_index for a in assoc]):
                graph.add(f)
        _add_prior(graph, key, frame.prior)
        self._add_gravity(graph, key, frame.gravity)
        values = gtsam.Values()
        values.insert(key, pose3(T_pred))
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        stamps[key] = float(index)
        timings["associate"] = (time.perf_counter() - t) * 1e3
        # the update cannot be interrupted: it starts only if the CPU time left covers the
        # previous one's (the window's cost changes slowly from frame to frame)
        if deadline_passed(deadline) or (deadline is not None and deadline.remaining_cpu_s()
                                         < UPDATE_COST_MARGIN * self._update_cpu_s):
            return self._no_pose(index, frame, T_oc, usable, TIME_BUDGET_EXCEEDED, timings)
        t, cpu = time.perf_counter(), time.thread_time()
        try:
            self._smoother.update(graph, values, stamps)
            T = self._smoother.calculateEstimatePose3(key).matrix()
            cov = self._marginal(key)
        except RuntimeError:
            T, cov = None, None
        self._update_cpu_s = time.thread_time() - cpu
        timings["update"] = (time.perf_counter() - t) * 1e3
        if T is None or cov is None or not np.all(np.isfinite(T)):
            self.reset()
            return self._no_pose(index, frame, T_oc, usable, "lost", timings)
        xi = gtsam.Pose3.Logmap(pose3(invert_pose(T_pred) @ T))
        jumped = float(xi @ np.linalg.solve(cov_pred, xi)) > JUMP_CHI2
        fused = bool(assoc)  # detections in the smoother's update
        if jumped and ((not assoc and frame.prior is None) or (assoc and (
                len(usable) < LOST_UNEXPLAINED_DETECTIONS or len(
                    self._verify(frame.detections, usable, T_pred))
                >= len(self._verify(frame.detections, usable, T))))):
            # The detections pulled the estimate away from its odometry: 1-2 of them (too few
            # to say which of estimate and detection is wrong), or more that the prediction
            # explains at least as well as the estimate (as many one-to-one inliers): a wrong
            # association (a spurious detection, a neighbouring room's object) or a biased
            # detection (occluded) moved it, not a wrong prediction. Or the update had nothing
            # new but odometry (no detection, no client prior) and still moved it: the
            # smoother re-linearised factors of earlier frames (iSAM2 takes one step per
            # update, so a detection keeps pulling after its own frame's check), which is no
            # evidence against the prediction. The frame's detections are dropped: the
            # smoother restarts from the prediction and its covariance (the window
            # marginalised into one prior), the place and its scores stay.
            restarted = self._restart_at(key, index, T_pred, cov_pred)
            if restarted is None:
                self.reset()
                return self._no_pose(index, frame, T_oc, usable, "lost", timings)
            T, cov = restarted
            jumped = False
            fused = False  # its detections were dropped: they constrain nothing
        elif jumped and float(xi @ np.linalg.solve(
                cov_pred + np.diag(JUMP_TOLERANCE_STD ** 2), xi)) <= JUMP_CHI2:
            # an estimate that explains more of the frame, moved within a pose's tolerance:
            # a correction the tight predicted covariance did not expect, not a wrong
            # prediction (JUMP_TOLERANCE_STD). Before, such a frame sent the session to
            # ``lost`` (a building walk's session 2 cm from the truth, in a room repeated
            # elsewhere, where re-initializing cannot tell the copies apart)
            jumped = False
        inliers = self._verify(frame.detections, usable, T)
        # a frame whose usable detections are all unexplained contradicts the estimate
        contradicted = bool(usable) and not inliers and (
            bool(assoc) or self._places.predicts_objects_in_view(T_pred))
        self._misses = self._misses + 1 if contradicted else 0
        pos_std = math.sqrt(max(float(np.linalg.eigvalsh(cov[3:, 3:]).max()), 0.0))
        if pos_std > self.options.lost_position_std_m or jumped \
                or self._misses >= self.options.lost_after_misses \
                or (contradicted and len(usable) >= LOST_UNEXPLAINED_DETECTIONS):
            self.reset()
            return self._no_pose(index, frame, T_oc, usable, "lost", timings)
        t = time.perf_counter()
        given_up = self._check_place(index, frame, T, usable, inliers)
        timings["places"] = (time.perf_counter() - t) * 1e3
        if given_up is not None:
            return self._no_pose(index, frame, T_oc, usable, given_up, timings)
        fused_objects = frozenset(m.object_id for m in inliers) if fused else frozenset()
        self._recent_objects.append(fused_objects)
        if fused_objects and len(frozenset().union(*self._recent_objects)) \
                >= CONSTRAINING_OBJECTS:
            self._anchor = _DriftAnchor.at(T_oc, float(frame.timestamp))
        elif self._anchor is not None:
            self._anchor.advance(T_oc, float(frame.timestamp))
        self._last = (index, float(frame.timestamp), T_oc, T, cov)
        return self._result(index, frame, T_oc, T, cov, inliers, len(usable),
                            "detections_unexplained" if contradicted else None, timings,
                            contradicted)

    def _restart_at(self, key: int, index: int, T: FloatArray, cov: FloatArray
                    ) -> tuple[FloatArray, FloatArray] | None:
        """A new smoother holding only pose ``key`` with a prior ``N(T, cov)`` (6x6
        ``[omega, v]``, body frame); its estimate and marginal (None if it fails)."""
        graph = gtsam.NonlinearFactorGraph()
        graph.add(gtsam.PriorFactorPose3(key, pose3(T), gtsam.noiseModel.Gaussian.Covariance(
            0.5 * (cov + cov.T))))
        values = gtsam.Values()
        values.insert(key, pose3(T))
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        stamps[key] = float(index)
        self._smoother = self._new_smoother()
        try:
            self._smoother.update(graph, values, stamps)
            est = self._smoother.calculateEstimatePose3(key).matrix()
        except RuntimeError:
            return None
        marginal = self._marginal(key)
        return None if marginal is None else (est, marginal)

    # ------------------------------------------------------------------ (re)initialization
    def _initialize(self, index: int, frame: FrameInput, T_oc: FloatArray, usable: list[int],
                    timings: dict[str, float], deadline: Deadline | None = None
                    ) -> FrameResult:
        """Buffer the frame, score the place hypotheses on it, propose new ones every
        ``init_interval_frames`` (multi-frame RANSAC over the buffer, single-frame ``localize``
        with its alternatives), and commit to the most probable place once its posterior is
        :data:`~quadloc.service.tracking.places.COMMIT_PROBABILITY` (docs/tracking.md,
        "Places")."""
        opts = self.options
        dets = tuple(frame.detections)
        _, ell, labels = self._evidence
        self._buffer.append(_Buffered(index, float(frame.timestamp), InitFrame(
            T_oc, ell, labels, tuple(usable)), dets, frame.prior, frame.gravity))
        # bounded in detections too, not only frames (the newest frame always stays)
        buffered = sum(len(b.detections) for b in self._buffer)
        while len(self._buffer) > 1 and buffered > MAX_BUFFERED_DETECTIONS:
            buffered -= len(self._buffer.popleft().detections)
        reason = "lost" if self.state == "lost" else "waiting_for_constraints"
        t = time.perf_counter()
        self._places.update(T_oc, ell, labels)
        self._history.append(self._evidence)
        timings["places"] = (time.perf_counter() - t) * 1e3
        with_dets = [b for b in list(self._buffer)[:-1] if len(b.frame.labels)]
        chosen = [*_spread(with_dets, opts.init_max_frames - 1), self._buffer[-1]]
        n_pool = sum(len(b.frame.labels) for b in chosen)
        if n_pool >= 3 and usable and index - self._last_attempt >= opts.init_interval_frames:
            self._last_attempt = index
            self._places.new_round()
            t = time.perf_counter()
            extra = [invert_pose(frame.prior.world_from_camera)] if frame.prior is not None \
                else []
            out = multi_frame_ransac([b.frame for b in chosen], self.compiled, self.camera,
                                     inlier_iou=opts.inlier_iou,
                                     max_samples=opts.init_max_samples, rng=self._rng,
                                     extra_hypotheses=extra, deadline=deadline)
            timings["multi_frame_ransac"] = (time.perf_counter() - t) * 1e3
            proposals = [] if out.camera_from_world is None \
                else [invert_pose(out.camera_from_world[-1])]
            t = time.perf_counter()
            proposals += self._localize_proposals(frame, usable)
            timings["localize"] = (time.perf_counter() - t) * 1e3
            if out.reason == TIME_BUDGET_EXCEEDED or deadline_passed(deadline):
                return self._no_pose(index, frame, T_oc, usable, TIME_BUDGET_EXCEEDED, timings)
            self._places.propose([alignment(T, T_oc) for T in proposals], T_oc, self._history,
                                 rounds=1)
        best, _ = self._places.best()
        p = 0.0 if best is None else self._places.place_probability(best)
        # a one-place map has no copy of its room for later rounds to propose, nor another
        # room to explain the objects seen
        one_place = single_place(self.compiled)
        rounds = 1 if one_place else MIN_PROPOSAL_ROUNDS
        copied = False
        if best is not None and p >= COMMIT_PROBABILITY and best.rounds >= rounds \
                and best.established_objects(1 if one_place else MIN_OBJECT_FRAMES) \
                >= MIN_COMMIT_OBJECTS \
                and not (copied := self._places.has_copy(best)):
            t = time.perf_counter()
            poses = [best.world_from_odom @ b.frame.odom_from_camera for b in chosen]
            started = self._start_graph(chosen, poses, [
                self._matches(b, T) for b, T in zip(chosen, poses, strict=True)])
            timings["init_refine"] = (time.perf_counter() - t) * 1e3
            if started is not None:
                T, cov = started
                best.world_from_odom = alignment(T, T_oc)
                self._committed = best
                self.state = "tracking"
                # the pooled frames (>= 3 objects) constrain the pose: the drift restarts here
                self._anchor = _DriftAnchor.at(T_oc, float(frame.timestamp))
                self._recent_objects.clear()
                self._buffer.clear()
                self._misses = 0
                inliers = self._verify(dets, usable, T)
                return self._result(index, frame, T_oc, T, cov, inliers, len(usable), None,
                                    timings)
        if copied or sum(q >= AMBIGUOUS_PROBABILITY for q in self._places.posteriors()) >= 2:
            reason = "ambiguous"
        return self._no_pose(index, frame, T_oc, usable, reason, timings)

    def _matches(self, b: _Buffered, world_from_camera: FloatArray) -> list[Match]:
        """The one-to-one inlier matches of a buffered frame at a pose."""
        if not b.frame.labels:
            return []
        sc = MatchScorer(self.compiled, self.camera, [b.detections[i].ellipse
                                                      for i in b.frame.detection_indices],
                         list(b.frame.labels), list(b.frame.detection_indices))
        return list(sc.matches(invert_pose(world_from_camera), self.options.inlier_iou))

    def _localize_proposals(self, frame: FrameInput, usable: list[int]) -> list[FloatArray]:
        """``world_from_camera`` of single-frame ``localize``'s pose and alternatives on a
        frame with >= 3 usable detections (no time budget: its seeded search gives the same
        answer whatever the load; the frame's own budget is checked after it)."""
        if len(usable) < 3:
            return []
        try:
            r = localize([frame.detections[i] for i in usable], self.compiled, self.camera,
                         LocalizationOptions(seed=self.options.seed, time_budget_ms=None,
                                             inlier_iou=self.options.inlier_iou),
                         gravity=frame.gravity)
        except ScoringTimeoutError:
            return []
        out = [r.world_from_camera] if r.world_from_camera is not None else []
        return out + [a.world_from_camera for a in r.alternatives]

    def _check_place(self, index: int, frame: FrameInput, T: FloatArray,
                     usable: list[int], inliers: Sequence[InlierMatch]) -> str | None:
        """A tracking frame scores the committed place (at the smoother's pose ``T``) and its
        rivals, asking ``localize`` for new rivals every :data:`CHECK_INTERVAL_FRAMES`. The
        session gives the place up (``lost``, keeping the hypotheses) when a rival has become
        more probable (returns ``"ambiguous"``) or the place's posterior fell below
        :data:`~quadloc.service.tracking.places.KEEP_PROBABILITY` (``"lost"``); else None.
        A pose in an exact copy of the committed place is no rival (:meth:`_copy_of_committed`):
        not proposed, and dropped when it would decide."""
        T_oc, ell, labels = self._evidence
        committed = self._committed
        assert committed is not None
        committed.world_from_odom = alignment(T, T_oc)
        self._places.update(T_oc, ell, labels, T, committed,
                            [(self.compiled.index_of(m.object_id), m.iou) for m in inliers])
        self._history.append(self._evidence)
        if index - self._last_check >= CHECK_INTERVAL_FRAMES and len(usable) >= 3:
            self._last_check = index
            self._places.propose([alignment(Tw, T_oc)
                                  for Tw in self._localize_proposals(frame, usable)
                                  if not self._copy_of_committed(Tw, [
                                      self.compiled.index_of(m.object_id) for m in
                                      self._verify(frame.detections, usable, Tw)], T)],
                                 T_oc, self._history, protect=committed)
        p_committed, rival = self._standing(committed)
        if rival or p_committed < KEEP_PROBABILITY:
            # copies of the committed place are no rivals (_copy_of_committed): dropped
            copies = [h for h in self._places.hypotheses
                      if h is not committed and not same_place(h, committed)
                      and self._copy_of_committed(h.world_from_odom @ T_oc, h.objects, T)]
            if copies:
                self._places.discard(copies)
                p_committed, rival = self._standing(committed)
        reason = None
        if rival:
            reason = "ambiguous"
        elif p_committed < KEEP_PROBABILITY:
            reason = "lost"
        if reason is not None:
            self.reset(keep_places=True)
        return reason

    def _standing(self, committed: PlaceHypothesis) -> tuple[float, bool]:
        """The posterior of the committed place and whether another place (not
        :func:`same_place` as ``committed``) is more probable, from one pass over the
        hypotheses' place posteriors."""
        probs = list(zip(self._places.hypotheses, self._places.place_probabilities(),
                         strict=True))
        p_committed = next((q for h, q in probs if h is committed), 0.0)
        return p_committed, any(q > p_committed for h, q in probs
                                if h is not committed and not same_place(h, committed))

    def _copy_of_committed(self, world_from_camera: FloatArray, objects: Iterable[int],
                           committed_world_from_camera: FloatArray) -> bool:
        """Whether a place at the camera pose ``world_from_camera`` that matched ``objects``
        (map indices) is an exact copy of the committed place at
        ``committed_world_from_camera``: each object, carried by the transform between the two
        poses, lands within :data:`COPY_SEARCH_M` of an object of its label, and those
        correspondences (at least 3) pass :func:`~quadloc.service.localization.copies.is_copy`
        (rigid fit, 5 cm). Such a place is no rival: the session committed where the objects
        it matched had no copy, and its odometry carried the alignment from there, so the walk
        tells the copies apart where the frames cannot (a walk from a room into a room that is
        repeated elsewhere)."""
        mine = sorted(objects)
        carry = committed_world_from_camera @ invert_pose(world_from_camera)
        centers = self.compiled.centers
        moved = centers[mine] @ carry[:3, :3].T + carry[:3, 3]
        theirs = []
        for j, p in zip(mine, moved, strict=True):
            same = self.compiled.indices_for(self.compiled.categories[j])
            d = np.linalg.norm(centers[same] - p, axis=1)
            k = int(np.argmin(d))
            if d[k] > COPY_SEARCH_M:
                return False
            theirs.append(int(same[k]))
        return is_copy(self.compiled, np.array(mine, dtype=np.intp),
                       np.array(theirs, dtype=np.intp))

    def _start_graph(self, chosen: list[_Buffered], poses: list[FloatArray],
                     matches: list[list[Match]]) -> tuple[FloatArray, FloatArray] | None:
        """Joint LM over the chosen frames (odometry between consecutive ones, detection
        factors of the RANSAC inliers, a weak prior on the first), then seed the smoother."""
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        weak = gtsam.noiseModel.Diagonal.Sigmas(np.array([3.0] * 3 + [10.0] * 3))
        graph.add(gtsam.PriorFactorPose3(_key(chosen[0].index), pose3(poses[0]), weak))
        for j, (b, T, ms) in enumerate(zip(chosen, poses, matches, strict=True)):
            key = _key(b.index)
            values.insert(key, pose3(T))
            stamps[key] = float(b.index)
            by_det = {m.detection_index: m.object_index for m in ms}
            det_idx = sorted(by_det)
            for f in self._factors_for(key, T, [b.detections[i] for i in det_idx],
                                       [by_det[i] for i in det_idx]):
                graph.add(f)
            _add_prior(graph, key, b.prior)
            self._add_gravity(graph, key, b.gravity)
            if j:
                a = chosen[j - 1]
                between, _, _ = self._between(_key(a.index), key, a.frame.odom_from_camera,
                                              b.frame.odom_from_camera, b.timestamp - a.timestamp)
                graph.add(between)
        try:
            params = gtsam.LevenbergMarquardtParams()
            params.setMaxIterations(30)
            result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        except RuntimeError:
            return None
        refined = [result.atPose3(_key(b.index)).matrix() for b in chosen]
        objs: set[str] = set()
        for b, T in zip(chosen, refined, strict=True):
            objs |= {m.object_id for m in self._verify(b.detections,
                                                       list(b.frame.detection_indices), T)}
        if len(objs) < 3:
            return None
        self._smoother = self._new_smoother()
        try:
            self._smoother.update(graph, result, stamps)
            last = chosen[-1]
            T = self._smoother.calculateEstimatePose3(_key(last.index)).matrix()
            cov = self._marginal(_key(last.index))
        except RuntimeError:
            cov = None
        if cov is None:
            self._smoother = None
            return None
        self._last = (last.index, last.timestamp, last.frame.odom_from_camera, T, cov)
        return T, cov


    def _add_gravity(self, graph: gtsam.NonlinearFactorGraph, key: int,
                     gravity: Gravity | None) -> None:
        """The frame's measured gravity as a factor on its tilt against the map's up axis."""
        if gravity is not None:
            graph.add(gravity_factor(key, gravity_measurement(gravity,
                                                              self.compiled.scene_map.up)))


def _add_prior(graph: gtsam.NonlinearFactorGraph, key: int, prior: PosePrior | None) -> None:
    """The client's prior on ``world_from_camera`` as a factor, when it has a covariance."""
    if prior is not None and prior.covariance is not None:
        graph.add(gtsam.PriorFactorPose3(key, pose3(prior.world_from_camera),
                                         gtsam.noiseModel.Gaussian.Covariance(
                                             np.asarray(prior.covariance))))


def _spread(items: Sequence[_T], n: int) -> list[_T]:
    """At most ``n`` items evenly spread over ``items`` (keeping the newest)."""
    if n <= 0:
        return []
    if len(items) <= n:
        return list(items)
    idx = np.unique(np.round(np.linspace(len(items) - 1, 0, n)).astype(int))
    return [items[i] for i in sorted(idx)]
