"""Inputs and outputs of :func:`quadloc.service.localization.pipeline.localize`, validated on
construction (bad input raises :class:`LocalizationInputError` or
:class:`quadloc.factors.names.GeometryError`, both ``ValueError``, naming the field).

Frames: ``world_from_camera`` is the camera's pose in the map (4x4, camera axes OpenCV:
+X right, +Y down, +Z forward). Covariances are 6x6 in GTSAM's Pose3 tangent order
``[omega_x, omega_y, omega_z, v_x, v_y, v_z]`` (radians, metres), right perturbation, expressed
in the camera (body) frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.conics import Ellipse
from quadloc.factors.metrics import residual
from quadloc.factors.names import FieldError, GeometryError, check_robust
from quadloc.factors.rotations import check_pose
from quadloc.service.limits import (
    AMBIGUITY_POLICIES,
    GRAVITY_DEFAULT_SIGMA_DEG,
    GRAVITY_MAX_SIGMA_DEG,
    METRICS,
    NO_REFINEMENT,
    REASONS,
    ROBUST_KERNELS,
    UNKNOWN_LABEL_POLICIES,
)

__all__ = [  # METRICS and ROBUST_KERNELS: quadloc.service.limits' names, re-exported for callers
    "METRICS",
    "ROBUST_KERNELS",
    "Alternative",
    "Detection",
    "Gravity",
    "InlierMatch",
    "LocalizationInputError",
    "LocalizationOptions",
    "LocalizationResult",
    "PlaceHint",
    "PosePrior",
]

class LocalizationInputError(FieldError):
    """Invalid input to :func:`localize`, naming its ``field`` (a :class:`FieldError`); the
    message reads e.g. ``"detections[2].label: 'Sofa' is not a category of the map ..."``."""


@dataclass(frozen=True)
class Detection:
    """One detected object: its ellipse (px), category label, optional predicted ``sigma``
    (the paper's per-detection uncertainty, > 0, unitless: it scales the metric's cost as
    ``sigma^-1 * Delta``) and optional detector ``score`` in [0, 1]."""

    ellipse: Ellipse
    label: str
    sigma: float | None = None
    score: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.ellipse, Ellipse):
            raise GeometryError("Detection.ellipse must be an Ellipse")
        if not isinstance(self.label, str) or not self.label:
            raise GeometryError("Detection.label must be a non-empty string")
        if self.sigma is not None and not (math.isfinite(self.sigma) and self.sigma > 0):
            raise GeometryError(f"Detection.sigma must be finite and > 0, got {self.sigma}")
        if self.score is not None and not (math.isfinite(self.score) and 0 <= self.score <= 1):
            raise GeometryError(f"Detection.score must be in [0, 1], got {self.score}")


def check_detections(detections: object,
                     error: type[FieldError] = LocalizationInputError) -> None:
    """THE rule of a request's detections: a non-empty sequence of :class:`Detection`;
    otherwise raises ``error`` with ``field`` ``"detections"`` or ``"detections[i]"``. Shared by
    ``localize`` and :func:`quadloc.service.localization.refine.refine`."""
    if isinstance(detections, (str, bytes, Detection)) or not isinstance(detections, Sequence):
        raise error(f"must be a sequence of Detection, got {type(detections).__name__}",
                    field="detections")
    if len(detections) == 0:
        raise error("must not be empty", field="detections")
    for i, d in enumerate(detections):
        if not isinstance(d, Detection):
            raise error(f"must be a Detection, got {type(d).__name__}", field=f"detections[{i}]")


def _bad(field_name: str, problem: str) -> LocalizationInputError:
    return LocalizationInputError(problem, field=field_name)


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


#: THE rules of the scalar options: name -> (test, rule), shared by
#: :class:`LocalizationOptions` and :func:`quadloc.service.localization.refine.refine`.
_OPTION_RULES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "min_confidence": (lambda v: v is None or (_number(v) and 0.0 <= v <= 1.0),
                       "must be in [0, 1] or None"),
    "on_ambiguity": (lambda v: v in AMBIGUITY_POLICIES, f"must be one of {AMBIGUITY_POLICIES}"),
    "ransac_max_hypotheses": (lambda v: _is_int(v) and v >= 1, "must be an integer >= 1"),
    "inlier_iou": (lambda v: _number(v) and 0.0 < v <= 1.0, "must be in (0, 1]"),
    "min_inliers": (lambda v: _is_int(v) and v >= 2, "must be an integer >= 2"),
    "use_sigma": (lambda v: isinstance(v, bool), "must be a bool"),
    "unknown_label_policy": (lambda v: v in UNKNOWN_LABEL_POLICIES,
                             f"must be one of {UNKNOWN_LABEL_POLICIES}"),
    "seed": (lambda v: v is None or _is_int(v), "must be an integer or None"),
    "time_budget_ms": (lambda v: v is None or (_number(v) and v > 0), "must be > 0 or None"),
    "max_iterations": (lambda v: _is_int(v) and v >= 1, "must be an integer >= 1"),
}


def check_options(values: Mapping[str, object], error: type[FieldError] = LocalizationInputError,
                  prefix: str = "options.") -> None:
    """Each ``values[name]`` obeys :data:`_OPTION_RULES` ``[name]``; otherwise raises ``error``
    with ``field = prefix + name``."""
    for name, value in values.items():
        test, rule = _OPTION_RULES[name]
        if not test(value):
            raise error(f"{rule}, got {value!r}", field=prefix + name)


@dataclass(frozen=True)
class LocalizationOptions:
    """Options of :func:`quadloc.service.localization.pipeline.localize` (validated on
    construction).

    Attributes:
        metric: refinement metric, one of :data:`METRICS` (default ``"level_set"``, the paper's),
            or ``"none"`` to return the best RANSAC hypothesis unrefined.
        ransac_max_hypotheses: budget of minimal samples (label-compatible detection/object
            triples for P3P, pairs for P2E). When the number of label-compatible samples is at
            most this budget they are all tried (exhaustive); otherwise this many are drawn at
            random (seeded) with early exit once a hypothesis explains every detection.
        inlier_iou: a detection is an inlier of a pose when the IoU (intersection over union,
            in [0, 1]) of its ellipse and its assigned projected ellipsoid is >= this.
        min_inliers: minimum number of inlier detections (>= 2) for a pose to be accepted.
        use_sigma: weight each detection's cost by ``sigma^-1`` (paper eq. 8). ``localize()``
            weights only when every detection has a sigma, else all weights are 1; the
            covariance and confidence are calibrated for either (``confidence.calibration_key``).
        robust: robust kernel of the refinement, ``None`` or one of :data:`ROBUST_KERNELS`.
        robust_scale: kernel scale (in units of the metric's residual); ``None`` = the
            refinement module's documented default. Only allowed with ``robust``.
        unknown_label_policy: what to do with a detection whose label is not a category of
            the map: ``"ignore"`` (default) drops it from matching (it is never an inlier;
            with fewer than 2 detections left the reason is ``no_label_match``); ``"error"``
            raises
            :class:`LocalizationInputError` naming ``detections[i].label``.
        seed: seed of the hypothesis sampler (``None`` = nondeterministic). Exhaustive runs do
            not depend on it.
        time_budget_ms: budget (ms) of the whole ``localize`` call, from its start, in CPU
            time of the solving thread with a wall-clock hard limit
            (:meth:`quadloc.factors.budget.Deadline.cpu_budget`). The hypothesis search stops
            at it (the best hypothesis so far is used, or ``reason="time_budget_exceeded"``); no
            refinement iteration starts after it (``refinement_status="time_budget"``).
            ``None`` = unbounded.
        max_iterations: Levenberg-Marquardt iteration cap of the refinement.
        metric_options: extra keyword options of the metric (e.g. level-set sampling),
            validated on construction (an unknown key or bad value raises naming
            ``options.metric_options.<key>``).
        on_ambiguity: what to answer when a distinct hypothesis explains the detections
            comparably well (``quadloc.service.localization.confidence``): ``"not_localized"``
            (default: ``localized=False, reason="ambiguous"``, the hypotheses listed in
            ``alternatives``) or ``"best"`` (the best pose, localized, with the others in
            ``alternatives``; each with its probability).
        min_confidence: answers whose ``confidence`` is below this are returned as
            ``localized=False, reason="low_confidence"``; ``None`` = the calibrated default
            ``quadloc.service.localization.calibration.MIN_CONFIDENCE`` (chosen on the tuning seeds
            so that 2-3 detection frames are not answered with a wrong pose), or
            ``MIN_CONFIDENCE_PLACES`` for the answers of a large map's place search (chosen on
            building frames: there a failure is more often a wrong place); 0 accepts every
            verified pose (an ambiguous one is not: ``on_ambiguity``).

    Integer fields accept any integral number (numpy integers too) and store a Python int.
    """

    metric: str = "level_set"
    ransac_max_hypotheses: int = 300
    inlier_iou: float = 0.2
    min_inliers: int = 2
    use_sigma: bool = True
    robust: str | None = None
    robust_scale: float | None = None
    unknown_label_policy: str = "ignore"
    seed: int | None = 0
    time_budget_ms: float | None = 1000.0
    max_iterations: int = 50
    metric_options: Mapping[str, Any] | None = None
    on_ambiguity: str = "not_localized"
    min_confidence: float | None = None

    def __post_init__(self) -> None:
        if self.metric not in METRICS and self.metric != NO_REFINEMENT:
            raise _bad("options.metric",
                       f"unknown metric {self.metric!r}; valid: {', '.join(METRICS)} "
                       f"or {NO_REFINEMENT!r}")
        check_robust(self.robust, self.robust_scale, prefix="options.",
                     error=LocalizationInputError)
        check_options({name: getattr(self, name) for name in _OPTION_RULES})
        # integral numbers (numpy ints too) are accepted and stored as Python ints
        for name in ("ransac_max_hypotheses", "min_inliers", "max_iterations", "seed"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, int(value))
        if self.metric_options is not None:
            if not isinstance(self.metric_options, Mapping):
                raise _bad("options.metric_options",
                           f"must be a mapping, got {type(self.metric_options).__name__}")
            for key in self.metric_options:
                if not isinstance(key, str):
                    raise _bad("options.metric_options", f"keys must be strings, got {key!r}")
            _check_metric_options(self.metric, self.metric_options)
            object.__setattr__(self, "metric_options", MappingProxyType(dict(self.metric_options)))


_PROBES = (Ellipse(100.0, 80.0, 20.0, 10.0, 0.3), Ellipse(104.0, 82.0, 22.0, 11.0, 0.35))


def _check_metric_options(metric: str, options: Mapping[str, Any]) -> None:
    """Each metric option is valid for ``metric`` (name and value): checked here, before any
    work, by evaluating the metric once on a fixed ellipse pair with that option alone."""
    for key, value in options.items():
        if metric == NO_REFINEMENT:
            raise _bad(f"options.metric_options.{key}",
                       f"metric {NO_REFINEMENT!r} takes no options")
        try:
            residual(metric, *_PROBES, **{key: value})
        except (TypeError, ValueError) as exc:
            raise _bad(f"options.metric_options.{key}", str(exc)) from exc


def check_covariance(field_name: str, value: object,
                     error: type[FieldError] = LocalizationInputError) -> FloatArray:
    """A 6x6 pose covariance (finite, symmetric to rtol 1e-9, positive definite) as a read-only
    float array; otherwise raises ``error`` (a :class:`FieldError`) with ``field=field_name``.
    Shared by :class:`PosePrior` and :func:`quadloc.service.localization.refine.refine`."""
    try:
        S = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise error("must be a numeric 6x6 matrix", field=field_name) from exc
    if S.shape != (6, 6):
        raise error(f"must have shape (6, 6), got {S.shape}", field=field_name)
    if not np.all(np.isfinite(S)):
        raise error("must be finite", field=field_name)
    if not np.allclose(S, S.T, rtol=1e-9, atol=1e-12 * max(1.0, float(np.abs(S).max()))):
        raise error("must be symmetric", field=field_name)
    if float(np.linalg.eigvalsh(0.5 * (S + S.T)).min()) <= 0.0:
        raise error("must be positive definite", field=field_name)
    S.setflags(write=False)
    return S


@dataclass(frozen=True, eq=False)
class PosePrior:
    """A client's pose prior.

    Attributes:
        world_from_camera: 4x4 camera pose in the map frame (OpenCV camera axes).
        covariance: optional 6x6 covariance in Pose3 tangent order ``[omega, v]`` (rad, m),
            body (camera) frame, right perturbation. With a covariance the prior is also a soft
            factor in the refinement; without, it is only the starting point.
    """

    world_from_camera: FloatArray
    covariance: FloatArray | None = None

    def __post_init__(self) -> None:
        try:
            T = check_pose(self.world_from_camera, "prior.world_from_camera")
        except GeometryError as exc:
            raise LocalizationInputError(exc.problem, field=exc.field) from exc
        T.setflags(write=False)
        object.__setattr__(self, "world_from_camera", T)
        if self.covariance is not None:
            object.__setattr__(self, "covariance",
                               check_covariance("prior.covariance", self.covariance))


@dataclass(frozen=True, eq=False)
class PlaceHint:
    """A coarse hint of where the camera is (a zone, or a position with a large uncertainty:
    a GPS / Wi-Fi / beacon fix, the app's last known position).

    It weights the search of a large map (half of the places searched are the hint's,
    :func:`quadloc.service.localization.constellations.place_seeds`) and settles an ambiguity
    between places in its favour, never more: a candidate outside the hint that the evidence
    favours is still the answer, and the answer passes the same checks.

    Attributes:
        position: (3,) the camera's position, world metres, or None.
        sigma_m: the position's 1-sigma uncertainty (isotropic, m, > 0) when ``position`` is
            given.
        object_ids: the objects of the hinted zone (the application resolves a zone id to
            them), or None.
    """

    position: FloatArray | None = None
    sigma_m: float | None = None
    object_ids: frozenset[str] | None = None

    def __post_init__(self) -> None:
        if (self.position is None) == (self.object_ids is None):
            raise LocalizationInputError("give either a position or the objects of a zone",
                                         field="hint")
        if self.position is not None:
            p = np.asarray(self.position, dtype=float)
            if p.shape != (3,) or not np.all(np.isfinite(p)):
                raise LocalizationInputError("must be 3 finite numbers (m)",
                                             field="hint.position")
            s = self.sigma_m
            if s is None or not (math.isfinite(s) and s > 0):
                raise LocalizationInputError("must be a number > 0 (m)", field="hint.sigma_m")
            p.setflags(write=False)
            object.__setattr__(self, "position", p)
        elif self.object_ids is not None and not self.object_ids:
            raise LocalizationInputError("the zone has no objects", field="hint.zone")

    #: A camera within this many sigmas of a position hint agrees with it.
    AGREE_SIGMAS = 3.0

    def agrees(self, world_from_camera: FloatArray, object_ids: Sequence[str]) -> bool:
        """Whether a candidate (its pose, the ids of its inlier objects) is where the hint says:
        within :attr:`AGREE_SIGMAS` sigmas of the position, or most of its inliers in the
        zone."""
        if self.position is not None and self.sigma_m is not None:
            d = float(np.linalg.norm(np.asarray(world_from_camera)[:3, 3] - self.position))
            return d <= self.AGREE_SIGMAS * self.sigma_m
        assert self.object_ids is not None
        inside = sum(1 for o in object_ids if o in self.object_ids)
        return 2 * inside > len(object_ids)


@dataclass(frozen=True)
class Gravity:
    """The direction of gravity measured by the client (e.g. the IMU of an AR framework).

    Attributes:
        direction_camera: (3,) the direction gravity pulls (DOWN, toward the ground) in the
            image's OpenCV camera axes (+X right, +Y down, +Z forward); any positive length
            (normalised here). An accelerometer at rest measures the opposite (up).
        sigma_deg: its angular uncertainty (1 sigma, degrees), in (0, 30].
    """

    direction_camera: FloatArray
    sigma_deg: float = GRAVITY_DEFAULT_SIGMA_DEG

    def __post_init__(self) -> None:
        try:
            g = np.asarray(self.direction_camera, dtype=float)
        except (TypeError, ValueError) as exc:
            raise _bad("gravity.direction", "must be 3 numbers") from exc
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise _bad("gravity.direction", f"must be 3 finite numbers, got {g.tolist()}")
        n = float(np.linalg.norm(g))
        if not n > 1e-9:
            raise _bad("gravity.direction", "must not be the zero vector")
        g = g / n
        g.setflags(write=False)
        object.__setattr__(self, "direction_camera", g)
        if not (_number(self.sigma_deg) and 0.0 < self.sigma_deg <= GRAVITY_MAX_SIGMA_DEG):
            raise _bad("gravity.sigma_deg",
                       f"must be in (0, {GRAVITY_MAX_SIGMA_DEG:g}], got {self.sigma_deg!r}")


@dataclass(frozen=True)
class InlierMatch:
    """One inlier of the returned pose.

    Attributes:
        detection_index: index into the ``detections`` passed to ``localize``.
        object_id: the matched map object's id.
        iou: intersection over union (in [0, 1]) of the detection and the object's projection
            at the returned pose.
        cost: the refinement metric's (unweighted) cost for this pair at the returned pose; with
            ``metric="none"`` it is the Jaccard distance ``1 - iou``.
    """

    detection_index: int
    object_id: str
    iou: float
    cost: float


@dataclass(frozen=True, eq=False)
class Alternative:
    """A distinct candidate pose of an ambiguous frame.

    Attributes:
        world_from_camera: 4x4 camera pose in the map frame.
        confidence: probability that this pose is within the confidence tolerance
            (``quadloc.service.localization.confidence``).
        n_inliers: its inlier count; score: the sum of its inliers' IoUs.
        object_ids: the map objects of its inliers (in detection order).
    """

    world_from_camera: FloatArray
    confidence: float
    n_inliers: int
    score: float
    object_ids: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class LocalizationResult:
    """The answer of ``localize``.

    Attributes:
        localized: whether a pose is returned.
        reason: ``None`` when localized, else one of :data:`REASONS`:
            ``too_few_detections`` (the request has fewer than 2 detections, whatever their
            labels), ``no_label_match`` (at least 2 detections, but fewer than 2 whose label
            is a category of the map, or no label-compatible minimal sample: e.g. two
            detections labelled like the map's single object of that category),
            ``no_hypothesis_above_inlier_threshold`` (no pose with ``min_inliers`` detections at
            IoU >= ``inlier_iou``), ``refinement_diverged`` (the refined pose lost its inliers
            or the solver failed), ``time_budget_exceeded`` (the budget ran out before any
            hypothesis qualified), ``ambiguous`` (a distinct pose explains the detections
            comparably well; see ``alternatives``), ``low_confidence`` (the best pose's
            ``confidence`` is below ``options.min_confidence``; its value is kept in
            ``evidence``), ``gravity_mismatch`` (every refined candidate's tilt disagrees with
            the client's measured gravity: :mod:`quadloc.service.localization.gravity`).
        world_from_camera: 4x4 camera pose in the map frame, or ``None``.
        covariance: 6x6 pose covariance, order ``[omega, v]``, body frame, or ``None`` (not
            localized, ``metric="none"``, or a singular information matrix). Calibrated
            (``quadloc.service.localization.confidence``): conditioned on the inlier associations
            and the detection noise, scaled by the frame's residual level.
        confidence: in [0, 1]; 0 when not localized. The probability that the returned pose
            is within 0.10 m and 5 deg of the truth, from a logistic model of the solver's
            evidence, calibrated on simulated frames (``quadloc.service.localization.confidence``).
        inliers: the inlier matches (sorted by detection index).
        metric: the refinement metric used (``"none"`` when unrefined).
        hypotheses_evaluated: number of candidate poses scored (P3P/P2E solutions + prior).
        used_prior: whether the returned pose comes from refining the client's prior.
        timings_ms: wall time per stage in ms (``validate``, ``prior``, ``hypotheses``,
            ``refine``, ``total``; stages not run are absent).
        refinement_status: ``None`` when no refinement ran (``metric="none"`` or stopped
            before), else the last refinement's ``RefinementResult.status`` (``converged``,
            ``max_iterations``, ``time_budget``, ``diverged``, ``invalid_projection``);
            ``time_budget`` also when the budget ran out before the level-set re-lay or the
            re-association refinement, i.e. the pose is returned less refined than it would
            be without the budget.
        pose_source: ``"prior"`` (the refined client prior won) or ``"ransac"``; None when
            not localized.
        alternatives: the distinct candidate poses (best first) of a verified answer that is
            not localized (``ambiguous``, ``low_confidence``, ``gravity_mismatch``) or of an
            ambiguous one answered with ``on_ambiguity="best"``; empty otherwise.
        evidence: the confidence model's features and ``s2`` (for diagnostics and the bench).
    """

    localized: bool
    reason: str | None
    world_from_camera: FloatArray | None
    covariance: FloatArray | None
    confidence: float
    inliers: tuple[InlierMatch, ...]
    metric: str
    hypotheses_evaluated: int
    used_prior: bool
    timings_ms: dict[str, float] = field(default_factory=dict)
    refinement_status: str | None = None
    pose_source: str | None = None
    alternatives: tuple[Alternative, ...] = ()
    evidence: Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        if self.localized:
            if self.reason is not None or self.world_from_camera is None:
                raise ValueError("a localized result has a pose and no reason")
        elif self.reason not in REASONS:
            raise ValueError(f"reason must be one of {REASONS}, got {self.reason!r}")
        if not (0.0 <= self.confidence <= 1.0):
            raise ValueError(f"confidence must be in [0, 1], got {self.confidence}")
