"""Hostile map writes and database states (issue 11), on SQLite and PostgreSQL.

Each case used to answer 500: lone surrogates in map strings (no UTF-8 encoding, so neither
hashable nor storable), containers inside ``categories`` or as Chess labels (unhashable), an
unmigrated database (``ProgrammingError`` on PostgreSQL). ``/readyz`` (no key needed) used to
echo the driver's error text (host, port, database, SQL).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from quadloc.maps.store import MapStore
from quadloc.service.api.app import create_app
from quadloc.service.schemas.examples import CHESS_IMPORT_EXAMPLE, MAP_EXAMPLE
from quadloc.service.settings import Settings
from tests.maps.test_maps_store import store_url  # noqa: F401 (fixture: sqlite + postgresql)

PROBLEM = "application/problem+json"


def _client(url: str, **settings: object) -> TestClient:
    store = MapStore(url, migrate=settings.pop("migrate", True))  # type: ignore[arg-type]
    app = create_app(Settings(api_keys="", **settings), store=store)  # type: ignore[arg-type]
    return TestClient(app, raise_server_exceptions=False)


@pytest.fixture
def client(store_url: str) -> Iterator[TestClient]:  # noqa: F811
    with _client(store_url) as c:
        yield c
        c.app.state.services.store.close()


def _post(c: TestClient, path: str, body: object):
    # json.dumps escapes a lone surrogate as "\ud800", which the server's JSON parser accepts
    return c.post(path, content=json.dumps(body), headers={"content-type": "application/json"})


def _refused(r, field_prefix: str) -> None:
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith(PROBLEM)
    fields = [e["field"] for e in r.json()["errors"]]
    assert any(f.startswith(field_prefix) for f in fields), fields


_OBJ = MAP_EXAMPLE["objects"][0]
_BAD_MAPS = {
    "surrogate in name": ({"name": "x\ud800"}, "name"),
    "surrogate in a category": ({"categories": ["a\udfff", *MAP_EXAMPLE["categories"]]},
                                "categories[0]"),
    "surrogate in an object id": ({"objects": [{**_OBJ, "object_id": "o\ud800"}]},
                                  "objects[0].object_id"),
    "surrogate in metadata": ({"metadata": {"note\ud800": "x"}}, "metadata"),
    "list inside categories": ({"categories": [["TV"], *MAP_EXAMPLE["categories"]]},
                               "categories[0]"),
    "dict inside categories": ({"categories": [{"TV": 1}, *MAP_EXAMPLE["categories"]]},
                               "categories[0]"),
}


@pytest.mark.parametrize("case", sorted(_BAD_MAPS))
def test_hostile_map_strings_and_categories_are_422_and_store_nothing(
        client: TestClient, case: str) -> None:
    change, field = _BAD_MAPS[case]
    body = {**MAP_EXAMPLE, "map_id": "hostile", **change}
    _refused(_post(client, "/v1/maps", body), field)
    assert client.get("/v1/maps/hostile").status_code == 404
    # the same body as an update of an existing map: refused, the map is unchanged
    current = client.get("/v1/maps/chess")
    r = client.put("/v1/maps/chess", content=json.dumps({**body, "map_id": "chess"}),
                   headers={"content-type": "application/json", "If-Match": current.headers[
                       "etag"]})
    _refused(r, field)
    assert client.get("/v1/maps/chess").headers["etag"] == current.headers["etag"]


@pytest.mark.parametrize("label", [["TV"], {"x": 1}, "TV\ud800"])
def test_hostile_chess_labels_are_422(client: TestClient, label: object) -> None:
    body = {**CHESS_IMPORT_EXAMPLE, "category_id_to_label": {
        **CHESS_IMPORT_EXAMPLE["category_id_to_label"],
        next(iter(CHESS_IMPORT_EXAMPLE["category_id_to_label"])): label}}
    r = _post(client, "/v1/maps:import-chess?map_id=hostile-chess", body)
    assert r.status_code == 422, r.text
    assert r.json()["errors"]
    assert client.get("/v1/maps/hostile-chess").status_code == 404


def test_readyz_names_the_check_without_driver_text(caplog: pytest.LogCaptureFixture) -> None:
    url = "postgresql://postgres@127.0.0.1:1/secretdb?connect_timeout=2"
    with _client(url, migrate=False, seed_demo_map=False) as c, caplog.at_level(logging.ERROR):
        r = c.get("/readyz")
        assert r.status_code == 503 and r.headers["content-type"].startswith(PROBLEM)
        body = r.json()
        assert body["detail"] == "database: unavailable"
        assert body["errors"] == [{"field": "database", "message": "unavailable"}]
        for secret in ("127.0.0.1", "secretdb", "Error", "connect"):
            assert secret not in r.text
        assert "secretdb" in caplog.text or "127.0.0.1" in caplog.text  # the operator's log
        r = c.get("/v1/maps")
        assert r.status_code == 503 and "127.0.0.1" not in r.text
        c.app.state.services.store.close()


def test_unmigrated_database_is_503_with_a_migrate_log_line(
        store_url: str, caplog: pytest.LogCaptureFixture) -> None:  # noqa: F811
    with _client(store_url, migrate=False, seed_demo_map=False) as c, \
            caplog.at_level(logging.ERROR, logger="quadloc.api"):
        for r in (c.get("/v1/maps"), c.get("/v1/maps/chess"), _post(c, "/v1/maps", MAP_EXAMPLE),
                  c.post("/v1/maps/chess/localize", json={"camera": {}, "detections": []})):
            if r.status_code == 422:  # the request itself was invalid: refused first
                continue
            assert r.status_code == 503, r.text
            assert r.json()["type"] == "urn:quadloc:problem:database-unavailable"
            assert r.headers["retry-after"]
        r = c.get("/readyz")
        assert r.status_code == 503 and r.json()["detail"] == "database: unavailable"
        assert "upgrade head" in caplog.text and "not migrated" in caplog.text
        c.app.state.services.store.migrate()  # the operator migrates: the same process recovers
        assert c.get("/v1/maps").status_code == 200
        c.app.state.services.store.close()


def test_readyz_names_a_missing_default_map(tmp_path: Path) -> None:
    """A missing default map is named as such (not as a database failure)."""
    with _client(f"sqlite:///{tmp_path / 'q.db'}", seed_demo_map=False) as c:
        r = c.get("/readyz")
        assert r.status_code == 503
        assert r.json()["errors"] == [{"field": "default_map", "message": "not found"}]
        c.app.state.services.store.close()


def test_store_reuses_parsed_versions_within_an_object_bound(
        store_url: str, monkeypatch: pytest.MonkeyPatch) -> None:  # noqa: F811
    """GET of an unchanged version does not re-parse it (a 10,000-object map costs seconds to
    parse); the cache holds at most ``max_objects`` objects (the newest map always)."""
    import quadloc.maps.store as store_module
    from quadloc.maps.cache import CompiledMapCache
    from quadloc.maps.model import scene_map_from_dict

    n = len(MAP_EXAMPLE["objects"])
    store = MapStore(store_url, cache=CompiledMapCache(max_objects=2 * n))
    try:
        for k in range(3):
            store.create(scene_map_from_dict({**MAP_EXAMPLE, "map_id": f"m{k}"}, version=1))
        a, b = store.get("m0"), store.get("m0")
        assert a.scene_map is b.scene_map and a.content_hash == b.content_hash
        parsed = []
        monkeypatch.setattr(store_module, "scene_map_from_dict",
                            lambda *args, **kw: parsed.append(1) or scene_map_from_dict(*args,
                                                                                        **kw))
        store.get("m1")
        store.get("m2")  # evicts m0 (3 maps > 2 maps' worth of objects)
        assert len(parsed) == 2 and len(store.cache) == 2
        store.get("m1")
        store.compiled("m2")
        assert len(parsed) == 2  # still cached
        store.get("m0")
        assert len(parsed) == 3  # parsed again after eviction
    finally:
        store.close()


def test_a_slow_map_load_answers_503_within_the_budget_then_serves(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The first use of a big map version takes seconds to parse: the localization waits at
    most the solve budget, answers 503 map-loading + Retry-After, and a retry after the load
    (which went on in the background, once for all waiting requests) is served."""
    import threading
    import time

    import quadloc.maps.store as store_module
    from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE

    with _client(f"sqlite:///{tmp_path / 'q.db'}", solve_time_budget_ms=300.0) as c:
        store = c.app.state.services.store
        real = store_module.scene_map_from_dict
        release = threading.Event()
        calls = []

        def slow_parse(*args, **kwargs):  # the expensive step of a first load
            calls.append(1)
            release.wait(10)
            return real(*args, **kwargs)

        monkeypatch.setattr(store_module, "scene_map_from_dict", slow_parse)
        store.cache.forget("chess")  # as on a replica that never loaded this version
        t0 = time.perf_counter()
        r = c.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE)
        waited = time.perf_counter() - t0
        assert r.status_code == 503 and r.headers["retry-after"], r.text
        assert r.json()["type"] == "urn:quadloc:problem:map-loading"
        assert 0.3 <= waited < 3.0, waited
        r2 = c.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE)  # joins the same load
        assert r2.status_code == 503 and len(calls) == 1
        release.set()
        for _ in range(50):
            r3 = c.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE)
            if r3.status_code == 200:
                break
            time.sleep(0.1)
        assert r3.status_code == 200 and r3.json()["localized"], r3.text
        assert len(calls) == 1  # parsed once: the retries hit the store's cache
        store.close()


