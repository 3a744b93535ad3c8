"""Pose layouts (quaternion_xyzw, column-major matrix), the Unity conversion, and the map
versions endpoint (HTTP, SDK)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient

import quadloc_sdk as sdk
from quadloc.factors.rotations import rotation_from_quaternion_wxyz
from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE, MAP_EXAMPLE
from quadloc_sdk.geometry import (
    column_major_from_matrix,
    matrix_from_column_major,
    matrix_from_quaternion_wxyz,
    quaternion_wxyz_from_matrix,
    quaternion_wxyz_from_xyzw,
    quaternion_xyzw_from_wxyz,
    unity_pose_from_world_from_camera,
    world_from_camera_opencv_to_opengl,
)
from tests.conftest import make_test_app


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    T = np.eye(4)
    T[:3, :3] = matrix_from_quaternion_wxyz(q / np.linalg.norm(q))
    T[:3, 3] = rng.normal(size=3)
    return T


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> TestClient:
    with TestClient(make_test_app(tmp_path_factory.mktemp("poses"))) as c:
        yield c


def test_response_carries_every_layout_consistently(client: TestClient) -> None:
    for convention in ("opencv", "opengl"):
        frame = json.loads(json.dumps(LOCALIZE_EXAMPLE))
        frame["options"] = {**frame.get("options", {}), "output_convention": convention}
        pose = client.post("/v1/maps/chess/localize", json=frame).json()["world_from_camera"]
        T = np.array(pose["matrix"])  # row-major: rows
        w, x, y, z = pose["quaternion_wxyz"]
        assert pose["quaternion_xyzw"] == [x, y, z, w]
        np.testing.assert_allclose(rotation_from_quaternion_wxyz(pose["quaternion_wxyz"]),
                                   T[:3, :3], atol=1e-9)
        # column-major: column 3 (entries 12..14) is the translation
        cm = pose["matrix_column_major"]
        assert len(cm) == 16 and cm[12:15] == pose["translation_m"] == T[:3, 3].tolist()
        np.testing.assert_array_equal(matrix_from_column_major(cm), T)


def test_prior_in_xyzw_equals_prior_in_wxyz(client: TestClient) -> None:
    T = np.eye(4)
    T[:3, :3] = matrix_from_quaternion_wxyz(np.array([0.45, -0.89, -0.07, 0.01]) /
                                            np.linalg.norm([0.45, -0.89, -0.07, 0.01]))
    T[:3, 3] = [-0.03, -0.3, 0.78]
    q = quaternion_wxyz_from_matrix(T[:3, :3])
    answers = []
    for pose in ({"quaternion_wxyz": q.tolist(), "translation_m": T[:3, 3].tolist()},
                 {"quaternion_xyzw": quaternion_xyzw_from_wxyz(q).tolist(),
                  "translation_m": T[:3, 3].tolist()},
                 {"matrix": T.tolist()}):
        frame = {**LOCALIZE_EXAMPLE, "prior": {"world_from_camera": pose,
                                               "covariance": (np.eye(6) * 0.01).tolist()}}
        r = client.post("/v1/maps/chess/localize", json=frame)
        assert r.status_code == 200, r.text
        answers.append(r.json())
    assert all(a["used_prior"] for a in answers)
    for a in answers[1:]:
        np.testing.assert_allclose(a["world_from_camera"]["matrix"],
                                   answers[0]["world_from_camera"]["matrix"], atol=1e-9)
    both = {**LOCALIZE_EXAMPLE, "prior": {"world_from_camera": {
        "quaternion_wxyz": q.tolist(), "quaternion_xyzw": q.tolist(),
        "translation_m": [0, 0, 0]}}}
    r = client.post("/v1/maps/chess/localize", json=both)
    assert r.status_code == 422 and "quaternion_xyzw" in r.text


def test_quaternion_order_and_column_major_round_trip() -> None:
    rng = np.random.default_rng(0)
    q = rng.normal(size=(5, 4))
    np.testing.assert_array_equal(quaternion_wxyz_from_xyzw(quaternion_xyzw_from_wxyz(q)), q)
    assert quaternion_xyzw_from_wxyz(np.array([1.0, 2.0, 3.0, 4.0])).tolist() == [2, 3, 4, 1]
    T = np.arange(16.0).reshape(4, 4)
    assert column_major_from_matrix(T)[:4] == [0.0, 4.0, 8.0, 12.0]  # column 0
    np.testing.assert_array_equal(matrix_from_column_major(column_major_from_matrix(T)), T)


@pytest.mark.parametrize("world_up", ["y", "z"])
def test_unity_pose_maps_points_like_the_mirrored_world(world_up: str) -> None:
    """A point seen by the camera lands, in Unity, on the mirror image of its map position;
    the Unity camera looks along +Z and its +Y is the image's up (-y in OpenCV)."""
    mirror = {"y": np.diag([1.0, 1.0, -1.0]),
              "z": np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])}[world_up]
    rng = np.random.default_rng(1)
    for _ in range(20):
        T = _random_pose(rng)
        position, q_xyzw = unity_pose_from_world_from_camera(T, world_up=world_up)
        R_u = matrix_from_quaternion_wxyz(quaternion_wxyz_from_xyzw(q_xyzw))
        assert np.linalg.det(R_u) == pytest.approx(1.0)
        p_cam_cv = rng.normal(size=3)
        p_cam_unity = p_cam_cv * [1, -1, 1]  # Unity camera: +Y up
        np.testing.assert_allclose(R_u @ p_cam_unity + position,
                                   mirror @ (T[:3, :3] @ p_cam_cv + T[:3, 3]), atol=1e-9)
        # the same pose given with OpenGL camera axes gives the same Unity transform
        p2, q2 = unity_pose_from_world_from_camera(world_from_camera_opencv_to_opengl(T),
                                                   convention="opengl", world_up=world_up)
        np.testing.assert_allclose(p2, position, atol=1e-12)
        assert min(np.abs(q2 - q_xyzw).max(), np.abs(q2 + q_xyzw).max()) < 1e-9


