"""``POST /v1/maps/{map_id}/localize`` and ``.../localize:batch``.

Plain ``def`` routes: FastAPI runs them in its threadpool, so the CPU-bound solve never blocks
the event loop. "Not localized" is a normal 200 answer with ``localized: false`` and a reason.
A plain valid single-frame request skips FastAPI's dependency injection (``_plain_frame``, same
work in the same threadpool; every other request and every error goes through FastAPI):
docs/design/service.md#request-fast-path.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Coroutine
from typing import Annotated, Any

from fastapi import APIRouter, Body, Header, Query, Request, Response
from fastapi.routing import APIRoute
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from quadloc.maps.model import MAP_ID_PATTERN
from quadloc.service.api.auth import ReadAccess, request_access
from quadloc.service.api.deps import MapIdPath
from quadloc.service.api.errors import (
    ProblemError,
    json_depth_violation,
    problem_responses,
)
from quadloc.service.api.inspector import SVG_HEADERS, SVG_MEDIA_TYPE, wants_svg
from quadloc.service.app.drawing import render_localization_svg
from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE, LOCALIZE_RESPONSE_EXAMPLE
from quadloc.service.schemas.localize import (
    BatchLocalizeRequest,
    BatchLocalizeResponse,
    LocalizeRequest,
    LocalizeResponse,
)

__all__ = ["router"]

router = APIRouter(prefix="/v1", tags=["localization"])

#: ``MAP_ID_PATTERN`` as ``MapIdPath`` applies it (``fullmatch``: no trailing newline at ``$``).
_MAP_ID = re.compile(MAP_ID_PATTERN)

VersionQuery = Annotated[int | None, Query(ge=1, le=2**31 - 1,
                                           description="Map version (default: latest).")]


def _localize_one(state: Any, map_id: str, frame: LocalizeRequest, version: int | None,
                  accept: str | None) -> Response:
    """The single-frame route's work, blocking (runs in the threadpool); ``state`` is the
    app's ``app.state``."""
    compiled, result = state.services.localizer.localize(map_id, frame, version)
    if wants_svg(accept):
        return Response(render_localization_svg(compiled, frame, result),
                        media_type=SVG_MEDIA_TYPE, headers=SVG_HEADERS)
    # Already a validated model: serialise it directly (skips FastAPI's re-validation).
    return Response(result.model_dump_json(), media_type="application/json")


def localize_frame(
    map_id: MapIdPath,
    frame: Annotated[LocalizeRequest, Body(openapi_examples={
        "chess_demo": {"summary": "A simulated frame of the demo Chess map",
                       "value": LOCALIZE_EXAMPLE}})],
    request: Request, _key: ReadAccess, version: VersionQuery = None,
    accept: Annotated[str | None, Header(
        description="`image/svg+xml` for the frame drawn (see above)")] = None,
) -> Response:
    # app.state read here: a dependency per object costs FastAPI's injection ~30 us each.
    return _localize_one(request.app.state, map_id, frame, version, accept)


#: Every parameter of :func:`localize_frame` (and the app-wide ``check_body_depth``) that
#: :func:`_plain_frame` checks by hand; tests/service/api/test_api_localize.py compares it with the
# route's.
FAST_PATH_PARAMETERS = ("map_id", "frame", "request", "_key", "version", "accept")


async def _plain_frame(request: Request) -> LocalizeRequest | None:
    """The validated frame of a request that FastAPI's full handling would hand to
    :func:`localize_frame` with ``version`` and ``accept`` meaning None (no query string,
    ``Content-Type: application/json``, a valid map id, JSON within the depth limit, read
    access, a valid ``LocalizeRequest``); None for anything else, which the full handling then
    answers (every error comes from there). Why: docs/design/service.md#request-fast-path."""
    headers = request.headers
    if (request.scope.get("query_string")
            or headers.get("content-type", "").lower() != "application/json"
            or wants_svg(headers.get("accept"))
            or not _MAP_ID.fullmatch(request.path_params.get("map_id", ""))):
        return None
    try:
        document = await request.json() if await request.body() else None
    except Exception:  # malformed, not UTF-8, nested past the parser: FastAPI's answer
        return None
    if document is None or json_depth_violation(
            document, request.app.state.settings.max_json_depth) is not None:
        return None
    try:
        await request_access(request, "read")
        return LocalizeRequest.model_validate(document)
    except (ProblemError, ValidationError):
        return None


class _FastLocalizeRoute(APIRoute):
    """The single-frame route: a plain valid request skips FastAPI's dependency injection
    (:func:`_plain_frame`), any other goes through it."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        full = super().get_route_handler()

        async def handler(request: Request) -> Response:
            frame = await _plain_frame(request)
            if frame is None:
                return await full(request)
            return await run_in_threadpool(_localize_one, request.app.state,
                                           request.path_params["map_id"], frame, None, None)

        return handler


router.add_api_route(
    "/maps/{map_id}/localize", localize_frame, methods=["POST"],
    route_class_override=_FastLocalizeRoute, response_model=LocalizeResponse,
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
    request: Request, _key: ReadAccess, version: VersionQuery = None,
) -> Response:
    out = request.app.state.services.localizer.localize_batch(map_id, batch.frames, version)
    return Response(out.model_dump_json(), media_type="application/json")
