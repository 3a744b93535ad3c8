"""The published OpenAPI document (docs/openapi.json) and the demo example are up to date, and
the document has what clients need: examples, problem+json errors, security schemes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from service.api.examples import (
    EXAMPLE_TRUE_WORLD_FROM_CAMERA,
    LOCALIZE_EXAMPLE,
    build_example_frame,
)
from service.cli import OPENAPI_PATH, openapi_document, openapi_text

REPO = Path(__file__).resolve().parents[1]


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


def test_demo_example_is_the_simulated_frame_at_a_real_pose() -> None:
    """The example body is what the simulator produces at the stated ground-truth pose."""
    poses = REPO.parent / "shared" / "data" / "chess_test_poses.json"
    body, truth, _ = build_example_frame(poses)
    assert body == LOCALIZE_EXAMPLE
    np.testing.assert_allclose(truth, EXAMPLE_TRUE_WORLD_FROM_CAMERA, atol=0)
    doc_example = json.loads((REPO / "docs" / "examples" / "localize_chess.json").read_text())
    assert doc_example == LOCALIZE_EXAMPLE
