"""Fuzzing and the hostile repros of issue 32 on the session and build routes, on SQLite and on
PostgreSQL (skipped with a message where PostgreSQL is absent): every request answers 200 /
202 or a documented 4xx naming its field or limit, never a 5xx, and a job always reads back."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from quadloc.service.schemas.sessions import MAX_SESSION_BATCH_FRAMES
from quadloc.service.tracking.session import MAX_WINDOW_FRAMES
from tests.service.api.test_api_fuzz import (
    _BACKENDS,
    _KEY,
    _backend_app,
    _detection,
    _gravity,
    _prior,
    _quaternion,
)
from tests.support.helpers import wait_for_job
from tests.support.hostile import HOSTILE_CAMERA, hostile_recording

pytestmark = pytest.mark.slow

HEADERS = {"X-API-Key": _KEY}
CAMERA = {"fx": HOSTILE_CAMERA.fx, "fy": HOSTILE_CAMERA.fy, "cx": HOSTILE_CAMERA.cx,
          "cy": HOSTILE_CAMERA.cy, "width": HOSTILE_CAMERA.width, "height": HOSTILE_CAMERA.height}
#: Every documented reason of a failed build job (service/app/builds.py).
JOB_FAILURES = {"time_budget_exceeded", "invalid_map", "no_objects", "version_conflict",
                "map_exists", "map_not_found", "store_unavailable", "busy", "runner_lost"}


@pytest.fixture(scope="module", params=_BACKENDS)
def client(request: pytest.FixtureRequest,
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    for app in _backend_app(request.param, tmp_path_factory):
        with TestClient(app) as c:
            yield c


_session_frame = st.fixed_dictionaries(
    {"detections": st.lists(_detection, max_size=12),
     "odom_from_camera": st.fixed_dictionaries(
         {"quaternion_wxyz": _quaternion,
          "translation_m": st.lists(st.floats(-50, 50), min_size=3, max_size=3)})},
    optional={"prior": _prior, "gravity": _gravity,
              "frame_id": st.text(max_size=8)})
_options = st.fixed_dictionaries({}, optional={
    "smoother": st.sampled_from(["isam2", "batch"]),
    "window_frames": st.integers(2, 300), "inlier_iou": st.floats(1e-6, 1.0)})


@settings(max_examples=20, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(options=_options, frames=st.lists(_session_frame, min_size=1, max_size=12),
       one_by_one=st.booleans())
def test_wild_session_frames_never_fail_the_server(client: TestClient, options: dict,
                                                   frames: list[dict], one_by_one: bool
                                                   ) -> None:
    r = client.post("/v1/maps/chess/sessions", json={"camera": CAMERA, "options": options},
                    headers=HEADERS)
    if r.status_code == 422:  # the only refusal: a window beyond the smoother's limit
        assert options.get("window_frames", 30) > MAX_WINDOW_FRAMES[
            options.get("smoother", "isam2")]
        assert r.json()["errors"][0]["field"] == "options.window_frames"
        return
    assert r.status_code == 201, r.text
    url = f"/v1/sessions/{r.json()['session_id']}/frames"
    frames = [{**f, "timestamp": float(i)} for i, f in enumerate(frames)]
    bodies = frames if one_by_one else [{"frames": frames}]
    for body in bodies:
        r = client.post(url, json=body, headers=HEADERS)
        assert r.status_code in (200, 422), r.text
        if r.status_code == 422:
            assert r.json()["errors"][0]["field"]
            continue
        for res in r.json()["results"]:
            if res["world_from_camera"] is not None:
                assert res["state"] == "tracking"
                assert np.all(np.isfinite(res["world_from_camera"]["matrix"]))
            else:
                assert res["reason"]
    client.delete(url.removesuffix("/frames"), headers=HEADERS)


def test_build_repros_answer_a_documented_4xx_or_succeed(client: TestClient) -> None:
    # within the limits: 202, and the job ends with a map or a documented failure, readable
    doc = hostile_recording(60, 10, 9, layout="ring")
    r = client.post("/v1/maps:build", params={"map_id": "hostile-small"}, json=doc,
                    headers=HEADERS)
    assert r.status_code == 202, r.text
    job = wait_for_job(client, r.headers["location"], HEADERS)
    assert job["status"] == "succeeded" or job["error"]["reason"] in JOB_FAILURES, job
    # the limits in force where this app's builds run (in-process on SQLite, the job queue on
    # PostgreSQL: Settings.build_limits_for)
    limits = client.app.state.services.builds.limits
    # over the frame limit: 422 naming the field, no job
    r = client.post("/v1/maps:build", params={"map_id": "hostile-frames"},
                    json=hostile_recording(limits.max_frames + 1, 1, 1), headers=HEADERS)
    assert r.status_code == 422, r.text
    assert any(e["field"] == "frames" for e in r.json()["errors"])
    # over the detections-per-frame limit
    over = hostile_recording(2, 257, 257)
    r = client.post("/v1/maps:build", params={"map_id": "hostile-dets"}, json=over,
                    headers=HEADERS)
    assert r.status_code == 422, r.text
    assert any(e["field"].startswith("frames[0].detections") for e in r.json()["errors"])
    # over the body limit (checked before the body is parsed): 413 naming it
    big = b" " * (limits.max_body_bytes + 1)
    r = client.post("/v1/maps:build", params={"map_id": "hostile-big"}, content=big,
                    headers={**HEADERS, "content-type": "application/json"})
    assert r.status_code == 413, r.text
    assert "body" in r.text


def test_session_repros_answer_a_documented_4xx_or_succeed(client: TestClient) -> None:
    r = client.post("/v1/maps/chess/sessions", json={"camera": CAMERA, "options": {
        "smoother": "batch", "window_frames": MAX_WINDOW_FRAMES["batch"] + 1}}, headers=HEADERS)
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "options.window_frames"
    r = client.post("/v1/maps/chess/sessions", json={"camera": CAMERA}, headers=HEADERS)
    url = f"/v1/sessions/{r.json()['session_id']}/frames"
    det = {"label": "TV", "ellipse": {"cx": 300.0, "cy": 200.0, "a": 40.0, "b": 30.0,
                                      "angle": 0.0}}
    frame = {"detections": [det] * 257, "odom_from_camera": {"matrix": np.eye(4).tolist()},
             "timestamp": 0.0}
    r = client.post(url, json=frame, headers=HEADERS)
    assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("detections")
    too_many = [{**frame, "detections": [det]}] * (MAX_SESSION_BATCH_FRAMES + 1)
    r = client.post(url, json={"frames": too_many}, headers=HEADERS)
    assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("frames")
    # the session is unchanged by the refusals
    assert client.get(url.removesuffix("/frames"), headers=HEADERS).json()["frames"] == 0
