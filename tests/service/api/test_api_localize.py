"""POST /v1/maps/{id}/localize and :batch - accuracy on a real ground-truth pose, conventions,
prior, "not localized" answers, every class of bad input, batch bounds, busy slots, metrics."""

from __future__ import annotations

import copy
import json
import math
import time
from pathlib import Path

import gtsam
import numpy as np
import pytest
from fastapi.testclient import TestClient

from quadloc.factors import budget as budget_module
from quadloc.factors.conics import Ellipse
from quadloc.factors.names import GeometryError
from quadloc.factors.rotations import rotation_angle, rotation_from_quaternion_wxyz
from quadloc.service.app import localization as solver_module
from quadloc.service.localization import pipeline as pipeline_module
from quadloc.service.schemas.examples import EXAMPLE_TRUE_WORLD_FROM_CAMERA, LOCALIZE_EXAMPLE
from tests.conftest import make_test_app
from tests.support.helpers import assert_problem as _problem

URL = "/v1/maps/chess/localize"
TRUTH = np.array(EXAMPLE_TRUE_WORLD_FROM_CAMERA)
FLIP = np.diag([1.0, -1.0, -1.0, 1.0])


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory):
    with TestClient(make_test_app(tmp_path_factory.mktemp("loc"))) as c:
        yield c


def _frame(**changes: object) -> dict:
    body = copy.deepcopy(LOCALIZE_EXAMPLE)
    body.update(changes)
    return body


def _rot_err_deg(A: np.ndarray, B: np.ndarray) -> float:
    return math.degrees(float(rotation_angle(A[:3, :3], B[:3, :3])))


def test_demo_frame_localizes_near_the_ground_truth(client: TestClient) -> None:
    r = client.post(URL, json=LOCALIZE_EXAMPLE)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["localized"] and out["reason"] is None
    assert out["refinement_status"] == "converged"
    pose = out["world_from_camera"]
    T = np.array(pose["matrix"])
    assert np.linalg.norm(T[:3, 3] - TRUTH[:3, 3]) < 0.05
    assert _rot_err_deg(T, TRUTH) < 2.0
    # The quaternion and translation describe the same matrix (independent conversion).
    np.testing.assert_allclose(rotation_from_quaternion_wxyz(pose["quaternion_wxyz"]), T[:3, :3],
                               atol=1e-9)
    np.testing.assert_allclose(pose["translation_m"], T[:3, 3])
    assert pose["quaternion_wxyz"][0] >= 0 and pose["convention"] == "opencv"
    cov = np.array(out["covariance"]["matrix"])
    assert out["covariance"]["order"] == ["omega_x", "omega_y", "omega_z", "v_x", "v_y", "v_z"]
    np.testing.assert_allclose(cov, cov.T, atol=1e-15)
    assert np.linalg.eigvalsh(cov).min() > 0
    assert 0 < out["confidence"] <= 1 and len(out["inliers"]) >= 3
    assert out["map_id"] == "chess" and out["map_version"] == 1
    assert out["frame_id"] == LOCALIZE_EXAMPLE["frame_id"]
    assert out["timestamp"] == LOCALIZE_EXAMPLE["timestamp"]
    assert out["timings_ms"]["total"] > 0


def test_opengl_output_is_the_flipped_pose_and_adjoint_covariance(client: TestClient) -> None:
    cv = client.post(URL, json=LOCALIZE_EXAMPLE).json()
    gl_body = _frame(options={**LOCALIZE_EXAMPLE["options"], "output_convention": "opengl"})
    gl = client.post(URL, json=gl_body).json()
    T_cv, T_gl = np.array(cv["world_from_camera"]["matrix"]), np.array(gl["world_from_camera"]
                                                                        ["matrix"])
    np.testing.assert_allclose(T_gl, T_cv @ FLIP, atol=1e-12)
    assert gl["world_from_camera"]["convention"] == "opengl"
    # OpenGL camera looks down -Z: its -Z axis is the OpenCV +Z axis in the world.
    np.testing.assert_allclose(-T_gl[:3, 2], T_cv[:3, 2], atol=1e-12)
    # Covariance: xi_gl = Ad(F^-1) xi_cv with GTSAM's adjoint (independent of our formula).
    F = gtsam.Pose3(gtsam.Rot3(FLIP[:3, :3]), np.zeros(3))
    ad = F.inverse().AdjointMap()
    np.testing.assert_allclose(np.array(gl["covariance"]["matrix"]),
                               ad @ np.array(cv["covariance"]["matrix"]) @ ad.T, atol=1e-15)


