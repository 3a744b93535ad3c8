"""Writes the test vectors shared by the Python, TypeScript and C# SDKs (this folder's *.json).

The expected values are computed by the Python SDK (``quadloc_sdk.geometry``, the reference);
tests/sdk/test_sdk_vectors.py checks them against independent computations and checks that
this script still writes the committed files, sdk/typescript/test/vectors.test.ts and
sdk/csharp/tests check the two other SDKs against them.

    .venv/bin/python sdk/test-vectors/generate.py            # rewrite the files
    .venv/bin/python sdk/test-vectors/generate.py --check    # exit 1 when a file is stale

Files:

* ``poses.json``: quaternion <-> rotation (both orders), pose inversion, OpenCV <-> OpenGL
  camera axes, the covariance flip, column-major layout, session_from_map, Unity's
  left-handed pose (both world_up, both conventions), and poses every SDK must refuse.
* ``ellipses.json``: box -> inscribed ellipse, canonical ellipses, mask -> moment ellipse
  (masks as runs ``[row, first column, last column + 1]``), log-variance <-> sigma.
* ``problems.json``: every problem type the server documents (slug, HTTP status) and the error
  class the SDKs raise for it (the Python name; TypeScript uses the same names, C# adds the
  suffix ``Exception``).
* ``build_recording.json``: a small recording (24 posed frames, 3 objects) that builds a map in
  seconds: the map-building fixture of the SDKs' live tests.

Numbers are written with Python's shortest round-trip repr, so every language parses the same
doubles.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from quadloc_sdk import errors as sdk_errors
from quadloc_sdk import geometry as g

HERE = Path(__file__).resolve().parent


def _rotation(axis: list[float], angle: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _pose(R: np.ndarray, t: list[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def _rotations() -> list[np.ndarray]:
    rng = np.random.default_rng(31)
    out = [np.eye(3), _rotation([1, 0, 0], math.pi), _rotation([0, 1, 0], math.pi),
           _rotation([0, 0, 1], math.pi), _rotation([1, 1, 0], math.pi - 1e-7),
           _rotation([0.2, -0.5, 0.8], 1e-9), _rotation([0, 0, 1], math.pi / 2),
           _rotation([1, -2, 0.5], 2.5)]
    for _ in range(6):
        axis = rng.normal(size=3)
        out.append(_rotation(list(axis), float(rng.uniform(0, math.pi))))
    return out


def poses() -> dict[str, Any]:
    rng = np.random.default_rng(7)
    quaternions = []
    for R in _rotations():
        q = g.quaternion_wxyz_from_matrix(R)
        quaternions.append({"matrix": R.tolist(), "quaternion_wxyz": q.tolist(),
                            "quaternion_xyzw": g.quaternion_xyzw_from_wxyz(q).tolist(),
                            "matrix_from_quaternion": g.matrix_from_quaternion_wxyz(q).tolist()})
    cases = []
    for i, R in enumerate(_rotations()[::2] + _rotations()[1::4]):
        t = [round(float(x), 6) for x in rng.uniform(-3, 3, size=3)]
        T = _pose(R, t)
        q, tt = g.quaternion_wxyz_translation_from_pose(T)
        unity = []
        for convention in ("opencv", "opengl"):
            pose = T if convention == "opencv" else g.world_from_camera_opencv_to_opengl(T)
            for world_up in ("y", "z"):
                position, rotation_xyzw = g.unity_pose_from_world_from_camera(
                    pose, convention=convention, world_up=world_up)  # type: ignore[arg-type]
                unity.append({"convention": convention, "world_up": world_up,
                              "world_from_camera": pose.tolist(),
                              "position": position.tolist(),
                              "rotation_xyzw": rotation_xyzw.tolist()})
        cases.append({
            "name": f"pose-{i}",
            "world_from_camera": T.tolist(),
            "camera_from_world": g.to_camera_from_world(T).tolist(),
            "quaternion_wxyz": q.tolist(),
            "translation_m": tt.tolist(),
            "column_major": g.column_major_from_matrix(T),
            "world_from_camera_opengl": g.world_from_camera_opencv_to_opengl(T).tolist(),
            "unity": unity,
        })
    A = rng.normal(size=(6, 6))
    cov = A @ A.T * 1e-4
    session_from_camera = _pose(_rotation([0, 1, 0], 0.4), [0.1, 1.5, -0.3])
    map_from_camera = _pose(_rotation([1, 0.3, 0], -1.1), [2.0, -0.5, 0.8])
    bad_rotation = np.eye(4)
    bad_rotation[0, 0] = 1.1
    reflection = np.diag([1.0, 1.0, -1.0, 1.0])
    bad_last_row = np.eye(4)
    bad_last_row[3, 0] = 0.5
    return {
        "tolerance": {"absolute": 1e-9},
        "quaternions": quaternions,
        "poses": cases,
        "covariance": {"opencv": cov.tolist(),
                       "opengl": g.covariance_opencv_to_opengl(cov).tolist()},
        "session_from_map": {
            "session_from_camera": session_from_camera.tolist(),
            "map_from_camera": map_from_camera.tolist(),
            "session_from_map": g.session_from_map(session_from_camera,
                                                   map_from_camera).tolist()},
        "invalid_poses": [
            {"why": "rotation block not orthonormal", "matrix": bad_rotation.tolist()},
            {"why": "rotation block is a reflection (det -1)", "matrix": reflection.tolist()},
            {"why": "last row is not [0, 0, 0, 1]", "matrix": bad_last_row.tolist()},
        ],
    }


def _runs_mask(width: int, height: int, runs: list[list[int]]) -> np.ndarray:
    m = np.zeros((height, width), np.uint8)
    for row, c0, c1 in runs:
        m[row, c0:c1] = 1
    return m


def _runs_of(mask: np.ndarray) -> list[list[int]]:
    runs = []
    for i, row in enumerate(mask):
        j = 0
        while j < len(row):
            if row[j]:
                k = j
                while k < len(row) and row[k]:
                    k += 1
                runs.append([i, j, k])
                j = k
            else:
                j += 1
    return runs


def _ellipse_dict(e: Any) -> dict[str, float]:
    return {"cx": e.cx, "cy": e.cy, "a": e.a, "b": e.b, "angle": e.angle}


def ellipses() -> dict[str, Any]:
    boxes = [[276.0, 115.0, 361.0, 179.0], [10.0, 200.0, 110.0, 420.0], [0.5, 0.5, 1.5, 3.25],
             [100.0, 100.0, 150.0, 150.0]]
    canonical = [[300.0, 200.0, 80.0, 40.0, 0.1], [300.0, 200.0, 40.0, 80.0, 0.1],
                 [10.0, 20.0, 5.0, 3.0, 2.0], [10.0, 20.0, 5.0, 3.0, -2.0],
                 [0.0, 0.0, 2.0, 1.0, math.pi / 2], [0.0, 0.0, 2.0, 1.0, -math.pi / 2],
                 [0.0, 0.0, 2.0, 1.0, 7.5]]
    masks = []
    # the docs/sdk.md example: rows 100..180, columns 200..360 of a 640 x 480 image
    rect = np.zeros((480, 640), np.uint8)
    rect[100:181, 200:361] = 1
    masks.append(("rectangle", rect))
    # a rotated ellipse rasterised at pixel centres
    yy, xx = np.mgrid[0:120, 0:160] + 0.5
    c, s = math.cos(0.6), math.sin(0.6)
    u = (xx - 80.3) * c + (yy - 58.7) * s
    v = -(xx - 80.3) * s + (yy - 58.7) * c
    masks.append(("rotated-ellipse", ((u / 55.0) ** 2 + (v / 22.0) ** 2 <= 1).astype(np.uint8)))
    # a ragged region of two components (partial, noisy instance mask)
    rng = np.random.default_rng(3)
    ragged = np.zeros((40, 50), np.uint8)
    for i in range(5, 30):
        a, b = sorted(rng.integers(3, 45, size=2))
        ragged[i, a:b + 1] = 1
    ragged[33:37, 40:48] = 1
    masks.append(("ragged-two-components", ragged))
    # a tall thin region (angle near -pi/2)
    tall = np.zeros((30, 10), np.uint8)
    tall[2:28, 4:6] = 1
    masks.append(("tall", tall))
    return {
        "tolerance": {"absolute": 1e-9, "angle": "compared modulo pi"},
        "boxes": [{"box": b, "ellipse": _ellipse_dict(g.ellipse_from_box(tuple(b)))}
                  for b in boxes],
        "canonical": [{"input": c_, "ellipse": _ellipse_dict(g.canonical_ellipse(*c_))}
                      for c_ in canonical],
        "masks": [{"name": name, "width": int(m.shape[1]), "height": int(m.shape[0]),
                   "runs": _runs_of(m), "ellipse": _ellipse_dict(g.ellipse_from_mask(m))}
                  for name, m in masks],
        "log_variance": [{"log_variance": a, "sigma": g.sigma_from_log_variance(a)}
                         for a in (-10.1, -4.2, 0.0, 1.5)],
    }


def problems() -> dict[str, Any]:
    from quadloc.service.api.errors import PROBLEM_TYPES

    out = []
    for slug, (status, title) in PROBLEM_TYPES.items():
        cls = sdk_errors._BY_STATUS.get(status) or (
            sdk_errors.ServerError if status >= 500 else sdk_errors.ClientError)
        out.append({"slug": slug, "type": f"urn:quadloc:problem:{slug}", "status": status,
                    "title": title, "error": cls.__name__})
    return {"problems": out}


def build_recording() -> dict[str, Any]:
    """24 posed frames on an arc around three objects (two of one label), exact detections."""
    from quadloc.factors.camera import Camera, Ellipsoid, project_ellipsoid
    from quadloc.factors.rotations import invert_pose, pose_matrix
    from quadloc.maps.building.recording import recording_to_dict

    cam = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)
    objects = [("Box", Ellipsoid(np.array([0.3, 0.0, 2.0]), np.array([0.15, 0.1, 0.08]))),
               ("Box", Ellipsoid(np.array([-0.4, 0.1, 2.3]), np.array([0.12, 0.12, 0.1]))),
               ("Lamp", Ellipsoid(np.array([0.0, -0.3, 2.6]), np.array([0.08, 0.2, 0.08])))]
    frames = []
    n = 24
    for i in range(n):
        ang = math.radians(-35 + 70 * i / (n - 1))
        eye = np.array([2.2 * math.sin(ang), 0.1 * math.cos(3 * ang), 2.2 - 2.2 * math.cos(ang)])
        z = np.array([0.0, 0.0, 2.2]) - eye
        z /= np.linalg.norm(z)
        x = np.cross(np.array([0.0, -1.0, 0.0]), z)
        x /= np.linalg.norm(x)
        T = pose_matrix(np.column_stack([x, np.cross(z, x), z]), eye)
        dets = []
        for label, ell in objects:
            e = project_ellipsoid(cam, invert_pose(T), ell)
            dets.append({"label": label, "ellipse": {
                "cx": round(e.cx, 6), "cy": round(e.cy, 6), "a": round(e.a, 6),
                "b": round(e.b, 6), "angle": round(e.angle, 9)}})
        frames.append((f"f{i}", T, dets))
    return recording_to_dict(cam, frames, name="SDK test room")


FILES = {"poses.json": poses, "ellipses.json": ellipses, "problems.json": problems,
         "build_recording.json": build_recording}


def render(name: str) -> str:
    return json.dumps(FILES[name](), indent=1) + "\n"


def main(argv: list[str]) -> int:
    stale = []
    for name in FILES:
        text = render(name)
        path = HERE / name
        if "--check" in argv:
            if not path.exists() or path.read_text() != text:
                stale.append(name)
        else:
            path.write_text(text)
            print(f"wrote sdk/test-vectors/{name}")
    if stale:
        print(f"stale: {stale}: run .venv/bin/python sdk/test-vectors/generate.py",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
