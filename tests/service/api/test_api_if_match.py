"""``If-Match: *`` is ONE rule for ``PUT /v1/maps/{map_id}`` and ``POST /v1/maps:build``
(issue 32, item 11): RFC 9110 13.1.1, ``*`` matches when the map exists (the write replaces
its latest version) and fails with 412 when it does not; a missing header is still 428."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from tests.conftest import make_test_app
from tests.service.api.test_api_build import _recording
from tests.support.helpers import assert_problem, wait_for_job


@pytest.fixture
def client(tmp_path: Path):
    with TestClient(make_test_app(tmp_path)) as c:
        yield c


def test_put_with_star_updates_an_existing_map_and_412_on_a_missing_one(
        client: TestClient) -> None:
    r = client.get("/v1/maps/chess")
    etag, doc = r.headers["etag"], r.json()["map"]
    doc["objects"][0]["axes"] = [0.2, 0.4, 0.3]
    r = client.put("/v1/maps/chess", json=doc, headers={"If-Match": "*"})
    assert r.status_code == 200, r.text
    assert r.json()["version"] == 2 and r.headers["etag"] != etag
    assert client.get("/v1/maps/chess").json()["map"]["objects"][0]["axes"] == [0.2, 0.4, 0.3]
    # '*' among other tags matches too; a stale tag alone still does not
    r = client.put("/v1/maps/chess", json=doc, headers={"If-Match": f'{etag}, *'})
    assert r.status_code == 200 and r.json()["version"] == 3
    assert_problem(client.put("/v1/maps/chess", json=doc, headers={"If-Match": etag}),
                   412, "precondition-failed")
    # no current representation: '*' is false (412), nothing created
    body = assert_problem(client.put("/v1/maps/ghost", json={**doc, "map_id": "ghost"},
                                     headers={"If-Match": "*"}), 412, "precondition-failed")
    assert body["errors"][0]["field"] == "header.if-match"
    assert client.get("/v1/maps/ghost").status_code == 404
    # a missing header is still 428
    assert_problem(client.put("/v1/maps/chess", json=doc), 428, "precondition-required")


def test_build_with_star_builds_the_next_version_and_412_on_a_new_map(
        client: TestClient) -> None:
    rec, _ = _recording(8)
    body = assert_problem(client.post("/v1/maps:build", params={"map_id": "room"}, json=rec,
                                      headers={"If-Match": "*"}), 412, "precondition-failed")
    assert body["errors"][0]["field"] == "header.if-match"
    r = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec)
    assert r.status_code == 202, r.text
    assert wait_for_job(client, r.headers["Location"])["map_version"] == 1
    assert_problem(client.post("/v1/maps:build", params={"map_id": "room"}, json=rec),
                   428, "precondition-required")
    r = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec,
                    headers={"If-Match": "*"})
    assert r.status_code == 202, r.text
    assert r.json()["base_version"] == 1
    job = wait_for_job(client, r.headers["Location"])
    assert job["status"] == "succeeded" and job["map_version"] == 2, job