def test_boxes_and_log_variance_are_converted(client: TestClient) -> None:
    body = _frame()
    sigmas = []
    for d in body["detections"]:
        e = Ellipse(**d["ellipse"])
        xmin, ymin, xmax, ymax = e.bbox()
        d.pop("ellipse")
        d["box"] = {"xmin": xmin, "ymin": ymin, "xmax": xmax, "ymax": ymax}
        sigmas.append(d.pop("sigma"))
        d["log_variance"] = 2.0 * math.log(sigmas[-1])
    ref = copy.deepcopy(body)
    for d, s in zip(ref["detections"], sigmas, strict=True):
        b = d.pop("box")
        # Independent box -> inscribed ellipse.
        d["ellipse"] = {"cx": (b["xmin"] + b["xmax"]) / 2, "cy": (b["ymin"] + b["ymax"]) / 2,
                        "a": (b["xmax"] - b["xmin"]) / 2, "b": (b["ymax"] - b["ymin"]) / 2,
                        "angle": 0.0}
        d.pop("log_variance")
        d["sigma"] = s
    a, b = client.post(URL, json=body).json(), client.post(URL, json=ref).json()
    assert a["localized"] == b["localized"]
    if a["localized"]:
        np.testing.assert_allclose(a["world_from_camera"]["matrix"],
                                   b["world_from_camera"]["matrix"], atol=1e-9)


def test_prior_in_either_convention(client: TestClient) -> None:
    cov = np.diag([1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2])
    T_start = TRUTH.copy()
    T_start[:3, 3] += [0.03, -0.02, 0.01]
    prior_cv = {"world_from_camera": {"matrix": T_start.tolist()}, "covariance": cov.tolist()}
    prior_gl = {"world_from_camera": {"matrix": (T_start @ FLIP).tolist()},
                "covariance": cov.tolist(), "convention": "opengl"}
    a = client.post(URL, json=_frame(prior=prior_cv)).json()
    b = client.post(URL, json=_frame(prior=prior_gl)).json()
    assert a["localized"] and a["used_prior"]
    assert np.linalg.norm(np.array(a["world_from_camera"]["translation_m"]) - TRUTH[:3, 3]) < 0.05
    # The diagonal covariance is invariant under the flip, so both requests are identical.
    np.testing.assert_allclose(a["world_from_camera"]["matrix"], b["world_from_camera"]["matrix"],
                               atol=1e-9)
    q = prior_cv["world_from_camera"]
    from quadloc.factors.rotations import quaternion_wxyz_from_rotation

    q_form = {"quaternion_wxyz": quaternion_wxyz_from_rotation(T_start[:3, :3]).tolist(),
              "translation_m": T_start[:3, 3].tolist()}
    c = client.post(URL, json=_frame(prior={**prior_cv, "world_from_camera": q_form})).json()
    np.testing.assert_allclose(c["world_from_camera"]["matrix"], a["world_from_camera"]["matrix"],
                               atol=1e-7)
    assert q  # (matrix form used above)


def test_gravity_in_either_convention(client: TestClient) -> None:
    """The true down direction (any length, OpenCV or OpenGL camera axes) gives the same answer
    in both conventions, within a millimetre of the answer without; one 30 deg off answers
    ``gravity_mismatch`` with the candidate in ``alternatives``."""
    down_cv = -(TRUTH[:3, :3].T @ np.array([0.0, 0.0, 1.0]))  # the Chess map's up is +Z
    plain = client.post(URL, json=_frame()).json()
    a = client.post(URL, json=_frame(gravity={"direction": (9.81 * down_cv).tolist()})).json()
    b = client.post(URL, json=_frame(gravity={"direction": (FLIP[:3, :3] @ down_cv).tolist(),
                                              "convention": "opengl"})).json()
    assert plain["localized"] and a["localized"] and b["localized"]
    np.testing.assert_allclose(a["world_from_camera"]["matrix"],
                               b["world_from_camera"]["matrix"], atol=1e-9)
    np.testing.assert_allclose(a["world_from_camera"]["matrix"],
                               plain["world_from_camera"]["matrix"], atol=1e-3)
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    axis = np.cross(down_cv, [0.0, 0.0, 1.0])
    axis /= np.linalg.norm(axis)
    tilted = c * down_cv + s * np.cross(axis, down_cv)
    off = client.post(URL, json=_frame(gravity={"direction": tilted.tolist(),
                                                "sigma_deg": 1.0})).json()
    assert not off["localized"] and off["reason"] == "gravity_mismatch"
    alt = np.array(off["alternatives"][0]["world_from_camera"]["matrix"])
    assert np.linalg.norm(alt[:3, 3] - np.array(plain["world_from_camera"]["matrix"])[:3, 3]) \
        < 0.05


