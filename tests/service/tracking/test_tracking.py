"""Tracking sessions: geometry checks against numerical/closed forms, the session on a short
simulated walk, input errors, the store's bounds, memory flatness, the API and the proxy routing
rule."""

from __future__ import annotations

import dataclasses
import gc
import math
import re
import sys
from pathlib import Path

import gtsam
import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy.stats import chi

from quadloc.factors.names import FieldError
from quadloc.factors.pose_residuals import expmap_pose3
from quadloc.factors.rotations import invert_pose
from quadloc.service.app.errors import field_and_problem
from quadloc.service.app.session_store import SessionCapacityError, SessionNotFound, SessionStore
from quadloc.service.localization.gravity import tilt_errors_deg
from quadloc.service.localization.types import Gravity
from quadloc.service.tracking.association import centre_jacobians
from quadloc.service.tracking.confidence import (
    LONE_UNEXPLAINED_LIKELIHOOD_RATIO,
    session_confidence,
)
from quadloc.service.tracking.session import (
    FrameInput,
    SessionOptions,
    TrackingInputError,
    TrackingSession,
    pose_adjoint,
)
from tests.conftest import make_test_app
from tests.support.errors import pose_errors as pose_error
from tests.support.simulate import simulate_gravity
from tests.support.walks import ChessWalk, chess_walk, frame_json

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def walk() -> ChessWalk:
    """120 Chess frames; frames 30-89 keep at most 2 detections (a sparse stretch)."""
    return chess_walk(120, seed=7, keep=lambda i, dets: dets[:2] if 30 <= i < 90 else dets)


def test_centre_jacobian_matches_central_differences(walk: ChessWalk) -> None:
    cam, T = walk.camera, walk.poses[10]
    pts = walk.compiled.centers
    _, J = centre_jacobians(cam, T, pts)
    h = 1e-6
    for k in range(6):
        xi = np.zeros(6)
        xi[k] = h
        up, _ = centre_jacobians(cam, T @ expmap_pose3(xi), pts)
        um, _ = centre_jacobians(cam, T @ expmap_pose3(-xi), pts)
        np.testing.assert_allclose(J[:, :, k], (up - um) / (2 * h), rtol=1e-4, atol=1e-3)


def test_pose_adjoint_moves_a_perturbation_across_a_composition() -> None:
    rng = np.random.default_rng(0)
    A = expmap_pose3(rng.normal(size=6))
    B = expmap_pose3(rng.normal(size=6))
    xi = rng.normal(size=6) * 0.1
    # A Exp(xi) B == A B Exp(Ad_{B^-1} xi)  (the world_from_odom covariance uses this)
    lhs = A @ expmap_pose3(xi) @ B
    rhs = A @ B @ expmap_pose3(pose_adjoint(invert_pose(B)) @ xi)
    np.testing.assert_allclose(lhs, rhs, atol=1e-9)


def test_confidence_matches_the_closed_form_for_isotropic_covariances() -> None:
    for s_rot, s_pos in [(math.radians(2), 0.04), (math.radians(3), 0.08), (0.01, 0.2)]:
        cov = np.diag([s_rot ** 2] * 3 + [s_pos ** 2] * 3)
        exact = chi.cdf(math.radians(5) / s_rot, 3) * chi.cdf(0.1 / s_pos, 3)
        assert session_confidence("tracking", cov) == pytest.approx(exact, abs=1e-9)
    assert session_confidence("lost", np.eye(6) * 1e-6) == 0.0
    assert session_confidence("tracking", None) == 0.0


