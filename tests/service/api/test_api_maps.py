"""/v1/maps routes: create, import, list, get (ETag), update (If-Match), delete - in process."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from quadloc.maps.demo import load_demo_map
from quadloc.maps.model import content_hash, scene_map_from_dict
from quadloc.service.schemas.examples import CHESS_IMPORT_EXAMPLE, MAP_EXAMPLE
from tests.conftest import make_test_app
from tests.support.helpers import FakeClock
from tests.support.helpers import assert_problem as _problem
from tests.support.reference_data import CHESS_SCENE_PATH, load_chess_scene_json

PROBLEM = "application/problem+json"
CHESS_SCENE = CHESS_SCENE_PATH


@pytest.fixture
def client(tmp_path: Path):
    with TestClient(make_test_app(tmp_path)) as c:
        yield c


def test_demo_map_is_seeded_and_matches_the_shipped_file(client: TestClient) -> None:
    r = client.get("/v1/maps")
    assert r.status_code == 200
    [summary] = r.json()["maps"]
    assert summary["map_id"] == "chess" and summary["version"] == 1
    r = client.get("/v1/maps/chess")
    assert r.status_code == 200
    body = r.json()
    demo = load_demo_map()
    # The ETag is the independently computed content hash of the shipped demo map.
    assert body["content_hash"] == content_hash(demo)
    assert r.headers["etag"] == f'"{content_hash(demo)}"'
    got = scene_map_from_dict(body["map"])
    assert [o.object_id for o in got.objects] == [o.object_id for o in demo.objects]
    for a, b in zip(got.objects, demo.objects, strict=True):
        np.testing.assert_allclose(a.ellipsoid.center, b.ellipsoid.center, rtol=0, atol=0)


def test_create_get_list_delete(client: TestClient) -> None:
    r = client.post("/v1/maps", json=MAP_EXAMPLE)
    assert r.status_code == 201, r.text
    assert r.headers["location"] == "/v1/maps/office-3"
    created = r.json()
    assert created["version"] == 1
    assert r.headers["etag"] == f'"{created["content_hash"]}"'
    # The stored hash equals the hash of the parsed document (independent computation).
    assert created["content_hash"] == content_hash(scene_map_from_dict(MAP_EXAMPLE, version=1))
    ids = [m["map_id"] for m in client.get("/v1/maps").json()["maps"]]
    assert ids == ["chess", "office-3"]
    assert client.get("/v1/maps/office-3").json()["map"]["objects"][2]["object_id"] == "plant-1"
    _problem(client.post("/v1/maps", json=MAP_EXAMPLE), 409, "map-exists")
    assert client.delete("/v1/maps/office-3").status_code == 204
    _problem(client.get("/v1/maps/office-3"), 404, "map-not-found")
    _problem(client.delete("/v1/maps/office-3"), 404, "map-not-found")


def test_create_ignores_client_version(client: TestClient) -> None:
    doc = {**MAP_EXAMPLE, "version": 7}
    assert client.post("/v1/maps", json=doc).json()["version"] == 1
    # ignored, but still held to its schema (an integer >= 1): nothing is stored
    for bad in (0, 0.0, -3, "2"):
        body = _problem(client.post("/v1/maps", json={**MAP_EXAMPLE, "map_id": "v-bad",
                                                      "version": bad}), 422, "invalid-map")
        assert [e["field"] for e in body["errors"]] == ["version"], bad
    _problem(client.get("/v1/maps/v-bad"), 404, "map-not-found")


def test_invalid_maps_name_the_field(client: TestClient) -> None:
    bad = copy.deepcopy(MAP_EXAMPLE)
    bad["objects"][1]["axes"] = [0.3, -1.0, 0.2]
    bad["objects"][0]["quaternion_wxyz"] = [2.0, 0.0, 0.0, 0.0]
    body = _problem(client.post("/v1/maps", json=bad), 422, "invalid-map")
    fields = {e["field"] for e in body["errors"]}
    assert {"objects[1].axes[1]", "objects[0].quaternion_wxyz"} <= fields
    # NaN literal inside the map document (Python's json accepts it; the API must not).
    text = json.dumps(MAP_EXAMPLE).replace("1.2, 0.4, 0.45", "NaN, 0.4, 0.45")
    assert "NaN" in text
    body = _problem(client.post("/v1/maps", content=text,
                                headers={"content-type": "application/json"}),
                    422, "invalid-map")
    assert body["errors"][0]["field"] == "objects[0].center[0]"
    # Not an object at all.
    _problem(client.post("/v1/maps", json=[1, 2, 3]), 422, "validation-error")
    _problem(client.post("/v1/maps", content=b"{", headers={"content-type": "application/json"}),
             400, "malformed-json")


def test_object_count_limit(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path, max_map_objects=2)) as c:
        body = _problem(c.post("/v1/maps", json=MAP_EXAMPLE), 422, "invalid-map")
        assert body["errors"][0]["field"] == "objects"


def test_update_requires_a_fresh_etag(client: TestClient) -> None:
    r = client.get("/v1/maps/chess")
    etag, doc = r.headers["etag"], r.json()["map"]
    doc["objects"][0]["axes"] = [0.2, 0.4, 0.3]
    _problem(client.put("/v1/maps/chess", json=doc), 428, "precondition-required")
    # (If-Match: * is tests/service/api/test_api_if_match.py)
    stale = _problem(client.put("/v1/maps/chess", json=doc, headers={"If-Match": '"0000"'}),
                     412, "precondition-failed")
    assert stale["errors"][0]["field"] == "header.if-match"
    r = client.put("/v1/maps/chess", json=doc, headers={"If-Match": etag})
    assert r.status_code == 200, r.text
    v2 = r.json()
    assert v2["version"] == 2 and r.headers["etag"] != etag
    assert v2["map"]["objects"][0]["axes"] == [0.2, 0.4, 0.3]
    # The old ETag is now stale: a second writer that edited version 1 is refused...
    r = client.put("/v1/maps/chess", json=doc, headers={"If-Match": etag})
    assert _problem(r, 412, "precondition-failed")
    assert r.headers["etag"] == f'"{v2["content_hash"]}"'
    # ...and version 1 stays readable, unchanged.
    v1 = client.get("/v1/maps/chess", params={"version": 1})
    assert v1.headers["etag"] == etag
    assert v1.json()["map"]["objects"][0]["axes"] != [0.2, 0.4, 0.3]
    _problem(client.get("/v1/maps/chess", params={"version": 3}), 404, "map-not-found")
    _problem(client.get("/v1/maps/chess", params={"version": 0}), 422, "validation-error")
    _problem(client.get("/v1/maps/chess", params={"version": "x"}), 422, "validation-error")


def test_invalid_update_names_the_field_and_loses_nothing(client: TestClient) -> None:
    before = client.get("/v1/maps/chess")
    etag, doc = before.headers["etag"], before.json()["map"]
    bad = copy.deepcopy(doc)
    bad["objects"][2]["axes"] = [0.2, float("nan"), 0.3]
    bad["objects"][4]["category"] = "Sofa"
    text = json.dumps(bad)  # NaN literal on the wire
    body = _problem(client.put("/v1/maps/chess", content=text,
                               headers={"If-Match": etag, "content-type": "application/json"}),
                    422, "invalid-map")
    fields = {e["field"] for e in body["errors"]}
    assert {"objects[2].axes[1]", "objects[4].category"} <= fields
    _problem(client.put("/v1/maps/chess", content=b'{"objects": [', headers={
        "If-Match": etag, "content-type": "application/json"}), 400, "malformed-json")
    after = client.get("/v1/maps/chess")
    assert after.status_code == 200
    assert after.headers["etag"] == etag
    assert after.json() == before.json()
    assert [m["version"] for m in client.get("/v1/maps").json()["maps"]
            if m["map_id"] == "chess"] == [before.json()["version"]]
    # the untouched document still updates normally with the same ETag
    assert client.put("/v1/maps/chess", json=doc, headers={"If-Match": etag}).status_code == 200


def test_update_rejects_a_different_map_id_and_unknown_maps(client: TestClient) -> None:
    r = client.get("/v1/maps/chess")
    doc = {**r.json()["map"], "map_id": "other"}
    body = _problem(client.put("/v1/maps/chess", json=doc, headers={"If-Match": r.headers["etag"]}),
                    422, "invalid-map")
    assert body["errors"][0]["field"] == "map_id"
    _problem(client.put("/v1/maps/nope", json={**MAP_EXAMPLE, "map_id": "nope"},
                        headers={"If-Match": '"x"'}), 404, "map-not-found")
    # the documented order: the body (422), then If-Match (428), then the map (404), the ETag
    bad = {**MAP_EXAMPLE, "map_id": "nope", "objects": [{"object_id": "x"}]}
    _problem(client.put("/v1/maps/nope", json=bad), 422, "invalid-map")
    _problem(client.put("/v1/maps/nope", json={**MAP_EXAMPLE, "map_id": "nope"}), 428,
             "precondition-required")


def test_lost_race_is_a_409(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    """Another writer commits between the If-Match check and the write: 409, not overwrite."""
    store = client.app.state.services.store
    r = client.get("/v1/maps/chess")
    etag, doc = r.headers["etag"], r.json()["map"]
    real_update = store.update

    def racing_update(map_id, scene_map, expected_version):
        real_update(map_id, scene_map_from_dict({**doc, "name": "other writer"},
                                                version=expected_version + 1), expected_version)
        return real_update(map_id, scene_map, expected_version)

    monkeypatch.setattr(store, "update", racing_update)
    body = _problem(client.put("/v1/maps/chess", json=doc, headers={"If-Match": etag}),
                    409, "version-conflict")
    assert "version 2" in body["detail"]
    monkeypatch.undo()
    latest = client.get("/v1/maps/chess").json()
    assert latest["version"] == 2 and latest["map"]["name"] == "other writer"


def test_import_chess_format(client: TestClient) -> None:
    r = client.post("/v1/maps:import-chess", params={"map_id": "mini", "name": "Mini"},
                    json=CHESS_IMPORT_EXAMPLE)
    assert r.status_code == 201, r.text
    objs = r.json()["map"]["objects"]
    assert [o["category"] for o in objs] == ["TV", "Chair"]
    # Orientation: the returned quaternion reproduces the Chess R (independent conversion).
    from quadloc.factors.rotations import rotation_from_quaternion_wxyz

    R = np.array(CHESS_IMPORT_EXAMPLE["objects"][0]["ellipsoid"]["R"])
    np.testing.assert_allclose(rotation_from_quaternion_wxyz(objs[0]["quaternion_wxyz"]), R,
                               atol=1e-9)
    if CHESS_SCENE.exists():
        full = load_chess_scene_json(CHESS_SCENE)
        r = client.post("/v1/maps:import-chess", params={"map_id": "chess2"}, json=full)
        assert r.status_code == 201 and len(r.json()["map"]["objects"]) == 11
    bad = copy.deepcopy(CHESS_IMPORT_EXAMPLE)
    bad["objects"][0]["ellipsoid"]["axes"] = [1.0, 2.0]
    body = _problem(client.post("/v1/maps:import-chess", params={"map_id": "bad"}, json=bad),
                    422, "invalid-map")
    assert body["errors"][0]["field"] == "objects[0].ellipsoid.axes"
    _problem(client.post("/v1/maps:import-chess", params={"map_id": "bad id!"},
                         json=CHESS_IMPORT_EXAMPLE), 422, "validation-error")


def _map_version_used(c: TestClient) -> int:
    from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE

    frame = {**LOCALIZE_EXAMPLE, "detections": LOCALIZE_EXAMPLE["detections"][:1]}
    r = c.post("/v1/maps/chess/localize", json=frame)
    assert r.status_code == 200, r.text
    return r.json()["map_version"]


def test_localize_sees_local_updates_at_once_and_other_replicas_within_the_ttl(
        tmp_path: Path) -> None:
    from quadloc.maps.store import MapStore
    from quadloc.service.app.maps import seed_demo_map
    from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE

    # "chess" is not the default map here: the default map cannot be deleted (409).
    app = make_test_app(tmp_path, map_cache_ttl_s=0.3, default_map_id="chess-default")
    clock = FakeClock()
    app.state.services.store.cache.clock = clock  # the TTL runs on the fake clock: no sleeping
    assert seed_demo_map(app.state.services.store, "chess")
    with TestClient(app) as c:
        assert _map_version_used(c) == 1
        r = c.get("/v1/maps/chess")
        assert c.put("/v1/maps/chess", json=r.json()["map"],
                     headers={"If-Match": r.headers["etag"]}).status_code == 200
        assert _map_version_used(c) == 2  # written through this app: invalidated at once
        # Another replica (its own store and cache) writes to the shared database.
        other = MapStore(app.state.settings.effective_database_url)
        try:
            doc = c.get("/v1/maps/chess").json()["map"]
            other.update("chess", scene_map_from_dict(doc, version=3), expected_version=2)
        finally:
            other.close()
        assert _map_version_used(c) == 2  # cached for at most the TTL
        clock.advance(0.29)
        assert _map_version_used(c) == 2
        clock.advance(0.02)
        assert _map_version_used(c) == 3
        assert c.delete("/v1/maps/chess").status_code == 204
        assert c.post("/v1/maps/chess/localize", json={}).status_code == 422
        assert c.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE).status_code == 404


def test_database_outage_is_a_503_problem(client: TestClient,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from quadloc.maps.errors import StoreUnavailable

    def down(*args, **kwargs):
        raise StoreUnavailable("database unreachable: OperationalError")

    store = client.app.state.services.store
    monkeypatch.setattr(store, "list", down)
    monkeypatch.setattr(store, "ping", down)
    body = _problem(client.get("/v1/maps"), 503, "database-unavailable")
    assert client.get("/v1/maps").headers["retry-after"] == "5"
    assert body["detail"]
    _problem(client.get("/readyz"), 503, "not-ready")


def test_body_without_json_content_type_is_415(client: TestClient) -> None:
    r = client.post("/v1/maps", content=json.dumps(MAP_EXAMPLE),
                    headers={"content-type": "text/plain"})
    body = _problem(r, 415, "unsupported-media-type")
    assert body["errors"][0]["field"] == "header.content-type"


# ------------------------------------------------------------ review 6: depth, NUL, If-Match


def _nested(depth: int) -> dict:
    """A map-body ``metadata`` value such that the whole body is ``depth`` containers deep
    (the body object is depth 1, ``metadata``'s object depth 2, ...)."""
    value: object = 1
    for _ in range(depth - 1):
        value = {"k": value}
    return value  # type: ignore[return-value]


def test_json_depth_counts_containers() -> None:
    from quadloc.service.api.errors import json_depth_violation

    assert json_depth_violation({"a": 1}, 1) is None
    assert json_depth_violation({"a": {"b": 1}}, 1) == "a"
    assert json_depth_violation({"a": [1, {"b": 2}]}, 2) == "a[1]"
    assert json_depth_violation([[[]]], 3) is None
    assert json_depth_violation([[[]]], 2) == "[0][0]"
    deep: object = 0
    for _ in range(5000):  # far beyond the recursion limit: iterative walk
        deep = [deep]
    assert json_depth_violation(deep, 32) is not None


def test_over_deep_body_is_refused_before_anything_is_stored(client: TestClient) -> None:
    ok = {**MAP_EXAMPLE, "map_id": "deep-32", "metadata": _nested(32)}  # body depth 32
    r = client.post("/v1/maps", json=ok)
    assert r.status_code == 201, r.text
    assert client.get("/v1/maps/deep-32").status_code == 200
    bad = {**MAP_EXAMPLE, "map_id": "deep-33", "metadata": _nested(33)}  # body depth 33
    body = _problem(client.post("/v1/maps", json=bad), 422, "validation-error")
    [err] = body["errors"]
    assert err["field"].startswith("metadata.k.k") and "32" in err["message"]
    _problem(client.get("/v1/maps/deep-33"), 404, "map-not-found")  # nothing stored
    # ~250 levels (the reviewer's case) too, and on PUT and localize as well.
    huge = {**MAP_EXAMPLE, "map_id": "deep-250", "metadata": _nested(250)}
    _problem(client.post("/v1/maps", json=huge), 422, "validation-error")
    _problem(client.get("/v1/maps/deep-250"), 404, "map-not-found")
    etag = client.get("/v1/maps/deep-32").headers["etag"]
    _problem(client.put("/v1/maps/deep-32", json={**bad, "map_id": "deep-32"},
                        headers={"If-Match": etag}), 422, "validation-error")
    assert client.get("/v1/maps/deep-32").json()["version"] == 1
    from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE

    frame = {**LOCALIZE_EXAMPLE, "frame_id": _nested(40)}
    body = _problem(client.post("/v1/maps/chess/localize", json=frame), 422, "validation-error")
    assert body["errors"][0]["field"].startswith("frame_id.k")


@pytest.mark.parametrize("method,path", [
    ("GET", "/v1/maps/%00"), ("PUT", "/v1/maps/%00"), ("DELETE", "/v1/maps/%00"),
    ("POST", "/v1/maps/%00/localize"), ("POST", "/v1/maps/%00/localize:batch"),
    ("GET", "/v1/maps/a%00b"), ("GET", "/v1/maps/-leading-dash"), ("GET", "/v1/maps/" + "x" * 129),
])
def test_path_map_id_outside_the_pattern_is_a_422(client: TestClient, method: str,
                                                  path: str) -> None:
    from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE

    body = {"frames": [LOCALIZE_EXAMPLE]} if path.endswith(":batch") else (
        LOCALIZE_EXAMPLE if path.endswith("localize") else MAP_EXAMPLE)
    r = client.request(method, path, json=None if method in ("GET", "DELETE") else body,
                       headers={"If-Match": '"x"'} if method == "PUT" else {})
    problem = _problem(r, 422, "validation-error")
    assert problem["errors"][0]["field"] == "path.map_id"


def test_weak_if_match_never_matches(client: TestClient) -> None:
    r = client.get("/v1/maps/chess")
    etag = r.headers["etag"]
    assert etag.startswith('"')
    body = _problem(client.put("/v1/maps/chess", json=r.json()["map"],
                               headers={"If-Match": f"W/{etag}"}), 412, "precondition-failed")
    assert body["errors"][0]["field"] == "header.if-match"
    assert client.get("/v1/maps/chess").json()["version"] == 1
    # a list holding the weak tag and the strong one matches through the strong one
    r2 = client.put("/v1/maps/chess", json=r.json()["map"],
                    headers={"If-Match": f'W/{etag}, {etag}'})
    assert r2.status_code == 200, r2.text


def test_default_map_cannot_be_deleted(client: TestClient) -> None:
    body = _problem(client.delete("/v1/maps/chess"), 409, "default-map")
    assert "QUADLOC_DEFAULT_MAP_ID" in body["detail"] and body["errors"][0]["field"] == \
        "path.map_id"
    assert client.get("/v1/maps/chess").status_code == 200
    assert client.get("/readyz").status_code == 200
    # another map is deletable
    assert client.post("/v1/maps", json=MAP_EXAMPLE).status_code == 201
    assert client.delete("/v1/maps/office-3").status_code == 204


def test_default_map_is_whatever_is_configured(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path, default_map_id="demo")) as c:
        assert c.post("/v1/maps", json={**MAP_EXAMPLE, "map_id": "chess"}).status_code == 201
        assert c.delete("/v1/maps/chess").status_code == 204
        _problem(c.delete("/v1/maps/demo"), 409, "default-map")


