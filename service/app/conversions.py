"""Conversions between the wire models (:mod:`quadloc.service.schemas`) and the domain types of
localization and tracking: the edge of the application layer.

Camera conventions: the solver works in OpenCV camera axes (+X right, +Y down, +Z forward).
OpenGL/ARKit/ARCore axes (+X right, +Y up, -Z forward) differ by ``F = diag(1, -1, -1)`` on the
camera side: ``world_from_camera_gl = world_from_camera_cv @ diag(F, 1)``. ``F`` is a proper
rotation (pi about +X) and its own inverse, so the same product converts both ways. A body-frame
covariance in tangent order ``[omega, v]`` transforms with the adjoint of ``F``:
``Cov_gl = Ad Cov_cv Ad^T`` with ``Ad = blockdiag(F, F)`` (right perturbation:
``T_cv exp(xi_cv) F = T_cv F exp(Ad_F^-1 xi_cv)``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.camera import Camera
from quadloc.factors.conics import Ellipse
from quadloc.factors.names import FieldError
from quadloc.factors.rotations import (
    DOCUMENT_ROTATION_TOLERANCE,
    QUATERNION_NORM_TOLERANCE,
    check_pose,
    pose_matrix,
    quaternion_wxyz_from_rotation,
    rotation_from_quaternion_wxyz,
)
from quadloc.maps.building.recording import (
    BuildLimits,
    FrameRecord,
    Observation,
    OdometryNoise,
    Recording,
    SizePrior,
    held_out,
)
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.zones import ZoneIndex
from quadloc.service.localization.types import (
    Detection,
    Gravity,
    InlierMatch,
    LocalizationInputError,
    LocalizationOptions,
    LocalizationResult,
    PlaceHint,
    PosePrior,
)
from quadloc.service.schemas.localize import (
    CameraIn,
    CovarianceOut,
    DetectionIn,
    GravityIn,
    HintIn,
    InlierOut,
    LocalizeOptionsIn,
    LocalizeResponse,
    PoseIn,
    PoseOut,
    PosePriorIn,
)
from quadloc.service.schemas.recording import (
    LEGACY_RECORDING_WARNING,
    LegacyRecordingIn,
    RecordingFrameIn,
    RecordingIn,
)
from quadloc.service.schemas.sessions import (
    PlaceCandidateOut,
    SessionFrameIn,
    SessionFrameOut,
    SessionOptionsIn,
)
from quadloc.service.tracking.session import (
    DriftModel,
    FrameInput,
    FrameResult,
    SessionOptions,
)

__all__ = [
    "OPENGL_FROM_OPENCV",
    "RecordingInputError",
    "camera_from_request",
    "convert_covariance",
    "convert_pose",
    "covariance_out",
    "detections_from_request",
    "frame_input_from_wire",
    "frame_out",
    "gravity_from_request",
    "held_out_frames_from_wire",
    "hint_from_request",
    "inliers_out",
    "options_from_request",
    "pose_matrix_from_wire",
    "pose_out",
    "prior_from_request",
    "recording_from_wire",
    "response_from_result",
    "session_options_from_wire",
]

#: ``diag(1, -1, -1)``: camera-side flip between OpenCV and OpenGL axes (its own inverse). The
#: server's one copy; ``sdk/python/quadloc_sdk/geometry.py`` keeps its own (the SDK imports nothing
# of the server).
OPENGL_FROM_OPENCV = np.diag([1.0, -1.0, -1.0])


def convert_pose(world_from_camera: FloatArray, source: str, target: str) -> FloatArray:
    """Re-express a 4x4 ``world_from_camera`` from ``source`` to ``target`` camera axes
    (``"opencv"`` or ``"opengl"``)."""
    T = np.array(world_from_camera, dtype=float)
    if source == target:
        return T
    T[:3, :3] = T[:3, :3] @ OPENGL_FROM_OPENCV
    return T


def convert_covariance(covariance: FloatArray, source: str, target: str) -> FloatArray:
    """Re-express a 6x6 body-frame ``[omega, v]`` covariance between camera conventions."""
    S = np.array(covariance, dtype=float)
    if source == target:
        return S
    ad = np.kron(np.eye(2), OPENGL_FROM_OPENCV).astype(np.float64)
    out: FloatArray = ad @ S @ ad.T
    return out


def camera_from_request(camera: CameraIn) -> Camera:
    return Camera(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height)


def detections_from_request(detections: Sequence[DetectionIn]) -> list[Detection]:
    """Wire detections -> :class:`Detection` (boxes become inscribed ellipses)."""
    def ellipse(d: DetectionIn) -> Ellipse:
        e, b = d.ellipse, d.box  # exactly one of them (DetectionIn's validator)
        return (Ellipse(e.cx, e.cy, e.a, e.b, e.angle) if e is not None
                else Ellipse.from_bbox(b.xmin, b.ymin, b.xmax, b.ymax))  # type: ignore[union-attr]

    return [Detection(ellipse(d), d.label, d.effective_sigma(), d.score) for d in detections]


def pose_matrix_from_wire(pose: PoseIn, field: str) -> FloatArray:
    """The 4x4 of a wire pose (its ``matrix``, or its unit ``quaternion_wxyz`` and
    ``translation_m``), in the pose's own camera convention; a quaternion off unit norm raises
    :class:`LocalizationInputError` naming ``<field>.quaternion_wxyz``."""
    if pose.matrix is not None:
        return np.array(pose.matrix, dtype=float)
    # PoseIn's validator: a pose without a matrix has both of these
    assert pose.quaternion_wxyz is not None and pose.translation_m is not None
    q = np.array(pose.quaternion_wxyz, dtype=float)
    n = float(np.linalg.norm(q))
    if not abs(n - 1.0) <= QUATERNION_NORM_TOLERANCE:
        raise LocalizationInputError(f"must have unit norm, |q| = {n:.9g}",
                                     field=f"{field}.quaternion_wxyz")
    return pose_matrix(rotation_from_quaternion_wxyz(q / n), pose.translation_m)


def prior_from_request(prior: PosePriorIn | None) -> PosePrior | None:
    """Wire prior (any convention) -> :class:`PosePrior` in OpenCV axes."""
    if prior is None:
        return None
    T = pose_matrix_from_wire(prior.world_from_camera, "prior.world_from_camera")
    cov = None
    if prior.covariance is not None:
        cov = np.array(prior.covariance, dtype=float)
        if np.all(np.isfinite(cov)):
            cov = convert_covariance(cov, prior.convention, "opencv")
    if np.all(np.isfinite(T)):
        T = convert_pose(T, prior.convention, "opencv")
    return PosePrior(T, cov)


def hint_from_request(hint: HintIn | None, compiled: CompiledMap) -> PlaceHint | None:
    """Wire hint -> :class:`PlaceHint`; a zone is its objects. An object id or zone id the map
    does not have is refused (:class:`LocalizationInputError` naming ``hint.object_ids[k]`` or
    ``hint.zone_id``)."""
    if hint is None:
        return None
    if hint.zone_id is not None:
        try:
            zone = compiled.scene_map.zone_by_id(hint.zone_id)
        except KeyError:
            raise LocalizationInputError(f"{hint.zone_id!r} is not a zone of the map",
                                         field="hint.zone_id") from None
        return PlaceHint(object_ids=frozenset(zone.object_ids))
    if hint.object_ids is not None:
        known = set(compiled.object_ids)
        for k, o in enumerate(hint.object_ids):
            if o not in known:
                raise LocalizationInputError(f"{o!r} is not an object of the map",
                                             field=f"hint.object_ids[{k}]")
        return PlaceHint(object_ids=frozenset(hint.object_ids))
    return PlaceHint(position=np.array(hint.position, dtype=float), sigma_m=hint.sigma_m)


def gravity_from_request(gravity: GravityIn | None,
                         default_convention: str = "opencv") -> Gravity | None:
    """Wire gravity -> :class:`Gravity` in OpenCV axes (``F`` maps a camera vector between the
    conventions, both ways). Its axes: ``gravity.convention`` when the request sets it, else
    ``default_convention`` (a tracking session's convention)."""
    if gravity is None:
        return None
    g = np.array(gravity.direction, dtype=float)
    convention = (gravity.convention if "convention" in gravity.model_fields_set
                  else default_convention)
    if convention != "opencv":
        g = OPENGL_FROM_OPENCV @ g
    return Gravity(g, gravity.sigma_deg)


#: The wire options that are :class:`LocalizationOptions` fields of the same name and meaning.
_SHARED_OPTIONS = tuple(sorted({f.name for f in dataclasses.fields(LocalizationOptions)}
                               & set(LocalizeOptionsIn.model_fields)))


def options_from_request(options: LocalizeOptionsIn, max_budget_ms: float) -> LocalizationOptions:
    """Wire options -> :class:`LocalizationOptions`; the time budget is capped by the server."""
    budget = max_budget_ms if options.time_budget_ms is None else min(options.time_budget_ms,
                                                                      max_budget_ms)
    return LocalizationOptions(**{**{k: getattr(options, k) for k in _SHARED_OPTIONS},
                                  "time_budget_ms": float(budget)})


def _pose_fields(world_from_camera_cv: FloatArray, convention: str) -> dict[str, object]:
    """The :class:`PoseOut` fields (plain Python lists of floats) of a 4x4 OpenCV-axes
    ``world_from_camera`` re-expressed in ``convention`` axes."""
    T = convert_pose(world_from_camera_cv, "opencv", convention)
    q = quaternion_wxyz_from_rotation(T[:3, :3]).tolist()
    return {"quaternion_wxyz": q, "quaternion_xyzw": q[1:] + q[:1],
            "translation_m": T[:3, 3].tolist(), "matrix": T.tolist(),
            "matrix_column_major": T.T.reshape(16).tolist(), "convention": convention}


def pose_out(world_from_camera_cv: FloatArray, convention: str) -> PoseOut:
    """4x4 OpenCV-axes ``world_from_camera`` -> wire pose in ``convention`` axes."""
    return PoseOut(**_pose_fields(world_from_camera_cv, convention))  # type: ignore[arg-type]


def _finite(x: float) -> float:
    return float(x) if math.isfinite(float(x)) else 0.0


def _covariance_fields(covariance: FloatArray | None, source: str,
                       target: str) -> dict[str, object] | None:
    """The :class:`CovarianceOut` fields (``order`` and ``frame`` default) of a 6x6 covariance;
    None when absent or not finite."""
    if covariance is None or not np.all(np.isfinite(covariance)):
        return None
    return {"matrix": convert_covariance(covariance, source, target).tolist()}


def covariance_out(covariance: FloatArray | None, source: str,
                   target: str) -> CovarianceOut | None:
    """6x6 ``[omega, v]`` covariance in ``source`` camera axes -> wire covariance in ``target``
    axes; None when absent or not finite."""
    fields = _covariance_fields(covariance, source, target)
    return None if fields is None else CovarianceOut(**fields)  # type: ignore[arg-type]


def _inlier_fields(inliers: Sequence[InlierMatch]) -> list[dict[str, object]]:
    return [{"detection_index": m.detection_index, "object_id": m.object_id,
             "iou": _finite(m.iou), "cost": _finite(m.cost)} for m in inliers]


def inliers_out(inliers: Sequence[InlierMatch]) -> list[InlierOut]:
    """Solver inlier matches -> wire inliers (non-finite IoU / cost as 0)."""
    return [InlierOut(**fields) for fields in _inlier_fields(inliers)]  # type: ignore[arg-type]


def response_from_result(
    result: LocalizationResult,
    *,
    map_id: str,
    map_version: int,
    convention: str,
    frame_id: str | None,
    timestamp: float | None,
    zones: ZoneIndex | None = None,
) -> LocalizeResponse:
    """Solver result -> wire response (pose and covariance in ``convention`` camera axes);
    ``zones``: the map's zones, naming the ``zone`` of the answer and of each alternative
    (:mod:`quadloc.maps.zones`; without: null)."""
    def zone_of(object_ids: Iterable[str]) -> str | None:
        return None if zones is None else zones.zone_of(object_ids)

    pose = cov = None
    if result.localized and result.world_from_camera is not None:
        if not np.all(np.isfinite(result.world_from_camera)):
            raise FloatingPointError("localize() returned a non-finite pose")
        pose = _pose_fields(result.world_from_camera, convention)
        cov = _covariance_fields(result.covariance, "opencv", convention)
    # Plain fields validated in ONE pydantic call (nested models built in its core): the same
    # model and JSON as constructing each nested model, at a fraction of the per-request cost.
    return LocalizeResponse.model_validate({
        "localized": result.localized,
        "reason": result.reason,
        "world_from_camera": pose,
        "covariance": cov,
        "confidence": _finite(result.confidence),
        "inliers": _inlier_fields(result.inliers),
        "metric": result.metric,
        "hypotheses_evaluated": result.hypotheses_evaluated,
        "used_prior": result.used_prior,
        "refinement_status": result.refinement_status,
        "pose_source": result.pose_source,
        "zone": zone_of(i.object_id for i in result.inliers) if result.inliers
        else zone_of(result.alternatives[0].object_ids) if result.alternatives else None,
        "alternatives": [{"world_from_camera": _pose_fields(a.world_from_camera, convention),
                          "confidence": _finite(a.confidence), "n_inliers": a.n_inliers,
                          "score": _finite(a.score), "zone": zone_of(a.object_ids)}
                         for a in result.alternatives],
        "map_id": map_id,
        "map_version": map_version,
        "timings_ms": {k: _finite(v) for k, v in result.timings_ms.items()},
        "frame_id": frame_id,
        "timestamp": timestamp,
    })


# --------------------------------------------------------------------------- tracking sessions


def session_options_from_wire(options: SessionOptionsIn) -> SessionOptions:
    """Wire session options -> :class:`SessionOptions` (odometry rotation noise from degrees to
    radians)."""
    return SessionOptions(
        window_frames=options.window_frames, smoother=options.smoother,
        inlier_iou=options.inlier_iou,
        drift=DriftModel(
            translation_m_per_sqrt_m=options.odometry_translation_m_per_sqrt_m,
            translation_m_per_sqrt_s=options.odometry_translation_m_per_sqrt_s,
            rotation_rad_per_sqrt_m=math.radians(options.odometry_rotation_deg_per_sqrt_m),
            rotation_rad_per_sqrt_s=math.radians(options.odometry_rotation_deg_per_sqrt_s)))


def frame_input_from_wire(frame: SessionFrameIn, convention: str) -> FrameInput:
    """Wire session frame (poses and gravity in the session's ``convention`` unless they say
    otherwise) -> :class:`FrameInput` in OpenCV axes. Raises the domain input errors
    (``GeometryError``, ``LocalizationInputError``, ``TrackingInputError``) naming the field
    relative to the frame."""
    detections = detections_from_request(frame.detections)
    T = pose_matrix_from_wire(frame.odom_from_camera, "odom_from_camera")
    T = check_pose(convert_pose(T, convention, "opencv"), "odom_from_camera",
                   DOCUMENT_ROTATION_TOLERANCE)
    return FrameInput(detections, T, float(frame.timestamp), frame.frame_id,
                      prior_from_request(frame.prior), gravity_from_request(frame.gravity,
                                                                            convention))


def frame_out(result: FrameResult, convention: str,
              zones: ZoneIndex | None = None) -> SessionFrameOut:
    """A session frame's answer -> wire (``world_from_camera`` and its covariance in the
    session's ``convention``; ``world_from_odom`` maps odometry to map coordinates, so its
    matrix is convention-free and its covariance stays in the odometry (OpenCV body) frame);
    ``zone`` of its inliers by the map's ``zones`` (:mod:`quadloc.maps.zones`)."""
    return SessionFrameOut(
        frame_index=result.frame_index, frame_id=result.frame_id, timestamp=result.timestamp,
        state=result.state, reason=result.reason,
        world_from_camera=None if result.world_from_camera is None
        else pose_out(result.world_from_camera, convention),
        covariance=covariance_out(result.covariance, "opencv", convention),
        world_from_odom=None if result.world_from_odom is None
        else pose_out(result.world_from_odom, "opencv").model_copy(
            update={"convention": convention}),
        world_from_odom_covariance=covariance_out(result.world_from_odom_covariance, "opencv",
                                                  "opencv"),
        confidence=result.confidence,
        inliers=inliers_out(result.inliers),
        zone=None if zones is None else zones.zone_of(m.object_id for m in result.inliers),
        candidates=[PlaceCandidateOut(world_from_camera=pose_out(c.world_from_camera,
                                                                 convention),
                                      probability=c.probability, zone=c.zone)
                    for c in result.candidates],
        n_usable_detections=result.n_usable_detections,
        timings_ms={k: float(v) for k, v in result.timings_ms.items()})



class RecordingInputError(FieldError):
    """An invalid recording beyond its schema (poses, limits): ``errors`` lists every
    ``{"field", "message"}``; ``field`` / ``problem`` are the first."""

    def __init__(self, errors: list[dict[str, str]]) -> None:
        super().__init__(errors[0]["message"], field=errors[0]["field"])
        self.errors = errors


def _current(body: RecordingIn | LegacyRecordingIn) -> tuple[RecordingIn, tuple[str, ...]]:
    """The recording in the current form, and the warnings of its form."""
    if isinstance(body, LegacyRecordingIn):
        return body.upgraded(), (LEGACY_RECORDING_WARNING,)
    return body, ()


def _frame_poses(rec: RecordingIn, errors: list[dict[str, str]]) -> list[FloatArray | None]:
    """Every frame's ``world_from_camera`` in OpenCV axes (None, with an error, when invalid)."""
    poses: list[FloatArray | None] = []
    for k, frame in enumerate(rec.frames):
        path = f"frames[{k}].world_from_camera"
        try:
            T = pose_matrix_from_wire(frame.world_from_camera, path)
            poses.append(check_pose(convert_pose(T, rec.convention, "opencv"), path,
                                    DOCUMENT_ROTATION_TOLERANCE))
        except FieldError as exc:
            errors.append({"field": exc.field or path, "message": exc.problem})
            poses.append(None)
    return poses


def _frame_id(frame: RecordingFrameIn, position: int) -> str:
    return frame.frame_id if frame.frame_id is not None else str(position)


def recording_from_wire(body: RecordingIn | LegacyRecordingIn,
                        limits: BuildLimits | None = None) -> Recording:
    """A wire recording (either form) -> the :class:`Recording` to build, in OpenCV axes,
    without its held-out frames (``holdout_every``). Raises :class:`RecordingInputError`
    naming every invalid pose and every exceeded limit (``limits``: the server's)."""
    rec, warnings = _current(body)
    lim = limits or BuildLimits()
    errors: list[dict[str, str]] = []
    if len(rec.frames) > lim.max_frames:
        errors.append({"field": "frames", "message": f"at most {lim.max_frames} frames"})
    for k, frame in enumerate(rec.frames):
        if len(frame.detections) > lim.max_detections_per_frame:
            errors.append({"field": f"frames[{k}].detections",
                           "message": f"at most {lim.max_detections_per_frame} detections"})
    if sum(len(f.detections) for f in rec.frames) > lim.max_detections:
        errors.append({"field": "frames",
                       "message": f"at most {lim.max_detections} detections in total"})
    poses = _frame_poses(rec, errors)
    if errors:
        raise RecordingInputError(errors)
    out = held_out(len(rec.frames), rec.holdout_every)
    frames: list[FrameRecord] = []
    observations: list[Observation] = []
    for k, (frame, T) in enumerate(zip(rec.frames, poses, strict=True)):
        if out[k] or T is None:
            continue
        for i, d in enumerate(detections_from_request(frame.detections)):
            observations.append(Observation(len(frames), i, d.label, d.ellipse, d.sigma,
                                            frame.detections[i].track_id))
        frames.append(FrameRecord(_frame_id(frame, k), T, source_index=k))
    if out.any():
        warnings += (f"{int(out.sum())} of {len(rec.frames)} frames held out of the build "
                     f"(every {rec.holdout_every}th) for calibration",)
    noise = rec.odometry_noise
    return Recording(
        camera=camera_from_request(rec.camera), frames=tuple(frames),
        observations=tuple(observations), name=rec.name,
        up_axis=(rec.up_axis[0], rec.up_axis[1], rec.up_axis[2]),
        size_priors={label: SizePrior(p.semi_axis_m, p.log_sigma)
                     for label, p in rec.size_priors.items()},
        refine_camera_poses=rec.refine_camera_poses,
        odometry_noise=OdometryNoise(**noise.model_dump()), warnings=warnings)


def held_out_frames_from_wire(
    body: RecordingIn | LegacyRecordingIn,
) -> tuple[Camera, list[tuple[str, FloatArray, list[Detection]]]]:
    """The camera and the frames a recording holds out of its build (``holdout_every``; none
    without it): ``(frame_id, world_from_camera 4x4 in OpenCV axes, detections)``. Raises
    :class:`RecordingInputError` naming every invalid pose."""
    rec, _ = _current(body)
    errors: list[dict[str, str]] = []
    poses = _frame_poses(rec, errors)
    if errors:
        raise RecordingInputError(errors)
    out = held_out(len(rec.frames), rec.holdout_every)
    return camera_from_request(rec.camera), [
        (_frame_id(frame, k), T, detections_from_request(frame.detections))
        for k, (frame, T) in enumerate(zip(rec.frames, poses, strict=True))
        if out[k] and T is not None]
