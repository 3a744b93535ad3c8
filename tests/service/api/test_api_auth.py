"""API keys: hashed storage, scopes, both headers, refusals; loopback-only when open."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from quadloc.service.schemas.examples import MAP_EXAMPLE
from quadloc.service.settings import (
    Settings,
    check_bind_allowed,
    hash_api_key,
    is_loopback_host,
    parse_api_keys,
)
from tests.conftest import make_test_app

READ_KEY, WRITE_KEY, OTHER_KEY = "reader-key-123", "writer-key-456", "intruder-789"


def _sha(k: str) -> str:
    return hashlib.sha256(k.encode()).hexdigest()


@pytest.fixture
def client(tmp_path: Path):
    keys = f"{_sha(READ_KEY)}:read,{_sha(WRITE_KEY)}:read+write"
    with TestClient(make_test_app(tmp_path, api_keys=keys)) as c:
        yield c


def test_hash_matches_hashlib() -> None:
    assert hash_api_key("abc") == hashlib.sha256(b"abc").hexdigest()


def test_parse_compact_and_json_forms() -> None:
    compact = parse_api_keys(f"{_sha('a')}:read {_sha('b')}:write")
    as_json = parse_api_keys(json.dumps([{"sha256": _sha("a"), "scopes": ["read"]},
                                         {"sha256": _sha("b"), "scopes": ["write"],
                                          "name": "ci"}]))
    assert [(k.sha256, k.scopes) for k in compact] == [(k.sha256, k.scopes) for k in as_json]
    assert compact[1].allows("read") and compact[1].allows("write")
    assert compact[0].allows("read") and not compact[0].allows("write")
    for bad, word in [("nothex:read", "sha256"), (f"{_sha('a')}:root", "root"),
                      (f"{_sha('a')}", "expected"), ("[{]", "JSON")]:
        with pytest.raises(ValueError, match=word):
            parse_api_keys(bad)
    with pytest.raises(ValueError, match="api_keys"):
        Settings(api_keys="zz:read")


@pytest.mark.parametrize("host,loop", [("127.0.0.1", True), ("localhost", True), ("::1", True),
                                       ("127.8.0.1", True), ("0.0.0.0", False),
                                       ("192.168.1.4", False), ("example.com", False)])
def test_loopback_detection(host: str, loop: bool) -> None:
    assert is_loopback_host(host) is loop


def test_open_service_refuses_public_binds() -> None:
    open_settings = Settings(api_keys="")
    check_bind_allowed(open_settings, "127.0.0.1")
    with pytest.raises(ValueError, match="QUADLOC_API_KEYS"):
        check_bind_allowed(open_settings, "0.0.0.0")
    check_bind_allowed(Settings(api_keys=f"{_sha('k')}:read"), "0.0.0.0")


def _assert_problem(r, status: int) -> None:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    assert r.json()["status"] == status


def test_missing_and_wrong_keys_are_refused(client: TestClient) -> None:
    for path in ("/v1/maps", "/v1/maps/chess"):
        r = client.get(path)
        _assert_problem(r, 401)
        assert r.headers["www-authenticate"].startswith("Bearer")
        _assert_problem(client.get(path, headers={"Authorization": f"Bearer {OTHER_KEY}"}), 401)
        _assert_problem(client.get(path, headers={"X-API-Key": OTHER_KEY}), 401)
        _assert_problem(client.get(path, headers={"Authorization": f"Basic {READ_KEY}"}), 401)
    _assert_problem(client.post("/v1/maps/chess/localize", json={}), 401)
    _assert_problem(client.post("/v1/maps", json=MAP_EXAMPLE), 401)
    # Probes stay public (Kubernetes does not send keys).
    assert client.get("/healthz").status_code == 200
    assert client.get("/readyz").status_code == 200


def test_read_key_reads_but_cannot_write(client: TestClient) -> None:
    for headers in ({"Authorization": f"Bearer {READ_KEY}"}, {"X-API-Key": READ_KEY}):
        assert client.get("/v1/maps", headers=headers).status_code == 200
        r = client.get("/v1/maps/chess", headers=headers)
        assert r.status_code == 200
        etag, doc = r.headers["etag"], r.json()["map"]
        _assert_problem(client.post("/v1/maps", json=MAP_EXAMPLE, headers=headers), 403)
        _assert_problem(client.put("/v1/maps/chess", json=doc,
                                   headers={**headers, "If-Match": etag}), 403)
        _assert_problem(client.delete("/v1/maps/chess", headers=headers), 403)
        _assert_problem(client.post("/v1/maps:import-chess", params={"map_id": "x"}, json={},
                                    headers=headers), 403)
    # Localize is a read: the key passes auth (the empty body then fails validation).
    r = client.post("/v1/maps/chess/localize", json={}, headers={"X-API-Key": READ_KEY})
    _assert_problem(r, 422)


def test_write_key_writes(client: TestClient) -> None:
    headers = {"Authorization": f"Bearer {WRITE_KEY}"}
    assert client.post("/v1/maps", json=MAP_EXAMPLE, headers=headers).status_code == 201
    assert client.get("/v1/maps/office-3", headers=headers).status_code == 200
    assert client.delete("/v1/maps/office-3", headers=headers).status_code == 204


def test_no_keys_means_open(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path)) as c:
        assert c.get("/v1/maps").status_code == 200
        assert c.post("/v1/maps", json=MAP_EXAMPLE).status_code == 201


@pytest.mark.parametrize("host,status", [("127.0.0.1", 200), ("192.168.1.20", 403),
                                         ("[::1]", 200), ("10.0.0.7", 403)])
def test_open_server_answers_only_on_loopback(tmp_path: Path, host: str, status: int) -> None:
    """Even when started with `uvicorn --host 0.0.0.0` directly (bypassing `quadloc serve`),
    an open server refuses requests that arrive on a non-loopback address."""
    import asyncio

    import httpx

    app = make_test_app(tmp_path)

    async def get() -> httpx.Response:
        transport = httpx.ASGITransport(app=app)  # scope["server"] = the URL's host
        async with httpx.AsyncClient(transport=transport, base_url=f"http://{host}") as c:
            return await c.get("/v1/maps")

    r = asyncio.run(get())
    assert r.status_code == status, r.text
    if status == 403:
        assert "loopback" in r.json()["detail"]
    with_keys = make_test_app(tmp_path / "k", api_keys=f"{_sha(READ_KEY)}:read")

    async def get_with_key() -> httpx.Response:
        transport = httpx.ASGITransport(app=with_keys)
        async with httpx.AsyncClient(transport=transport, base_url=f"http://{host}") as c:
            return await c.get("/v1/maps", headers={"X-API-Key": READ_KEY})

    assert asyncio.run(get_with_key()).status_code == 200


def test_settings_come_from_quadloc_environment(monkeypatch: pytest.MonkeyPatch,
                                                tmp_path: Path) -> None:
    monkeypatch.setenv("QUADLOC_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("QUADLOC_MAX_BATCH_FRAMES", "5")
    monkeypatch.setenv("QUADLOC_SOLVE_TIME_BUDGET_MS", "250")
    monkeypatch.setenv("QUADLOC_API_KEYS", f"{_sha('k')}:read+write")
    monkeypatch.delenv("QUADLOC_DATABASE_URL", raising=False)
    s = Settings()
    assert s.max_batch_frames == 5 and s.solve_time_budget_ms == 250.0
    assert s.effective_database_url == f"sqlite:///{(tmp_path / 'quadloc.db').resolve()}"
    assert s.auth_enabled and s.keys[0].allows("write")
    monkeypatch.setenv("QUADLOC_DATABASE_URL", "postgresql://u@db/quadloc")
    assert Settings().effective_database_url == "postgresql://u@db/quadloc"
    monkeypatch.setenv("QUADLOC_MAX_BATCH_FRAMES", "zero")
    with pytest.raises(ValueError, match="max_batch_frames"):
        Settings()


@pytest.mark.parametrize("value", [",", "[]", " , ", "\n,\t"])
def test_api_keys_that_hold_no_key_are_refused_at_start(value: str,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="contains no key"):
        Settings(api_keys=value)
    monkeypatch.setenv("QUADLOC_API_KEYS", value)
    with pytest.raises(ValidationError, match="QUADLOC_API_KEYS"):
        Settings()


def test_auth_enabled_follows_the_parsed_keys() -> None:
    digest = hashlib.sha256(b"k").hexdigest()
    assert Settings(api_keys="").auth_enabled is False
    assert Settings(api_keys="   ").auth_enabled is False
    assert Settings(api_keys=f"{digest}:read").auth_enabled is True
    assert Settings(api_keys=json.dumps([{"sha256": digest, "scopes": ["read"]}])).auth_enabled
    # an open server still refuses public binds; a keyed one may bind them
    with pytest.raises(ValueError):
        check_bind_allowed(Settings(api_keys=""), "0.0.0.0")
    check_bind_allowed(Settings(api_keys=f"{digest}:read"), "0.0.0.0")


@pytest.mark.parametrize("field,ok,bad", [
    ("max_detections", 256, 257), ("max_batch_frames", 64, 65), ("max_json_depth", 64, 65),
    ("max_json_depth", 8, 7),
])
def test_settings_beyond_the_schema_caps_fail_at_start(field: str, ok: int, bad: int,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    from pydantic import ValidationError

    from quadloc.service.limits import MAX_BATCH_FRAMES, MAX_DETECTIONS

    assert (MAX_DETECTIONS, MAX_BATCH_FRAMES) == (256, 64)  # the caps of the request schema
    assert getattr(Settings(**{field: ok}), field) == ok
    with pytest.raises(ValidationError, match=field):
        Settings(**{field: bad})
    monkeypatch.setenv(f"QUADLOC_{field.upper()}", str(bad))
    with pytest.raises(ValidationError):
        Settings()