def test_a_lone_unexplained_detection_weighs_by_bayes_rule_two_zero_the_confidence() -> None:
    """On a frame whose usable detections are all unexplained at the pose: one of them is
    weak evidence (posterior odds = prior odds x LONE_UNEXPLAINED_LIKELIHOOD_RATIO), two or
    more zero the confidence (before, one did too: on building walks 96 % of such frames were
    within tolerance)."""
    lam = LONE_UNEXPLAINED_LIKELIHOOD_RATIO
    for s_rot, s_pos, place in [(math.radians(2), 0.04, 1.0), (math.radians(1), 0.02, 0.9),
                                (0.01, 0.2, 0.7)]:
        cov = np.diag([s_rot ** 2] * 3 + [s_pos ** 2] * 3)
        prior = chi.cdf(math.radians(5) / s_rot, 3) * chi.cdf(0.1 / s_pos, 3) * place
        odds = prior / (1.0 - prior) * lam
        assert session_confidence("tracking", cov, 1, place) == pytest.approx(
            odds / (1.0 + odds), abs=1e-9)
        assert session_confidence("tracking", cov, 1, place) < prior
        assert session_confidence("tracking", cov, 2, place) == 0.0
        assert session_confidence("tracking", cov, 0, place) == pytest.approx(prior, abs=1e-9)


def test_session_initializes_and_tracks_through_a_sparse_stretch(walk: ChessWalk) -> None:
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    results = [s.add_frame(f) for f in walk.frames]
    first = next(r.frame_index for r in results if r.state == "tracking")
    assert first < 30
    sparse = [r for r in results[30:90] if r.state == "tracking"]
    assert len(sparse) >= 50
    errs = [pose_error(r.world_from_camera, walk.poses[r.frame_index]) for r in sparse]
    assert np.mean([e[0] <= 0.10 and e[1] <= 5 for e in errs]) >= 0.8
    r = results[-1]
    # world_from_odom maps this frame's odometry pose onto its world pose
    np.testing.assert_allclose(r.world_from_odom @ walk.frames[-1].odom_from_camera,
                               r.world_from_camera, atol=1e-9)
    assert r.covariance.shape == (6, 6) and 0.0 <= r.confidence <= 1.0
    # the window is bounded
    assert len(s._smoother.timestamps()) <= SessionOptions().window_frames


class _MovedEstimate:
    """A smoother whose estimates are moved by ``shift`` (4x4, right-multiplied): what an
    iSAM2 re-linearisation of earlier frames' factors does to a frame that brings nothing but
    odometry (seen on the building walks: 2 cm / 0.6 deg, beyond JUMP_CHI2 under the
    covariance a lone detection had just tightened)."""

    def __init__(self, inner: object, shift: np.ndarray) -> None:
        self.inner, self.shift = inner, shift

    def __getattr__(self, name: str) -> object:
        return getattr(self.inner, name)

    def calculateEstimatePose3(self, key: int) -> gtsam.Pose3:  # GTSAM's name
        return gtsam.Pose3(self.inner.calculateEstimatePose3(key).matrix() @ self.shift)


def test_an_estimate_moved_without_new_detections_restarts_at_the_prediction(
        walk: ChessWalk) -> None:
    """A tracking frame without detections whose smoother estimate left the odometry
    prediction beyond JUMP_CHI2 keeps tracking at the prediction (the smoother restarts there);
    with a detection-free frame the estimate has no new evidence to jump on."""
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    k = 100
    last = None
    for f in walk.frames[:k]:
        last = s.add_frame(f)
    assert last is not None and last.state == "tracking"
    shift = np.eye(4)
    shift[:3, 3] = [0.3, 0.0, 0.0]
    s._smoother = _MovedEstimate(s._smoother, shift)
    r = s.add_frame(dataclasses.replace(walk.frames[k], detections=[]))
    predicted = last.world_from_camera @ invert_pose(walk.frames[k - 1].odom_from_camera) \
        @ walk.frames[k].odom_from_camera
    assert r.state == "tracking", r.reason
    np.testing.assert_allclose(r.world_from_camera, predicted, atol=1e-6)
    nxt = s.add_frame(walk.frames[k + 1])
    assert nxt.state == "tracking" and not isinstance(s._smoother, _MovedEstimate)


