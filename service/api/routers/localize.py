"""``POST /v1/maps/{map_id}/localize`` and ``.../localize:batch``.

Plain ``def`` routes: FastAPI runs them in its threadpool, so the CPU-bound solve never blocks
the event loop. "Not localized" is a normal 200 answer with ``localized: false`` and a reason.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Header, Query, Response

from maps.compiled import CompiledMap
from maps.errors import MapNotFound
from service.api.auth import ReadAccess
from service.api.deps import MapIdPath, MapLoaderDep, SettingsDep, SolverDep
from service.api.errors import ProblemError, map_not_found, problem_responses
from service.api.examples import LOCALIZE_EXAMPLE, LOCALIZE_RESPONSE_EXAMPLE
from service.api.inspector import SVG_MEDIA_TYPE, render_localization_svg, wants_svg
from service.api.map_loader import MapLoader, MapStillLoading
from service.api.schemas import (
    BatchLocalizeRequest,
    BatchLocalizeResponse,
    LocalizeRequest,
    LocalizeResponse,
)

__all__ = ["router"]

router = APIRouter(prefix="/v1", tags=["localization"])

VersionQuery = Annotated[int | None, Query(ge=1, le=2**31 - 1,
                                           description="Map version (default: latest).")]


def _compiled(loader: MapLoader, map_id: str, version: int | None) -> CompiledMap:
    try:
        return loader.get(map_id, version)
    except MapNotFound as exc:
        raise map_not_found(map_id, version) from exc
    except MapStillLoading as exc:  # a new version's first use on this replica: bounded wait
        raise ProblemError("map-loading", f"map {map_id!r} is being loaded on this server "
                           "(first use of this version); retry shortly",
                           headers={"Retry-After": "2"}) from exc


@router.post(
    "/maps/{map_id}/localize", response_model=LocalizeResponse,
    summary="Localize one frame",
    description="Matches the frame's detections to the map's ellipsoids (label-constrained "
                "RANSAC with P3P/P2E, then refinement with the chosen metric) and returns the "
                "camera pose `world_from_camera`, its covariance and a confidence. "
                "`localized: false` with a `reason` is a normal 200 answer. With "
                "`Accept: image/svg+xml` the answer is the frame drawn instead (detections, "
                "the map's ellipsoids projected at the returned pose, inliers vs outliers, "
                "IoU and cost per match; the JSON answer inside `<metadata>`).",
    responses={**problem_responses(400, 401, 403, 404, 413, 415, 422, 503),
               200: {"content": {"application/json": {"example": LOCALIZE_RESPONSE_EXAMPLE},
                                 SVG_MEDIA_TYPE: {"schema": {"type": "string"}}}}},
)
def localize_frame(
    map_id: MapIdPath,
    frame: Annotated[LocalizeRequest, Body(openapi_examples={
        "chess_demo": {"summary": "A simulated frame of the demo Chess map",
                       "value": LOCALIZE_EXAMPLE}})],
    loader: MapLoaderDep, solver: SolverDep, _key: ReadAccess, version: VersionQuery = None,
    accept: Annotated[str | None, Header(
        description="`image/svg+xml` for the frame drawn (see above)")] = None,
) -> Response:
    compiled = _compiled(loader, map_id, version)
    result = solver.localize_frames(compiled, [frame], batch=False)[0]
    if wants_svg(accept):
        return Response(render_localization_svg(compiled, frame, result),
                        media_type=SVG_MEDIA_TYPE)
    # Already a validated model: serialise it directly (skips FastAPI's re-validation).
    return Response(result.model_dump_json(), media_type="application/json")


@router.post(
    "/maps/{map_id}/localize:batch", response_model=BatchLocalizeResponse,
    summary="Localize several frames",
    description="Frames are solved in order against one map version (bounded count: "
                "QUADLOC_MAX_BATCH_FRAMES). Errors name the frame: `frames[3].detections[0]...`. "
                "The whole batch has a time budget (QUADLOC_BATCH_TIME_BUDGET_MS, queue waits "
                "included): frames not started when it runs out answer `localized: false` with "
                "reason `time_budget_exceeded`; frames already solved are kept.",
    responses={**problem_responses(400, 401, 403, 404, 413, 415, 422, 503),
               200: {"content": {"application/json": {"example": {
                   "map_id": "chess", "map_version": 1,
                   "results": [LOCALIZE_RESPONSE_EXAMPLE, LOCALIZE_RESPONSE_EXAMPLE]}}}}},
)
def localize_batch(
    map_id: MapIdPath,
    batch: Annotated[BatchLocalizeRequest, Body(openapi_examples={
        "two_frames": {"summary": "The demo frame twice",
                       "value": {"frames": [LOCALIZE_EXAMPLE, LOCALIZE_EXAMPLE]}}})],
    loader: MapLoaderDep, solver: SolverDep, settings: SettingsDep, _key: ReadAccess,
    version: VersionQuery = None,
) -> Response:
    if len(batch.frames) > settings.max_batch_frames:
        raise ProblemError("validation-error",
                           f"frames: at most {settings.max_batch_frames} frames per batch",
                           field="frames", message=f"at most {settings.max_batch_frames} frames")
    compiled = _compiled(loader, map_id, version)
    results = solver.localize_frames(compiled, batch.frames, batch=True)
    out = BatchLocalizeResponse(map_id=compiled.map_id, map_version=compiled.version,
                                results=results)
    return Response(out.model_dump_json(), media_type="application/json")
