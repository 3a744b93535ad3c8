"""The API's OpenAPI document, generated from the app's routes and wire models and tidied so
that problem answers are documented as ``application/problem+json`` only (``docs/openapi.json``
is written from it: ``quadloc openapi``, :func:`quadloc.service.api.app.openapi_text`)."""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi

from quadloc.service.api.errors import PROBLEM_MEDIA_TYPE

__all__ = ["build_openapi"]


def _tidy_openapi(schema: dict[str, Any]) -> dict[str, Any]:
    """Problem responses: schema under application/problem+json only; drop FastAPI's default
    HTTPValidationError (our 422s are problem documents)."""
    for path_item in schema.get("paths", {}).values():
        for op in path_item.values():
            for code, resp in op.get("responses", {}).items():
                content = resp.get("content", {})
                if str(code).startswith(("4", "5")) and PROBLEM_MEDIA_TYPE in content:
                    plain = content.pop("application/json", None)
                    if plain and "schema" in plain:
                        content[PROBLEM_MEDIA_TYPE]["schema"] = plain["schema"]
    comps = schema.get("components", {}).get("schemas", {})
    text = str(schema.get("paths"))
    for name in ("HTTPValidationError", "ValidationError"):
        if name in comps and f"#/components/schemas/{name}" not in text:
            del comps[name]
    return schema


def build_openapi(app: FastAPI) -> dict[str, Any]:
    """The app's OpenAPI document (cached on the app)."""
    if app.openapi_schema is None:
        schema = get_openapi(title=app.title, version=app.version, description=app.description,
                             routes=app.routes, tags=app.openapi_tags)
        app.openapi_schema = _tidy_openapi(schema)
    return app.openapi_schema
