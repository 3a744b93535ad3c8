"""Wire models of the tracking-session endpoints (``/v1/maps/{map_id}/sessions``,
``/v1/sessions/{id}...``). Shared pieces (camera, detections, poses, covariances) come from
:mod:`quadloc.service.schemas`; conventions are the same (OpenCV camera axes unless
``convention: "opengl"``; covariances 6x6 ``[omega, v]``, body frame, right perturbation)."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, Discriminator, Field, Tag

from quadloc.service.limits import MAX_DETECTIONS
from quadloc.service.schemas.common import Convention, Text, WireModel
from quadloc.service.schemas.localize import (
    ZONE_RULE,
    CameraIn,
    CovarianceOut,
    DetectionIn,
    GravityIn,
    InlierOut,
    PoseIn,
    PoseOut,
    PosePriorIn,
)

__all__ = ["MAX_SESSION_BATCH_FRAMES", "PlaceCandidateOut", "SessionCreate", "SessionFrameIn",
           "SessionFrameOut", "SessionFramesBody", "SessionFramesIn", "SessionFramesOut",
           "SessionOptionsIn", "SessionOut"]

#: Frames per batch upload request (an offline recording is sent in chunks of this size).
MAX_SESSION_BATCH_FRAMES = 900


class SessionOptionsIn(WireModel):
    """Session options; omitted fields take the defaults shown."""

    window_frames: int = Field(default=30, ge=2, le=300,
                               description="Camera poses kept in the sliding window (at most "
                                           "300 with isam2, 60 with batch).")
    smoother: str = Field(default="isam2", pattern="^(isam2|batch)$",
                          description="isam2 (incremental fixed-lag) or batch (LM per frame).")
    inlier_iou: float = Field(default=0.2, gt=0, le=1)
    odometry_translation_m_per_sqrt_m: float = Field(
        default=0.02, ge=0, le=10, description="Odometry random-walk translation std after 1 m "
                                               "travelled (m); variance grows per metre.")
    odometry_translation_m_per_sqrt_s: float = Field(
        default=0.003, ge=0, le=10, description="... after 1 s (m); variance grows per second.")
    odometry_rotation_deg_per_sqrt_m: float = Field(default=0.5, ge=0, le=90)
    odometry_rotation_deg_per_sqrt_s: float = Field(default=0.05, ge=0, le=90)


class SessionCreate(WireModel):
    """Start a tracking session on a map."""

    camera: CameraIn
    convention: Convention = Field(
        default="opencv", description="Camera axes of every odom_from_camera, prior and "
                                      "returned world_from_camera of the session (opengl = "
                                      "ARKit/ARCore).")
    options: SessionOptionsIn = Field(default_factory=SessionOptionsIn)


class SessionOut(BaseModel):
    """A session's description."""

    session_id: str
    url: str = Field(description="The session's resource path.")
    map_id: str
    map_version: int
    convention: Convention
    state: str = Field(description="initializing, tracking or lost.")
    frames: int = Field(description="Frames received so far.")
    idle_timeout_s: float = Field(description="The session expires after this idle time.")


class SessionFrameIn(WireModel):
    """One frame: detections as for localize plus the app's odometry pose."""

    detections: list[DetectionIn] = Field(default_factory=list, max_length=MAX_DETECTIONS)
    odom_from_camera: PoseIn = Field(description="Camera pose in the app's odometry (session) "
                                                 "frame, in the session's convention.")
    timestamp: float = Field(ge=-1e12, le=1e12, description="Client clock (s), non-decreasing.")
    frame_id: Text | None = Field(default=None, max_length=256, description="Echoed back.")
    prior: PosePriorIn | None = None
    gravity: GravityIn | None = Field(
        default=None, description="The gravity direction the device measures in this frame's "
        "camera (as for localize; `convention` defaults to the session's): a factor on the "
        "frame's tilt against the map's up axis.")


class SessionFramesIn(WireModel):
    """Several frames in time order (offline recording)."""

    frames: list[SessionFrameIn] = Field(min_length=1, max_length=MAX_SESSION_BATCH_FRAMES)


def _batch_or_frame(value: Any) -> str:
    """Which body a frames request is: a batch (``{"frames": [...]}``) or one frame."""
    if isinstance(value, dict):
        return "~batch" if "frames" in value else "~frame"
    return "~batch" if isinstance(value, SessionFramesIn) else "~frame"


#: The body of ``POST /v1/sessions/{id}/frames``: a batch or one frame, told apart by a
#: ``frames`` key, so that a bad body is reported against the form it is (not also as the
#: other form). The ``~`` tags are not fields: ``quadloc.service.schemas.common.field_path`` drops
#: them.
SessionFramesBody = Annotated[
    Annotated[SessionFramesIn, Tag("~batch")] | Annotated[SessionFrameIn, Tag("~frame")],
    Discriminator(_batch_or_frame)]


class PlaceCandidateOut(BaseModel):
    """A place the session's walk may be in (docs/tracking.md, "Places")."""

    world_from_camera: PoseOut = Field(description="This frame's camera pose if the walk is "
                                                   "in this place.")
    probability: float = Field(ge=0, le=1, description="Posterior probability that the walk is "
                                                       "in this place (the rest: in none of "
                                                       "those listed).")
    zone: str | None = Field(default=None, description="The map zone of the objects this place "
                                                       "matched (the zone rule of `zone`); "
                                                       "null without zones.")


class SessionFrameOut(BaseModel):
    """A frame's answer."""

    frame_index: int
    frame_id: str | None
    timestamp: float
    state: str = Field(description="initializing, tracking or lost.")
    reason: str | None = Field(description="Why no pose: waiting_for_constraints, ambiguous, "
                                           "lost, time_budget_exceeded (the frame was counted "
                                           "but not fused: its CPU budget or its request's ran "
                                           "out); with a pose: detections_unexplained (the "
                                           "frame's usable detections are all unexplained at "
                                           "the pose; confidence 0 when two or more are, lowered "
                                           "when one is); else None.")
    world_from_camera: PoseOut | None
    covariance: CovarianceOut | None
    world_from_odom: PoseOut | None = Field(
        description="Alignment of the app's odometry frame to the map (same in both camera "
                    "conventions); apply it once to the app's scene.")
    world_from_odom_covariance: CovarianceOut | None = Field(
        description="6x6 [omega, v], right perturbation, in the ODOMETRY frame's axes, given "
                    "this frame's odometry pose.")
    confidence: float = Field(ge=0, le=1, description="P(pose within 10 cm and 5 deg): the "
                                                      "posterior probability of the session's "
                                                      "place times P(within tolerance) under "
                                                      "the pose posterior; 0 unless tracking; "
                                                      "when detections_unexplained, 0 with two "
                                                      "or more unexplained detections, lowered "
                                                      "by Bayes' rule (likelihood ratio 0.1) "
                                                      "with one.")
    inliers: list[InlierOut]
    zone: str | None = Field(default=None, description=ZONE_RULE)
    candidates: list[PlaceCandidateOut] = Field(
        default_factory=list,
        description="The places the walk may be in with their probabilities (>= 0.01), most "
                    "probable first; several while `ambiguous`.")
    n_usable_detections: int
    timings_ms: dict[str, float]


class SessionFramesOut(BaseModel):
    session_id: str
    results: list[SessionFrameOut]
