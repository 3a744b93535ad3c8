"""Tracking sessions from the SDK (pure Python: no numpy, no gtsam, no server import).

    session = client.start_session("chess", camera=Camera(...), convention="opengl")
    result = session.add_frame([Detection(...), ...],
                               odom_from_camera=arkit_transform_to_matrix(t),
                               timestamp=frame.timestamp)
    if result.state == "tracking":
        scene_anchor = result.world_from_odom.as_matrix()   # apply once to the app's scene
    session.get().frames                                    # GET /v1/sessions/{id}
    session.close()

Works with :class:`quadloc_sdk.client.QuadLocClient` (sync) and
:class:`quadloc_sdk.client.AsyncQuadLocClient` (``await start_session_async(...)``, ``await
session.add_frame(...)``). Requests are the typed models of :mod:`quadloc_sdk.models`
(:class:`~quadloc_sdk.models.Detection`, :class:`~quadloc_sdk.models.SessionFrame`, ...; plain
dicts in the wire format are validated into them before anything is sent); answers are
:class:`~quadloc_sdk.models.SessionInfo` and :class:`~quadloc_sdk.models.SessionFrameResult`
(``docs/tracking.md``). A 404
``session-not-found`` (the session expired or its server restarted) surfaces as the client's usual
error: start a new session.

ARKit / ARCore helpers: ``ARFrame.camera.transform`` (simd_float4x4, COLUMN-major, OpenGL
camera axes +Y up, -Z forward) and ARCore ``Pose.toMatrix`` (column-major float[16]) are the
camera's pose in the AR session frame: ``odom_from_camera`` with ``convention="opengl"``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any
from urllib.parse import quote

from quadloc_sdk.models import (
    Camera,
    Convention,
    Detection,
    Gravity,
    PoseInput,
    PosePrior,
    SessionFrame,
    SessionFrameResult,
    SessionInfo,
    SessionOptions,
)
from quadloc_sdk.transport import Call

__all__ = ["AsyncTrackingSession", "TrackingSession", "arcore_pose_to_matrix",
           "arkit_transform_to_matrix", "get_session", "get_session_async", "session_frame",
           "start_session", "start_session_async"]


def arkit_transform_to_matrix(columns: Sequence[Sequence[float]]) -> list[list[float]]:
    """ARKit ``simd_float4x4`` given as its 4 COLUMNS (``transform.columns.0 ... 3``) -> a
    row-major 4x4 ``odom_from_camera`` (OpenGL camera axes: send with ``convention="opengl"``)."""
    cols = [list(map(float, c)) for c in columns]
    if len(cols) != 4 or any(len(c) != 4 for c in cols):
        raise ValueError("columns: must be 4 columns of 4 numbers")
    return [[cols[c][r] for c in range(4)] for r in range(4)]


def arcore_pose_to_matrix(column_major: Sequence[float]) -> list[list[float]]:
    """ARCore ``Pose.toMatrix(float[16], 0)`` (column-major) -> row-major 4x4
    ``odom_from_camera`` (OpenGL camera axes: ``convention="opengl"``)."""
    m = list(map(float, column_major))
    if len(m) != 16:
        raise ValueError(f"column_major: must have 16 numbers, got {len(m)}")
    return [[m[c * 4 + r] for c in range(4)] for r in range(4)]


def session_frame(detections: Sequence[Detection | Mapping[str, Any]],
                  odom_from_camera: PoseInput | Mapping[str, Any] | Sequence[Sequence[float]],
                  timestamp: float, frame_id: str | None = None,
                  prior: PosePrior | Mapping[str, Any] | None = None,
                  gravity: Gravity | Mapping[str, Any] | None = None) -> SessionFrame:
    """A :class:`SessionFrame` from its parts: ``detections`` as models or wire dicts,
    ``odom_from_camera`` a :class:`PoseInput`, its wire dict, or a row-major 4x4 (nested lists
    or numpy). Invalid input raises ``pydantic.ValidationError`` naming the field."""
    if isinstance(odom_from_camera, PoseInput | Mapping):
        pose: Any = odom_from_camera
    else:
        pose = {"matrix": odom_from_camera}
    return SessionFrame.model_validate({"detections": list(detections), "odom_from_camera": pose,
                                        "timestamp": timestamp, "frame_id": frame_id,
                                        "prior": prior, "gravity": gravity})


def _frames_body(frames: Sequence[SessionFrame | Mapping[str, Any]]) -> dict[str, Any]:
    if not frames:
        raise ValueError("frames: must be a non-empty sequence of session frames")
    return {"frames": [SessionFrame.model_validate(f).to_wire() for f in frames]}


def _results(data: Any) -> list[SessionFrameResult]:
    return [SessionFrameResult.model_validate(r) for r in data["results"]]


def _session_path(session_id: str) -> str:
    if not isinstance(session_id, str) or not session_id:
        raise ValueError(f"session_id: must be a non-empty string, got {session_id!r}")
    return f"/v1/sessions/{quote(session_id, safe='')}"


class TrackingSession:
    """A live session (sync). ``info`` is the server's :class:`SessionInfo` (refreshed by
    :meth:`get`)."""

    def __init__(self, client: Any, info: SessionInfo) -> None:
        self.client, self.info = client, info
        self.session_id: str = info.session_id

    def _frames_call(self, body: dict[str, Any]) -> Call:
        return self.client._json_call(  # type: ignore[no-any-return]
            "POST", f"{_session_path(self.session_id)}/frames", "frames", body)

    def add_frame(self, detections: Sequence[Detection | Mapping[str, Any]], *,
                  odom_from_camera: PoseInput | Mapping[str, Any] | Sequence[Sequence[float]],
                  timestamp: float, frame_id: str | None = None,
                  prior: PosePrior | Mapping[str, Any] | None = None,
                  gravity: Gravity | Mapping[str, Any] | None = None) -> SessionFrameResult:
        """Send one frame; returns its :class:`SessionFrameResult` (state, world_from_camera,
        world_from_odom, ...). ``gravity``: a :class:`Gravity` (or ``{"direction": [x, y, z],
        "sigma_deg": 2.0}``), the direction gravity pulls in this frame's camera (in the
        session's convention unless it says otherwise): a factor on the frame's tilt."""
        frame = session_frame(detections, odom_from_camera, timestamp, frame_id, prior, gravity)
        return self.add_frames([frame])[0]

    def add_frames(self, frames: Sequence[SessionFrame | Mapping[str, Any]]
                   ) -> list[SessionFrameResult]:
        """Send recorded frames (:class:`SessionFrame` or wire dicts, time order) in one
        request (<= 900); the results are in the same order."""
        body = _frames_body(frames)
        return _results(self.client._json(self.client._send(self._frames_call(body))))

    def get(self) -> SessionInfo:
        """The session's state on the server (``GET /v1/sessions/{id}``); updates ``info``."""
        self.info = get_session(self.client, self.session_id)
        return self.info

    def close(self) -> None:
        """End the session on the server (DELETE)."""
        self.client._send(Call("DELETE", _session_path(self.session_id)))