def test_unity_matches_ar_foundation_for_a_y_up_session() -> None:
    """AR Foundation converts an ARKit pose (right-handed, Y up, OpenGL camera axes) to Unity
    with position (x, y, -z) and rotation (-qx, -qy, qz, qw): an independent reference."""
    rng = np.random.default_rng(2)
    for _ in range(10):
        T_gl = world_from_camera_opencv_to_opengl(_random_pose(rng))
        w, x, y, z = quaternion_wxyz_from_matrix(T_gl[:3, :3])
        position, q = unity_pose_from_world_from_camera(T_gl, "opengl", world_up="y")
        np.testing.assert_allclose(position, T_gl[:3, 3] * [1, 1, -1], atol=1e-12)
        expected = np.array([-x, -y, z, w])
        assert min(np.abs(q - expected).max(), np.abs(q + expected).max()) < 1e-9


def test_map_versions_endpoint_and_sdk(client: TestClient) -> None:
    doc = {**MAP_EXAMPLE, "map_id": "versions-test"}
    created = client.post("/v1/maps", json=doc)
    assert created.status_code == 201
    etag = created.headers["etag"]
    updated = client.put("/v1/maps/versions-test", json={**doc, "name": "renamed"},
                         headers={"If-Match": etag})
    assert updated.status_code == 200
    r = client.get("/v1/maps/versions-test/versions")
    assert r.status_code == 200
    body = r.json()
    assert [v["version"] for v in body["versions"]] == [1, 2]
    assert body["versions"][1]["content_hash"] == updated.json()["content_hash"]
    assert body["versions"][0]["content_hash"] == created.json()["content_hash"]
    missing = client.get("/v1/maps/no-such-map/versions")
    assert missing.status_code == 404
    assert missing.headers["content-type"].startswith("application/problem+json")
    # the SDK against the same app
    import httpx

    def handler(request: httpx.Request) -> httpx.Response:
        out = client.request(request.method, request.url.path, headers=request.headers)
        return httpx.Response(out.status_code, headers=out.headers, content=out.content)

    with sdk.QuadLocClient("http://testserver", transport=httpx.MockTransport(handler)) as c:
        versions = c.list_versions("versions-test")
        assert [v.version for v in versions] == [1, 2]
        assert isinstance(versions[0], sdk.MapVersion)
        with pytest.raises(sdk.NotFound):
            c.list_versions("no-such-map")
    client.delete("/v1/maps/versions-test")
