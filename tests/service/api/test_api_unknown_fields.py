"""Unknown fields are refused everywhere (422 naming them), checked generically over the OpenAPI
document, not endpoint by endpoint: (1) every request body's schema, recursively, is closed
(``additionalProperties: false`` on every object with properties; maps such as ``size_priors``
are checked through their values; the only free-form objects are the map document's
``metadata``: user data, stored as given); (2) every operation with a body, sent its own
documented example plus one unknown field, answers 422 naming exactly that field."""

from __future__ import annotations

import copy
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from quadloc.service.api.app import openapi_document
from tests.conftest import make_test_app

DOC = openapi_document()
#: Free-form objects by design (their property name): user data, any JSON.
FREE_FORM = {"metadata"}


def _resolve(schema: dict[str, Any]) -> dict[str, Any]:
    ref = schema.get("$ref")
    if ref is None:
        return schema
    out: dict[str, Any] = DOC
    for part in ref.removeprefix("#/").split("/"):
        out = out[part]
    return out


def _open_objects(schema: dict[str, Any], path: str, seen: set[str]) -> Iterator[str]:
    """Paths of the object schemas under ``schema`` that accept unknown properties."""
    ref = schema.get("$ref")
    if ref is not None:
        if ref in seen:
            return
        seen = seen | {ref}
    s = _resolve(schema)
    for key in ("anyOf", "oneOf", "allOf"):
        for k, sub in enumerate(s.get(key, [])):
            yield from _open_objects(sub, f"{path}<{key}{k}>", seen)
    if "items" in s:
        yield from _open_objects(s["items"], f"{path}[]", seen)
    props = s.get("properties")
    extra = s.get("additionalProperties")
    if props is not None:
        if extra is not False:
            yield path
        for name, sub in props.items():
            if name in FREE_FORM:
                assert _resolve(sub).get("properties") is None, f"{path}.{name}"
                continue
            yield from _open_objects(sub, f"{path}.{name}", seen)
    elif isinstance(extra, dict):  # a map: its values are checked
        yield from _open_objects(extra, f"{path}{{}}", seen)
    elif s.get("type") == "object" or extra is True:
        yield path


def _operations() -> list[tuple[str, str, dict[str, Any]]]:
    """``(method, url, body)`` of every operation with a JSON body; the url's path and required
    query parameters filled with valid values."""
    out = []
    for route, ops in DOC["paths"].items():
        for method, op in ops.items():
            body = op.get("requestBody", {}).get("content", {}).get("application/json")
            if body is not None:
                query = [f"{p['name']}=probe" for p in op.get("parameters", [])
                         if p["in"] == "query" and p.get("required")]
                url = route.replace("{map_id}", "chess").replace("{session_id}", "s-0000")
                out.append((method, url + ("?" + "&".join(query) if query else ""), body))
    return out


OPERATIONS = _operations()


def test_there_are_request_bodies_to_check() -> None:
    routes = {(m, r) for m, r, _ in OPERATIONS}
    assert ("post", "/v1/maps:build?map_id=probe") in routes
    assert ("post", "/v1/maps/chess/localize") in routes
    assert len(routes) >= 8


@pytest.mark.parametrize(("method", "route", "body"), OPERATIONS,
                         ids=[f"{m} {r}" for m, r, _ in OPERATIONS])
def test_every_request_schema_is_closed(method: str, route: str, body: dict[str, Any]) -> None:
    assert list(_open_objects(body["schema"], "body", set())) == []


def _example(body: dict[str, Any]) -> Any:
    if "example" in body:
        return copy.deepcopy(body["example"])
    first = next(iter(body["examples"].values()))
    return copy.deepcopy(first["value"])


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    tmp: Path = tmp_path_factory.mktemp("unknown")
    with TestClient(make_test_app(tmp)) as c:
        yield c


@pytest.mark.parametrize(("method", "route", "body"), OPERATIONS,
                         ids=[f"{m} {r}" for m, r, _ in OPERATIONS])
def test_an_unknown_field_is_refused_naming_it(client: TestClient, method: str, route: str,
                                               body: dict[str, Any]) -> None:
    example = _example(body)
    assert isinstance(example, dict)
    example["unknwon_field"] = 1
    if "map_id" in example:  # a map document names its own map: the path's
        route = route.replace("/chess", f"/{example['map_id']}")
    r = client.request(method.upper(), route, json=example)
    assert r.status_code == 422, (route, r.status_code, r.text)
    assert [e["field"] for e in r.json()["errors"]] == ["unknwon_field"], r.text