def test_not_localized_is_a_200(client: TestClient) -> None:
    one = _frame(detections=LOCALIZE_EXAMPLE["detections"][:1])
    r = client.post(URL, json=one)
    assert r.status_code == 200
    out = r.json()
    assert out["localized"] is False and out["reason"] == "too_few_detections"
    assert out["world_from_camera"] is None and out["confidence"] == 0
    assert out["refinement_status"] is None
    out = client.post(URL, json=_frame(detections=[])).json()
    assert out["localized"] is False and out["reason"] == "too_few_detections"
    unknown = _frame(detections=[{**d, "label": "Sofa"} for d in LOCALIZE_EXAMPLE["detections"]])
    out = client.post(URL, json=unknown).json()
    assert out["localized"] is False and out["reason"] in ("too_few_detections",
                                                           "no_label_match")


BAD_INPUTS = [
    # (body transformer, expected status, field that must be named)
    (lambda b: b["camera"].update(fx=-1), 422, "camera.fx"),
    (lambda b: b["camera"].update(width=640.5), 422, "camera.width"),
    (lambda b: b["camera"].update(width="640"), 422, "camera.width"),
    (lambda b: b["detections"][1]["ellipse"].update(a=0), 422, "detections[1].ellipse.a"),
    (lambda b: b["detections"][0].update(label=""), 422, "detections[0].label"),
    (lambda b: b["detections"][0].update(label=7), 422, "detections[0].label"),
    (lambda b: b["detections"][0].update(sigma=-2), 422, "detections[0].sigma"),
    (lambda b: b["detections"][0].update(log_variance=0.0), 422, "detections[0]"),
    (lambda b: b["detections"][0].update(box={"xmin": 5, "ymin": 0, "xmax": 1, "ymax": 3}), 422,
     "detections[0]"),
    (lambda b: b["detections"][0].pop("ellipse"), 422, "detections[0]"),
    (lambda b: b["detections"][0].update(score=1.5), 422, "detections[0].score"),
    (lambda b: b["detections"][0].update(sigmaa=1.0), 422, "detections[0].sigmaa"),
    (lambda b: b.update(detections="many"), 422, "detections"),
    (lambda b: b.update(detections=b["detections"][:1] * 257), 422, "detections"),
    (lambda b: b["options"].update(metric="l2"), 422, "options.metric"),
    (lambda b: b["options"].update(robust_scale=1.0), 422, "options"),
    (lambda b: b["options"].update(inlier_iou=0), 422, "options.inlier_iou"),
    (lambda b: b["options"].update(output_convention="arkit"), 422, "options.output_convention"),
    (lambda b: b.update(prior={"world_from_camera": {"quaternion_wxyz": [1, 1, 0, 0],
                                                     "translation_m": [0, 0, 0]}}),
     422, "prior.world_from_camera.quaternion_wxyz"),
    (lambda b: b.update(prior={"world_from_camera": {"matrix": np.diag([1, 1, -1, 1]).tolist()}}),
     422, "prior.world_from_camera"),
    (lambda b: b.update(prior={"world_from_camera": {"matrix": TRUTH.tolist()},
                               "covariance": (-np.eye(6)).tolist()}), 422, "prior.covariance"),
    (lambda b: b.update(prior={"world_from_camera": {"matrix": TRUTH.tolist()},
                               "covariance": [[1.0] * 5] * 6}), 422, "prior.covariance"),
    (lambda b: b.update(gravity={"direction": [0, 0, 0]}), 422, "gravity"),
    (lambda b: b.update(gravity={"direction": [0, 1]}), 422, "gravity.direction"),
    (lambda b: b.update(gravity={"direction": [0, 1, 0], "sigma_deg": 0}), 422,
     "gravity.sigma_deg"),
    (lambda b: b.update(gravity={"direction": [0, 1, 0], "convention": "arkit"}), 422,
     "gravity.convention"),
    (lambda b: b.update(gravity={"direction": [0, 1, 0], "up": True}), 422, "gravity.up"),
    (lambda b: b.update(options={"unknown_label_policy": "error"},
                        detections=[*b["detections"], {**b["detections"][0], "label": "Sofa"}]),
     422, f"detections[{len(LOCALIZE_EXAMPLE['detections'])}].label"),
]


