"""``/v1/maps``: create, import (Chess format), list, get (ETag), update (If-Match), delete.

Concurrency: a map version is immutable and its ``content_hash`` is served as a strong ETag
(``"<sha256hex>"``). ``PUT`` requires ``If-Match`` with the ETag of the latest version: a missing
header is refused with 428, a stale one with 412, and a writer that loses a race between the
check and the write gets 409 (the store's version conflict) - never a silent overwrite.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Header, Query, Response, status

from quadloc.maps.model import (
    CHESS_JSON_SCHEMA,
    MAP_ID_PATTERN,
    MAP_JSON_SCHEMA,
    content_hash,
    scene_map_from_dict,
)
from quadloc.service.api.auth import ReadAccess, WriteAccess
from quadloc.service.api.deps import AppDep, MapIdPath
from quadloc.service.api.errors import problem_responses
from quadloc.service.schemas.examples import CHESS_IMPORT_EXAMPLE, MAP_EXAMPLE
from quadloc.service.schemas.maps import (
    MapListOut,
    MapOut,
    MapVersionsOut,
    etag_of,
)

__all__ = ["router"]

router = APIRouter(prefix="/v1", tags=["maps"])

#: Request-body schemas, generated from the pydantic document models that validate the bodies
#: (quadloc.maps.model.MapDocument / ChessDocument), without the standalone document's
# ``$schema``/``$id``.
_MAP_SCHEMA = {k: v for k, v in MAP_JSON_SCHEMA.items() if not k.startswith("$")}


_EXAMPLE_MAP = scene_map_from_dict(MAP_EXAMPLE, version=1)
_MAP_OUT_EXAMPLE = {"map_id": _EXAMPLE_MAP.map_id, "version": 1,
                    "content_hash": content_hash(_EXAMPLE_MAP),
                    "created_at": "2026-01-05T10:00:00+00:00", "map": _EXAMPLE_MAP.to_dict()}
_LIST_EXAMPLE = {"maps": [{"map_id": _EXAMPLE_MAP.map_id, "name": _EXAMPLE_MAP.name, "version": 1,
                           "content_hash": content_hash(_EXAMPLE_MAP),
                           "updated_at": "2026-01-05T10:00:00+00:00"}]}


#: OpenAPI links from a response carrying a stored map (``MapOut`` + ETag) to what a client
#: does next with it (clients and stateful fuzzers follow them).
_MAP_LINKS: dict[str, Any] = {
    "GetMap": {"operationId": "get_map_v1_maps__map_id__get",
               "parameters": {"path.map_id": "$response.body#/map_id"}},
    "UpdateMap": {"operationId": "update_map_v1_maps__map_id__put",
                  "parameters": {"path.map_id": "$response.body#/map_id",
                                 "header.If-Match": "$response.header.ETag"}},
    "DeleteMap": {"operationId": "delete_map_v1_maps__map_id__delete",
                  "parameters": {"path.map_id": "$response.body#/map_id"}},
    "LocalizeFrame": {"operationId": "localize_frame_v1_maps__map_id__localize_post",
                      "parameters": {"path.map_id": "$response.body#/map_id"}},
}


def _ok(status_code: int, example: dict[str, Any], headers: bool = True
        ) -> dict[int | str, dict[str, Any]]:
    doc: dict[str, Any] = {"content": {"application/json": {"example": example}}}
    if headers:
        doc["headers"] = {"ETag": {"description": "Strong ETag: the version's content hash.",
                                   "schema": {"type": "string"}}}
        doc["links"] = _MAP_LINKS
    return {status_code: doc}


def _body_doc(schema: dict[str, Any], example: dict[str, Any]) -> dict[str, Any]:
    return {"requestBody": {"required": True, "content": {"application/json": {
        "schema": schema, "example": example}}}}


_CREATED_RESPONSES = {**problem_responses(400, 401, 403, 409, 413, 415, 422, 503),
                      **_ok(201, _MAP_OUT_EXAMPLE)}


@router.post(
    "/maps", status_code=status.HTTP_201_CREATED, response_model=MapOut,
    summary="Create a map (version 1)",
    description="Body: the map document (docs/maps.md). `version` in the body is ignored: a "
                "new map is version 1. Answers 201 with the stored map, its `ETag` and "
                "`Location`; 409 if the id is taken; 422 naming every invalid field.",
    responses=_CREATED_RESPONSES,
    openapi_extra=_body_doc(_MAP_SCHEMA, MAP_EXAMPLE),
)
def create_map(body: Annotated[dict[str, Any], Body()], response: Response, app: AppDep,
               _key: WriteAccess) -> MapOut:
    return _created(app.maps.create(body), response)


@router.post(
    "/maps:import-chess", status_code=status.HTTP_201_CREATED, response_model=MapOut,
    summary="Create a map from the Chess scene format",
    description="Body: the Chess format (`category_id_to_label`, `objects[]` with "
                "`ellipsoid {axes, R, center}`; world +Z up). The map id and name come from "
                "the query.",
    responses=_CREATED_RESPONSES,
    openapi_extra=_body_doc(CHESS_JSON_SCHEMA, CHESS_IMPORT_EXAMPLE),
)
def import_chess_map(
    body: Annotated[dict[str, Any], Body()], response: Response, app: AppDep,
    _key: WriteAccess,
    map_id: Annotated[str, Query(pattern=MAP_ID_PATTERN, description="Id of the new map.")],
    name: Annotated[str, Query(min_length=1, max_length=256)] = "Chess",
) -> MapOut:
    return _created(app.maps.import_chess(body, map_id, name), response)


def _created(stored: MapOut, response: Response) -> MapOut:
    response.headers["ETag"] = etag_of(stored.content_hash)
    response.headers["Location"] = f"/v1/maps/{stored.map_id}"
    return stored


@router.get("/maps", response_model=MapListOut, summary="List maps (latest versions)",
            responses={**problem_responses(401, 403, 503), **_ok(200, _LIST_EXAMPLE, False)})
def list_maps(app: AppDep, _key: ReadAccess) -> MapListOut:
    return app.maps.list()


@router.get(
    "/maps/{map_id}", response_model=MapOut, summary="Get a map (latest or a given version)",
    description="The response carries `ETag: \"<content_hash>\"`; send it back in `If-Match` "
                "to update. Old versions stay readable with `?version=n`.",
    responses={**problem_responses(401, 403, 404, 422, 503), **_ok(200, _MAP_OUT_EXAMPLE)},
)
def get_map(map_id: MapIdPath, response: Response, app: AppDep, _key: ReadAccess,
            version: Annotated[int | None, Query(ge=1, le=2**31 - 1)] = None) -> MapOut:
    stored = app.maps.get(map_id, version)
    response.headers["ETag"] = etag_of(stored.content_hash)
    return stored


@router.get(
    "/maps/{map_id}/versions", response_model=MapVersionsOut, summary="List a map's versions",
    description="Every stored version (immutable, readable with `GET /v1/maps/{map_id}"
                "?version=n`), ascending, with its content hash (the ETag) and creation time.",
    responses={**problem_responses(401, 403, 404, 422, 503),
               **_ok(200, {"map_id": _EXAMPLE_MAP.map_id, "versions": [
                   {"version": 1, "content_hash": content_hash(_EXAMPLE_MAP),
                    "created_at": "2026-01-05T10:00:00+00:00"}]}, False)},
)
def list_map_versions(map_id: MapIdPath, app: AppDep, _key: ReadAccess) -> MapVersionsOut:
    return app.maps.versions(map_id)


@router.put(
    "/maps/{map_id}", response_model=MapOut, summary="Update a map (new version)",
    description="Body: the full map document (its `map_id` must equal the path's). Requires "
                "`If-Match` with the latest version's ETag. Checked in this order: the body "
                "(invalid -> 422 naming the fields), then `If-Match` (missing or `*` -> 428), "
                "the map (absent -> 404), the ETag (stale -> 412, the current ETag is in the "
                "response); a lost race -> 409. Answers 200 with the new version and its ETag.",
    responses={**problem_responses(400, 401, 403, 404, 409, 412, 413, 415, 422, 428, 503),
               **_ok(200, {**_MAP_OUT_EXAMPLE, "version": 2})},
    openapi_extra={**_body_doc(_MAP_SCHEMA, MAP_EXAMPLE), "parameters": [{
        # Required (428 when missing); declared here because the route answers 428 itself
        # rather than FastAPI's 422 for a missing header.
        "name": "If-Match", "in": "header", "required": True,
        "description": "ETag of the version edited (strong, as returned by GET).",
        "schema": {"type": "string", "minLength": 1}, "example": '"d79f785a18e6e97f..."'}]},
)
def update_map(
    map_id: MapIdPath, body: Annotated[dict[str, Any], Body()], response: Response,
    app: AppDep, _key: WriteAccess,
    if_match: Annotated[str | None, Header(include_in_schema=False)] = None,
) -> MapOut:
    stored = app.maps.update(map_id, body, if_match)
    response.headers["ETag"] = etag_of(stored.content_hash)
    return stored


@router.delete("/maps/{map_id}", status_code=status.HTTP_204_NO_CONTENT,
               summary="Delete a map (all its versions)",
               description="Deletes every version. The server's default map "
                           "(QUADLOC_DEFAULT_MAP_ID, `chess` unless configured) is refused with "
                           "409: /readyz checks it, so deleting it would take every replica out "
                           "of service. Update it with PUT instead.",
               responses=problem_responses(401, 403, 404, 409, 422, 503))
def delete_map(map_id: MapIdPath, app: AppDep, _key: WriteAccess) -> Response:
    app.maps.delete(map_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