def test_one_detection_per_frame_initializes_once_the_frames_see_three_objects(
        walk: ChessWalk) -> None:
    # single-frame localize cannot use any of these frames (one detection each)
    rng = np.random.default_rng(11)
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    out = []
    for f, T in zip(walk.frames[:45], walk.poses[:45], strict=True):
        one = [f.detections[int(rng.integers(len(f.detections)))]] if f.detections else []
        r = s.add_frame(FrameInput(one, f.odom_from_camera, f.timestamp))
        out.append((r, T))
    tracked = [(r, T) for r, T in out if r.state == "tracking"]
    assert tracked and tracked[0][0].frame_index < 30
    errs = [pose_error(r.world_from_camera, T) for r, T in tracked]
    assert max(e[0] for e in errs) < 0.10 and max(e[1] for e in errs) < 5.0


def test_a_kidnapped_session_goes_lost_then_relocalizes(walk: ChessWalk) -> None:
    """Track 40 frames, then the camera is elsewhere in the room while the odometry claims a
    continuous motion (a different odometry frame): the detections stop matching, the session
    says ``lost`` (no pose) and relocalizes with multi-frame RANSAC."""
    cm, camera = walk.compiled, walk.camera
    s = TrackingSession(cm, camera, SessionOptions())
    for f in walk.frames[:40]:
        s.add_frame(f)
    assert s.state == "tracking"
    far = chess_walk(100, seed=3, start=600)
    # continue the first odometry smoothly: the kidnapping is invisible to the odometry
    bridge = walk.frames[39].odom_from_camera @ invert_pose(far.odometry[0])
    states, errs = [], []
    for k, (T, f) in enumerate(zip(far.poses, far.frames, strict=True)):
        r = s.add_frame(FrameInput(f.detections, bridge @ f.odom_from_camera,
                                   40 / 30.0 + (k + 1) / 30.0))
        states.append(r.state)
        # never a wrong pose with a confidence
        if r.world_from_camera is not None and pose_error(r.world_from_camera, T)[0] > 0.1:
            assert r.confidence == 0.0 and r.reason == "detections_unexplained"
        if r.state == "tracking" and "lost" in states:
            errs.append(pose_error(r.world_from_camera, T))
    assert "lost" in states
    first_lost = states.index("lost")
    assert first_lost < 30
    assert errs, states
    assert np.mean([e[0] <= 0.10 and e[1] <= 5 for e in errs]) >= 0.95


def test_frames_with_two_objects_each_do_not_initialize_alone(walk: ChessWalk) -> None:
    # the same frame repeated (no motion, 2 objects): never three distinct objects -> no pose
    f = next(f for f in walk.frames if len(f.detections) == 2)
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    rs = [s.add_frame(FrameInput(f.detections, f.odom_from_camera, k / 30.0))
          for k in range(20)]
    assert all(r.state == "initializing" and r.world_from_camera is None for r in rs)


def test_bad_frames_name_the_field_and_leave_the_session_unchanged(walk: ChessWalk) -> None:
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    s.add_frame(walk.frames[0])
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(TrackingInputError, match=r"^odom_from_camera: must be a rigid"):
        s.add_frame(FrameInput([], bad, 1.0))
    with pytest.raises(TrackingInputError, match=r"^timestamp: .* before"):
        s.add_frame(FrameInput([], np.eye(4), -1.0))
    assert s.frame_count == 1
    with pytest.raises(TrackingInputError, match=r"^options\.smoother") as exc:
        SessionOptions(smoother="kalman")
    # structured, a FieldError like the localization's errors: the API reads exc.field
    assert isinstance(exc.value, FieldError) and exc.value.field == "options.smoother"
    assert exc.value.problem.startswith("must be one of")
    with pytest.raises(TrackingInputError) as exc:
        s.add_frame(FrameInput([], np.eye(4), float("nan")))
    assert (exc.value.field, exc.value.problem) == ("timestamp", "must be a finite number, got nan")
    assert field_and_problem(exc.value, "frames[3].") == ("frames[3].timestamp",
                                                          exc.value.problem)


