"""Sessions and build jobs belong to the API key that created them (issue 32, item 10), with a
per-key session quota besides the global cap (item 4's quota part) and the idle clock counted
from the END of the last request (item 8).

Repros: a second read key could GET and DELETE another key's session; any read key read any
build job; one key could fill the global session cap; the session id carried the host name; a
frames request longer than the idle timeout answered 200 and the next frame 404.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from quadloc.maps.building.jobs import jobs_table
from quadloc.maps.compiled import compile_map
from quadloc.maps.demo import load_demo_map
from quadloc.service.app.conversions import camera_from_request
from quadloc.service.app.ownership import Caller
from quadloc.service.app.session_store import SessionNotFound, SessionStore, replica_id
from quadloc.service.schemas.examples import FRAME_EXAMPLE, SESSION_CREATE_EXAMPLE
from quadloc.service.schemas.localize import CameraIn
from quadloc.service.settings import ApiKey, hash_api_key
from quadloc.service.tracking.session import TrackingSession
from tests.conftest import make_test_app
from tests.service.api.conftest import ClientFactory
from tests.service.api.test_api_build import _recording
from tests.support.helpers import FakeClock, assert_problem, wait_for_job

KEYS = {"alice": "read", "bob": "read", "writer": "write", "writer2": "write", "ops": "admin"}
API_KEYS = " ".join(f"{hash_api_key(k)}:{scope}" for k, scope in KEYS.items())


def _as(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


def _session(client: TestClient, key: str) -> str:
    r = client.post("/v1/maps/chess/sessions", json=SESSION_CREATE_EXAMPLE, headers=_as(key))
    assert r.status_code == 201, r.text
    return str(r.json()["url"])


@pytest.fixture
def client(tmp_path: Path):
    with TestClient(make_test_app(tmp_path, api_keys=API_KEYS, max_sessions_per_key=2,
                                  max_sessions=5)) as c:
        yield c


def test_admin_scope_implies_write_and_read() -> None:
    admin = ApiKey("0" * 64, frozenset({"admin"}))
    write = ApiKey("1" * 64, frozenset({"write"}))
    assert admin.allows("read") and admin.allows("write") and admin.allows("admin")
    assert write.allows("read") and not write.allows("admin")
    assert Caller.of(admin).may_access("1" * 64) and not Caller.of(write).may_access("0" * 64)
    assert Caller.of(None).may_access(None)  # no keys: one caller, sees everything


def test_a_session_is_seen_only_by_its_key_and_admin(client: TestClient) -> None:
    url = _session(client, "alice")
    assert client.get(url, headers=_as("alice")).status_code == 200
    for key in ("bob", "writer"):  # another key, whatever its scope: as if it did not exist
        for r in (client.get(url, headers=_as(key)), client.delete(url, headers=_as(key)),
                  client.post(f"{url}/frames", json=FRAME_EXAMPLE, headers=_as(key))):
            body = assert_problem(r, 404, "session-not-found")
            assert body["errors"][0]["field"] == "path.session_id"
    r = client.get(url, headers=_as("alice"))  # untouched by those attempts
    assert r.status_code == 200 and r.json()["frames"] == 0
    assert client.post(f"{url}/frames", json=FRAME_EXAMPLE,
                       headers=_as("alice")).status_code == 200
    assert client.get(url, headers=_as("ops")).json()["frames"] == 1  # admin sees all
    assert client.delete(url, headers=_as("ops")).status_code == 204
    assert_problem(client.get(url, headers=_as("alice")), 404, "session-not-found")


def test_per_key_session_quota_besides_the_global_cap(client: TestClient) -> None:
    a1, _ = _session(client, "alice"), _session(client, "alice")
    r = client.post("/v1/maps/chess/sessions", json=SESSION_CREATE_EXAMPLE, headers=_as("alice"))
    body = assert_problem(r, 429, "session-quota")
    assert float(r.headers["Retry-After"]) > 0 and "2" in body["detail"]
    # the other keys are not locked out by alice
    _session(client, "bob")
    _session(client, "bob")
    # ending a session frees the key's quota
    assert client.delete(a1, headers=_as("alice")).status_code == 204
    _session(client, "alice")
    # the global cap (5) still applies across keys: 503 session-capacity
    _session(client, "writer")
    r = client.post("/v1/maps/chess/sessions", json=SESSION_CREATE_EXAMPLE,
                    headers=_as("writer"))
    assert_problem(r, 503, "session-capacity")


def test_session_ids_carry_a_replica_tag_not_the_host_name(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path)) as c:
        url = _session(c, "")
    tag = url.removeprefix("/v1/sessions/s-").split(".")[0]
    host = replica_id(socket.gethostname())
    assert tag == replica_id() and (tag != host or host.startswith("r"))
    with TestClient(make_test_app(tmp_path / "b", replica_id="quadloc-7")) as c:
        assert _session(c, "").startswith("/v1/sessions/s-quadloc-7.")


def test_the_idle_clock_runs_from_the_end_of_the_last_request() -> None:
    clock = FakeClock()
    store = SessionStore(max_sessions=2, idle_timeout_s=3.0, clock=clock)
    entry = store.create("chess", 1, _idle_session(), "opencv", owner="k")
    with store.use(entry.session_id, Caller("k")):
        clock.advance(12.6)  # a request longer than the idle timeout
        assert store.expire() == 0  # held: never idle
    clock.advance(2.9)
    assert store.get(entry.session_id, Caller("k")) is entry  # 2.9 s after the request ended
    clock.advance(3.1)
    with pytest.raises(SessionNotFound):
        store.get(entry.session_id, Caller("k"))


def _idle_session() -> TrackingSession:
    camera = camera_from_request(CameraIn.model_validate(SESSION_CREATE_EXAMPLE["camera"]))
    return TrackingSession(compile_map(load_demo_map()), camera)


def test_a_frames_request_longer_than_the_idle_timeout_keeps_its_session(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    original = TrackingSession.add_frame

    def slow_add_frame(self: TrackingSession, *args: Any, **kwargs: Any) -> Any:
        time.sleep(1.5)  # the request outlasts the 1 s idle timeout
        return original(self, *args, **kwargs)

    with TestClient(make_test_app(tmp_path, session_idle_timeout_s=1.0)) as c:
        url = _session(c, "")
        monkeypatch.setattr(TrackingSession, "add_frame", slow_add_frame)
        assert c.post(f"{url}/frames", json=FRAME_EXAMPLE).status_code == 200
        monkeypatch.setattr(TrackingSession, "add_frame", original)
        frame = {**FRAME_EXAMPLE, "timestamp": FRAME_EXAMPLE["timestamp"] + 1.0}
        r = c.post(f"{url}/frames", json=frame)  # used to be 404 session-not-found
        assert r.status_code == 200, r.text
        assert c.get(url).json()["frames"] == 2


def test_a_build_job_is_seen_only_by_its_key_and_admin(store_clients: ClientFactory) -> None:
    client = store_clients(api_keys=API_KEYS)
    rec, _ = _recording(8)
    r = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec,
                    headers=_as("writer"))
    assert r.status_code == 202, r.text
    location = r.headers["Location"]
    job = wait_for_job(client, location, _as("writer"))
    assert job["status"] == "succeeded", job
    for key in ("alice", "writer2"):
        body = assert_problem(client.get(location, headers=_as(key)), 404, "not-found")
        assert body["errors"][0]["field"] == "path.job_id"
    # the unknown id gets the same answer (ids of other keys cannot be probed)
    unknown = client.get("/v1/build-jobs/00000000-0000-0000-0000-000000000000",
                         headers=_as("writer2"))
    assert_problem(unknown, 404, "not-found")
    assert client.get(location, headers=_as("ops")).json() == job
    # a row without owner (started before owners were stored): only an admin key reads it
    with client.app.state.services.store.engine.begin() as conn:  # type: ignore[attr-defined]
        conn.execute(sa.update(jobs_table).where(jobs_table.c.job_id == job["job_id"])
                     .values(owner=None))
    assert_problem(client.get(location, headers=_as("writer")), 404, "not-found")
    assert client.get(location, headers=_as("ops")).status_code == 200
    # a second replica on the same database applies the same rule
    replica = store_clients(api_keys=API_KEYS, seed_demo_map=False)
    assert_problem(replica.get(location, headers=_as("writer")), 404, "not-found")
    assert replica.get(location, headers=_as("ops")).status_code == 200


def test_jobs_of_a_database_before_owners_upgrade_and_downgrade(tmp_path: Path) -> None:
    from alembic import command
    from alembic.config import Config

    from quadloc.maps.building.jobs import JobStore
    from quadloc.maps.store import MIGRATIONS_DIR, MapStore

    store = MapStore(f"sqlite:///{tmp_path / 'old.db'}", migrate=False)
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))

    def alembic(step: Any, revision: str) -> None:
        with store.engine.begin() as conn:
            cfg.attributes["connection"] = conn
            step(cfg, revision)

    alembic(command.upgrade, "0002_build_jobs")
    with store.engine.begin() as conn:  # a job of that schema (no owner column)
        conn.execute(sa.text(
            "INSERT INTO quadloc_build_jobs (job_id, map_id, status, stage, percent, "
            "objects_found, created_at, updated_at) VALUES ('j1', 'm', 'failed', 'failed', 0, "
            "0, '2026-01-01 00:00:00', '2026-01-01 00:00:00')"))
    store.migrate()
    job = JobStore(store.engine).get("j1")
    assert job.owner is None and job.status == "failed"
    assert JobStore(store.engine).create("m", None, "f" * 64).owner == "f" * 64
    alembic(command.downgrade, "0002_build_jobs")
    with store.engine.connect() as conn:
        columns = {c["name"] for c in sa.inspect(conn).get_columns("quadloc_build_jobs")}
        assert "owner" not in columns and "job_id" in columns
    store.close()