# ------------------------------------------------------------ review 6: map cache race


def test_map_cache_does_not_store_a_version_read_before_an_invalidation() -> None:
    """A reader resolves version 1, a concurrent write commits version 2 and invalidates, and
    only then the reader remembers its resolution: it must not be remembered."""
    from quadloc.maps.cache import CompiledMapCache

    clock = FakeClock()
    cache = CompiledMapCache(resolve_ttl_s=60.0, clock=clock)
    v1, v2 = ("m", 1, "h1"), ("m", 2, "h2")
    c1, c2 = ["compiled v1"], ["compiled v2"]  # stand-ins with a len() (object count)
    cache.put(v1, c1)  # type: ignore[arg-type]
    seen = cache.generation("m")  # the reader starts, reads version 1 from the database
    cache.invalidate("m")  # a concurrent PUT commits version 2
    cache.resolved_as("m", None, v1, seen)  # the racing reader still answers what it read...
    assert cache.resolution("m", None) is None  # ... but did not cache it over the write
    cache.put(v2, c2)  # type: ignore[arg-type]
    cache.resolved_as("m", None, v2, cache.generation("m"))
    assert cache.resolution("m", None) is c2  # normal caching still works
    cache.invalidate("other")  # another map's write does not evict this one
    assert cache.resolution("m", None) is c2
    clock.advance(59.9)
    assert cache.resolution("m", None) is c2
    clock.advance(0.2)
    assert cache.resolution("m", None) is None  # past the TTL: ask the database again
    assert cache.get(v1) is c1 and len(cache) == 2  # versions are immutable: still held