def _with_gravity(walk: ChessWalk, seed: int = 11) -> list[FrameInput]:
    """The walk's frames with a simulated IMU gravity (1 deg per tilt axis, declared 2 deg)."""
    rng = np.random.default_rng(seed)
    up = walk.compiled.scene_map.up
    return [dataclasses.replace(f, gravity=Gravity(
        simulate_gravity(walk.poses[i], up, 1.0, rng), 2.0))
        for i, f in enumerate(walk.frames)]


def test_gravity_tightens_the_tilt_of_a_tracked_walk(walk: ChessWalk) -> None:
    """The same walk with the device's gravity on every frame (a factor on each frame's tilt):
    over the frames tracked both ways, a smaller mean tilt error against the truth and a
    smaller rotation covariance (small gains: odometry and detections already pin the tilt,
    0.150 -> 0.146 deg; docs/tracking.md); a gravity that is not a ``Gravity`` names the
    field."""
    up = walk.compiled.scene_map.up
    runs = {}
    for name, frames in (("plain", walk.frames), ("gravity", _with_gravity(walk))):
        s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
        runs[name] = [s.add_frame(f) for f in frames]
    both = [i for i, (a, b) in enumerate(zip(runs["plain"], runs["gravity"], strict=True))
            if a.state == "tracking" and b.state == "tracking"]
    assert len(both) >= 80
    tilt = {name: [float(tilt_errors_deg(invert_pose(runs[name][i].world_from_camera), up,
                                         Gravity(-(walk.poses[i][:3, :3].T @ up))))
                   for i in both] for name in runs}
    rot_var = {name: [float(np.trace(runs[name][i].covariance[:3, :3])) for i in both]
               for name in runs}
    assert np.mean(tilt["gravity"]) < np.mean(tilt["plain"])
    assert np.mean(rot_var["gravity"]) < np.mean(rot_var["plain"])
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    with pytest.raises(TrackingInputError, match=r"^gravity: must be a Gravity"):
        s.add_frame(dataclasses.replace(walk.frames[0], gravity=[0.0, 1.0, 0.0]))
    assert s.frame_count == 0


def test_store_bounds_count_and_expires_idle_sessions(walk: ChessWalk) -> None:
    now = [0.0]
    store = SessionStore(max_sessions=2, idle_timeout_s=10.0, clock=lambda: now[0])
    mk = lambda: TrackingSession(walk.compiled, walk.camera)  # noqa: E731
    a = store.create("chess", 1, mk(), "opencv")
    store.create("chess", 1, mk(), "opencv")
    with pytest.raises(SessionCapacityError):
        store.create("chess", 1, mk(), "opencv")
    now[0] = 5.0
    store.get(a.session_id)  # touched: stays alive
    now[0] = 12.0
    store.create("chess", 1, mk(), "opencv")  # the idle one was expired
    assert len(store) == 2
    now[0] = 30.0
    with pytest.raises(SessionNotFound):
        store.get(a.session_id)


@pytest.mark.slow
def test_long_session_memory_is_flat(walk: ChessWalk) -> None:
    """450 frames (15 s at 30 Hz, the walk replayed back and forth): the graph stays within its
    window and the Python heap does not grow with the frame count (``bench.tracking
    --long-minutes 10`` runs the 10-minute version: docs/tracking.md)."""
    frames = walk.frames
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    seq = frames + frames[::-1]
    last_T = last_src = None
    blocks = []
    for k in range(450):
        f = seq[k % len(seq)]
        T = f.odom_from_camera if last_T is None else last_T @ invert_pose(last_src) \
            @ f.odom_from_camera
        last_T, last_src = T, f.odom_from_camera
        s.add_frame(FrameInput(f.detections, T, k / 30.0))
        if (k + 1) % 75 == 0:
            gc.collect()
            blocks.append(sys.getallocatedblocks())
            assert s.state != "tracking" or len(s._smoother.timestamps()) <= 30
    # Python objects alive (pymalloc blocks; tracemalloc would make this test 20x slower):
    # flat after the first window. Leaking one frame's factor (a closure, its residual model
    # and its arrays: > 50 blocks) would add > 10000 blocks over the last 225 frames.
    assert max(blocks[3:]) < max(blocks[:3]) + 3000, blocks


