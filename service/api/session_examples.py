"""OpenAPI examples of the tracking-session endpoints. Requests reuse the REAL localize example
frame (:mod:`service.api.examples`: simulated detections at a real Chess ground-truth pose)
with an identity odometry pose; the response examples show the documents' shape (a session's
first frame is ``initializing`` unless that one frame already sees three objects)."""

from __future__ import annotations

from typing import Any

from service.api.examples import LOCALIZE_EXAMPLE

__all__ = ["FRAME_EXAMPLE", "FRAME_RESPONSE_EXAMPLE", "SESSION_CREATE_EXAMPLE",
           "SESSION_EXAMPLE"]

_EYE = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]

SESSION_CREATE_EXAMPLE: dict[str, Any] = {
    "camera": LOCALIZE_EXAMPLE["camera"], "convention": "opencv",
    "options": {"window_frames": 30}}

SESSION_EXAMPLE: dict[str, Any] = {
    "session_id": "s-quadloc-1.Yk3v0cQ2c1xQm8Xo7b9m1g", "url":
    "/v1/sessions/s-quadloc-1.Yk3v0cQ2c1xQm8Xo7b9m1g", "map_id": "chess", "map_version": 1,
    "convention": "opencv", "state": "initializing", "frames": 0, "idle_timeout_s": 300.0}

FRAME_EXAMPLE: dict[str, Any] = {
    "detections": LOCALIZE_EXAMPLE["detections"],
    "odom_from_camera": {"matrix": _EYE}, "timestamp": 0.0, "frame_id": "0"}

FRAME_RESPONSE_EXAMPLE: dict[str, Any] = {
    "session_id": SESSION_EXAMPLE["session_id"],
    "results": [{
        "frame_index": 0, "frame_id": "0", "timestamp": 0.0, "state": "initializing",
        "reason": "waiting_for_constraints", "world_from_camera": None, "covariance": None,
        "world_from_odom": None, "world_from_odom_covariance": None, "confidence": 0.0,
        "inliers": [], "n_usable_detections": len(LOCALIZE_EXAMPLE["detections"]),
        "timings_ms": {"total": 0.4}}]}