# ------------------------------------------------------------ review 6: PostgreSQL


@pytest.fixture
def pg_client():
    """A TestClient on a throw-away PostgreSQL schema (tests/support/postgres.py)."""
    from quadloc.maps.store import MapStore
    from quadloc.service.api.app import create_app
    from quadloc.service.settings import Settings
    from tests.support.postgres import pg_schema_url, pg_unavailable_reason

    reason = pg_unavailable_reason()
    if reason:
        pytest.skip(reason)
    with pg_schema_url("quadloc_api") as url:
        store = MapStore(url)
        try:
            with TestClient(create_app(Settings(api_keys=""), store=store),
                            raise_server_exceptions=False) as c:
                yield c
        finally:
            store.close()


@pytest.mark.postgres
def test_nul_characters_on_postgresql_are_4xx(pg_client: TestClient) -> None:
    from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE

    c = pg_client
    doc = c.get("/v1/maps/chess").json()["map"]
    for r in (c.get("/v1/maps/%00"), c.delete("/v1/maps/%00"),
              c.put("/v1/maps/%00", json=doc, headers={"If-Match": '"x"'}),
              c.post("/v1/maps/%00/localize", json=LOCALIZE_EXAMPLE)):
        assert _problem(r, 422, "validation-error")["errors"][0]["field"] == "path.map_id"
    # A NUL inside a name: refused (by the map model or by the DataError backstop), not stored.
    r = c.post("/v1/maps", json={**doc, "name": "a\u0000b", "map_id": "nul-0"})
    assert r.status_code == 422 and r.headers["content-type"].startswith(PROBLEM), r.text
    assert c.get("/v1/maps/nul-0").status_code == 404
    # (inside metadata it is JSON-escaped, stored and returned as sent)
    r = c.post("/v1/maps", json={**doc, "metadata": {"k": "a\u0000b"}, "map_id": "nul-1"})
    assert r.status_code == 201, r.text
    assert c.get("/v1/maps/nul-1").json()["map"]["metadata"] == {"k": "a\u0000b"}
    r = c.post("/v1/maps:import-chess?map_id=nul-q&name=a%00b", json=CHESS_IMPORT_EXAMPLE)
    assert 400 <= r.status_code < 500, r.text
    assert c.get("/readyz").status_code == 200  # the connection pool survived


