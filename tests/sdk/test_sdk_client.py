"""SDK client against httpx.MockTransport: retries/backoff, error mapping, request building,
response parsing, the async twin, and the import isolation of the ``quadloc_sdk`` package."""

from __future__ import annotations

import asyncio
import email.utils
import json
import math
import random
import re
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pydantic
import pytest

import quadloc_sdk as sdk
from quadloc_sdk import errors as errs
from quadloc_sdk.models import (
    Camera,
    Detection,
    Ellipse,
    Gravity,
    LocalizeOptions,
    LocalizeRequest,
    PosePrior,
)
from quadloc_sdk.retry import RetryPolicy, parse_retry_after

REPO = Path(__file__).resolve().parents[2]
CAMERA = Camera(fx=532.57, fy=531.54, cx=320, cy=240, width=640, height=480)
DETS = [
    Detection(label="TV", ellipse=Ellipse(cx=300, cy=200, a=80, b=40, angle=0.1), sigma=2.0),
    Detection(label="Chair", box={"xmin": 10, "ymin": 20, "xmax": 50, "ymax": 90},
              log_variance=0.5, score=0.9),
]


def _response_body(map_id: str = "chess", version: int = 1, **kw) -> dict:
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.2, 0.3]
    body = {
        "localized": True, "reason": None,
        "world_from_camera": {"quaternion_wxyz": [1, 0, 0, 0], "quaternion_xyzw": [0, 0, 0, 1],
                              "translation_m": [0.1, 0.2, 0.3], "matrix": T.tolist(),
                              "matrix_column_major": T.T.reshape(16).tolist(),
                              "convention": "opencv"},
        "covariance": {"order": ["omega_x", "omega_y", "omega_z", "v_x", "v_y", "v_z"],
                       "frame": "body", "matrix": (np.eye(6) * 1e-4).tolist()},
        "confidence": 0.9, "inliers": [{"detection_index": 0, "object_id": "3", "iou": 0.8,
                                        "cost": 0.01}],
        "metric": "level_set", "hypotheses_evaluated": 12, "used_prior": False,
        "map_id": map_id, "map_version": version, "timings_ms": {"total": 5.0},
        "frame_id": "f1", "timestamp": None, "a_future_field": 1,
    }
    body.update(kw)
    return body


def _problem(status: int, slug: str, errors=(), headers=None) -> httpx.Response:
    body = {"type": f"urn:quadloc:problem:{slug}", "title": slug.replace("-", " "),
            "status": status, "detail": f"detail of {slug}", "instance": "/v1/x",
            "errors": [{"field": f, "message": m} for f, m in errors]}
    return httpx.Response(status, json=body, headers={"content-type": "application/problem+json",
                                                      **(headers or {})})


class Recorder:
    """MockTransport handler replaying ``responses`` (Response or Exception) in order."""

    def __init__(self, *responses):
        self.responses = list(responses)
        self.requests: list[httpx.Request] = []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        self.requests.append(request)
        item = self.responses.pop(0)
        if isinstance(item, Exception):
            raise item
        return item


def _client(handler, **retry_kw) -> tuple[sdk.QuadLocClient, list[float]]:
    sleeps: list[float] = []
    policy = RetryPolicy(rng=random.Random(0), **retry_kw)
    client = sdk.QuadLocClient("http://quadloc.test", api_key="secret", retry=policy,
                               transport=httpx.MockTransport(handler), sleep=sleeps.append)
    return client, sleeps


# --------------------------------------------------------------------------- retry policy


def test_backoff_is_exponential_capped_and_jittered_within_bounds():
    policy = RetryPolicy(initial_backoff_s=0.1, multiplier=2, max_backoff_s=1.0, jitter=0.5,
                         rng=random.Random(1))
    for k in range(1, 10):
        base = min(1.0, 0.1 * 2 ** (k - 1))
        waits = [policy.backoff(k) for _ in range(200)]
        assert all(base * 0.5 <= w <= base for w in waits)
        assert max(waits) - min(waits) > 0.3 * base  # jitter actually spreads the waits
    no_jitter = RetryPolicy(initial_backoff_s=0.1, jitter=0.0)
    assert [no_jitter.backoff(k) for k in (1, 2, 3)] == pytest.approx([0.1, 0.2, 0.4])


