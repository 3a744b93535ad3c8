"""RFC 9457 ``application/problem+json`` errors for every request failure.

Body: ``{type, title, status, detail, instance, errors: [{field, message}]}``; ``type`` is
``urn:quadloc:problem:<slug>`` (:data:`PROBLEM_TYPES`); fields are spelled like
``detections[2].ellipse.a``, ``query.version``, ``header.if-match``. No 5xx but 503 (and a
logged 500 for bugs): docs/design/service.md#problem-documents.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import DataError, OperationalError, ProgrammingError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from quadloc.maps.errors import MapValidationError, StoreUnavailable
from quadloc.service.app.errors import AppError, first_line, log_database_error
from quadloc.service.schemas.common import Problem, field_path

__all__ = [
    "PROBLEM_MEDIA_TYPE",
    "PROBLEM_TYPES",
    "ProblemError",
    "install_error_handlers",
    "json_depth_violation",
    "problem_body",
    "problem_response",
    "problem_responses",
]

log = logging.getLogger("quadloc.api")


PROBLEM_MEDIA_TYPE = "application/problem+json"

#: slug -> (HTTP status, title). ``type`` = ``urn:quadloc:problem:<slug>``.
PROBLEM_TYPES: dict[str, tuple[int, str]] = {
    "malformed-json": (400, "Malformed JSON body"),
    "bad-request": (400, "Bad request"),
    "unauthorized": (401, "Missing or invalid API key"),
    "forbidden": (403, "API key lacks the required scope"),
    "not-found": (404, "Not found"),
    "map-not-found": (404, "Map not found"),
    "session-not-found": (404, "Tracking session not found"),
    "method-not-allowed": (405, "Method not allowed"),
    "not-acceptable": (406, "Not acceptable"),
    "map-exists": (409, "Map already exists"),
    "default-map": (409, "The default map cannot be deleted"),
    "version-conflict": (409, "Map version conflict"),
    "precondition-failed": (412, "Precondition failed: the map changed"),
    "payload-too-large": (413, "Request body too large"),
    "unsupported-media-type": (415, "Unsupported media type"),
    "validation-error": (422, "Request validation failed"),
    "invalid-map": (422, "Invalid map"),
    "invalid-geometry": (422, "Invalid geometry"),
    "precondition-required": (428, "If-Match header required"),
    "session-quota": (429, "This API key holds its quota of tracking sessions"),
    "busy": (503, "Solver busy, retry later"),
    "session-capacity": (503, "Too many tracking sessions on this replica, retry later"),
    "database-unavailable": (503, "Database unavailable, retry later"),
    "map-loading": (503, "Map version loading, retry shortly"),
    "not-ready": (503, "Service not ready"),
    "internal-error": (500, "Internal error"),
}


def problem_type(slug: str) -> str:
    return f"urn:quadloc:problem:{slug}"


class ProblemError(Exception):
    """Raise from a route to answer with a problem document (``slug`` from PROBLEM_TYPES);
    ``field`` and ``message`` spell a one-entry ``errors``."""

    def __init__(
        self,
        slug: str,
        detail: str,
        *,
        errors: Sequence[Mapping[str, str]] = (),
        headers: Mapping[str, str] | None = None,
        status: int | None = None,
        field: str | None = None,
        message: str = "",
    ) -> None:
        super().__init__(detail)
        default_status, self.title = PROBLEM_TYPES[slug]
        self.slug = slug
        self.status = status or default_status
        self.detail = detail
        self.errors = [dict(e) for e in errors] if field is None else [
            {"field": field, "message": message}]
        self.headers = dict(headers or {})


def problem_response(
    request: Request | None,
    slug: str,
    detail: str,
    *,
    errors: Iterable[Mapping[str, str]] = (),
    headers: Mapping[str, str] | None = None,
    status: int | None = None,
) -> JSONResponse:
    """Build the ``application/problem+json`` response for ``slug``."""
    body = problem_body(slug, detail, request.url.path if request is not None else None,
                        errors, status)
    return JSONResponse(body, status_code=body["status"], headers=dict(headers or {}),
                        media_type=PROBLEM_MEDIA_TYPE)


def problem_body(slug: str, detail: str, instance: str | None,
                 errors: Iterable[Mapping[str, str]] = (),
                 status: int | None = None) -> dict[str, Any]:
    """The problem document ``{type, title, status, detail, instance, errors}`` of ``slug``."""
    default_status, title = PROBLEM_TYPES[slug]
    return {"type": problem_type(slug), "title": title, "status": status or default_status,
            "detail": detail, "instance": instance,
            "errors": [{"field": str(e["field"]), "message": str(e["message"])} for e in errors]}



def json_depth_violation(document: Any, max_depth: int) -> str | None:
    """Path (``field_path`` spelling) of the first container nested deeper than ``max_depth``.

    Depth counts containers: the top-level object or array is depth 1, ``{"a": {"b": 1}}`` has
    depth 2, scalars add nothing. ``None`` when the document is within the limit. Iterative, so
    a document nested thousands deep cannot exhaust the Python stack here.
    """
    if not _deeper_than(document, max_depth):  # the common case: no path to build
        return None
    stack: list[tuple[Any, int, tuple[Any, ...]]] = [(document, 1, ())]
    while stack:
        node, depth, loc = stack.pop()
        children: Iterable[tuple[Any, Any]]
        if isinstance(node, dict):
            children = node.items()
        elif isinstance(node, list):
            children = enumerate(node)
        else:
            continue
        if depth > max_depth:
            return field_path(("body", *loc))
        for key, child in children:
            if isinstance(child, dict | list):
                stack.append((child, depth + 1, (*loc, key)))
    return None


def _deeper_than(document: Any, max_depth: int) -> bool:
    """Whether ``document`` has a container nested deeper than ``max_depth`` (the test of
    :func:`json_depth_violation`, level by level over containers only, without paths)."""
    level = [document] if isinstance(document, dict | list) else []
    depth = 0
    while level:
        depth += 1
        if depth > max_depth:
            return True
        level = [child for node in level
                 for child in (node.values() if isinstance(node, dict) else node)
                 if isinstance(child, dict | list)]
    return False


def _validation_errors(exc: RequestValidationError) -> tuple[str, list[dict[str, str]]]:
    errors: list[dict[str, str]] = []
    slug = "validation-error"
    for err in exc.errors():
        if err.get("type") == "json_invalid":
            slug = "malformed-json"
            ctx = err.get("ctx") or {}
            errors.append({"field": "body",
                           "message": f"malformed JSON: {ctx.get('error', 'cannot parse')}"})
            continue
        msg = str(err.get("msg", "invalid"))
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        field = field_path(err.get("loc", ()))
        if err.get("type") == "missing" and field == "body":
            msg = "a JSON request body is required"
        errors.append({"field": field, "message": msg})
    return slug, errors


async def _on_validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
    content_type = request.headers.get("content-type", "")
    has_body = request.headers.get("content-length", "0") != "0" or "transfer-encoding" in \
        request.headers
    if has_body and "json" not in content_type.lower() and any(
            tuple(e.get("loc", ())) == ("body",) for e in exc.errors()):
        return problem_response(request, "unsupported-media-type",
                                f"send the body as JSON with 'Content-Type: application/json' "
                                f"(got {content_type or 'no Content-Type'!r})",
                                errors=[{"field": "header.content-type",
                                         "message": "must be application/json"}])
    slug, errors = _validation_errors(exc)
    detail = "; ".join(f"{e['field']}: {e['message']}" for e in errors[:5])
    if len(errors) > 5:
        detail += f"; ... ({len(errors)} errors)"
    return problem_response(request, slug, detail, errors=errors)


async def _on_problem(request: Request, exc: ProblemError) -> JSONResponse:
    return problem_response(request, exc.slug, exc.detail, errors=exc.errors,
                            headers=exc.headers, status=exc.status)


_HTTP_SLUGS = {400: "bad-request", 401: "unauthorized", 403: "forbidden", 404: "not-found",
               405: "method-not-allowed", 406: "not-acceptable", 413: "payload-too-large",
               415: "unsupported-media-type"}


def _allowed_methods(request: Request) -> list[str]:
    """Every method any route accepts at this path (Starlette's 405 lists only one route's)."""
    scope = {"type": "http", "path": request.url.path, "method": "\0", "root_path": ""}
    methods: set[str] = set()
    for route in request.app.routes:
        match, _ = route.matches(scope)
        if match != Match.NONE:
            methods |= set(getattr(route, "methods", None) or ())
    return sorted(methods)


async def _on_http_exception(request: Request, exc: StarletteHTTPException) -> JSONResponse:
    slug = _HTTP_SLUGS.get(exc.status_code, "bad-request")
    detail = exc.detail if isinstance(exc.detail, str) else str(exc.detail)
    headers = dict(getattr(exc, "headers", None) or {})
    if exc.status_code == 400 and detail == "There was an error parsing the body":
        slug, detail = "malformed-json", "the body could not be parsed as JSON (malformed or " \
            "nested too deeply)"
    if exc.status_code == 404 and detail == "Not Found":
        detail = f"no route {request.method} {request.url.path}"
    if exc.status_code == 405:
        allowed = _allowed_methods(request)
        headers["Allow"] = ", ".join(allowed)
        detail = f"{request.method} is not allowed here; allowed: {', '.join(allowed)}"
    return problem_response(request, slug, detail, headers=headers,
                            status=exc.status_code if exc.status_code < 500 else 400)


async def _on_invalid_map(request: Request, exc: Exception) -> JSONResponse:
    return problem_response(request, "invalid-map", str(exc),
                            errors=getattr(exc, "errors", None) or [])


async def _on_database_error(request: Request, exc: Exception) -> JSONResponse:
    log_database_error(f"database error on {request.method} {request.url.path}", exc)
    return problem_response(request, "database-unavailable",
                            "the map database is unavailable; retry shortly",
                            headers={"Retry-After": "5"})


async def _on_data_error(request: Request, exc: Exception) -> JSONResponse:
    """The database refused a value of the request (e.g. a NUL character on PostgreSQL)."""
    log.warning("database refused a value on %s %s: %s", request.method, request.url.path,
                first_line(exc))
    return problem_response(request, "validation-error",
                            "the database refused a value of this request (for example a NUL "
                            "character in a string); remove control characters and retry",
                            errors=[{"field": "body", "message": "value refused by the database"}])


async def _on_unexpected(request: Request, exc: Exception) -> JSONResponse:  # pragma: no cover
    log.exception("unhandled error on %s %s", request.method, request.url.path)
    return problem_response(request, "internal-error",
                            "unexpected server error (logged); please report it")


async def _on_app_error(request: Request, exc: Exception) -> JSONResponse:
    """A use case's refusal (:class:`AppError`): its code's problem, with ``Retry-After`` /
    ``ETag`` when it carries them."""
    assert isinstance(exc, AppError)
    headers = {}
    if exc.retry_after_s is not None:
        headers["Retry-After"] = str(max(1, math.ceil(exc.retry_after_s)))
    if exc.etag is not None:
        headers["ETag"] = exc.etag
    return problem_response(request, exc.code, exc.detail, errors=exc.errors, headers=headers)


def install_error_handlers(app: FastAPI) -> None:
    """Register the problem+json handlers on ``app``."""
    app.add_exception_handler(AppError, _on_app_error)
    app.add_exception_handler(RequestValidationError, _on_validation_error)  # type: ignore[arg-type]
    app.add_exception_handler(ProblemError, _on_problem)  # type: ignore[arg-type]
    app.add_exception_handler(StarletteHTTPException, _on_http_exception)  # type: ignore[arg-type]
    app.add_exception_handler(MapValidationError, _on_invalid_map)
    app.add_exception_handler(StoreUnavailable, _on_database_error)
    app.add_exception_handler(OperationalError, _on_database_error)
    app.add_exception_handler(ProgrammingError, _on_database_error)
    app.add_exception_handler(DataError, _on_data_error)
    app.add_exception_handler(Exception, _on_unexpected)


# ----------------------------------------------------------------------- OpenAPI documentation

_SLUG_FOR_STATUS = {400: "malformed-json", 401: "unauthorized", 403: "forbidden",
                    404: "map-not-found", 409: "version-conflict", 412: "precondition-failed",
                    413: "payload-too-large", 415: "unsupported-media-type",
                    422: "validation-error",
                    428: "precondition-required", 429: "session-quota", 503: "busy"}


_DESCRIPTIONS = {
    400: "Malformed or unreadable body",
    404: "Map (or version) not found",
    409: "Conflict: map id taken, or an update lost a race",
    422: "Validation failed (validation-error, invalid-geometry or invalid-map); errors name "
         "the fields",
    503: "Temporarily unavailable (solver busy or database unavailable); see Retry-After",
}


def _example(status: int) -> dict[str, Any]:
    slug = _SLUG_FOR_STATUS[status]
    title = PROBLEM_TYPES[slug][1]
    example: dict[str, Any] = {"type": problem_type(slug), "title": title, "status": status,
                               "detail": title, "instance": "/v1/maps/chess", "errors": []}
    if status == 422:
        example["detail"] = "detections[0].ellipse.a: Input should be greater than 0"
        example["errors"] = [{"field": "detections[0].ellipse.a",
                              "message": "Input should be greater than 0"}]
    return example


def problem_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` entry documenting problem+json bodies for ``statuses``."""
    return {
        status: {
            "model": Problem,
            "description": _DESCRIPTIONS.get(status, PROBLEM_TYPES[_SLUG_FOR_STATUS[status]][1]),
            "content": {PROBLEM_MEDIA_TYPE: {"example": _example(status)}},
        }
        for status in statuses
    }