@pytest.mark.parametrize("mutate,status,field", BAD_INPUTS)
def test_bad_inputs_are_problems_naming_the_field(client: TestClient, mutate, status: int,
                                                  field: str) -> None:
    body = _frame()
    mutate(body)
    r = client.post(URL, json=body)
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    problem = r.json()
    assert problem["type"] in ("urn:quadloc:problem:validation-error",
                               "urn:quadloc:problem:invalid-geometry")
    fields = [e["field"] for e in problem["errors"]]
    assert any(f == field or f.startswith((field + ".", field + "[")) for f in fields), \
        (field, problem)
    assert problem["detail"]


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e400"])
def test_non_finite_json_numbers(client: TestClient, literal: str) -> None:
    text = json.dumps(LOCALIZE_EXAMPLE).replace('"fx": 532.57', f'"fx": {literal}', 1)
    assert literal in text
    body = _problem(client.post(URL, content=text, headers={"content-type": "application/json"}),
                    422, "validation-error")
    assert body["errors"][0]["field"] == "camera.fx"


def test_malformed_json_unknown_map_and_wrong_media(client: TestClient) -> None:
    _problem(client.post(URL, content=b'{"camera": ', headers={"content-type": "application/json"}),
             400, "malformed-json")
    body = _problem(client.post("/v1/maps/nope/localize", json=LOCALIZE_EXAMPLE), 404,
                    "map-not-found")
    assert body["errors"][0]["field"] == "path.map_id"
    _problem(client.post(URL, params={"version": 99}, json=LOCALIZE_EXAMPLE), 404,
             "map-not-found")
    r = client.post(URL, content=json.dumps(LOCALIZE_EXAMPLE), headers={"content-type":
                                                                        "text/plain"})
    assert 400 <= r.status_code < 500
    _problem(client.get(URL), 405, "method-not-allowed")


def test_errors_from_deep_in_the_pipeline(client: TestClient, monkeypatch) -> None:
    def geometry_error(*a, **k):
        raise GeometryError("projection is not an ellipse", field="detections[2].ellipse")

    monkeypatch.setattr(solver_module, "localize", geometry_error)
    body = _problem(client.post(URL, json=LOCALIZE_EXAMPLE), 422, "invalid-geometry")
    assert body["errors"] == [{"field": "detections[2].ellipse",
                               "message": "projection is not an ellipse"}]

    def linalg_error(*a, **k):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(solver_module, "localize", linalg_error)
    r = client.post(URL, json=LOCALIZE_EXAMPLE)
    assert r.status_code == 200 and r.json()["reason"] == "numerical_failure"


def test_time_budget_is_capped_by_the_server(tmp_path: Path, monkeypatch) -> None:
    seen = []
    real = solver_module.localize

    def spy(detections, scene_map, camera, options, prior=None, gravity=None, calibration=None,
            hint=None):
        seen.append(options.time_budget_ms)
        return real(detections, scene_map, camera, options, prior, gravity)

    monkeypatch.setattr(solver_module, "localize", spy)
    with TestClient(make_test_app(tmp_path, solve_time_budget_ms=250.0)) as c:
        c.post(URL, json=_frame(options={"time_budget_ms": 60000}))
        c.post(URL, json=_frame(options={"time_budget_ms": 10}))
        c.post(URL, json=_frame(options={}))
    assert seen == [250.0, 10.0, 250.0]


def test_batch(client: TestClient) -> None:
    frames = [LOCALIZE_EXAMPLE, _frame(detections=LOCALIZE_EXAMPLE["detections"][:1],
                                       frame_id="f2")]
    r = client.post(URL + ":batch", json={"frames": frames})
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["map_id"] == "chess" and out["map_version"] == 1
    assert [x["localized"] for x in out["results"]] == [True, False]
    assert out["results"][1]["frame_id"] == "f2"
    _problem(client.post(URL + ":batch", json={"frames": []}), 422, "validation-error")
    body = _problem(client.post(URL + ":batch", json={"frames": [LOCALIZE_EXAMPLE] * 65}), 422,
                    "validation-error")
    assert body["errors"][0]["field"] == "frames"
    bad = _frame()
    bad["detections"][3]["ellipse"]["b"] = -1
    body = _problem(client.post(URL + ":batch", json={"frames": [LOCALIZE_EXAMPLE, bad]}), 422,
                    "validation-error")
    assert body["errors"][0]["field"] == "frames[1].detections[3].ellipse.b"


def test_batch_limit_from_settings(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path, max_batch_frames=2)) as c:
        one = _frame(detections=LOCALIZE_EXAMPLE["detections"][:1])
        assert c.post(URL + ":batch", json={"frames": [one] * 2}).status_code == 200
        body = _problem(c.post(URL + ":batch", json={"frames": [one] * 3}), 422,
                        "validation-error")
        assert body["errors"][0]["field"] == "frames"


def test_busy_solver_answers_503_with_retry_after(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path, max_concurrent_solves=1,
                                  solve_queue_timeout_s=0.0)) as c:
        slots = c.app.state.services.localizer.slots
        assert slots.acquire(timeout=1)
        try:
            r = c.post(URL, json=LOCALIZE_EXAMPLE)
        finally:
            slots.release()
        _problem(r, 503, "busy")
        assert r.headers["retry-after"] == "1"
        assert c.post(URL, json=LOCALIZE_EXAMPLE).status_code == 200


