"""OpenAPI helpers: problem+json response documentation for each route."""

from __future__ import annotations

from typing import Any

from service.api.errors import PROBLEM_MEDIA_TYPE, PROBLEM_TYPES, problem_type
from service.api.schemas import Problem

__all__ = ["problem_responses"]

_SLUG_FOR_STATUS = {400: "malformed-json", 401: "unauthorized", 403: "forbidden",
                    404: "map-not-found", 409: "version-conflict", 412: "precondition-failed",
                    413: "payload-too-large", 415: "unsupported-media-type",
                    422: "validation-error",
                    428: "precondition-required", 503: "busy"}


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