def test_database_data_error_is_a_422_problem(client: TestClient,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """Backstop: a value the database refuses (psycopg.DataError, e.g. a NUL in text on
    PostgreSQL) is the request's fault: 422 problem, not 500."""
    from sqlalchemy.exc import DataError

    def refuse(*args, **kwargs):
        raise DataError("INSERT ...", {}, ValueError("PostgreSQL text fields cannot contain "
                                                     "NUL (0x00) bytes"))

    monkeypatch.setattr(client.app.state.services.store, "create", refuse)
    body = _problem(client.post("/v1/maps", json=MAP_EXAMPLE), 422, "validation-error")
    assert "NUL" in body["detail"]


def test_request_body_schemas_are_the_validating_models_schemas() -> None:
    """The published body schemas are generated from the pydantic models that validate the
    bodies (quadloc.maps.model.MapDocument / ChessDocument), not written by hand."""
    from quadloc.maps.model import CHESS_JSON_SCHEMA, MAP_JSON_SCHEMA
    from quadloc.service.api.app import openapi_document

    paths = openapi_document()["paths"]

    def body(path: str, method: str) -> dict:
        return paths[path][method]["requestBody"]["content"]["application/json"]["schema"]

    map_schema = {k: v for k, v in MAP_JSON_SCHEMA.items() if not k.startswith("$")}
    assert body("/v1/maps", "post") == map_schema == body("/v1/maps/{map_id}", "put")
    # FastAPI merges the declared dict body into it: unknown Chess fields are ignored, as stated
    assert body("/v1/maps:import-chess", "post") == {"additionalProperties": True,
                                                    **CHESS_JSON_SCHEMA}