def test_metrics_count_outcomes_and_latency(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path)) as c:
        c.post(URL, json=LOCALIZE_EXAMPLE)
        c.post(URL, json=_frame(detections=LOCALIZE_EXAMPLE["detections"][:1]))
        c.post(URL, json={})
        text = c.get("/metrics").text
    assert 'quadloc_localizations_total{outcome="localized"} 1.0' in text
    assert 'quadloc_localizations_total{outcome="too_few_detections"} 1.0' in text
    assert ('quadloc_http_requests_total{method="POST",route="/v1/maps/{map_id}/localize",'
            'status="422"} 1.0') in text
    assert ('quadloc_http_request_duration_seconds_count{method="POST",'
            'route="/v1/maps/{map_id}/localize"} 3.0') in text
    assert "quadloc_localization_solve_seconds_count 2.0" in text


def test_solver_slots_are_first_come_first_served() -> None:
    import threading
    import time

    from quadloc.service.app.localization import FairSlots

    slots = FairSlots(1)
    assert slots.acquire(timeout=0)
    assert not slots.acquire(timeout=0.05)  # timed out: must not leave a ghost waiter
    order: list[int] = []

    def waiter(k: int) -> None:
        assert slots.acquire(timeout=10)
        order.append(k)
        time.sleep(0.005)
        slots.release()

    threads = []
    for k in range(5):
        t = threading.Thread(target=waiter, args=(k,))
        t.start()
        threads.append(t)
        deadline = time.monotonic() + 10
        while len(slots._waiters) < k + 1:  # queued in a known order, whatever the load
            assert time.monotonic() < deadline, "waiter thread never queued"
            time.sleep(0.001)
    slots.release()
    for t in threads:
        t.join(timeout=10)
    assert order == [0, 1, 2, 3, 4]
    assert slots.acquire(timeout=0)  # the slot came back
    slots.release()


def test_solver_slot_handed_over_as_the_wait_times_out_is_taken(monkeypatch) -> None:
    """``release`` hands the slot to a waiter whose timed wait has just given up: the waiter
    must take it (not lose it: the slot would leak)."""
    from quadloc.service.app import localization as app_localization

    slots = app_localization.FairSlots(1)
    assert slots.acquire(timeout=0)

    class HandedOverAtTimeout:
        """A hand-off lock whose timed wait ends just after ``release`` handed it over."""

        def __init__(self) -> None:
            self.held = False

        def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
            if not self.held:  # the waiter takes its own lock first
                self.held = True
                return True
            slots.release()  # the holder releases during the wait...
            return False  # ...which timed out anyway

        def release(self) -> None:
            self.held = False

    monkeypatch.setattr(app_localization.threading, "Lock", HandedOverAtTimeout)
    assert slots.acquire(timeout=0.01)
    monkeypatch.undo()
    assert not slots._waiters and slots._free == 0  # the slot is held, nothing leaked
    slots.release()
    assert slots.acquire(timeout=0)


# ------------------------------------------------------------ review 6: prior covariance, batch


def _full_spd_covariance() -> np.ndarray:
    """A 6x6 SPD covariance [omega, v] with strong correlations in every block."""
    rng = np.random.default_rng(7)
    A = rng.normal(size=(6, 6))
    scales = np.diag([0.03, 0.03, 0.03, 0.1, 0.1, 0.1])
    cov = scales @ (A @ A.T + 0.5 * np.eye(6)) @ scales / 6.0
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert np.min(np.abs(cov[np.triu_indices(6, 1)])) > 1e-6  # no zero off-diagonal term
    return cov


def _opengl_from_opencv_adjoint() -> np.ndarray:
    """Independent: T_gl = T_cv * F with F = Pose3(diag(1,-1,-1), 0); a right perturbation
    xi_gl of T_gl is xi_cv = Ad_F xi_gl of T_cv (GTSAM's AdjointMap, [omega, v] order)."""
    F = gtsam.Pose3(gtsam.Rot3(np.diag([1.0, -1.0, -1.0])), np.zeros(3))
    return F.AdjointMap()


