"""Tracking sessions from the SDK (pure Python: no numpy, no gtsam, no server import).

    session = start_session(client, "chess", camera={...}, convention="opengl")
    result = session.add_frame(detections, odom_from_camera=arkit_transform_to_matrix(t),
                               timestamp=frame.timestamp)
    scene_anchor = result["world_from_odom"]          # apply once to the app's scene
    session.close()

Works with :class:`quadloc_sdk.client.QuadLocClient` (sync) and
:class:`quadloc_sdk.client.AsyncQuadLocClient` (``await start_session_async(...)``, ``await
session.add_frame(...)``). Results are the server's JSON documents (``docs/tracking.md``). A 404
``session-not-found`` (the session expired or its server restarted) surfaces as the client's usual
error: start a new session.

ARKit / ARCore helpers: ``ARFrame.camera.transform`` (simd_float4x4, COLUMN-major, OpenGL
camera axes +Y up, -Z forward) and ARCore ``Pose.toMatrix`` (column-major float[16]) are the
camera's pose in the AR session frame: ``odom_from_camera`` with ``convention="opengl"``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

from quadloc_sdk.transport import Call

__all__ = ["AsyncTrackingSession", "TrackingSession", "arcore_pose_to_matrix",
           "arkit_transform_to_matrix", "start_session", "start_session_async"]


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


def _frame(detections: Sequence[dict[str, Any]], odom_from_camera: Sequence[Sequence[float]],
           timestamp: float, frame_id: str | None, prior: dict[str, Any] | None,
           gravity: dict[str, Any] | None = None) -> dict[str, Any]:
    body: dict[str, Any] = {"detections": [dict(d) for d in detections],
                            "odom_from_camera": {"matrix": [list(map(float, r))
                                                            for r in odom_from_camera]},
                            "timestamp": float(timestamp)}
    if frame_id is not None:
        body["frame_id"] = frame_id
    if prior is not None:
        body["prior"] = prior
    if gravity is not None:
        body["gravity"] = dict(gravity)
    return body


class TrackingSession:
    """A live session (sync). ``info`` is the server's session document."""

    def __init__(self, client: Any, info: dict[str, Any]) -> None:
        self.client, self.info = client, info
        self.session_id: str = info["session_id"]

    def _post(self, body: dict[str, Any]) -> list[dict[str, Any]]:
        call = self.client._json_call("POST", f"/v1/sessions/{self.session_id}/frames",
                                      "frames", body)
        return cast(list[dict[str, Any]], self.client._json(self.client._send(call))["results"])

    def add_frame(self, detections: Sequence[dict[str, Any]], *,
                  odom_from_camera: Sequence[Sequence[float]], timestamp: float,
                  frame_id: str | None = None, prior: dict[str, Any] | None = None,
                  gravity: dict[str, Any] | None = None) -> dict[str, Any]:
        """Send one frame; returns its result document (state, world_from_camera, ...).
        ``gravity``: ``{"direction": [x, y, z], "sigma_deg": 2.0}``, the direction gravity pulls
        in this frame's camera (in the session's convention unless ``"convention"`` says
        otherwise): a factor on the frame's tilt."""
        return self._post(_frame(detections, odom_from_camera, timestamp, frame_id, prior,
                                 gravity))[0]

    def add_frames(self, frames: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
        """Send recorded frames (wire documents, time order) in one request (<= 900)."""
        return self._post({"frames": list(frames)})

    def close(self) -> None:
        """End the session on the server (DELETE)."""
        self.client._send(Call("DELETE", f"/v1/sessions/{self.session_id}"))


class AsyncTrackingSession(TrackingSession):
    """A live session with an :class:`quadloc_sdk.client.AsyncQuadLocClient`."""

    async def _post(self, body: dict[str, Any]) -> list[dict[str, Any]]:  # type: ignore[override]
        call = self.client._json_call("POST", f"/v1/sessions/{self.session_id}/frames",
                                      "frames", body)
        results = self.client._json(await self.client._send(call))["results"]
        return cast(list[dict[str, Any]], results)

    async def add_frame(self, detections: Sequence[dict[str, Any]], *,  # type: ignore[override]
                        odom_from_camera: Sequence[Sequence[float]], timestamp: float,
                        frame_id: str | None = None, prior: dict[str, Any] | None = None,
                        gravity: dict[str, Any] | None = None) -> dict[str, Any]:
        return (await self._post(_frame(detections, odom_from_camera, timestamp, frame_id,
                                         prior, gravity)))[0]

    async def add_frames(self, frames: Sequence[dict[str, Any]]  # type: ignore[override]
                         ) -> list[dict[str, Any]]:
        return await self._post({"frames": list(frames)})

    async def close(self) -> None:  # type: ignore[override]
        await self.client._send(Call("DELETE", f"/v1/sessions/{self.session_id}"))


def _create_call(client: Any, map_id: str, camera: dict[str, Any], convention: str,
                 options: dict[str, Any] | None) -> Any:
    body = {"camera": dict(camera), "convention": convention, "options": dict(options or {})}
    return client._json_call("POST", f"/v1/maps/{map_id}/sessions", "session", body)


def start_session(client: Any, map_id: str, *, camera: dict[str, Any], convention: str = "opencv",
                  options: dict[str, Any] | None = None) -> TrackingSession:
    """Start a session on ``map_id`` with a sync client (``camera``: fx, fy, cx, cy, width,
    height; ``convention``: camera axes of odometry and returned poses)."""
    resp = client._send(_create_call(client, map_id, camera, convention, options))
    return TrackingSession(client, client._json(resp))


async def start_session_async(client: Any, map_id: str, *, camera: dict[str, Any],
                              convention: str = "opencv",
                              options: dict[str, Any] | None = None) -> AsyncTrackingSession:
    """:func:`start_session` for an :class:`quadloc_sdk.client.AsyncQuadLocClient`."""
    resp = await client._send(_create_call(client, map_id, camera, convention, options))
    return AsyncTrackingSession(client, client._json(resp))
