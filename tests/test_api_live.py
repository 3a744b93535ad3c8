"""End to end against a real Uvicorn server on a loopback port (tests/conftest.py fixtures):
the documented curl examples of docs/api.md run as written, plus HTTP-level behaviour that
only a real server shows (chunked bodies over the limit, auth with keys, metrics)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import httpx
import numpy as np
import pytest

from service.api.examples import EXAMPLE_TRUE_WORLD_FROM_CAMERA, LOCALIZE_EXAMPLE
from service.settings import hash_api_key

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "api.md"
DOC_BASE = "http://127.0.0.1:8000"


def documented_blocks() -> list[tuple[str, str]]:
    """``(expected substring, bash block)`` for each block marked ``<!-- expect: ... -->``."""
    text = DOC.read_text()
    return re.findall(r"<!-- expect: (.*?) -->\n```bash\n(.*?)```", text, flags=re.S)


def test_docs_have_runnable_examples() -> None:
    blocks = documented_blocks()
    assert len(blocks) >= 12
    assert all(DOC_BASE in block for _, block in blocks)


@pytest.mark.skipif(shutil.which("curl") is None, reason="curl is not installed")
def test_documented_curl_examples_work_as_written(live_server: str) -> None:
    blocks = documented_blocks()
    script = ["set -u"]
    for i, (_, block) in enumerate(blocks):
        script.append(f"echo '@@BLOCK {i}@@'")
        script.append(block.replace(DOC_BASE, live_server))
    proc = subprocess.run(["bash", "-c", "\n".join(script)], cwd=REPO, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    outputs = re.split(r"@@BLOCK \d+@@\n", proc.stdout)[1:]
    assert len(outputs) == len(blocks), proc.stdout
    for (expect, block), out in zip(blocks, outputs, strict=True):
        assert expect.lower() in out.lower(), f"{block}\n--- got ---\n{out[:2000]}"


def test_real_server_localizes_the_demo_frame(live_server: str) -> None:
    with httpx.Client(base_url=live_server, timeout=30) as client:
        assert client.get("/readyz").json()["status"] == "ready"
        r = client.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE)
        assert r.status_code == 200
        T = np.array(r.json()["world_from_camera"]["matrix"])
        truth = np.array(EXAMPLE_TRUE_WORLD_FROM_CAMERA)
        assert np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 0.05
        metrics = client.get("/metrics").text
        assert 'quadloc_localizations_total{outcome="localized"}' in metrics


def test_chunked_body_over_the_limit_is_413(live_server_factory) -> None:
    base = live_server_factory({"QUADLOC_MAX_BODY_BYTES": "4096"})

    def chunks():
        for _ in range(64):
            yield b" " * 1024

    with httpx.Client(base_url=base, timeout=30) as client:
        r = client.post("/v1/maps/chess/localize", content=chunks(),
                        headers={"content-type": "application/json"})
        assert r.status_code == 413
        assert r.headers["content-type"].startswith("application/problem+json")
        ok = client.post("/v1/maps/chess/localize", content=json.dumps(LOCALIZE_EXAMPLE),
                         headers={"content-type": "application/json"})
        assert ok.status_code == 200


def test_real_server_with_keys(live_server_factory) -> None:
    base = live_server_factory({"QUADLOC_API_KEYS": f"{hash_api_key('r')}:read"})
    with httpx.Client(base_url=base, timeout=30) as client:
        assert client.get("/v1/maps").status_code == 401
        assert client.get("/v1/maps", headers={"X-API-Key": "r"}).status_code == 200
        assert client.delete("/v1/maps/chess", headers={"X-API-Key": "r"}).status_code == 403
        assert client.get("/healthz").status_code == 200
