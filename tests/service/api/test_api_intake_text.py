"""Text a client sends that is stored or echoed (issue 32, items 5 and 9), on both stores.

* A lone surrogate or a control character in a recording's ``frame_id``, ``track_id``,
  ``label``, ``name`` or ``size_priors`` key is refused up front (422 naming the field, no job,
  nothing stored); it used to give 202, then a job failing at 95 % (``invalid_map``) or a job
  whose every read was a 500.
* Job rows stored before that check (lone surrogates escaped in their JSON) are still read:
  200, the surrogates as U+FFFD.
* Labels and frame ids of localize and session frames follow the same rule (422 naming the
  field); a label with a character XML forbids that the rule lets through (U+FFFE) still gives
  a well-formed SVG, served with ``Content-Security-Policy`` and ``nosniff``.
"""

from __future__ import annotations

import copy
import json
import xml.etree.ElementTree as ET
from typing import Any

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from quadloc.factors.names import text_problem
from quadloc.maps.building.jobs import jobs_table
from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE, SESSION_CREATE_EXAMPLE
from tests.service.api.conftest import ClientFactory
from tests.service.api.test_api_build import _recording
from tests.support.helpers import assert_problem, wait_for_job

#: Text the intake refuses: a lone surrogate of each half, C0 controls (NUL, U+0001, newline).
BAD_TEXT = ["\ud800", "a\udc00b", "\u0000", "x\u0001", "two\nlines"]


def _post_json(client: TestClient, url: str, body: Any, **kwargs: Any) -> Any:
    """POST ``body`` serialised by ``json.dumps`` (which writes a lone surrogate as the escape
    ``\\ud800``, as a hostile client would; httpx's encoder refuses it)."""
    return client.post(url, content=json.dumps(body),
                       headers={"content-type": "application/json",
                                **kwargs.pop("headers", {})}, **kwargs)


def _hostile_recordings() -> list[tuple[str, dict[str, Any]]]:
    """(field, recording) pairs: each recording with one hostile text at ``field``."""
    cases = []
    for bad in BAD_TEXT:
        for field in ("frames[0].frame_id", "frames[1].detections[0].track_id",
                      "frames[2].detections[1].label", "name", "size_priors"):
            rec, _ = _recording(6)
            if field == "frames[0].frame_id":
                rec["frames"][0]["frame_id"] = bad
            elif field == "frames[1].detections[0].track_id":
                rec["frames"][1]["detections"][0]["track_id"] = bad
            elif field == "frames[2].detections[1].label":
                rec["frames"][2]["detections"][1]["label"] = bad
            elif field == "name":
                rec["name"] = bad
            else:
                rec["size_priors"] = {bad: {"semi_axis_m": 0.1, "log_sigma": 0.5}}
            cases.append((field, rec))
    return cases


def test_blank_labels_and_names_of_a_recording_are_refused_up_front(
        store_clients: ClientFactory) -> None:
    client = store_clients()
    rec, _ = _recording(6)
    rec["frames"][3]["detections"][2]["label"] = "   "
    rec["name"] = " "
    body = assert_problem(client.post("/v1/maps:build", params={"map_id": "blank"}, json=rec),
                          422, "validation-error")
    assert {"frames[3].detections[2].label", "name"} <= {e["field"] for e in body["errors"]}


def test_the_text_rule_itself() -> None:
    for bad in BAD_TEXT:
        assert text_problem(bad) is not None, repr(bad)
    for good in ("Box", "chaise longue", "冷蔵庫", "\U0001f4e6 parcel", "\ufffe", "tab-free"):
        assert text_problem(good) is None, repr(good)


def test_recordings_with_hostile_text_are_refused_up_front(
        store_clients: ClientFactory) -> None:
    client = store_clients()
    for i, (field, rec) in enumerate(_hostile_recordings()):
        map_id = f"hostile-{i}"
        r = _post_json(client, "/v1/maps:build", rec, params={"map_id": map_id})
        body = assert_problem(r, 422, "validation-error")
        # (a refused size_priors label is named by its key: size_priors.<key>.[key])
        assert any(e["field"] == field or e["field"].startswith(f"{field}.")
                   for e in body["errors"]), (field, body)
        assert client.get(f"/v1/maps/{map_id}").status_code == 404
    # the same connection still answers (nothing was reset)
    assert client.get("/healthz").status_code == 200


