"""``POST /v1/maps:build`` (start a map-building job) and ``GET /v1/build-jobs/{job_id}``.

The body is a recording (``quadloc.maps.building.recording``); the map id is the ``map_id`` query
parameter; an existing map needs ``If-Match`` (428 / 412 as for ``PUT /v1/maps/{map_id}``).
Answers 202 with ``Location: /v1/build-jobs/{job_id}``. Details:
docs/design/service.md#post-v1mapsbuild.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any

from fastapi import APIRouter, Body, Header, Path, Query, Request, Response, status
from pydantic import BaseModel, Field

from quadloc.maps.building.jobs import BuildJob, JobNotFoundError
from quadloc.maps.building.recording import RecordingError, parse_recording
from quadloc.maps.errors import MapNotFound
from quadloc.maps.model import MAP_ID_PATTERN
from quadloc.service.api.auth import ReadAccess, WriteAccess
from quadloc.service.api.build_jobs import RETRY_AFTER_S, RunnerBusyError, build_limits
from quadloc.service.api.deps import SettingsDep, StoreDep
from quadloc.service.api.errors import ProblemError, problem_responses

__all__ = ["BuildJobOut", "job_out", "router"]

router = APIRouter(prefix="/v1", tags=["maps"])

#: Job ids are UUIDs; anything else is refused (422 ``path.job_id``) before reaching the database.
JOB_ID_PATTERN = r"^[0-9a-fA-F-]{1,64}$"

_RECORDING_EXAMPLE: dict[str, Any] = {
    "intrinsics": {"fx": 585.0, "fy": 585.0, "cx": 320.0, "cy": 240.0, "width": 640,
                   "height": 480},
    "name": "My room",
    "frames": [{"frame_id": "0001",
                "world_from_camera": {"quaternion_wxyz": [1.0, 0.0, 0.0, 0.0],
                                      "translation_m": [0.0, 0.0, 0.0]},
                "detections": [{"label": "TV", "ellipse": {"cx": 300.0, "cy": 200.0, "a": 80.0,
                                                           "b": 40.0, "angle": 0.1},
                                "sigma": 0.02},
                               {"label": "Chair", "box": [10.0, 200.0, 110.0, 420.0]}]}],
}


_JOB_EXAMPLE: dict[str, Any] = {
    "job_id": "5f0c3c1e-8a53-4b7c-9a56-0f1f7e3f2b11", "map_id": "my-room", "status": "running",
    "stage": "refining", "percent": 62.5, "objects_found": 9, "base_version": None,
    "map_version": None, "error": None, "report": None,
    "created_at": "2026-11-23T20:00:00+00:00", "updated_at": "2026-11-23T20:00:04+00:00"}
_DONE_EXAMPLE: dict[str, Any] = {
    **_JOB_EXAMPLE, "status": "succeeded", "stage": "done", "percent": 100.0, "map_version": 1,
    "report": {"objects": [{"object_id": "TV_1", "label": "TV", "association": "geometric",
                            "detections": [{"frame_id": "0001", "frame_index": 0,
                                            "detection_index": 0}],
                            "quality": {"n_views": 69, "view_spread_deg": 27.0,
                                        "residual_cost": 12.3, "rms_level_residual": 0.21,
                                        "log_semi_axis_std": [0.05, 0.4, 0.6],
                                        "unconstrained_axes": [1, 2],
                                        "semi_axes_m": [0.42, 0.34, 0.18]}}],
               "rejected_detections": [{"frame_id": "0003", "frame_index": 2,
                                        "detection_index": 1, "label": "Chair",
                                        "reason": "fits_no_object"}],
               "dropped_objects": [], "counts": {"frames": 300, "detections": 1855,
                                                 "objects": 10, "rejected_detections": 64}}}


def _ok(code: int, example: dict[str, Any]) -> dict[int | str, Any]:
    return {code: {"content": {"application/json": {"example": example}}}}


class BuildJobOut(BaseModel):
    job_id: str
    map_id: str
    status: str = Field(description="queued, running, succeeded or failed")
    stage: str = Field(description="queued, associating, refining, saving, done or failed")
    percent: float = Field(description="Progress, 0-100.")
    objects_found: int
    base_version: int | None = Field(description="Version the build replaces (If-Match), "
                                                 "null for a new map.")
    map_version: int | None = Field(description="Version created (succeeded jobs).")
    error: dict[str, Any] | None = Field(description="{reason, detail} of a failed job.")
    report: dict[str, Any] | None = Field(description="Association and quality report.")
    created_at: str
    updated_at: str


def job_out(job: BuildJob) -> BuildJobOut:
    """The wire form of ``job`` (the same fields; times as ISO 8601 text)."""
    return BuildJobOut(**{**dataclasses.asdict(job), "created_at": job.created_at.isoformat(),
                          "updated_at": job.updated_at.isoformat()})


def _base_version(store: Any, map_id: str, if_match: str | None) -> int | None:
    from quadloc.service.api.routers.maps import check_etag

    try:
        current = store.get(map_id)
    except MapNotFound:
        if if_match is not None:
            raise ProblemError("precondition-failed",
                               f"map {map_id!r} does not exist, so If-Match cannot match; omit "
                               "it to build a new map",
                               field="header.if-match", message="map does not exist") from None
        return None
    if if_match is None or not if_match.strip():
        raise ProblemError("precondition-required",
                           f"map {map_id!r} exists: building a new version needs 'If-Match: "
                           "\"<ETag>\"' with its latest ETag (GET /v1/maps/{map_id})",
                           field="header.if-match", message="missing")
    check_etag(map_id, current, {t.strip() for t in if_match.split(",") if t.strip()})
    return int(current.scene_map.version)


@router.post(
    "/maps:build", status_code=status.HTTP_202_ACCEPTED, response_model=BuildJobOut,
    summary="Build a map from a recording (asynchronous job)",
    description="Body: a recording (docs/map_building.md). Answers 202 with the job and "
                "`Location: /v1/build-jobs/{job_id}`; poll it for progress and the result. "
                "422 names every invalid field; 428/412 for If-Match on an existing map; 503 "
                "+ Retry-After when this replica has too many builds queued.",
    responses={**problem_responses(400, 401, 403, 412, 413, 415, 422, 428, 503),
               **_ok(202, {**_JOB_EXAMPLE, "status": "queued", "stage": "queued",
                           "percent": 0.0, "objects_found": 0})},
    openapi_extra={"requestBody": {"required": True, "content": {"application/json": {
        "schema": {"type": "object", "required": ["intrinsics", "frames"]},
        "example": _RECORDING_EXAMPLE}}}},
)
def start_build(
    body: Annotated[dict[str, Any], Body()], request: Request, response: Response,
    store: StoreDep,
    settings: SettingsDep, _key: WriteAccess,
    map_id: Annotated[str, Query(pattern=MAP_ID_PATTERN, description="Id of the map to build.")],
    if_match: Annotated[str | None, Header(description="ETag of the map's latest version "
                                                       "(only when the map exists).")] = None,
) -> BuildJobOut:
    try:
        recording = parse_recording(body, build_limits(settings))
    except RecordingError as exc:
        raise ProblemError("validation-error", f"invalid recording: {exc}",
                           errors=exc.errors) from exc
    base = _base_version(store, map_id, if_match)
    runner, jobs = request.app.state.build_runner, request.app.state.build_jobs
    job = jobs.create(map_id, base)
    try:
        runner.submit(job.job_id, recording)
    except (RunnerBusyError, RuntimeError) as exc:
        jobs.fail(job.job_id, "busy", str(exc))
        raise ProblemError("busy", f"too many map builds on this replica ({exc}); retry later",
                           headers={"Retry-After": str(RETRY_AFTER_S)}) from exc
    response.headers["Location"] = f"/v1/build-jobs/{job.job_id}"
    return job_out(jobs.get(job.job_id))


@router.get(
    "/build-jobs/{job_id}", response_model=BuildJobOut, summary="A map-building job",
    description="Status, stage, percent, objects found; the map version and the report when "
                "it succeeded, `error {reason, detail}` when it failed. A job whose runner "
                "stopped reporting (replica restarted) is marked failed (`runner_lost`).",
    responses={**problem_responses(401, 403, 404, 422, 503), **_ok(200, _DONE_EXAMPLE)},
)
def get_build_job(job_id: Annotated[str, Path(pattern=JOB_ID_PATTERN, description="Job id.")],
                  request: Request, settings: SettingsDep,
                  _key: ReadAccess) -> BuildJobOut:
    jobs = request.app.state.build_jobs
    jobs.fail_stale(settings.build_stale_after_s)
    try:
        return job_out(jobs.get(job_id))
    except JobNotFoundError as exc:
        raise ProblemError("not-found", f"no build job {job_id!r}",
                           field="path.job_id", message="not found") from exc