def test_integral_floats_are_integers_and_the_schema_says_what_is_enforced(
        tmp_path: Path) -> None:
    """JSON Schema's ``integer`` includes 640.0: the server accepts it; 640.5 / "640" / true
    are refused naming the field. robust_scale without robust: the schema's if/then says it."""
    from quadloc.service.api.app import openapi_document
    from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE

    with _client(f"sqlite:///{tmp_path / 'q.db'}") as c:
        def frame(**camera_and_options):
            opts = camera_and_options.pop("options", {})
            return {**LOCALIZE_EXAMPLE, "camera": {**LOCALIZE_EXAMPLE["camera"],
                                                   **camera_and_options},
                    "options": {**LOCALIZE_EXAMPLE.get("options", {}), **opts}}

        ok = c.post("/v1/maps/chess/localize", json=frame(width=640.0, height=480.0,
                                                          options={"seed": 3.0,
                                                                   "max_iterations": 20.0}))
        assert ok.status_code == 200, ok.text
        for bad, field in ((frame(width=640.5), "camera.width"),
                           (frame(width="640"), "camera.width"),
                           (frame(width=True), "camera.width"),
                           (frame(options={"seed": 1.5}), "options.seed"),
                           (frame(options={"robust_scale": 2.0}), "options")):
            r = c.post("/v1/maps/chess/localize", json=bad)
            assert r.status_code == 422, (bad, r.text)
            assert any(e["field"].startswith(field) for e in r.json()["errors"]), r.text
        c.app.state.services.store.close()
    options = openapi_document()["components"]["schemas"]["LocalizeOptionsIn"]
    assert options["then"]["required"] == ["robust"]
    assert options["if"]["required"] == ["robust_scale"]
    put = openapi_document()["paths"]["/v1/maps/{map_id}"]["put"]
    assert any(p["name"] == "If-Match" and p["required"] for p in put["parameters"])


def test_map_loader_returns_when_the_load_finishes_before_it_is_tracked() -> None:
    """A load that completes before its done-callback is attached runs the callback in the
    caller's thread: it must not wait for the loader's own lock (it used to deadlock the
    request thread when a cache hit was fast)."""
    import threading
    from concurrent.futures import Future

    from quadloc.service.app.map_loader import MapLoader

    class Store:
        def compiled(self, map_id, version=None):
            return f"{map_id}@{version}"

    loader = MapLoader(Store(), max_wait_s=1.0)  # type: ignore[arg-type]

    def done_at_once(fn, *args):
        f: Future = Future()
        f.set_result(fn(*args))
        return f

    loader._pool.submit = done_at_once  # type: ignore[method-assign]
    out: list[str] = []
    t = threading.Thread(target=lambda: out.append(loader.get("m", 2)), daemon=True)
    t.start()
    t.join(5)
    assert out == ["m@2"], "MapLoader.get deadlocked"
    assert loader._pending == {}
    loader.close()