def test_parse_retry_after_seconds_and_http_date():
    assert parse_retry_after("3") == 3.0
    assert parse_retry_after(" 1.5 ") == 1.5
    assert parse_retry_after("-4") == 0.0
    assert parse_retry_after(None) is None
    assert parse_retry_after("soon") is None
    assert parse_retry_after("nan") is None
    now = time.time()
    date = email.utils.formatdate(now + 120, usegmt=True)
    assert parse_retry_after(date, now=now) == pytest.approx(120, abs=1.0)
    assert parse_retry_after(email.utils.formatdate(now - 50, usegmt=True), now=now) == 0.0


def test_retry_policy_validation_names_the_field():
    with pytest.raises(ValueError, match="max_attempts"):
        RetryPolicy(max_attempts=0)
    with pytest.raises(ValueError, match="jitter"):
        RetryPolicy(jitter=1.5)
    with pytest.raises(ValueError, match="multiplier"):
        RetryPolicy(multiplier=0.5)
    with pytest.raises(ValueError, match="initial_backoff_s"):
        RetryPolicy(initial_backoff_s=float("nan"))


# --------------------------------------------------------------------------- retries in the client


def test_503_then_success_is_retried_with_backoff():
    rec = Recorder(_problem(503, "busy"), _problem(503, "busy"),
                   httpx.Response(200, json=_response_body()))
    client, sleeps = _client(rec, initial_backoff_s=0.2, jitter=0.5)
    answer = client.localize("chess", camera=CAMERA, detections=DETS)
    assert answer.localized and len(rec.requests) == 3
    assert len(sleeps) == 2
    assert 0.1 <= sleeps[0] <= 0.2 and 0.2 <= sleeps[1] <= 0.4


def test_429_waits_at_least_retry_after():
    rec = Recorder(_problem(429, "rate-limited", headers={"Retry-After": "2"}),
                   httpx.Response(200, json={"maps": []}))
    client, sleeps = _client(rec, initial_backoff_s=0.01)
    assert client.list_maps() == []
    assert sleeps == [2.0]


def test_retry_after_beyond_cap_raises_at_once_with_the_advice():
    rec = Recorder(_problem(429, "rate-limited", headers={"Retry-After": "120"}))
    client, sleeps = _client(rec, max_retry_after_s=30)
    with pytest.raises(errs.RateLimited) as info:
        client.list_maps()
    assert info.value.retry_after == 120 and sleeps == [] and len(rec.requests) == 1


def test_retries_exhausted_raise_the_last_error_with_attempt_count():
    rec = Recorder(*[_problem(503, "not-ready") for _ in range(3)])
    client, sleeps = _client(rec, max_attempts=3)
    with pytest.raises(errs.ServiceUnavailable) as info:
        client.readyz()
    assert info.value.attempts == 3 and len(rec.requests) == 3 and len(sleeps) == 2
    assert isinstance(info.value, errs.ServerError)


@pytest.mark.parametrize(("status", "slug"), [(400, "malformed-json"), (401, "unauthorized"),
                                              (403, "forbidden"), (404, "map-not-found"),
                                              (409, "map-exists"), (412, "precondition-failed"),
                                              (413, "payload-too-large"),
                                              (422, "validation-error"),
                                              (428, "precondition-required"),
                                              (500, "internal-error"), (502, "bad-gateway")])
def test_other_errors_are_never_retried(status, slug):
    rec = Recorder(_problem(status, slug), httpx.Response(200, json={"maps": []}))
    client, sleeps = _client(rec)
    with pytest.raises(errs.APIError) as info:
        client.list_maps()
    assert len(rec.requests) == 1 and sleeps == [] and info.value.status == status


