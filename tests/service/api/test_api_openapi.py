"""The published OpenAPI document (docs/openapi.json) and the demo example are up to date, and
the document has what clients need: examples, problem+json errors, security schemes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bench.examples import FRAME_INDEX
from quadloc.factors import metrics
from quadloc.factors.camera import Camera, project_ellipsoid
from quadloc.factors.conics import DegenerateProjectionError, Ellipse
from quadloc.factors.rotations import invert_pose, pose_matrix, snap_to_rotation
from quadloc.maps.demo import load_demo_map
from quadloc.service.api.app import openapi_document, openapi_text
from quadloc.service.schemas.examples import (
    EXAMPLE_TRUE_WORLD_FROM_CAMERA,
    LOCALIZE_EXAMPLE,
    MAP_EXAMPLE,
)
from tests.support.reference_data import CHESS_POSES_PATH as POSES_PATH

REPO = Path(__file__).resolve().parents[3]
OPENAPI_PATH = REPO / "docs" / "openapi.json"
POSES = POSES_PATH


def test_committed_openapi_matches_the_app() -> None:
    assert OPENAPI_PATH.exists(), "run: quadloc openapi --output docs/openapi.json"
    assert OPENAPI_PATH.read_text() == openapi_text(), (
        "docs/openapi.json is stale; regenerate with: quadloc openapi --output docs/openapi.json")


def test_every_operation_is_documented_with_examples_and_problems() -> None:
    doc = openapi_document()
    assert doc["openapi"].startswith("3.")
    assert {"HTTPBearer", "APIKeyHeader"} <= set(doc["components"]["securitySchemes"])
    for path, item in doc["paths"].items():
        for method, op in item.items():
            ok = [c for c in op["responses"] if c.startswith("2")]
            assert ok, (method, path)
            content = op["responses"][ok[0]].get("content")
            if content:  # 204 has no body
                assert any("example" in m or "examples" in m for m in content.values()), \
                    (method, path)
            if "requestBody" in op:
                assert "example" in json.dumps(op["requestBody"]), (method, path)
            for code, resp in op["responses"].items():
                if code.startswith("4"):
                    assert list(resp["content"]) == ["application/problem+json"], (path, code)
                    assert resp["content"]["application/problem+json"]["schema"] == {
                        "$ref": "#/components/schemas/Problem"}


def test_demo_example_is_a_frame_seen_from_its_real_ground_truth_pose() -> None:
    """The example's pose is a real ground-truth pose of the Chess test set, and every
    detection overlaps the true projection of a map object with its label (the simulator adds
    noise and truncation, so the overlap is partial). Independent of the simulator's version."""
    data = json.loads(POSES.read_text())
    frame = data["frames"][FRAME_INDEX]
    camera_from_world = pose_matrix(snap_to_rotation(np.array(frame["R"])), frame["t"])
    np.testing.assert_allclose(EXAMPLE_TRUE_WORLD_FROM_CAMERA, invert_pose(camera_from_world),
                               atol=1e-12)
    assert LOCALIZE_EXAMPLE["frame_id"] == f"{frame['sequence']}/frame-{frame['frame']:06d}"
    cam = LOCALIZE_EXAMPLE["camera"]
    np.testing.assert_allclose([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1]],
                               data["K"])
    camera = Camera(cam["fx"], cam["fy"], cam["cx"], cam["cy"], cam["width"], cam["height"])
    scene = load_demo_map()
    best = []
    for det in LOCALIZE_EXAMPLE["detections"]:
        ellipse = Ellipse(**det["ellipse"])
        ious = []
        for obj in scene.objects:
            if obj.category != det["label"]:
                continue
            try:
                projection = project_ellipsoid(camera, camera_from_world, obj.ellipsoid)
            except DegenerateProjectionError:
                continue
            ious.append(1.0 - metrics.cost("iou", ellipse, projection))
        best.append(max(ious, default=0.0))
    assert len(best) >= 4
    assert min(best) >= 0.3 and float(np.median(best)) >= 0.7, best
    doc_example = json.loads((REPO / "docs" / "examples" / "localize_chess.json").read_text())
    assert doc_example == LOCALIZE_EXAMPLE
    assert json.loads((REPO / "docs" / "examples" / "office_map.json").read_text()) == MAP_EXAMPLE
