"""Tracking sessions: ``POST /v1/maps/{map_id}/sessions``, ``POST /v1/sessions/{id}/frames``,
``GET`` / ``DELETE /v1/sessions/{id}``. Sessions live in this process; an unknown id, or
another key's session, is 404 ``session-not-found`` (an ``admin`` key sees all). Replicas and
locking: docs/design/service.md#tracking-session-routes.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Annotated

from fastapi import APIRouter, Body, Path, Request, Response
from fastapi.concurrency import run_in_threadpool

from quadloc.service.api.auth import ReadAccess
from quadloc.service.api.deps import AppDep, MapIdPath
from quadloc.service.api.errors import problem_responses
from quadloc.service.app.ownership import Caller
from quadloc.service.schemas.examples import (
    FRAME_EXAMPLE,
    FRAME_RESPONSE_EXAMPLE,
    SESSION_CREATE_EXAMPLE,
    SESSION_EXAMPLE,
)
from quadloc.service.schemas.sessions import (
    SessionCreate,
    SessionFramesBody,
    SessionFramesOut,
    SessionOut,
)

__all__ = ["router"]

router = APIRouter(prefix="/v1", tags=["tracking"])

#: How often (s) a frames request checks whether its client went away.
DISCONNECT_POLL_S = 0.2

SessionIdPath = Annotated[str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$",
                                    description="Session id returned at creation.")]


@router.post("/maps/{map_id}/sessions", response_model=SessionOut, status_code=201,
             summary="Start a tracking session",
             description="The session belongs to the API key that created it: other keys get "
                         "404 (an `admin` key sees all). 429 `session-quota` when this key "
                         "holds `QUADLOC_MAX_SESSIONS_PER_KEY` live sessions on this replica, "
                         "503 `session-capacity` when the replica holds `QUADLOC_MAX_SESSIONS`.",
             responses={**problem_responses(400, 401, 403, 404, 413, 415, 422, 429, 503),
                        201: {"content": {"application/json": {"example": SESSION_EXAMPLE}}}})
def create_session(map_id: MapIdPath,
                   body: Annotated[SessionCreate, Body(openapi_examples={"chess": {
                       "summary": "Chess camera", "value": SESSION_CREATE_EXAMPLE}})],
                   app: AppDep, _key: ReadAccess, response: Response) -> SessionOut:
    out = app.sessions.create(map_id, body, Caller.of(_key))
    response.headers["Location"] = out.url
    return out


@router.get("/sessions/{session_id}", response_model=SessionOut, summary="Describe a session",
            responses={**problem_responses(401, 403, 404, 422),
                       200: {"content": {"application/json": {"example": SESSION_EXAMPLE}}}})
def get_session(session_id: SessionIdPath, app: AppDep, _key: ReadAccess) -> SessionOut:
    return app.sessions.get(session_id, Caller.of(_key))


@router.delete("/sessions/{session_id}", status_code=204, summary="End a session",
               responses=problem_responses(401, 403, 404, 422))
def delete_session(session_id: SessionIdPath, app: AppDep, _key: ReadAccess) -> Response:
    app.sessions.delete(session_id, Caller.of(_key))
    return Response(status_code=204)


@router.post("/sessions/{session_id}/frames", response_model=SessionFramesOut,
             summary="Add frames to a session (one, or a recording in time order)",
             description="Body: one frame object, or `{\"frames\": [...]}` (batch, at most "
                         "900). Frames are validated all before any is fused: an error names "
                         "`frames[i]....` and leaves the session unchanged.",
             responses={**problem_responses(400, 401, 403, 404, 413, 415, 422, 503),
                        200: {"content": {"application/json": {
                            "example": FRAME_RESPONSE_EXAMPLE}}}})
async def add_frames(session_id: SessionIdPath,
               body: Annotated[SessionFramesBody, Body(openapi_examples={
                   "one_frame": {"summary": "One frame", "value": FRAME_EXAMPLE},
                   "batch": {"summary": "A recording (batch)",
                             "value": {"frames": [FRAME_EXAMPLE]}}})],
               app: AppDep, _key: ReadAccess, request: Request) -> SessionFramesOut:
    # the frames are fused in a worker thread; this task watches the connection meanwhile and
    # cancels the work when the client goes away (the frames left answer time_budget_exceeded)
    gone = threading.Event()

    async def watch() -> None:
        while not await request.is_disconnected():
            await asyncio.sleep(DISCONNECT_POLL_S)
        gone.set()

    watcher = asyncio.create_task(watch())
    try:
        return await run_in_threadpool(app.sessions.add_frames, session_id, body,
                                       Caller.of(_key), gone)
    finally:
        watcher.cancel()
