"""Session work and memory bounded (issue 32, items 2 and 4): a CPU-time budget per frame and
per request, deterministic initialization, the smoothers' window limits, the buffer of an
initializing session bounded in detections."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from fastapi.testclient import TestClient

from quadloc.factors.budget import Deadline
from quadloc.factors.conics import Ellipse
from quadloc.service.localization.types import Detection
from quadloc.service.tracking.session import (
    MAX_BUFFERED_DETECTIONS,
    MAX_WINDOW_FRAMES,
    MIN_PROPOSAL_ROUNDS,
    TIME_BUDGET_EXCEEDED,
    SessionOptions,
    TrackingInputError,
    TrackingSession,
)
from tests.conftest import make_test_app
from tests.support.errors import pose_errors
from tests.support.walks import ChessWalk, chess_walk, frame_json

#: A deadline that has passed (a budget of -1 s of wall time).
PASSED = Deadline.wall_budget(-1.0)


@pytest.fixture(scope="module")
def walk() -> ChessWalk:
    return chess_walk(60, seed=32)


def _run(walk: ChessWalk, deadlines: dict[int, Deadline] | None = None) -> list:
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    return [s.add_frame(f, (deadlines or {}).get(i)) for i, f in enumerate(walk.frames)]


def test_the_same_frames_give_the_same_answers_however_slow_the_machine(walk: ChessWalk) -> None:
    """No wall clock in initialization: two runs are identical, bit for bit, and the first
    fix is where it was without any budget."""
    a, b = _run(walk), _run(walk)
    first = next(r.frame_index for r in a if r.state == "tracking")
    assert first < 30
    for ra, rb in zip(a, b, strict=True):
        assert ra.state == rb.state and ra.reason == rb.reason
        if ra.world_from_camera is not None:
            assert np.array_equal(ra.world_from_camera, rb.world_from_camera)
    err = pose_errors(a[-1].world_from_camera, walk.poses[-1])
    assert err[0] < 0.1


def test_a_frame_past_its_deadline_is_counted_not_fused_and_the_session_goes_on(
        walk: ChessWalk) -> None:
    base = _run(walk)
    first = next(r.frame_index for r in base if r.state == "tracking")
    # one tracking frame and one initialization attempt past their deadline
    late = {first + 5: PASSED, 0: PASSED}
    res = _run(walk, late)
    for i in late:
        r = res[i]
        assert r.reason == TIME_BUDGET_EXCEEDED and r.world_from_camera is None
        assert r.confidence == 0.0 and r.frame_index == i
    assert res[first + 5].state == "tracking"
    # the next frames chain their odometry from the last fused frame: still tracking, close
    r = res[first + 6]
    assert r.state == "tracking" and r.world_from_camera is not None
    assert pose_errors(r.world_from_camera, walk.poses[first + 6])[0] < 0.1


def test_an_initialization_past_its_deadline_gives_up_without_a_pose(walk: ChessWalk) -> None:
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions(init_interval_frames=1))
    for f in walk.frames[:12]:
        r = s.add_frame(f, PASSED)
        assert r.reason == TIME_BUDGET_EXCEEDED and s.state == "initializing"
    # with time, the same buffer initializes (after MIN_PROPOSAL_ROUNDS rounds, one a frame)
    for f in walk.frames[12:12 + MIN_PROPOSAL_ROUNDS]:
        r = s.add_frame(f)
    assert s.state == "tracking" and r.world_from_camera is not None


def test_window_limits_per_smoother_are_refused_naming_the_field() -> None:
    SessionOptions(window_frames=MAX_WINDOW_FRAMES["isam2"])
    SessionOptions(smoother="batch", window_frames=MAX_WINDOW_FRAMES["batch"])
    with pytest.raises(TrackingInputError) as exc:
        SessionOptions(smoother="batch", window_frames=MAX_WINDOW_FRAMES["batch"] + 1)
    assert exc.value.field == "options.window_frames"


def test_an_initializing_session_buffers_a_bounded_number_of_detections(walk: ChessWalk) -> None:
    """256 detections per frame (none of them a map label's object, so the session never
    initializes): the buffer keeps at most MAX_BUFFERED_DETECTIONS, whatever the frame count."""
    det = Detection(Ellipse(320.0, 240.0, 30.0, 20.0, 0.1), "no-such-label")
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    for i in range(40):
        s.add_frame(dataclasses.replace(walk.frames[0], detections=[det] * 256,
                                        timestamp=float(i)))
        held = sum(len(b.detections) for b in s._buffer)
        assert held <= max(MAX_BUFFERED_DETECTIONS, 256)
    assert len(s._buffer) == MAX_BUFFERED_DETECTIONS // 256
    assert s.frame_count == 40


def _session(c: TestClient, walk: ChessWalk, **options: object) -> str:
    cam = walk.camera
    r = c.post("/v1/maps/chess/sessions", json={"camera": {
        "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "width": cam.width,
        "height": cam.height}, "options": options})
    assert r.status_code == 201, r.text
    return str(r.json()["session_id"])


def test_api_a_batch_and_the_same_frames_one_by_one_agree(tmp_path, walk: ChessWalk) -> None:
    """Tolerance: identical (the same code path and seed; 1e-9 m / rad on the poses)."""
    frames = [frame_json(f) for f in walk.frames[:40]]
    with TestClient(make_test_app(tmp_path)) as c:
        sid = _session(c, walk)
        batch = c.post(f"/v1/sessions/{sid}/frames", json={"frames": frames}).json()["results"]
        sid2 = _session(c, walk)
        single = [c.post(f"/v1/sessions/{sid2}/frames", json=f).json()["results"][0]
                  for f in frames]
    assert any(r["state"] == "tracking" for r in batch)
    for a, b in zip(batch, single, strict=True):
        assert (a["state"], a["reason"]) == (b["state"], b["reason"])
        if a["world_from_camera"] is not None:
            np.testing.assert_allclose(a["world_from_camera"]["matrix"],
                                       b["world_from_camera"]["matrix"], atol=1e-9)


def test_api_a_request_past_its_budget_answers_its_remaining_frames_without_work(
        tmp_path, walk: ChessWalk) -> None:
    frames = [frame_json(f) for f in walk.frames[:30]]
    with TestClient(make_test_app(tmp_path, session_request_budget_ms=1e-3)) as c:
        sid = _session(c, walk)
        r = c.post(f"/v1/sessions/{sid}/frames", json={"frames": frames})
        assert r.status_code == 200, r.text
        res = r.json()["results"]
        assert len(res) == 30 and all(x["reason"] == TIME_BUDGET_EXCEEDED for x in res)
        assert [x["frame_index"] for x in res] == list(range(30))
        # the session counted them and goes on
        assert c.get(f"/v1/sessions/{sid}").json()["frames"] == 30
        bad = c.post("/v1/maps/chess/sessions", json={"camera": {
            "fx": 500, "fy": 500, "cx": 320, "cy": 240, "width": 640, "height": 480},
            "options": {"smoother": "batch", "window_frames": MAX_WINDOW_FRAMES["batch"] + 1}})
        assert bad.status_code == 422
        assert any(e["field"] == "options.window_frames" for e in bad.json()["errors"])