def test_opengl_prior_full_covariance_is_converted_to_opencv(client: TestClient) -> None:
    from quadloc.service.app.conversions import prior_from_request
    from quadloc.service.schemas.localize import PosePriorIn

    cov_cv = _full_spd_covariance()
    Ad = _opengl_from_opencv_adjoint()
    cov_gl = np.linalg.inv(Ad) @ cov_cv @ np.linalg.inv(Ad).T  # xi_gl = Ad^-1 xi_cv
    assert not np.allclose(cov_gl, cov_cv)  # the test can tell the conventions apart
    T_start = TRUTH.copy()
    T_start[:3, 3] += [0.03, -0.02, 0.01]
    prior_gl = {"world_from_camera": {"matrix": (T_start @ FLIP).tolist()},
                "covariance": cov_gl.tolist(), "convention": "opengl"}
    converted = prior_from_request(PosePriorIn.model_validate(prior_gl))
    assert converted is not None
    np.testing.assert_allclose(converted.covariance, cov_cv, rtol=0, atol=1e-15)
    np.testing.assert_allclose(converted.world_from_camera, T_start, rtol=0, atol=1e-12)
    # Through the API: the OpenCV and the OpenGL spelling of the same prior give one answer.
    prior_cv = {"world_from_camera": {"matrix": T_start.tolist()}, "covariance": cov_cv.tolist()}
    a = client.post(URL, json=_frame(prior=prior_cv)).json()
    b = client.post(URL, json=_frame(prior=prior_gl)).json()
    assert a["localized"] and a["used_prior"] and b["used_prior"]
    np.testing.assert_allclose(a["world_from_camera"]["matrix"], b["world_from_camera"]["matrix"],
                               atol=1e-9)


def test_batch_total_budget_answers_the_rest_not_localized(tmp_path: Path, monkeypatch) -> None:
    import types

    # The solver's clock is simulated: each solve "takes" 200 ms of it, whatever the machine's
    # load, so the test is deterministic (no wall-clock assertions).
    clock = {"now": 1000.0}
    fake_time = types.SimpleNamespace(perf_counter=lambda: clock["now"],
                                      thread_time=time.thread_time)
    # every wall clock of the request reads the simulated clock: the batch's budget (a
    # Deadline), the frames' timings and the start of each solve (its own Deadline's wall
    # stop). A real clock beside the simulated one made the test depend on the machine's
    # uptime: a solve's wall stop at real start + 0.9 s was read as passed at 1000 s while
    # the machine had been up less than that.
    for module in (solver_module, budget_module, pipeline_module):
        monkeypatch.setattr(module, "time", fake_time)
    real = solver_module.localize
    budgets = []

    def slow(detections, scene_map, camera, options, prior=None, gravity=None,
             calibration=None, hint=None):
        budgets.append(options.time_budget_ms)
        result = real(detections, scene_map, camera, options, prior, gravity)
        clock["now"] += 0.2  # each solve takes 200 ms of the batch's clock
        return result

    monkeypatch.setattr(solver_module, "localize", slow)
    frames = [_frame(frame_id=f"f{i}") for i in range(5)]
    with TestClient(make_test_app(tmp_path, batch_time_budget_ms=300.0)) as c:
        start = clock["now"]
        r = c.post(URL + ":batch", json={"frames": frames})
        elapsed = clock["now"] - start
    assert r.status_code == 200, r.text
    results = r.json()["results"]
    assert [x["frame_id"] for x in results] == [f"f{i}" for i in range(5)]
    assert results[0]["localized"] is True  # solved before the budget ran out: kept
    assert len(budgets) == 2  # frames 0 and 1 started (1 with what was left), 2-4 never did
    assert budgets[0] <= 300.0 and budgets[1] == pytest.approx(300.0 - 200.0)
    for x in results[2:]:
        assert x["localized"] is False and x["reason"] == "time_budget_exceeded"
        assert x["world_from_camera"] is None and x["hypotheses_evaluated"] == 0
    assert elapsed == pytest.approx(0.4)  # two solves started, none after the budget
    # Without the batch budget pressure every frame is solved.
    budgets.clear()
    with TestClient(make_test_app(tmp_path / "b", batch_time_budget_ms=60_000.0)) as c:
        results = c.post(URL + ":batch", json={"frames": frames[:3]}).json()["results"]
    assert [x["localized"] for x in results] == [True, True, True] and len(budgets) == 3


def test_batch_budget_setting_is_bounded() -> None:
    from pydantic import ValidationError

    from quadloc.service.settings import Settings

    assert Settings(batch_time_budget_ms=300_000).batch_time_budget_ms == 300_000
    for bad in (0, -1, 300_001, float("inf")):
        with pytest.raises(ValidationError):
            Settings(batch_time_budget_ms=bad)