def test_connection_refused_is_retried_for_any_method():
    rec = Recorder(httpx.ConnectError("refused"), httpx.ConnectTimeout("slow"),
                   httpx.Response(201, json={"map_id": "m", "version": 1, "content_hash": "ab",
                                             "map": {}}, headers={"ETag": '"ab"'}))
    client, sleeps = _client(rec)
    record = client.create_map({"map_id": "m"})
    assert record.etag == '"ab"' and len(rec.requests) == 3 and len(sleeps) == 2


def test_read_timeout_is_retried_only_for_idempotent_calls():
    rec = Recorder(httpx.ReadTimeout("slow"), httpx.Response(200, json=_response_body()))
    client, _ = _client(rec)
    assert client.localize("chess", camera=CAMERA, detections=DETS).localized
    assert len(rec.requests) == 2
    rec = Recorder(httpx.ReadTimeout("slow"), httpx.Response(201, json={}))
    client, sleeps = _client(rec)
    with pytest.raises(errs.TransportError) as info:
        client.create_map({"map_id": "m"})  # may have been created: never replayed
    assert len(rec.requests) == 1 and sleeps == [] and info.value.attempts == 1
    assert "POST http://quadloc.test/v1/maps" in str(info.value)


def test_connection_errors_exhausted_raise_transport_error():
    rec = Recorder(*[httpx.ConnectError("refused")] * 2)
    client, _ = _client(rec, max_attempts=2)
    with pytest.raises(errs.TransportError, match="after 2 attempt"):
        client.healthz()


# --------------------------------------------------------------------------- error mapping


@pytest.mark.parametrize(("status", "cls"), [
    (400, errs.ValidationError), (401, errs.Unauthorized), (403, errs.Forbidden),
    (404, errs.NotFound),
    (409, errs.Conflict), (412, errs.PreconditionFailed), (413, errs.PayloadTooLarge),
    (422, errs.ValidationError), (428, errs.PreconditionRequired), (429, errs.RateLimited),
    (418, errs.ClientError), (500, errs.ServerError), (503, errs.ServiceUnavailable),
])
def test_status_maps_to_exception_class(status, cls):
    request = httpx.Request("GET", "http://quadloc.test/v1/maps")
    response = _problem(status, "x")
    response.request = request
    err = errs.error_from_response(response)
    assert type(err) is cls and err.status == status
    assert isinstance(err, errs.QuadLocError)
    assert isinstance(err, errs.ClientError) == (400 <= status < 500)


def test_validation_error_carries_the_fields():
    rec = Recorder(_problem(422, "validation-error",
                            errors=[("detections[1].ellipse.a", "must be > 0"),
                                    ("camera.fx", "Input should be a finite number")]))
    client, _ = _client(rec)
    with pytest.raises(errs.ValidationError) as info:
        client.localize("chess", camera=CAMERA, detections=DETS)
    err = info.value
    assert err.fields == ["detections[1].ellipse.a", "camera.fx"]
    assert err.errors[0] == errs.FieldError("detections[1].ellipse.a", "must be > 0")
    assert err.type == "urn:quadloc:problem:validation-error"
    assert err.detail == "detail of validation-error" and err.instance == "/v1/x"
    assert "detections[1].ellipse.a: must be > 0" in str(err)
    assert "POST http://quadloc.test/v1/maps/chess/localize" in str(err)


def test_conflicts_share_a_base_class_and_non_json_errors_keep_the_text():
    assert issubclass(errs.PreconditionFailed, errs.Conflict)
    assert issubclass(errs.PreconditionRequired, errs.Conflict)
    rec = Recorder(httpx.Response(502, text="<html>Bad Gateway</html>",
                                  headers={"content-type": "text/html"}))
    client, _ = _client(rec)
    with pytest.raises(errs.ServerError) as info:
        client.list_maps()
    assert info.value.problem == {} and "Bad Gateway" in str(info.value)
    assert info.value.title == "Bad Gateway"


# --------------------------------------------------------------------------- request building


