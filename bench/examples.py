"""Dev-time generator of the REAL localization example (``service/schemas/example_frame.json``).

Simulates the demo frame with ``tests.support.simulate`` at a ground-truth pose of the Chess test
set, solves it with the service's solver, and writes ``service/schemas/example_frame.json``,
``docs/examples/localize_chess.json``, ``docs/examples/office_map.json`` and
``docs/openapi.json``. Run from the checkout::

    .venv/bin/python -m bench.examples

It lives in ``bench`` (not installed, not in the image) because it needs the simulator and the
reference poses; the service only imports the generated data
(:mod:`quadloc.service.schemas.examples`).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from quadloc.factors.rotations import invert_pose
from quadloc.maps.demo import load_demo_map
from quadloc.service.app.context import App
from quadloc.service.schemas.examples import EXAMPLE_FRAME_PATH, MAP_EXAMPLE
from quadloc.service.schemas.localize import LocalizeRequest
from quadloc.service.settings import Settings
from tests.support.reference_data import CHESS_POSES_PATH, load_chess_poses
from tests.support.simulate import simulate_frame

__all__ = ["FRAME_INDEX", "SEED", "build_example_frame", "regenerate"]

_REPO = Path(__file__).resolve().parents[1]
DOC_EXAMPLE_PATH = _REPO / "docs" / "examples" / "localize_chess.json"
DOC_MAP_EXAMPLE_PATH = _REPO / "docs" / "examples" / "office_map.json"
FRAME_INDEX = 40
SEED = 7


def _r(x: float, nd: int = 3) -> float:
    return round(float(x), nd)


def build_example_frame(poses_path: Path | None = None, frame_index: int = FRAME_INDEX,
                        seed: int = SEED) -> tuple[dict[str, Any], list[list[float]], str]:
    """Simulate the demo frame: (request body, true world_from_camera 4x4, source text).

    Needs the source tree (``tests.support.simulate``, ``tests.support.reference_data``) and the
    reference poses (default ``tests.support.reference_data.CHESS_POSES_PATH``,
    ``tests/support/data`` in the checkout); dev-time only (the service imports the generated data,
    never this module).
    """
    camera, camera_from_world_all, names = load_chess_poses(
        CHESS_POSES_PATH if poses_path is None else poses_path)
    sequence, frame_number = names[frame_index].split("/")  # "seq-03/22"
    world_from_camera = invert_pose(camera_from_world_all[frame_index])
    sim = simulate_frame(load_demo_map(), camera, world_from_camera, seed)
    detections = []
    for d in sim.detections:
        e = d.ellipse
        det: dict[str, Any] = {"ellipse": {"cx": _r(e.cx), "cy": _r(e.cy), "a": _r(e.a),
                                           "b": _r(e.b), "angle": _r(e.angle, 5)},
                               "label": d.label}
        if d.sigma is not None:
            det["sigma"] = _r(d.sigma, 5)
        detections.append(det)
    body = {
        "camera": {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                   "width": camera.width, "height": camera.height},
        "detections": detections,
        "frame_id": f"{sequence}/frame-{int(frame_number):06d}",
        "timestamp": 1700000000.0 + frame_index / 30.0,
        "options": {"metric": "level_set", "output_convention": "opencv"},
    }
    source = (f"simulated detections (tests.support.simulate defaults, seed {seed}) of the Chess "
              "demo "
              f"map at the ground-truth pose of chess_test_poses.json frames[{frame_index}] "
              f"({sequence} frame {frame_number})")
    return body, [[float(x) for x in row] for row in world_from_camera], source


def regenerate() -> None:  # pragma: no cover - dev tool
    body, truth, source = build_example_frame()
    app = App.create(Settings(database_url="sqlite://", default_map_id="chess"))
    response = app.localizer.localize("chess", LocalizeRequest.model_validate(body))[1]
    resp = response.model_dump(mode="json")
    resp["timings_ms"] = {k: round(v, 2) for k, v in resp["timings_ms"].items()}
    out = EXAMPLE_FRAME_PATH
    out.write_text(json.dumps({"source": source, "true_world_from_camera": truth,
                               "localize_request": body, "localize_response": resp},
                              indent=1) + "\n")
    DOC_EXAMPLE_PATH.parent.mkdir(parents=True, exist_ok=True)
    DOC_EXAMPLE_PATH.write_text(json.dumps(body, indent=2) + "\n")
    DOC_MAP_EXAMPLE_PATH.write_text(json.dumps(MAP_EXAMPLE, indent=2) + "\n")
    print(f"wrote {out}, {DOC_EXAMPLE_PATH} and {DOC_MAP_EXAMPLE_PATH}", file=sys.stderr)
    # The OpenAPI document embeds these examples: regenerate it in a fresh interpreter.
    subprocess.run([sys.executable, "-m", "quadloc.service.cli", "openapi", "--output",
                    str(_REPO / "docs" / "openapi.json")], check=True, cwd=_REPO)


if __name__ == "__main__":  # pragma: no cover
    regenerate()