def test_a_job_row_stored_with_lone_surrogates_is_still_read(
        store_clients: ClientFactory) -> None:
    client = store_clients()
    rec, _ = _recording(8)
    r = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec)
    assert r.status_code == 202, r.text
    job = wait_for_job(client, r.headers["Location"])
    assert job["status"] == "succeeded", job
    # as a row written before the intake check: lone surrogates escaped in the stored JSON
    report = json.dumps(job["report"]).replace('"f0"', '"f\\ud800"')
    assert "\\ud800" in report
    error = json.dumps({"reason": "invalid_map", "detail": "label '\ud800' at 95 %"})
    jobs = client.app.state.services.builds.jobs  # type: ignore[attr-defined]
    with jobs.engine.begin() as conn:
        conn.execute(sa.update(jobs_table).where(jobs_table.c.job_id == job["job_id"])
                     .values(report=report, error=error))
    for _ in range(2):  # and the keep-alive connection is not reset after it
        r = client.get(f"/v1/build-jobs/{job['job_id']}")
        assert r.status_code == 200, r.text
        got = r.json()
        assert got["error"] == {"reason": "invalid_map", "detail": "label '\ufffd' at 95 %"}
        frame_ids = {d["frame_id"] for o in got["report"]["objects"] for d in o["detections"]}
        assert "f\ufffd" in frame_ids and "f0" not in frame_ids
    # a row whose report this version cannot read at all is served without it
    with jobs.engine.begin() as conn:
        conn.execute(sa.update(jobs_table).where(jobs_table.c.job_id == job["job_id"])
                     .values(report='{"objects": 3}', error="not json"))
    got = client.get(f"/v1/build-jobs/{job['job_id']}").json()
    assert got["report"] is None and got["error"]["reason"] == "internal_error"


@pytest.mark.parametrize("bad", BAD_TEXT)
def test_localize_and_session_text_fields_are_checked(client: TestClient, bad: str) -> None:
    body = copy.deepcopy(LOCALIZE_EXAMPLE)
    body["frame_id"] = bad
    r = _post_json(client, "/v1/maps/chess/localize", body)
    assert assert_problem(r, 422, "validation-error")["errors"][0]["field"] == "frame_id"
    body = copy.deepcopy(LOCALIZE_EXAMPLE)
    body["detections"][1]["label"] = bad
    r = _post_json(client, "/v1/maps/chess/localize", body)
    fields = {e["field"] for e in assert_problem(r, 422, "validation-error")["errors"]}
    assert "detections[1].label" in fields
    r = _post_json(client, "/v1/maps/chess/localize:batch", {"frames": [body]})
    fields = {e["field"] for e in assert_problem(r, 422, "validation-error")["errors"]}
    assert "frames[0].detections[1].label" in fields
    r = client.post("/v1/maps/chess/sessions", json=SESSION_CREATE_EXAMPLE)
    assert r.status_code == 201, r.text
    url = r.json()["url"]
    frame = {"detections": LOCALIZE_EXAMPLE["detections"], "timestamp": 0.0,
             "odom_from_camera": {"quaternion_wxyz": [1, 0, 0, 0], "translation_m": [0, 0, 0]},
             "frame_id": bad}
    r = _post_json(client, f"{url}/frames", {"frames": [frame]})
    fields = {e["field"] for e in assert_problem(r, 422, "validation-error")["errors"]}
    assert "frames[0].frame_id" in fields
    assert client.get(url).json()["frames"] == 0  # nothing fused


@pytest.fixture
def client(store_clients: ClientFactory) -> TestClient:
    return store_clients()


def test_svg_is_well_formed_and_served_with_security_headers(client: TestClient) -> None:
    doc = client.get("/v1/maps/chess").json()["map"]
    category = doc["objects"][0]["category"]
    # a map whose labels hold characters XML forbids but the text rule allows (U+FFFE, U+FFFF)
    odd = f"{category}\ufffe\uffff"
    for o in doc["objects"]:
        if o["category"] == category:
            o["category"] = odd
    doc["categories"] = [odd if c == category else c for c in doc["categories"]]
    r = client.post("/v1/maps", json={**doc, "map_id": "odd"})
    assert r.status_code == 201, r.text
    body = copy.deepcopy(LOCALIZE_EXAMPLE)
    for d in body["detections"]:
        if d["label"] == category:
            d["label"] = odd
    body["frame_id"] = "frame \ufffe"
    r = client.post("/v1/maps/odd/localize", json=body, headers={"Accept": "image/svg+xml"})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("image/svg+xml")
    assert r.headers["x-content-type-options"] == "nosniff"
    csp = r.headers["content-security-policy"]
    assert "default-src 'none'" in csp and "script-src" not in csp
    root = ET.fromstring(r.content)  # well-formed, or this raises
    texts = "".join(root.itertext())
    assert "\ufffe" not in texts and "\ufffd" in texts
    # the JSON answer inside still holds the exact label (JSON-escaped, then parsed)
    meta = next(e for e in root.iter() if e.get("id") == "quadloc-result")
    assert json.loads(meta.text or "")["frame_id"] == "frame \ufffe"
    page = client.get("/inspector")
    assert "frame-ancestors 'none'" in page.headers["content-security-policy"]
    assert page.headers["x-content-type-options"] == "nosniff"