def test_metric_none_and_trust_fields_over_http(client: TestClient) -> None:
    """metric "none" is accepted (pose unrefined, no covariance); the response says which path
    won and what the confidence is a probability of; the new options are validated."""
    body = _frame(options={**LOCALIZE_EXAMPLE.get("options", {}), "metric": "none"})
    r = client.post(URL, json=body)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["localized"] and out["metric"] == "none" and out["covariance"] is None
    assert out["pose_source"] == "ransac" and out["alternatives"] == []
    r = client.post(URL, json=_frame(options={"on_ambiguity": "best", "min_confidence": 0.0}))
    assert r.status_code == 200 and r.json()["localized"]
    for bad in ({"on_ambiguity": "maybe"}, {"min_confidence": 2.0}, {"metric": "nope"}):
        field = next(iter(bad))
        problem = _problem(client.post(URL, json=_frame(options=bad)), 422, "validation-error")
        assert any(e["field"] == f"options.{field}" for e in problem["errors"]), problem


def test_the_fast_path_answers_what_the_full_handling_answers(client: TestClient,
                                                              monkeypatch) -> None:
    """A plain request skips FastAPI's dependency injection (routers/localize.py,
    ``_plain_frame``): same answer as through the full handling; anything else (errors
    included) goes through the full handling; the route has no parameter the fast path ignores."""
    import inspect

    from quadloc.service.api.deps import check_body_depth
    from quadloc.service.api.routers import localize as loc

    assert tuple(inspect.signature(loc.localize_frame).parameters) == loc.FAST_PATH_PARAMETERS
    assert [d.dependency for d in client.app.router.dependencies] == [check_body_depth]
    seen: list[bool] = []
    real = loc._plain_frame

    async def spy(request):
        frame = await real(request)
        seen.append(frame is not None)
        return frame

    monkeypatch.setattr(loc, "_plain_frame", spy)
    deep: object = []
    for _ in range(client.app.state.settings.max_json_depth):
        deep = [deep]
    fast = client.post(URL, json=LOCALIZE_EXAMPLE)
    full = client.post(URL + "?version=1", json=LOCALIZE_EXAMPLE)  # a query: full handling
    assert seen == [True, False] and fast.status_code == full.status_code == 200
    a, b = fast.json(), full.json()
    assert a.pop("timings_ms").keys() == b.pop("timings_ms").keys()
    assert a == b and a["localized"]
    for url, kwargs, status in [
        (URL, {"content": b"{", "headers": {"content-type": "application/json"}}, 400),
        (URL, {"json": {**LOCALIZE_EXAMPLE, "extra": 1}}, 422),
        (URL, {"json": {**LOCALIZE_EXAMPLE, "frame_id": deep}}, 422),  # QUADLOC_MAX_JSON_DEPTH
        (URL, {"json": None}, 422),
        ("/v1/maps/chess%0A/localize", {"json": LOCALIZE_EXAMPLE}, 422),  # "$" before "\n"
        ("/v1/maps/nope/localize", {"json": LOCALIZE_EXAMPLE}, 404),
    ]:
        seen.clear()
        r = client.post(url, **kwargs)
        assert r.status_code == status, (url, r.text)
        assert seen == [status == 404], url  # 404 is the route's own answer, after the fast path
    seen.clear()
    svg = client.post(URL, json=LOCALIZE_EXAMPLE, headers={"accept": "image/svg+xml"})
    assert svg.status_code == 200 and svg.headers["content-type"].startswith("image/svg")
    assert seen == [False]


def _building_frame(building, bf, cam, **changes: object) -> dict:
    """The wire request of a simulated building frame."""
    body = {"camera": {"fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy,
                       "width": cam.width, "height": cam.height},
            "detections": [{"label": d.label, "sigma": d.sigma, "ellipse": {
                "cx": d.ellipse.cx, "cy": d.ellipse.cy, "a": d.ellipse.a, "b": d.ellipse.b,
                "angle": d.ellipse.angle}} for d in bf.frame.detections]}
    body.update(changes)
    return body