def test_localize_request_wire_format_and_headers():
    rec = Recorder(httpx.Response(200, json=_response_body(frame_id="f1")))
    client, _ = _client(rec)
    answer = client.localize(
        "my map/1", camera=CAMERA, detections=DETS, frame_id="f1", timestamp=12.5,
        options=LocalizeOptions(metric="wasserstein", output_convention="opengl"),
        prior=PosePrior.from_matrix(np.eye(4), np.eye(6) * 0.01), map_version=3,
        gravity=Gravity(direction=np.array([0.0, 9.8, 0.5]), sigma_deg=1.5),
    )
    req = rec.requests[0]
    assert req.method == "POST"
    assert req.url.raw_path == b"/v1/maps/my%20map%2F1/localize?version=3"  # id escaped
    assert req.url.params["version"] == "3"
    assert req.headers["authorization"] == "Bearer secret"
    assert req.headers["content-type"] == "application/json"
    body = json.loads(req.content)
    assert body["camera"] == {"fx": 532.57, "fy": 531.54, "cx": 320.0, "cy": 240.0,
                              "width": 640, "height": 480}
    assert body["detections"][0] == {"label": "TV", "sigma": 2.0, "ellipse": {
        "cx": 300.0, "cy": 200.0, "a": 80.0, "b": 40.0, "angle": 0.1}}
    assert body["detections"][1]["box"] == {"xmin": 10.0, "ymin": 20.0, "xmax": 50.0,
                                            "ymax": 90.0}
    assert body["options"] == {"metric": "wasserstein", "output_convention": "opengl"}
    assert body["prior"]["world_from_camera"]["matrix"] == np.eye(4).tolist()
    assert body["gravity"] == {"direction": [0.0, 9.8, 0.5], "sigma_deg": 1.5,
                               "convention": "opencv"}
    assert body["frame_id"] == "f1" and body["timestamp"] == 12.5
    # response parsing: numpy helpers, unknown fields tolerated
    assert answer.frame_id == "f1" and answer.inliers[0].object_id == "3"
    np.testing.assert_allclose(answer.world_from_camera.as_matrix()[:3, 3], [0.1, 0.2, 0.3])
    assert answer.covariance.as_array().shape == (6, 6)


def test_invalid_requests_fail_before_sending():
    rec = Recorder()
    client, _ = _client(rec)
    with pytest.raises(pydantic.ValidationError, match="cx"):
        Ellipse(cx=float("nan"), cy=0, a=1, b=1)
    with pytest.raises(pydantic.ValidationError, match="exactly one of 'ellipse' or 'box'"):
        Detection(label="TV")
    with pytest.raises(pydantic.ValidationError, match="at most one of 'sigma'"):
        Detection(label="TV", ellipse=Ellipse(cx=1, cy=1, a=1, b=1), sigma=1, log_variance=0)
    with pytest.raises(pydantic.ValidationError, match="sigm"):
        client.localize("chess", camera=CAMERA,
                        detections=[{"label": "TV", "sigm": 1,
                                     "ellipse": {"cx": 1, "cy": 1, "a": 1, "b": 1}}])
    with pytest.raises(pydantic.ValidationError, match="metric"):
        LocalizeOptions(metric="l2")
    with pytest.raises(pydantic.ValidationError, match="zero vector"):
        Gravity(direction=[0, 0, 0])
    with pytest.raises(pydantic.ValidationError, match="sigma_deg"):
        Gravity(direction=[0, 1, 0], sigma_deg=0)
    with pytest.raises(ValueError, match="'camera' and 'detections' are required"):
        client.localize("chess", detections=DETS)
    with pytest.raises(ValueError, match="map: contains NaN"):
        client.create_map({"map_id": "m", "objects": [{"axes": [math.inf, 1, 1]}]})
    with pytest.raises(ValueError, match="map_id"):
        client.get_map("")
    with pytest.raises(ValueError, match="version"):
        client.get_map("chess", version=0)
    with pytest.raises(ValueError, match="exactly one of if_match"):
        client.update_map("chess", {"map_id": "chess"})
    with pytest.raises(ValueError, match="frames"):
        client.localize_batch("chess", [])
    with pytest.raises(ValueError, match="base_url"):
        sdk.QuadLocClient("quadloc.test")
    assert rec.requests == []