# ----------------------------------------------------------------------------- API

@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory):
    with TestClient(make_test_app(tmp_path_factory.mktemp("trk"))) as c:
        yield c


def test_api_session_lifecycle(client: TestClient, walk: ChessWalk) -> None:
    cam = walk.camera
    r = client.post("/v1/maps/chess/sessions", json={"camera": {
        "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "width": cam.width,
        "height": cam.height}})
    assert r.status_code == 201, r.text
    sid = r.json()["session_id"]
    assert r.headers["location"] == f"/v1/sessions/{sid}"
    frames = [frame_json(f) for f in walk.frames[:40]]
    # a bad frame in a batch: 422 naming it, nothing fused
    bad = [*frames[:3], {**frames[3], "odom_from_camera": {"matrix": [[2, 0, 0, 0], [0, 1, 0, 0],
                                                                      [0, 0, 1, 0],
                                                                      [0, 0, 0, 1]]}}]
    r = client.post(f"/v1/sessions/{sid}/frames", json={"frames": bad})
    assert r.status_code == 422
    assert r.json()["errors"][0]["field"] == "frames[3].odom_from_camera"
    assert client.get(f"/v1/sessions/{sid}").json()["frames"] == 0
    r = client.post(f"/v1/sessions/{sid}/frames", json={"frames": frames[:39]})
    assert r.status_code == 200, r.text
    r = client.post(f"/v1/sessions/{sid}/frames", json=frames[39])
    out = r.json()["results"][0]
    assert out["state"] == "tracking"
    T = np.array(out["world_from_camera"]["matrix"])
    assert pose_error(T, walk.poses[39])[0] < 0.1
    assert len(out["covariance"]["matrix"]) == 6 and out["world_from_odom"] is not None
    assert client.get(f"/v1/sessions/{sid}").json()["state"] == "tracking"
    assert client.delete(f"/v1/sessions/{sid}").status_code == 204
    r = client.get(f"/v1/sessions/{sid}")
    assert r.status_code == 404 and r.json()["type"] == "urn:quadloc:problem:session-not-found"


def test_api_session_gravity_defaults_to_the_session_convention(client: TestClient,
                                                                walk: ChessWalk) -> None:
    """A frame's ``gravity`` is in the session's convention unless it says otherwise: an
    OpenGL session fed the OpenGL-axes odometry and gravity gives the OpenCV session's poses
    (converted); a zero gravity direction is a 422 naming ``frames[i].gravity`` alone."""
    cam = walk.camera
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    frames = _with_gravity(walk)[:40]
    out = {}
    for convention in ("opencv", "opengl"):
        r = client.post("/v1/maps/chess/sessions", json={"convention": convention, "camera": {
            "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "width": cam.width,
            "height": cam.height}})
        sid = r.json()["session_id"]
        body = []
        for f in frames:
            g = f.gravity.direction_camera
            doc = frame_json(f)
            if convention == "opengl":
                doc["odom_from_camera"] = {"matrix": (f.odom_from_camera @ flip).tolist()}
                g = flip[:3, :3] @ g
            body.append({**doc, "gravity": {"direction": g.tolist(), "sigma_deg": 2.0}})
        if convention == "opencv":
            bad = [*body[:2], {**body[2], "gravity": {"direction": [0.0, 0.0, 0.0]}}]
            r = client.post(f"/v1/sessions/{sid}/frames", json={"frames": bad})
            assert r.status_code == 422
            # the batch's own field path only (not also errors of the one-frame form)
            assert [e["field"] for e in r.json()["errors"]] == ["frames[2].gravity"]
        r = client.post(f"/v1/sessions/{sid}/frames", json={"frames": body})
        assert r.status_code == 200, r.text
        out[convention] = r.json()["results"][-1]
    assert out["opencv"]["state"] == out["opengl"]["state"] == "tracking"
    T_cv = np.array(out["opencv"]["world_from_camera"]["matrix"])
    T_gl = np.array(out["opengl"]["world_from_camera"]["matrix"])
    np.testing.assert_allclose(T_gl @ flip, T_cv, atol=1e-6)


