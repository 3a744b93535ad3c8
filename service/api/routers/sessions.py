"""Tracking sessions: ``POST /v1/maps/{map_id}/sessions``, ``POST /v1/sessions/{id}/frames``,
``GET`` / ``DELETE /v1/sessions/{id}``. Sessions live in this process; an unknown id is 404
``session-not-found``. Replicas and locking: docs/design/service.md#tracking-session-routes.
"""

from __future__ import annotations

import math
from typing import Annotated

from fastapi import APIRouter, Body, Path, Request, Response

from quadloc.factors.names import GeometryError
from quadloc.factors.rotations import DOCUMENT_ROTATION_TOLERANCE, check_pose
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.errors import MapNotFound
from quadloc.service.api.auth import ReadAccess
from quadloc.service.api.convert import (
    _pose_matrix_in,
    camera_from_request,
    convert_pose,
    covariance_out,
    detections_from_request,
    gravity_from_request,
    inliers_out,
    pose_out,
    prior_from_request,
)
from quadloc.service.api.deps import MapIdPath, StoreDep
from quadloc.service.api.errors import (
    ProblemError,
    field_and_problem,
    map_not_found,
    problem_responses,
)
from quadloc.service.localization.types import LocalizationInputError
from quadloc.service.schemas.examples import (
    FRAME_EXAMPLE,
    FRAME_RESPONSE_EXAMPLE,
    SESSION_CREATE_EXAMPLE,
    SESSION_EXAMPLE,
)
from quadloc.service.schemas.sessions import (
    SessionCreate,
    SessionFrameIn,
    SessionFrameOut,
    SessionFramesBody,
    SessionFramesIn,
    SessionFramesOut,
    SessionOut,
)
from quadloc.service.tracking.session import (
    DriftModel,
    FrameInput,
    FrameResult,
    SessionOptions,
    TrackingInputError,
    TrackingSession,
)
from quadloc.service.tracking.store import (
    SessionCapacityError,
    SessionEntry,
    SessionNotFound,
    SessionStore,
)

__all__ = ["new_session", "router"]

router = APIRouter(prefix="/v1", tags=["tracking"])

SessionIdPath = Annotated[str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$",
                                    description="Session id returned at creation.")]


def _store(request: Request) -> SessionStore:
    return request.app.state.sessions  # type: ignore[no-any-return] (set by create_app)


def new_session(compiled: CompiledMap, body: SessionCreate) -> TrackingSession:
    """A :class:`TrackingSession` on ``compiled`` for the wire ``body`` (odometry rotation
    noise from degrees to radians); raises ``GeometryError`` / ``TrackingInputError``."""
    o = body.options
    return TrackingSession(compiled, camera_from_request(body.camera), SessionOptions(
        window_frames=o.window_frames, smoother=o.smoother, inlier_iou=o.inlier_iou,
        drift=DriftModel(
            translation_m_per_sqrt_m=o.odometry_translation_m_per_sqrt_m,
            translation_m_per_sqrt_s=o.odometry_translation_m_per_sqrt_s,
            rotation_rad_per_sqrt_m=math.radians(o.odometry_rotation_deg_per_sqrt_m),
            rotation_rad_per_sqrt_s=math.radians(o.odometry_rotation_deg_per_sqrt_s))))


def _entry(store: SessionStore, session_id: str) -> SessionEntry:
    try:
        return store.get(session_id)
    except SessionNotFound as exc:
        raise ProblemError("session-not-found",
                           f"session {session_id!r} not found: it expired, was deleted, or its "
                           "server restarted; start a new session",
                           field="path.session_id", message="not found") from exc


def _out(entry: SessionEntry, store: SessionStore) -> SessionOut:
    return SessionOut(session_id=entry.session_id, url=f"/v1/sessions/{entry.session_id}",
                      map_id=entry.map_id, map_version=entry.map_version,
                      convention=entry.convention,  # type: ignore[arg-type]
                      state=entry.session.state, frames=entry.session.frame_count,
                      idle_timeout_s=store.idle_timeout_s)


@router.post("/maps/{map_id}/sessions", response_model=SessionOut, status_code=201,
             summary="Start a tracking session",
             responses={**problem_responses(400, 401, 403, 404, 413, 415, 422, 503),
                        201: {"content": {"application/json": {"example": SESSION_EXAMPLE}}}})
def create_session(map_id: MapIdPath,
                   body: Annotated[SessionCreate, Body(openapi_examples={"chess": {
                       "summary": "Chess camera", "value": SESSION_CREATE_EXAMPLE}})],
                   request: Request,
                   store: StoreDep, _key: ReadAccess, response: Response) -> SessionOut:
    try:
        compiled = store.compiled(map_id, None)
    except MapNotFound as exc:
        raise map_not_found(map_id) from exc
    try:
        session = new_session(compiled, body)
    except (GeometryError, TrackingInputError) as exc:
        raise _unprocessable(exc, "") from exc
    store = _store(request)
    try:
        entry = store.create(map_id, compiled.scene_map.version, session, body.convention)
    except SessionCapacityError as exc:
        raise ProblemError("session-capacity", str(exc), headers={"Retry-After": "30"}) from exc
    response.headers["Location"] = f"/v1/sessions/{entry.session_id}"
    return _out(entry, store)