def test_numpy_values_are_accepted():
    K = np.array([[500.0, 0, 320], [0, 501, 240], [0, 0, 1]], dtype=np.float32)
    cam = Camera.from_matrix(K, 640, 480)
    assert cam.fx == 500.0 and isinstance(cam.cx, float)
    e = Ellipse(cx=np.float32(3.5), cy=np.float64(2), a=np.int64(4), b=2.0)
    assert e.cx == 3.5 and e.a == 4.0
    req = LocalizeRequest(camera=cam, detections=[Detection(label="TV", ellipse=e)])
    json.dumps(req.to_wire())


def test_update_with_if_match_quotes_the_etag_and_expected_version_checks_the_latest():
    stored = {"map_id": "m", "version": 2, "content_hash": "abc", "map": {"map_id": "m"}}
    new = {**stored, "version": 3, "content_hash": "def"}
    rec = Recorder(httpx.Response(200, json=new, headers={"ETag": '"def"'}))
    client, _ = _client(rec)
    record = client.update_map("m", {"map_id": "m"}, if_match="abc")
    assert rec.requests[0].headers["if-match"] == '"abc"' and record.version == 3
    assert record.etag == '"def"'
    # expected_version: GET latest, then PUT with its ETag
    rec = Recorder(httpx.Response(200, json=stored, headers={"ETag": '"abc"'}),
                   httpx.Response(200, json=new, headers={"ETag": '"def"'}))
    client, _ = _client(rec)
    assert client.update_map("m", {"map_id": "m"}, expected_version=2).version == 3
    assert [r.method for r in rec.requests] == ["GET", "PUT"]
    assert rec.requests[1].headers["if-match"] == '"abc"'
    # stale expected_version: refused locally, nothing written
    rec = Recorder(httpx.Response(200, json=stored, headers={"ETag": '"abc"'}))
    client, _ = _client(rec)
    with pytest.raises(errs.PreconditionFailed) as info:
        client.update_map("m", {"map_id": "m"}, expected_version=1)
    assert [r.method for r in rec.requests] == ["GET"]
    assert info.value.fields == ["expected_version"] and info.value.status == 412
    # the server's 412 is not retried and maps to the same class
    rec = Recorder(_problem(412, "precondition-failed", headers={"ETag": '"zzz"'}))
    client, sleeps = _client(rec)
    with pytest.raises(errs.PreconditionFailed) as info:
        client.update_map("m", {"map_id": "m"}, if_match='"abc"')
    assert info.value.headers["etag"] == '"zzz"' and sleeps == []


def test_maps_calls_and_chess_import(tmp_path):
    chess_path = tmp_path / "chess.json"
    chess_path.write_text(json.dumps({"category_id_to_label": {"0": "TV"}, "objects": []}))
    created = {"map_id": "c2", "version": 1, "content_hash": "h", "map": {}}
    rec = Recorder(httpx.Response(201, json=created, headers={"ETag": '"h"'}),
                   httpx.Response(200, json={"maps": [{"map_id": "c2", "name": "Chess",
                                                       "version": 1, "content_hash": "h"}]}),
                   httpx.Response(200, json=created, headers={"ETag": '"h"'}),
                   httpx.Response(204))
    client, _ = _client(rec)
    client.import_chess_map(chess_path, map_id="c2", name="Chess")
    summaries = client.list_maps()
    record = client.get_map("c2", version=1)
    client.delete_map("c2")
    r0, r1, r2, r3 = rec.requests
    assert r0.url.path == "/v1/maps:import-chess"
    assert dict(r0.url.params) == {"map_id": "c2", "name": "Chess"}
    assert json.loads(r0.content)["category_id_to_label"] == {"0": "TV"}
    assert summaries[0].map_id == "c2" and r1.method == "GET"
    assert r2.url.params["version"] == "1" and record.etag == '"h"'
    assert r3.method == "DELETE" and r3.url.path == "/v1/maps/c2"
    with pytest.raises(ValueError, match="cannot read"):
        client.import_chess_map(tmp_path / "missing.json", map_id="x")