def test_hint_settles_exact_copies_and_bad_hints_are_422(client: TestClient) -> None:
    """A building of exact copies of a room: without a hint the answer is ``ambiguous`` with
    the rooms as alternatives; with the room's objects (or a position 1 m off, sigma 2 m) it is
    the true room (never a copy 12 m away; most answers within 10 cm, each within 10 cm with
    the probability its confidence states) or, when the pose is too uncertain or another pose
    competes, an honest refusal with the true room's pose among the candidates; an unknown
    object id or a position without sigma is a 422 naming the field."""
    from tests.support.buildings import building_frames, make_building

    b = make_building(8, "exact", seed=51)
    doc = b.scene_map.to_dict()
    doc["map_id"] = "building-api"
    assert client.post("/v1/maps", json=doc).status_code in (200, 201)
    url = "/v1/maps/building-api/localize"
    cam, frames = building_frames(b, 3, seed=52, min_detections=5)
    errors = []
    for bf in frames:
        r = client.post(url, json=_building_frame(b, bf, cam))
        assert r.status_code == 200, r.text
        plain = r.json()
        assert not plain["localized"] and plain["reason"] == "ambiguous"
        assert len(plain["alternatives"]) >= 2
        truth = bf.world_from_camera
        for hint in ({"object_ids": list(bf.room.object_ids)},
                     {"position": (truth[:3, 3] + [1.0, 0.0, 0.0]).tolist(), "sigma_m": 2.0}):
            out = client.post(url, json=_building_frame(b, bf, cam, hint=hint)).json()
            if out["localized"]:
                T = np.array(out["world_from_camera"]["matrix"])
                errors.append(float(np.linalg.norm(T[:3, 3] - truth[:3, 3])))
                assert errors[-1] < 0.5  # the true room, not a copy
            else:  # honest: a refusal (with a zone hint, the true room among the candidates)
                assert out["reason"] in ("low_confidence", "ambiguous"), out
                gaps = [np.linalg.norm(np.array(a["world_from_camera"]["matrix"])[:3, 3]
                                       - truth[:3, 3]) for a in out["alternatives"]]
                assert "position" in hint or min(gaps) < 0.5
    assert len(errors) >= 3 and np.median(errors) < 0.1, errors
    bf = frames[0]
    body = _problem(client.post(url, json=_building_frame(b, bf, cam,
                                                          hint={"object_ids": ["nope"]})),
                    422, "invalid-geometry")
    assert body["errors"][0]["field"] == "hint.object_ids[0]"
    body = _problem(client.post(url, json=_building_frame(b, bf, cam,
                                                          hint={"position": [0.0, 0.0, 0.0]})),
                    422, "validation-error")
    assert body["errors"][0]["field"].startswith("hint") and "sigma_m" in json.dumps(body)


def test_answers_name_their_zone_and_a_hint_may_name_one(client: TestClient) -> None:
    """On exact copies of a room (zones: rooms inside their floor), the ambiguous answer names
    each candidate's zone: the room nearest to the candidate's camera (computed here from the
    rooms' object centroids, not by the zone rule), distinct rooms; the answer's zone is its best
    candidate's. A hint naming the true room's zone gives the answer in that room (or an honest
    refusal with the room among the candidates); an unknown zone or two kinds at once are 422."""
    from tests.support.buildings import building_frames, make_building

    b = make_building(6, "exact", seed=61)
    doc = b.scene_map.to_dict()
    doc["map_id"] = "building-zones"
    assert client.post("/v1/maps", json=doc).status_code in (200, 201)
    url = "/v1/maps/building-zones/localize"
    centre = {o["object_id"]: np.array(o["center"]) for o in doc["objects"]}
    rooms = {r.zone_id: np.mean([centre[o] for o in r.object_ids], axis=0) for r in b.rooms}

    def nearest_room(out: dict) -> str:
        t = np.array(out["world_from_camera"]["matrix"])[:3, 3]
        return min(rooms, key=lambda z: float(np.linalg.norm(rooms[z] - t)))

    cam, frames = building_frames(b, 3, seed=62, min_detections=5)
    hinted_ok = 0
    for bf in frames:
        plain = client.post(url, json=_building_frame(b, bf, cam)).json()
        assert plain["reason"] == "ambiguous" and len(plain["alternatives"]) >= 2
        zones = [a["zone"] for a in plain["alternatives"]]
        assert zones == [nearest_room(a) for a in plain["alternatives"]]
        assert len(set(zones)) == len(zones)
        assert plain["zone"] == zones[0]
        out = client.post(url, json=_building_frame(
            b, bf, cam, hint={"zone_id": bf.room.zone_id})).json()
        if out["localized"]:
            hinted_ok += 1
            assert out["zone"] == bf.room.zone_id == nearest_room(out)
        else:
            assert bf.room.zone_id in [a["zone"] for a in out["alternatives"]]
    assert hinted_ok >= 2
    body = _problem(client.post(url, json=_building_frame(b, frames[0], cam,
                                                          hint={"zone_id": "f9-r9-c9"})),
                    422, "invalid-geometry")
    assert body["errors"][0]["field"] == "hint.zone_id"
    both = {"zone_id": "f0", "object_ids": list(frames[0].room.object_ids)}
    body = _problem(client.post(url, json=_building_frame(b, frames[0], cam, hint=both)),
                    422, "validation-error")
    assert body["errors"][0]["field"].startswith("hint")
    # a map without zones answers zone null
    chess = client.post(URL, json=LOCALIZE_EXAMPLE).json()
    assert chess["localized"] and chess["zone"] is None