def test_api_unknown_session_after_restart_is_404(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path)) as c:
        r = c.post("/v1/sessions/s-quadloc-1.abcdef/frames",
                   json={"odom_from_camera": {"matrix": np.eye(4).tolist()}, "timestamp": 0})
        assert r.status_code == 404
        assert r.json()["type"] == "urn:quadloc:problem:session-not-found"


def test_nginx_routes_a_session_to_the_replica_that_created_it(monkeypatch, walk) -> None:
    conf = (ROOT / "deploy" / "nginx.conf").read_text()
    block = re.search(r"map \$uri \$quadloc_session_upstream \{(.*?)\}", conf, re.S).group(1)
    rules = [(re.compile(m.group(1)), m.group(2))
             for m in re.finditer(r"~(\S+)\s+(\S+);", block)]
    default = re.search(r"default\s+(\S+);", block).group(1)
    upstreams = set(re.findall(r"upstream (\S+) \{", conf))

    def route(uri: str) -> str:
        return next((u for rx, u in rules if rx.search(uri)), default)

    for replica in ("quadloc-1", "quadloc-2"):
        monkeypatch.setenv("QUADLOC_REPLICA_ID", replica)
        sid = SessionStore().create("chess", 1, TrackingSession(walk.compiled, walk.camera),
                                    "opencv").session_id
        up = route(f"/v1/sessions/{sid}/frames")
        assert up in upstreams and f"server {replica}:8000" in conf.split(
            f"upstream {up} {{")[1].split("}")[0]
    assert route("/v1/maps/chess/sessions") == "quadloc"
    assert route("/v1/sessions/s-other.x") == "quadloc"


# ----------------------------------------------------------------------------- SDK

def test_arkit_and_arcore_helpers_transpose_column_major_input() -> None:
    from quadloc_sdk.session import arcore_pose_to_matrix, arkit_transform_to_matrix

    T = [[0.0, -1.0, 0.0, 1.5], [1.0, 0.0, 0.0, -2.0], [0.0, 0.0, 1.0, 0.25], [0, 0, 0, 1]]
    columns = [[T[r][c] for r in range(4)] for c in range(4)]
    assert arkit_transform_to_matrix(columns) == T
    assert arcore_pose_to_matrix([x for col in columns for x in col]) == T
    with pytest.raises(ValueError, match="column_major"):
        arcore_pose_to_matrix([0.0] * 15)


