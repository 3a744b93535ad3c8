"""``POST /v1/maps:build`` (start a map-building job) and ``GET /v1/build-jobs/{job_id}``.

The body is a recording (``quadloc.maps.building.recording``); the map id is the ``map_id``
query parameter; an existing map needs ``If-Match`` (428 / 412 as for ``PUT /v1/maps/{map_id}``).
Answers 202 with ``Location: /v1/build-jobs/{job_id}``. The use cases:
:class:`quadloc.service.app.builds.BuildService`; details: docs/design/service.md#post-v1mapsbuild.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Header, Path, Query, Response, status

from quadloc.maps.model import MAP_ID_PATTERN
from quadloc.service.api.auth import ReadAccess, WriteAccess
from quadloc.service.api.deps import AppDep, MapIdPath
from quadloc.service.api.errors import problem_responses
from quadloc.service.app.ownership import Caller
from quadloc.service.schemas.builds import BuildJobOut
from quadloc.service.schemas.calibration import CalibrationOut
from quadloc.service.schemas.examples import (
    BUILD_JOB_DONE_EXAMPLE,
    BUILD_JOB_EXAMPLE,
    CALIBRATION_EXAMPLE,
    RECORDING_EXAMPLE,
)
from quadloc.service.schemas.recording import RecordingBody

__all__ = ["router"]

router = APIRouter(prefix="/v1", tags=["maps"])

#: Job ids are UUIDs; anything else is refused (422 ``path.job_id``) before reaching the database.
JOB_ID_PATTERN = r"^[0-9a-fA-F-]{1,64}$"


def _ok(code: int, example: dict[str, Any]) -> dict[int | str, Any]:
    return {code: {"content": {"application/json": {"example": example}}}}


@router.post(
    "/maps:build", status_code=status.HTTP_202_ACCEPTED, response_model=BuildJobOut,
    summary="Build a map from a recording (asynchronous job)",
    description="Body: a recording (docs/map_building.md). Answers 202 with the job and "
                "`Location: /v1/build-jobs/{job_id}`; poll it for progress and the result. "
                "422 names every invalid field (`frames` beyond QUADLOC_MAX_BUILD_FRAMES); "
                "413 beyond QUADLOC_MAX_BUILD_BODY_BYTES (both: 2,000 frames / 4 MB when builds "
                "run in the API process, 10,000 / 32 MB with build workers; docs/deployment.md, "
                "\"Build limits\"); 428/412 for If-Match on an existing map; 503 "
                "+ Retry-After when this replica has too many builds queued.",
    responses={**problem_responses(400, 401, 403, 412, 413, 415, 422, 428, 503),
               **_ok(202, {**BUILD_JOB_EXAMPLE, "status": "queued", "stage": "queued",
                           "percent": 0.0, "objects_found": 0})},
    openapi_extra={"requestBody": {"content": {"application/json": {
        "example": RECORDING_EXAMPLE}}}},
)
def start_build(
    body: Annotated[RecordingBody, Body()], response: Response, app: AppDep,
    _key: WriteAccess,
    map_id: Annotated[str, Query(pattern=MAP_ID_PATTERN, description="Id of the map to build.")],
    if_match: Annotated[str | None, Header(description="ETag of the map's latest version "
                                                       "(only when the map exists).")] = None,
) -> BuildJobOut:
    job = app.builds.start(body, map_id, if_match, Caller.of(_key))
    response.headers["Location"] = f"/v1/build-jobs/{job.job_id}"
    return job


@router.get(
    "/build-jobs/{job_id}", response_model=BuildJobOut, summary="A map-building job",
    description="Status, stage, percent, objects found; the map version and the report when "
                "it succeeded, `error {reason, detail}` when it failed. A job whose runner "
                "stopped reporting (replica restarted) is marked failed (`runner_lost`). "
                "A job belongs to the API key that started it: other keys get 404 (an "
                "`admin` key sees all).",
    responses={**problem_responses(401, 403, 404, 422, 503), **_ok(200, BUILD_JOB_DONE_EXAMPLE)},
)
def get_build_job(job_id: Annotated[str, Path(pattern=JOB_ID_PATTERN, description="Job id.")],
                  app: AppDep, _key: ReadAccess) -> BuildJobOut:
    return app.builds.get(job_id, Caller.of(_key))


VersionQuery = Annotated[int | None, Query(ge=1, le=2**31 - 1,
                                           description="Map version (default: the latest).")]


@router.post(
    "/maps/{map_id}/calibration", response_model=CalibrationOut,
    summary="Calibrate a map version from a recording's held-out frames",
    description="Body: the recording the map was built from, with `holdout_every` (the frames "
                "held out of the build, their app poses the reference). Fits the covariance "
                "scale and the confidence model on them, reports mean NEES and the confidence "
                "calibration error before / after on them (after: cross-fitted, each frame by "
                "a fit on the other folds), and stores the calibration with the map version: "
                "localize and tracking sessions use it for the calibration key it was fitted "
                "for. Synchronous: two solves per held-out frame (1,000 held-out frames in "
                "about 25 s measured; the body limit, 2 MB by default, bounds a recording to "
                "about 2,500 frames, so at most about 1,250 held out). 422 "
                "when the recording holds no frame out or too few localize (at least 20 "
                "must: the inline example shows the body's form only and gets that 422; "
                "docs/map_building.md calibrates the shipped example recording).",
    responses={**problem_responses(400, 401, 403, 404, 413, 415, 422, 503),
               **_ok(200, CALIBRATION_EXAMPLE)},
    openapi_extra={"requestBody": {"content": {"application/json": {
        "example": RECORDING_EXAMPLE}}}},
)
def calibrate_map(map_id: MapIdPath, body: Annotated[RecordingBody, Body()], app: AppDep,
                  _key: WriteAccess, version: VersionQuery = None) -> CalibrationOut:
    return app.calibrations.calibrate(map_id, body, version)


@router.get(
    "/maps/{map_id}/calibration", response_model=CalibrationOut,
    summary="A map version's calibration (404 when it has none: the shipped one applies)",
    responses={**problem_responses(401, 403, 404, 422, 503), **_ok(200, CALIBRATION_EXAMPLE)},
)
def get_calibration(map_id: MapIdPath, app: AppDep, _key: ReadAccess,
                    version: VersionQuery = None) -> CalibrationOut:
    return app.calibrations.get(map_id, version)