@router.get("/sessions/{session_id}", response_model=SessionOut, summary="Describe a session",
            responses={**problem_responses(401, 403, 404, 422),
                       200: {"content": {"application/json": {"example": SESSION_EXAMPLE}}}})
def get_session(session_id: SessionIdPath, request: Request, _key: ReadAccess) -> SessionOut:
    store = _store(request)
    return _out(_entry(store, session_id), store)


@router.delete("/sessions/{session_id}", status_code=204, summary="End a session",
               responses=problem_responses(401, 403, 404, 422))
def delete_session(session_id: SessionIdPath, request: Request, _key: ReadAccess) -> Response:
    try:
        _store(request).delete(session_id)
    except SessionNotFound:
        _entry(_store(request), session_id)  # raises the 404 problem
    return Response(status_code=204)


@router.post("/sessions/{session_id}/frames", response_model=SessionFramesOut,
             summary="Add frames to a session (one, or a recording in time order)",
             description="Body: one frame object, or `{\"frames\": [...]}` (batch, at most "
                         "900). Frames are validated all before any is fused: an error names "
                         "`frames[i]....` and leaves the session unchanged.",
             responses={**problem_responses(400, 401, 403, 404, 413, 415, 422),
                        200: {"content": {"application/json": {
                            "example": FRAME_RESPONSE_EXAMPLE}}}})
def add_frames(session_id: SessionIdPath,
               body: Annotated[SessionFramesBody, Body(openapi_examples={
                   "one_frame": {"summary": "One frame", "value": FRAME_EXAMPLE},
                   "batch": {"summary": "A recording (batch)",
                             "value": {"frames": [FRAME_EXAMPLE]}}})],
               request: Request, _key: ReadAccess) -> SessionFramesOut:
    store = _store(request)
    entry = _entry(store, session_id)
    frames = body.frames if isinstance(body, SessionFramesIn) else [body]
    prefix = (lambda i: f"frames[{i}].") if isinstance(body, SessionFramesIn) else (lambda i: "")
    with entry.lock:
        session = entry.session
        inputs = []
        last_ts = session._last_timestamp
        for i, f in enumerate(frames):
            inp = _frame_input(f, entry.convention, prefix(i))
            if last_ts is not None and inp.timestamp < last_ts:
                raise _unprocessable(TrackingInputError(
                    f"{inp.timestamp} is before the previous frame's {last_ts}",
                    field="timestamp"), prefix(i))
            last_ts = inp.timestamp
            inputs.append(inp)
        results = []
        for i, inp in enumerate(inputs):
            try:
                results.append(_frame_out(session.add_frame(inp), entry.convention))
            except (TrackingInputError, GeometryError) as exc:
                raise _unprocessable(exc, prefix(i)) from exc
    return SessionFramesOut(session_id=session_id, results=results)


def _unprocessable(exc: Exception, prefix: str) -> ProblemError:
    field, problem = field_and_problem(exc, prefix)
    return ProblemError("validation-error", str(exc),
                        field=field, message=problem)


def _frame_input(f: SessionFrameIn, convention: str, prefix: str) -> FrameInput:
    try:
        dets = detections_from_request(f.detections)
        T = _pose_matrix_in(f.odom_from_camera, "odom_from_camera")
        T = check_pose(convert_pose(T, convention, "opencv"), "odom_from_camera",
                       DOCUMENT_ROTATION_TOLERANCE)
        prior = prior_from_request(f.prior)
        gravity = gravity_from_request(f.gravity, convention)
    except (GeometryError, LocalizationInputError, TrackingInputError) as exc:
        raise _unprocessable(exc, prefix) from exc
    return FrameInput(dets, T, float(f.timestamp), f.frame_id, prior, gravity)


def _frame_out(r: FrameResult, convention: str) -> SessionFrameOut:
    return SessionFrameOut(
        frame_index=r.frame_index, frame_id=r.frame_id, timestamp=r.timestamp, state=r.state,
        reason=r.reason,
        world_from_camera=None if r.world_from_camera is None
        else pose_out(r.world_from_camera, convention),
        covariance=covariance_out(r.covariance, "opencv", convention),
        world_from_odom=None if r.world_from_odom is None
        else pose_out(r.world_from_odom, "opencv").model_copy(update={"convention": convention}),
        world_from_odom_covariance=covariance_out(r.world_from_odom_covariance, "opencv",
                                                  "opencv"),
        confidence=r.confidence,
        inliers=inliers_out(r.inliers),
        n_usable_detections=r.n_usable_detections,
        timings_ms={k: float(v) for k, v in r.timings_ms.items()})