def test_sdk_session_sync_and_async(client: TestClient, walk: ChessWalk) -> None:
    """The SDK's sessions take its typed models (``Detection``, ``Camera``, ``Gravity``,
    ``SessionFrame``) or wire dicts, and answer typed models: the same walk sent both ways
    gives the same poses, within 5 cm of the truth once tracking; ``get`` is the server's
    ``GET /v1/sessions/{id}``; an unknown session is ``NotFound``."""
    import asyncio

    import httpx

    from quadloc_sdk import (
        AsyncQuadLocClient,
        Camera,
        Detection,
        Ellipse,
        Gravity,
        NotFound,
        QuadLocClient,
        SessionFrame,
        SessionFrameResult,
        SessionInfo,
        SessionOptions,
    )

    cam = walk.camera
    camera = Camera(fx=cam.fx, fy=cam.fy, cx=cam.cx, cy=cam.cy, width=cam.width,
                    height=cam.height)
    n = 12
    frames = [frame_json(f) for f in walk.frames[:n]]
    gravity = [Gravity(direction=f.gravity.direction_camera.tolist(), sigma_deg=2.0)
               for f in _with_gravity(walk)[:n]]
    with QuadLocClient("http://testserver", transport=client._transport) as qc:
        s = qc.start_session("chess", camera=camera, options=SessionOptions(window_frames=20))
        assert isinstance(s.info, SessionInfo) and s.info.state == "initializing"
        res = []
        for f, g in zip(walk.frames[:n], gravity, strict=True):
            detections = [Detection(label=d.label, sigma=d.sigma, ellipse=Ellipse(
                cx=d.ellipse.cx, cy=d.ellipse.cy, a=d.ellipse.a, b=d.ellipse.b,
                angle=d.ellipse.angle)) for d in f.detections]
            res.append(s.add_frame(detections, odom_from_camera=f.odom_from_camera,
                                   timestamp=f.timestamp, frame_id=f.frame_id, gravity=g))
        assert all(isinstance(r, SessionFrameResult) for r in res)
        assert [r.frame_index for r in res] == list(range(n))
        assert res[-1].state == "tracking" and res[-1].world_from_camera is not None
        info = s.get()
        assert info == qc.get_session(s.session_id) == s.info
        assert (info.frames, info.state, info.map_id) == (n, "tracking", "chess")
        s.close()
        with pytest.raises(NotFound):
            qc.get_session(s.session_id)

    async def run() -> tuple[list[SessionFrameResult], SessionInfo]:
        transport = httpx.ASGITransport(app=client.app)
        async with AsyncQuadLocClient("http://testserver", transport=transport) as ac:
            s = await ac.start_session("chess", camera=camera.model_dump(),
                                       options={"window_frames": 20})
            wire = [SessionFrame.model_validate({**f, "gravity": g.model_dump(
                exclude_none=True)}) for f, g in zip(frames[:-1], gravity, strict=False)]
            out = await s.add_frames(wire)
            last = frames[-1]
            one = await s.add_frame(last["detections"], odom_from_camera=last["odom_from_camera"],
                                    timestamp=last["timestamp"], frame_id=last["frame_id"],
                                    gravity=gravity[-1].model_dump())
            info = await s.get()
            await s.close()
            return [*out, one], info

    async_res, async_info = asyncio.run(run())
    assert async_info.frames == n
    for r, a, truth in zip(res, async_res, walk.poses[:n], strict=True):
        assert (r.state, r.frame_id) == (a.state, a.frame_id)
        if r.state == "tracking":
            assert r.world_from_camera is not None and a.world_from_camera is not None
            np.testing.assert_allclose(a.world_from_camera.as_matrix(),
                                       r.world_from_camera.as_matrix(), atol=1e-6)
            assert np.linalg.norm(r.world_from_camera.as_matrix()[:3, 3] - truth[:3, 3]) < 0.05


def test_sdk_session_refuses_bad_frames_before_sending() -> None:
    """A typo'd or invalid frame raises before any request (no transport is touched)."""
    import httpx
    from pydantic import ValidationError

    from quadloc_sdk import QuadLocClient, SessionInfo, TrackingSession

    def fail(request: httpx.Request) -> httpx.Response:
        raise AssertionError(f"sent {request.url}")

    with QuadLocClient("http://x", transport=httpx.MockTransport(fail)) as qc:
        s = TrackingSession(qc, SessionInfo(session_id="s1", url="/v1/sessions/s1", map_id="m",
                                            map_version=1, convention="opencv",
                                            state="initializing", frames=0,
                                            idle_timeout_s=300))
        with pytest.raises(ValidationError, match="sigmaa"):
            s.add_frame([{"label": "TV", "sigmaa": 0.5, "ellipse": {"cx": 1, "cy": 1, "a": 2,
                                                                      "b": 1}}],
                        odom_from_camera=np.eye(4), timestamp=0.0)
        with pytest.raises(ValidationError, match="odom_from_camera"):
            s.add_frame([], odom_from_camera=[[1.0, 0.0]], timestamp=0.0)
        with pytest.raises(ValueError, match="frames"):
            s.add_frames([])