def test_batch_request_and_response():
    rec = Recorder(httpx.Response(200, json={"map_id": "chess", "map_version": 1, "results": [
        _response_body(frame_id="a"), _response_body(localized=False, reason="no_label_match",
                                                     world_from_camera=None, covariance=None,
                                                     confidence=0.0, inliers=[],
                                                     frame_id="b")]}))
    client, _ = _client(rec)
    frames = [LocalizeRequest(camera=CAMERA, detections=DETS, frame_id="a"),
              {"camera": CAMERA.model_dump(), "detections": [], "frame_id": "b"}]
    out = client.localize_batch("chess", frames)
    assert [r.frame_id for r in out.results] == ["a", "b"]
    assert out.results[1].reason == "no_label_match" and out.results[1].world_from_camera is None
    body = json.loads(rec.requests[0].content)
    assert [f["frame_id"] for f in body["frames"]] == ["a", "b"]
    assert rec.requests[0].url.path == "/v1/maps/chess/localize:batch"


# --------------------------------------------------------------------------- async twin


def test_async_client_retries_and_maps_errors():
    sleeps: list[float] = []

    async def fake_sleep(s: float) -> None:
        sleeps.append(s)

    responses = [httpx.ConnectError("refused"), _problem(503, "busy"),
                 httpx.Response(200, json=_response_body()),
                 _problem(404, "map-not-found", errors=[("path.map_id", "not found")])]
    seen: list[httpx.Request] = []

    async def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request)
        item = responses.pop(0)
        if isinstance(item, Exception):
            raise item
        return item

    async def main() -> None:
        async with sdk.AsyncQuadLocClient(
            "http://quadloc.test", transport=httpx.MockTransport(handler),
            retry=RetryPolicy(rng=random.Random(0)), sleep=fake_sleep,
        ) as client:
            answer = await client.localize("chess", camera=CAMERA, detections=DETS)
            assert answer.localized
            with pytest.raises(errs.NotFound) as info:
                await client.get_map("nope")
            assert info.value.fields == ["path.map_id"]

    asyncio.run(main())
    assert len(seen) == 4 and len(sleeps) == 2
    assert "authorization" not in seen[0].headers


# --------------------------------------------------------------------------- contract and isolation


def test_sdk_requests_validate_against_the_server_schema():
    schemas = pytest.importorskip("quadloc.service.schemas.localize")
    req = LocalizeRequest(
        camera=CAMERA, detections=DETS, frame_id="x", timestamp=1.0,
        prior=PosePrior.from_matrix(np.eye(4), np.eye(6) * 0.01, convention="opengl"),
        gravity=Gravity(direction=[0, 1, 0.2], sigma_deg=3, convention="opengl"),
        options=LocalizeOptions(metric="bhattacharyya", ransac_max_hypotheses=50, inlier_iou=0.3,
                                use_sigma=False, robust="huber", robust_scale=1.5,
                                output_convention="opengl", seed=3, time_budget_ms=200,
                                max_iterations=20, min_inliers=3,
                                unknown_label_policy="error"),
    )
    server = schemas.LocalizeRequest.model_validate_json(json.dumps(req.to_wire()))
    assert server.options.metric == "bhattacharyya" and server.prior.convention == "opengl"
    assert server.gravity.convention == "opengl" and server.gravity.sigma_deg == 3
    assert set(schemas.GravityIn.model_fields) == set(Gravity.model_fields)
    # every option the server knows is expressible from the SDK, and vice versa
    assert set(schemas.LocalizeOptionsIn.model_fields) == set(LocalizeOptions.model_fields)
    assert set(schemas.DetectionIn.model_fields) == set(Detection.model_fields)
    assert set(schemas.CameraIn.model_fields) == set(Camera.model_fields)
    assert set(schemas.LocalizeRequest.model_fields) == set(LocalizeRequest.model_fields)
    assert set(sdk.METRICS) == set(__import__("quadloc.service.localization.types",
                                              fromlist=["METRICS"]).METRICS)
    # a response serialised by the server's model parses in the SDK with the same values
    body = _response_body()
    body.pop("a_future_field")
    server_out = schemas.LocalizeResponse.model_validate(body).model_dump(mode="json")
    parsed = sdk.LocalizeResponse.model_validate(server_out)
    dumped = parsed.model_dump(mode="json")
    for key, value in server_out.items():
        assert dumped[key] == value, key
    assert set(schemas.LocalizeResponse.model_fields) <= set(sdk.LocalizeResponse.model_fields)
    # and the server's documented response example (once generated) parses too
    examples = pytest.importorskip("quadloc.service.schemas.examples")
    if examples.LOCALIZE_RESPONSE_EXAMPLE:
        assert sdk.LocalizeResponse.model_validate(examples.LOCALIZE_RESPONSE_EXAMPLE).map_id


