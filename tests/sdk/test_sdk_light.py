"""The light SDK distribution: ``pip install ./sdk/python`` into a fresh virtual environment (no
system site-packages) brings only httpx and pydantic, and the client, its models and the
overlay work there without numpy, gtsam or the server.

Slow (a venv and a pip install through the package mirror/cache: ~20 s here), bounded by
timeouts. The source is copied to a temporary directory first so the build leaves nothing in
the checkout.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

CHECK = r'''
import importlib.util, json, sys
from pathlib import Path
import httpx
import quadloc_sdk as sdk
from quadloc_sdk.overlay import overlay_svg

for heavy in ("numpy", "gtsam", "cv2", "fastapi", "sqlalchemy", "quadloc"):
    assert importlib.util.find_spec(heavy) is None, f"{heavy} is installed with the light SDK"
assert Path(sdk.__file__).parent.joinpath("py.typed").is_file()

data = json.loads(Path(sys.argv[1]).read_text())
request, answer, scene_map = data["request"], data["answer"], data["map"]

def handler(req: httpx.Request) -> httpx.Response:
    if req.url.path == "/v1/maps/chess/localize":
        body = json.loads(req.content)
        assert body["camera"] == request["camera"], body
        return httpx.Response(200, json=answer)
    if req.url.path == "/v1/maps/chess":
        return httpx.Response(200, json={"map_id": "chess", "version": 1,
                                         "content_hash": "0" * 64, "map": scene_map},
                              headers={"ETag": '"' + "0" * 64 + '"'})
    return httpx.Response(404, json={"type": "urn:quadloc:problem:map-not-found",
                                     "title": "Map not found", "status": 404,
                                     "detail": "no such map"},
                          headers={"Content-Type": "application/problem+json"})

with sdk.QuadLocClient("http://quadloc.test", transport=httpx.MockTransport(handler)) as c:
    got = c.localize("chess", request)
    assert got.localized and got.world_from_camera.quaternion_xyzw is not None
    record = c.get_map("chess", version=got.map_version)
    try:
        c.get_map("nope")
        raise AssertionError("no NotFound")
    except sdk.NotFound as exc:
        assert exc.status == 404
    try:  # request models validate before sending, naming the field
        sdk.Camera(fx=-1, fy=1, cx=0, cy=0, width=1, height=1)
        raise AssertionError("no validation error")
    except ValueError as exc:
        assert "fx" in str(exc)
svg = overlay_svg(request, got, record.map)
assert svg.count('class="detection inlier"') == len(answer["inliers"]), svg[:500]
assert svg.count('class="projection matched"') == len({m["object_id"] for m in answer["inliers"]})
print("LIGHT-SDK-OK", sdk.__version__)
'''


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_light_sdk_installs_alone_and_works(tmp_path: Path) -> None:
    from fastapi.testclient import TestClient

    from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE
    from tests.conftest import make_test_app

    # A real answer and map document from the server, for the isolated client to consume.
    with TestClient(make_test_app(tmp_path / "server")) as client:
        answer = client.post("/v1/maps/chess/localize", json=LOCALIZE_EXAMPLE).json()
        scene_map = client.get("/v1/maps/chess").json()["map"]
    data = tmp_path / "data.json"
    data.write_text(json.dumps({"request": LOCALIZE_EXAMPLE, "answer": answer,
                                "map": scene_map}))

    src = tmp_path / "sdk-src"
    shutil.copytree(REPO / "sdk" / "python", src, ignore=shutil.ignore_patterns(
        "build", "*.egg-info", "__pycache__"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=60)
    py = venv / "bin" / "python"
    install = subprocess.run([str(py), "-m", "pip", "install", "--disable-pip-version-check",
                              "-q", str(src)], capture_output=True, text=True, timeout=180)
    assert install.returncode == 0, install.stdout[-2000:] + install.stderr[-2000:]
    listed = subprocess.run([str(py), "-m", "pip", "list", "--format=json"],
                            capture_output=True, text=True, timeout=60, check=True)
    names = {p["name"].lower() for p in json.loads(listed.stdout)}
    assert "quadloc-sdk" in names and "httpx" in names and "pydantic" in names
    assert not names & {"numpy", "gtsam", "opencv-python-headless", "fastapi", "sqlalchemy"}
    script = tmp_path / "check.py"
    script.write_text(CHECK)
    # Run outside the checkout, so nothing of the repository is importable.
    run = subprocess.run([str(py), "-I", str(script), str(data)], capture_output=True,
                         text=True, timeout=60, cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "LIGHT-SDK-OK" in run.stdout