def test_sdk_session_frame_gravity_takes_the_sessions_convention_unless_given() -> None:
    """A ``Gravity`` without an explicit convention is sent without one (the server then uses
    the session's, docs/tracking.md); an explicit one is sent as given."""
    from quadloc_sdk import Gravity, SessionFrame

    def wire(gravity: Gravity) -> dict:
        return SessionFrame(odom_from_camera={"matrix": np.eye(4)}, timestamp=0.0,
                            gravity=gravity).to_wire()["gravity"]

    assert wire(Gravity(direction=[0, 1, 0])) == {"direction": [0.0, 1.0, 0.0]}
    assert wire(Gravity(direction=[0, 1, 0], convention="opencv"))["convention"] == "opencv"
    frame = SessionFrame.model_validate({"odom_from_camera": {"matrix": np.eye(4).tolist()},
                                         "timestamp": 1.0, "gravity": {"direction": [0, -1, 0]}})
    assert "convention" not in frame.to_wire()["gravity"]


# ----------------------------------------------------------------------------- CLI

def test_cli_track_replays_the_example_recording(tmp_path: Path, capsys) -> None:
    import json

    from quadloc.service.cli.main import main

    db = f"sqlite:///{tmp_path / 'maps.db'}"
    rec = ROOT / "docs" / "examples" / "track_chess.json"
    assert main(["track", "--map", "chess", str(rec), "--database-url", db]) == 0
    out = capsys.readouterr().out
    m = re.search(r"within 10 cm and 5 deg ([0-9.]+) %", out)
    assert m and float(m.group(1)) >= 90.0, out[-500:]
    doc = json.loads(rec.read_text())
    doc["ground_truth_world_from_camera"] = doc["ground_truth_world_from_camera"][:3]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    assert main(["track", "--map", "chess", str(bad), "--database-url", db]) == 2
    assert "one entry per frame" in capsys.readouterr().err


def test_api_session_frames_name_their_zone(client: TestClient, walk: ChessWalk) -> None:
    """On the Chess map with zones (the whole room, and a 'corner' of three objects), each
    tracked frame's ``zone`` is the zone holding the most of its inliers, the smaller on a tie
    (counted here from the answer's own inliers); null without inliers."""
    doc = client.get("/v1/maps/chess").json()["map"]
    ids = [o["object_id"] for o in doc["objects"]]
    zones = {"room": set(ids), "corner": set(ids[:3])}
    doc = {**doc, "map_id": "chess-zoned", "zones": [
        {"zone_id": "room", "object_ids": ids}, {"zone_id": "corner", "object_ids": ids[:3]}]}
    assert client.post("/v1/maps", json=doc).status_code == 201
    cam = walk.camera
    r = client.post("/v1/maps/chess-zoned/sessions", json={"camera": {
        "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "width": cam.width,
        "height": cam.height}})
    sid = r.json()["session_id"]
    results = client.post(f"/v1/sessions/{sid}/frames", json={
        "frames": [frame_json(f) for f in walk.frames[:40]]}).json()["results"]
    seen = set()
    for out in results:
        used = [m["object_id"] for m in out["inliers"]]
        counts = {z: sum(o in members for o in used) for z, members in zones.items()}
        expected = None if not used else min(
            zones, key=lambda z: (-counts[z], len(zones[z]))) if max(counts.values()) else None
        assert out["zone"] == expected, (out["frame_index"], used)
        seen.add(out["zone"])
    assert "room" in seen
    assert client.delete(f"/v1/sessions/{sid}").status_code == 204