def test_importing_sdk_pulls_in_neither_gtsam_nor_the_server():
    code = (
        "import sys, quadloc_sdk, quadloc_sdk.geometry, quadloc_sdk.client, quadloc_sdk.models, "
        "quadloc_sdk.errors, quadloc_sdk.retry\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
        "('gtsam', 'quadloc', 'fastapi', 'uvicorn', 'sqlalchemy'))\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=REPO, timeout=60, check=True)
    assert out.stdout.strip() == ""


def test_docs_mask_example_runs():
    text = (REPO / "docs" / "sdk.md").read_text()
    code = text.split("<!-- sdk-mask-example", 1)[1].split("```python\n", 1)[1].split("```")[0]
    scope: dict = {}
    exec(compile(code, "docs/sdk.md", "exec"), scope)
    e = scope["ellipse"]
    # the 161 x 81 px block: centre (280.5, 140.5); a uniform rectangle's moment ellipse has
    # semi-axes 2 sqrt(w^2 / 12) = w / sqrt(3)
    assert (e.cx, e.cy) == pytest.approx((280.5, 140.5))
    assert (e.a, e.b) == pytest.approx((161 / math.sqrt(3), 81 / math.sqrt(3)))
    assert scope["detection"].sigma == pytest.approx(math.exp(-2.1))


def test_every_sdk_route_exists_in_the_servers_openapi(tmp_path):
    conftest = pytest.importorskip("tests.conftest")
    app = conftest.make_test_app(tmp_path)
    paths = app.openapi()["paths"]
    client = sdk.QuadLocClient("http://quadloc.test")
    req = LocalizeRequest(camera=CAMERA, detections=DETS)
    calls = [
        client._list_maps_call(), client._get_map_call("m", 2), client._create_map_call({}),
        client._import_chess_call({}, "m", "n"), client._update_map_call("m", {}, '"e"'),
        client._delete_map_call("m"), client._localize_call("m", req, 1),
        client._batch_call("m", [req], 1),
    ]
    for call in calls:
        template = re.sub(r"/v1/maps/m(?=/|$)", "/v1/maps/{map_id}", call.path)
        assert template in paths, call.path
        op = paths[template][call.method.lower()]
        declared = {p["name"] for p in op.get("parameters", []) if p["in"] == "query"}
        assert set(call.params or {}) <= declared, (call.path, call.params, declared)
        if call.method == "PUT":
            assert "if-match" in {p["name"].lower() for p in op["parameters"]
                                  if p["in"] == "header"}
    for probe in ("/healthz", "/readyz", "/metrics"):
        assert "get" in paths[probe]


def test_update_map_retries_as_its_docstring_says():
    """update_map: retried on 503 (the server did not process it) and always with the same
    If-Match (so a replay after a write that did land fails with 412, never overwrites); never
    replayed after a failure that may have reached the server."""
    doc = sdk.QuadLocClient.update_map.__doc__ or ""
    assert "Never retried" not in doc and "If-Match" in doc and "429/503" in doc
    record = {"map_id": "m", "version": 2, "content_hash": "h2", "created_at": None,
              "map": {"map_id": "m"}}
    rec = Recorder(_problem(503, "database-unavailable", headers={"Retry-After": "0"}),
                   httpx.Response(200, json=record, headers={"ETag": '"h2"'}))
    client, sleeps = _client(rec)
    assert client.update_map("m", {"map_id": "m"}, if_match='"h1"').version == 2
    assert [r.method for r in rec.requests] == ["PUT", "PUT"] and len(sleeps) == 1
    assert {r.headers["if-match"] for r in rec.requests} == {'"h1"'}
    rec = Recorder(httpx.ReadTimeout("slow"), httpx.Response(200, json=record))
    client, sleeps = _client(rec)
    with pytest.raises(errs.TransportError):
        client.update_map("m", {"map_id": "m"}, if_match='"h1"')
    assert len(rec.requests) == 1 and sleeps == []


@pytest.mark.parametrize(("model", "schema"), [
    ("SessionOptions", "SessionOptionsIn"), ("SessionFrame", "SessionFrameIn"),
    ("SessionInfo", "SessionOut"), ("SessionFrameResult", "SessionFrameOut"),
])
def test_session_models_have_the_fields_of_the_wire_schemas(model: str, schema: str) -> None:
    """The SDK's session models have exactly the fields of the server's schemas in
    docs/openapi.json (the contract), and the fields the server requires are required."""
    spec = json.loads((Path(__file__).resolve().parents[2] / "docs" / "openapi.json")
                      .read_text())["components"]["schemas"]
    cls = getattr(sdk, model)
    assert set(cls.model_fields) == set(spec[schema]["properties"]), model
    if model in ("SessionFrame", "SessionOptions"):  # requests: required where the server requires
        required = {n for n, f in cls.model_fields.items() if f.is_required()}
        assert required == set(spec[schema].get("required", [])), model


def test_session_routes_exist_in_the_servers_openapi() -> None:
    """Every path the session helpers call is a route of the server."""
    from quadloc_sdk.session import _session_path

    paths = json.loads((Path(__file__).resolve().parents[2] / "docs" / "openapi.json")
                       .read_text())["paths"]
    sid = _session_path("s-x.y").replace("s-x.y", "{session_id}")
    assert set(paths[sid]) >= {"get", "delete"}
    assert "post" in paths[sid + "/frames"] and "post" in paths["/v1/maps/{map_id}/sessions"]

def test_hint_is_sent_and_checked_before_sending():
    """``hint`` reaches the body as the server's ``HintIn`` (position + sigma_m, or object_ids);
    a position without sigma or both kinds fail before sending."""
    from quadloc_sdk.models import Hint

    rec = Recorder(httpx.Response(200, json=_response_body()),
                   httpx.Response(200, json=_response_body()),
                   httpx.Response(200, json={**_response_body(), "zone": "room-2"}))
    client, _ = _client(rec)
    client.localize("chess", camera=CAMERA, detections=DETS,
                    hint={"position": [1.0, 2.0, 0.5], "sigma_m": 5.0})
    client.localize("chess", camera=CAMERA, detections=DETS,
                    hint=Hint(object_ids=["0", "3"]))
    answer = client.localize("chess", camera=CAMERA, detections=DETS,
                             hint=Hint(zone_id="room-2"))
    assert answer.zone == "room-2"
    bodies = [json.loads(r.content) for r in rec.requests]
    assert bodies[0]["hint"] == {"position": [1.0, 2.0, 0.5], "sigma_m": 5.0}
    assert bodies[1]["hint"] == {"object_ids": ["0", "3"]}
    assert bodies[2]["hint"] == {"zone_id": "room-2"}
    with pytest.raises(pydantic.ValidationError, match="sigma_m"):
        Hint(position=[0, 0, 0])
    with pytest.raises(pydantic.ValidationError, match="one of"):
        Hint(position=[0, 0, 0], sigma_m=1, object_ids=["0"])
    with pytest.raises(pydantic.ValidationError, match="one of"):
        Hint(zone_id="room-2", object_ids=["0"])
    assert len(rec.requests) == 3
