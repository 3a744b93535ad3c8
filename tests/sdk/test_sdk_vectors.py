"""The test vectors shared by the Python, TypeScript and C# SDKs (sdk/test-vectors/*.json):
the committed files are what sdk/test-vectors/generate.py computes with the Python SDK today,
and their values agree with independent computations (scipy's rotations, OpenCV's image
moments, numpy's inverse, closed forms). The TypeScript and C# suites check their SDKs
against the same files (tests/e2e/test_sdk_typescript.py, test_sdk_csharp.py)."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from quadloc.service.api.errors import PROBLEM_TYPES
from quadloc_sdk import errors as sdk_errors
from quadloc_sdk import geometry as g

VECTORS = Path(__file__).resolve().parents[2] / "sdk" / "test-vectors"
TOL = 1e-9  # stated in the files ("tolerance")


def _load(name: str) -> Any:
    return json.loads((VECTORS / name).read_text())


def _generator() -> Any:
    spec = importlib.util.spec_from_file_location("sdk_vectors_generate", VECTORS / "generate.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name", ["poses.json", "ellipses.json", "problems.json",
                                  "build_recording.json"])
def test_committed_vectors_are_what_the_generator_writes(name: str) -> None:
    """Same structure and values as the generator computes here; numbers within
    :data:`REGENERATE_TOL` (another CPU or LAPACK kernel moves the last digits, never more)."""
    stale = _differences(_load(name), json.loads(_generator().render(name)), name)
    assert not stale, (
        f"sdk/test-vectors/{name} is stale ({stale[:3]}): run .venv/bin/python "
        "sdk/test-vectors/generate.py (then the TypeScript and C# suites check their SDKs "
        "against the new values)")


REGENERATE_TOL = 1e-12  # absolute and relative; 1000x below the files' stated tolerance


def _differences(committed: Any, generated: Any, where: str) -> list[str]:
    """Where ``committed`` and ``generated`` (parsed JSON) differ: keys, lengths, strings and
    booleans exactly, numbers within :data:`REGENERATE_TOL`."""
    if isinstance(committed, dict) and isinstance(generated, dict):
        if committed.keys() != generated.keys():
            return [f"{where}: keys {sorted(committed)} != {sorted(generated)}"]
        return [d for k in committed
                for d in _differences(committed[k], generated[k], f"{where}.{k}")]
    if isinstance(committed, list) and isinstance(generated, list):
        if len(committed) != len(generated):
            return [f"{where}: {len(committed)} items != {len(generated)}"]
        return [d for i, (a, b) in enumerate(zip(committed, generated, strict=True))
                for d in _differences(a, b, f"{where}[{i}]")]
    numbers = (int, float)
    if (isinstance(committed, numbers) and isinstance(generated, numbers)
            and not isinstance(committed, bool) and not isinstance(generated, bool)):
        close = math.isclose(committed, generated, rel_tol=REGENERATE_TOL,
                             abs_tol=REGENERATE_TOL)
        return [] if close else [f"{where}: {committed!r} != {generated!r}"]
    return [] if committed == generated else [f"{where}: {committed!r} != {generated!r}"]


def test_vector_comparison_sees_a_changed_value() -> None:
    poses = _load("poses.json")
    assert _differences(poses, poses, "poses") == []
    changed = json.loads(json.dumps(poses))
    changed["poses"][0]["translation_m"][0] += 1e-9
    assert _differences(poses, changed, "poses") == [
        f"poses.poses[0].translation_m[0]: {poses['poses'][0]['translation_m'][0]!r} != "
        f"{changed['poses'][0]['translation_m'][0]!r}"]
    changed["poses"][0]["extra"] = 1
    assert _differences(poses, changed, "poses")[0].startswith("poses.poses[0]: keys")


def test_pose_vectors_against_independent_computations() -> None:
    poses = _load("poses.json")
    assert poses["tolerance"]["absolute"] == TOL
    for c in poses["quaternions"]:
        R = np.array(c["matrix"])
        xyzw = Rotation.from_matrix(R).as_quat()  # scipy: scalar last
        xyzw *= 1 if xyzw[3] >= 0 else -1
        if abs(xyzw[3]) < 1e-6:  # w ~ 0: q and -q both have w >= 0 within rounding
            xyzw *= np.sign(np.dot(xyzw, c["quaternion_xyzw"]))
        np.testing.assert_allclose(c["quaternion_xyzw"], xyzw, atol=1e-9)
        np.testing.assert_allclose(c["quaternion_wxyz"], np.roll(xyzw, 1), atol=1e-9)
        np.testing.assert_allclose(c["matrix_from_quaternion"], R, atol=1e-9)
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    swap_yz = np.array([[1.0, 0, 0], [0, 0, 1], [0, 1, 0]])
    mirror_z = np.diag([1.0, 1.0, -1.0])
    for c in poses["poses"]:
        T = np.array(c["world_from_camera"])
        np.testing.assert_allclose(c["camera_from_world"], np.linalg.inv(T), atol=1e-9)
        np.testing.assert_allclose(c["column_major"], T.flatten(order="F"), atol=0)
        np.testing.assert_allclose(c["world_from_camera_opengl"], T @ flip, atol=1e-12)
        np.testing.assert_allclose(c["translation_m"], T[:3, 3], atol=0)
        for u in c["unity"]:
            # a camera point p (OpenCV axes) is at Unity's M_c p in Unity camera axes; the
            # Unity transform (scipy applies the quaternion) must put it at M_w (T p)
            M_w = swap_yz if u["world_up"] == "z" else mirror_z
            T_cv = T  # u["world_from_camera"] is T in u["convention"]
            if u["convention"] == "opengl":
                np.testing.assert_allclose(u["world_from_camera"], T @ flip, atol=1e-12)
            rot = Rotation.from_quat(u["rotation_xyzw"])
            for p in ([0.1, 0.2, 1.5], [-0.4, 0.3, 0.7], [0.0, 0.0, 0.0]):
                unity_cam = np.diag([1.0, -1.0, 1.0]) @ p
                got = rot.apply(unity_cam) + np.array(u["position"])
                np.testing.assert_allclose(got, M_w @ (T_cv[:3, :3] @ p + T_cv[:3, 3]),
                                           atol=1e-9)
    cov = np.array(poses["covariance"]["opencv"])
    J = np.diag([1.0, -1, -1, 1, -1, -1])
    np.testing.assert_allclose(poses["covariance"]["opengl"], J @ cov @ J.T, atol=1e-15)
    s = poses["session_from_map"]
    np.testing.assert_allclose(s["session_from_map"], np.array(s["session_from_camera"])
                               @ np.linalg.inv(s["map_from_camera"]), atol=1e-9)


def test_python_sdk_refuses_the_invalid_poses() -> None:
    for bad in _load("poses.json")["invalid_poses"]:
        with pytest.raises(ValueError, match="pose"):
            g.invert_pose(np.array(bad["matrix"]))


def _mask(m: dict[str, Any]) -> np.ndarray:
    mask = np.zeros((m["height"], m["width"]), np.uint8)
    for row, c0, c1 in m["runs"]:
        mask[row, c0:c1] = 1
    return mask


def test_ellipse_vectors_against_independent_computations() -> None:
    v = _load("ellipses.json")
    for c in v["boxes"]:
        xmin, ymin, xmax, ymax = c["box"]
        e = c["ellipse"]
        assert (e["cx"], e["cy"]) == ((xmin + xmax) / 2, (ymin + ymax) / 2)
        assert (e["a"], e["b"]) == (max(xmax - xmin, ymax - ymin) / 2,
                                    min(xmax - xmin, ymax - ymin) / 2)
        assert e["angle"] == (0.0 if xmax - xmin >= ymax - ymin else -math.pi / 2)
    for m in v["masks"]:
        mask = _mask(m)
        mo = cv2.moments(mask, binaryImage=True)  # pixel centres at integer coordinates
        cov = np.array([[mo["mu20"], mo["mu11"]], [mo["mu11"], mo["mu02"]]]) / mo["m00"]
        eig = np.linalg.eigvalsh(cov + np.eye(2) / 12)
        e = m["ellipse"]
        assert e["cx"] == pytest.approx(mo["m10"] / mo["m00"] + 0.5, abs=1e-9)
        assert e["cy"] == pytest.approx(mo["m01"] / mo["m00"] + 0.5, abs=1e-9)
        assert [e["a"], e["b"]] == pytest.approx(2 * np.sqrt(eig[::-1]), abs=1e-9)
        assert -math.pi / 2 <= e["angle"] < math.pi / 2
    rect = next(m for m in v["masks"] if m["name"] == "rectangle")["ellipse"]
    # 161 x 81 unit squares: variance w^2 / 12 per side, so a = 161 / sqrt(3)
    assert (rect["a"], rect["b"]) == pytest.approx((161 / math.sqrt(3), 81 / math.sqrt(3)),
                                                   abs=1e-9)
    rotated = next(m for m in v["masks"] if m["name"] == "rotated-ellipse")["ellipse"]
    assert (rotated["cx"], rotated["cy"], rotated["a"], rotated["b"]) == pytest.approx(
        (80.3, 58.7, 55.0, 22.0), abs=0.3)
    assert rotated["angle"] == pytest.approx(0.6, abs=0.01)
    for c in v["log_variance"]:
        assert c["sigma"] == pytest.approx(math.exp(c["log_variance"] / 2), rel=1e-15)


def test_python_sdk_matches_the_ellipse_vectors() -> None:
    v = _load("ellipses.json")
    for m in v["masks"]:
        got = g.ellipse_from_mask(_mask(m))
        e = m["ellipse"]
        assert [got.cx, got.cy, got.a, got.b] == pytest.approx(
            [e["cx"], e["cy"], e["a"], e["b"]], abs=TOL)
        d = (got.angle - e["angle"] + math.pi / 2) % math.pi - math.pi / 2
        assert abs(d) <= TOL


def test_problem_vectors_are_the_servers_problem_types_and_the_sdks_classes() -> None:
    problems = _load("problems.json")["problems"]
    assert {p["slug"]: (p["status"], p["title"]) for p in problems} == PROBLEM_TYPES, (
        "the server's problem types changed: run .venv/bin/python sdk/test-vectors/generate.py")
    for p in problems:
        response = httpx.Response(
            p["status"], json={"type": p["type"], "title": p["title"], "status": p["status"],
                               "detail": "d", "errors": [{"field": "camera.fx", "message": "m"}]},
            headers={"content-type": "application/problem+json"},
            request=httpx.Request("POST", "http://quadloc.test/v1/maps/chess/localize"))
        err = sdk_errors.error_from_response(response)
        assert type(err).__name__ == p["error"], p
        assert err.fields == ["camera.fx"] and err.type == p["type"]