class AsyncTrackingSession(TrackingSession):
    """A live session with an :class:`quadloc_sdk.client.AsyncQuadLocClient`."""

    async def add_frame(  # type: ignore[override]
            self, detections: Sequence[Detection | Mapping[str, Any]], *,
            odom_from_camera: PoseInput | Mapping[str, Any] | Sequence[Sequence[float]],
            timestamp: float, frame_id: str | None = None,
            prior: PosePrior | Mapping[str, Any] | None = None,
            gravity: Gravity | Mapping[str, Any] | None = None) -> SessionFrameResult:
        """:meth:`TrackingSession.add_frame`, awaited."""
        frame = session_frame(detections, odom_from_camera, timestamp, frame_id, prior, gravity)
        return (await self.add_frames([frame]))[0]

    async def add_frames(  # type: ignore[override]
            self, frames: Sequence[SessionFrame | Mapping[str, Any]]
    ) -> list[SessionFrameResult]:
        """:meth:`TrackingSession.add_frames`, awaited."""
        body = _frames_body(frames)
        return _results(self.client._json(await self.client._send(self._frames_call(body))))

    async def get(self) -> SessionInfo:  # type: ignore[override]
        """:meth:`TrackingSession.get`, awaited."""
        self.info = await get_session_async(self.client, self.session_id)
        return self.info

    async def close(self) -> None:  # type: ignore[override]
        """:meth:`TrackingSession.close`, awaited."""
        await self.client._send(Call("DELETE", _session_path(self.session_id)))


def _create_call(client: Any, map_id: str, camera: Camera | Mapping[str, Any],
                 convention: Convention, options: SessionOptions | Mapping[str, Any] | None
                 ) -> Any:
    body = {"camera": Camera.model_validate(camera).model_dump(mode="json"),
            "convention": convention,
            "options": SessionOptions.model_validate(options or {}).model_dump(
                mode="json", exclude_none=True)}
    return client._json_call("POST", f"{client._map_path(map_id)}/sessions", "session", body)


def start_session(client: Any, map_id: str, *, camera: Camera | Mapping[str, Any],
                  convention: Convention = "opencv",
                  options: SessionOptions | Mapping[str, Any] | None = None) -> TrackingSession:
    """Start a session on ``map_id`` with a sync client (``camera``: a :class:`Camera` or its
    wire dict; ``convention``: camera axes of odometry and returned poses)."""
    resp = client._send(_create_call(client, map_id, camera, convention, options))
    return TrackingSession(client, SessionInfo.model_validate(client._json(resp)))


async def start_session_async(client: Any, map_id: str, *, camera: Camera | Mapping[str, Any],
                              convention: Convention = "opencv",
                              options: SessionOptions | Mapping[str, Any] | None = None
                              ) -> AsyncTrackingSession:
    """:func:`start_session` for an :class:`quadloc_sdk.client.AsyncQuadLocClient`."""
    resp = await client._send(_create_call(client, map_id, camera, convention, options))
    return AsyncTrackingSession(client, SessionInfo.model_validate(client._json(resp)))


def get_session(client: Any, session_id: str) -> SessionInfo:
    """``GET /v1/sessions/{session_id}`` with a sync client: the session's
    :class:`SessionInfo` (``NotFound``, problem ``session-not-found``, once it expired)."""
    return SessionInfo.model_validate(client._json(client._send(
        Call("GET", _session_path(session_id), idempotent=True))))


async def get_session_async(client: Any, session_id: str) -> SessionInfo:
    """:func:`get_session` for an :class:`quadloc_sdk.client.AsyncQuadLocClient`."""
    return SessionInfo.model_validate(client._json(await client._send(
        Call("GET", _session_path(session_id), idempotent=True))))
