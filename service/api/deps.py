"""Shared FastAPI dependencies (``Annotated`` aliases) for the routers.

They are ``async def`` on purpose: they only read ``app.state``, and a plain ``def`` dependency
costs a threadpool round trip per request. The localize routes read ``request.app.state``
themselves (each dependency costs FastAPI's injection tens of microseconds per request:
docs/design/service.md#request-fast-path).
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Depends, Path, Request

from quadloc.maps.model import MAP_ID_PATTERN
from quadloc.service.api.errors import ProblemError, json_depth_violation
from quadloc.service.api.metrics import ApiMetrics
from quadloc.service.app.context import App
from quadloc.service.settings import Settings

__all__ = [
    "AppDep",
    "MapIdPath",
    "MetricsDep",
    "SettingsDep",
    "check_body_depth",
]


def _state(name: str) -> Any:
    """A dependency returning ``request.app.state.<name>``."""

    async def dependency(request: Request) -> Any:
        return getattr(request.app.state, name)

    dependency.__name__ = f"get_{name}"
    return Depends(dependency)


#: The application (its use cases): every route calls it and nothing below it.
AppDep = Annotated[App, _state("services")]
SettingsDep = Annotated[Settings, _state("settings")]
MetricsDep = Annotated[ApiMetrics, _state("metrics")]

#: The ``{map_id}`` path parameter of every map route, validated against ``MAP_ID_PATTERN``
#: (422 ``path.map_id`` otherwise) before it reaches the database: a NUL or other character no
#: map id can contain never becomes a query (PostgreSQL refuses NUL in text with a DataError).
MapIdPath = Annotated[str, Path(description="Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN).",
                                pattern=MAP_ID_PATTERN, examples=["chess"])]


async def check_body_depth(request: Request) -> None:
    """Refuse (422) a JSON body nested deeper than ``settings.max_json_depth`` (an app-wide
    dependency: after FastAPI parsed the body, before any route stores anything; why:
    docs/design/service.md#problem-documents)."""
    if request.method in ("GET", "HEAD", "OPTIONS", "DELETE"):
        return
    if "json" not in request.headers.get("content-type", "").lower():
        return
    try:
        document = await request.json()
    except Exception:  # malformed: FastAPI's own body parsing reports it
        return
    limit = request.app.state.settings.max_json_depth
    where = json_depth_violation(document, limit)
    if where is not None:
        message = f"nested more than {limit} levels deep (QUADLOC_MAX_JSON_DEPTH)"
        raise ProblemError("validation-error", f"{where}: {message}",
                           field=where, message=message)
