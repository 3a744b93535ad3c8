"""``quadloc track --map ID recording.json``: replay a recorded session in this process.

Recording format (JSON): ``{"camera": {fx, fy, cx, cy, width, height}, "convention": "opencv"
| "opengl", "options": {...session options...}, "frames": [...frames as for POST
/v1/sessions/{id}/frames...], "ground_truth_world_from_camera": [4x4 | null, ...]}``; the last
key is optional (one entry per frame, in the recording's convention). Prints one line per frame
(state, camera position, confidence) and, with ground truth, the trajectory error of the frames
with a pose. Exit status 0 when some frame was tracked, 1 otherwise, 2 on bad input.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np
from pydantic import ValidationError

from quadloc.factors.rotations import rotation_angle
from quadloc.service.cli.common import CliError, local_app, read_json
from quadloc.service.schemas.common import field_path
from quadloc.service.schemas.sessions import SessionCreate, SessionFramesIn

__all__ = ["cmd_track"]


def _recording(path: str) -> tuple[SessionCreate, SessionFramesIn, list[object] | None]:
    """(the session's parameters, its frames, the ground truth or None) of a recording."""
    doc = read_json(path)
    if not isinstance(doc, dict):
        raise CliError(f"{path}: must be a JSON object")
    truth = doc.pop("ground_truth_world_from_camera", None)
    try:
        frames = SessionFramesIn.model_validate({"frames": doc.pop("frames", [])})
        create = SessionCreate.model_validate(doc)
    except ValidationError as exc:
        raise CliError(f"{path}: invalid recording", problems=[
            (field_path(e["loc"]), e["msg"]) for e in exc.errors()]) from exc
    if truth is not None and (not isinstance(truth, list) or len(truth) != len(frames.frames)):
        raise CliError(f"{path}: ground_truth_world_from_camera must have one entry per frame")
    return create, frames, truth


def cmd_track(args: argparse.Namespace) -> int:
    create, frames, truth = _recording(args.file)
    app = local_app(args)
    app.warm_up()  # before the first frame: no frame pays for it
    sessions = app.sessions
    session = sessions.create(args.map, create)
    results = sessions.add_frames(session.session_id, frames).results
    errors: list[tuple[float, float]] = []
    tracked = 0
    for i, r in enumerate(results):
        line = f"{i:5d} {r.state:12s}"
        if r.world_from_camera is not None:
            tracked += 1
            T = np.array(r.world_from_camera.matrix, dtype=float)
            c = T[:3, 3]
            line += f" xyz=({c[0]:+.3f}, {c[1]:+.3f}, {c[2]:+.3f}) conf={r.confidence:.2f}"
            if truth is not None and truth[i] is not None:
                true_T = np.array(truth[i], dtype=float)  # both in the session's axes
                dp = float(np.linalg.norm(true_T[:3, 3] - c))
                da = math.degrees(float(rotation_angle(true_T[:3, :3], T[:3, :3])))
                errors.append((dp, da))
                line += f" err={dp * 100:.1f}cm/{da:.1f}deg"
        if not args.json:
            print(line)
    summary = sys.stderr if args.json else sys.stdout
    if args.json:
        print(json.dumps([r.model_dump() for r in results], indent=1))
    print(f"frames {len(results)}, tracked {tracked}", file=summary)
    if errors:
        e = np.array(errors)
        msg = (f"trajectory error over {len(e)} frames: position median "
               f"{np.median(e[:, 0]) * 100:.1f} cm, p90 {np.percentile(e[:, 0], 90) * 100:.1f} "
               f"cm; rotation median {np.median(e[:, 1]):.2f} deg; within 10 cm and 5 deg "
               f"{100 * np.mean((e[:, 0] <= 0.1) & (e[:, 1] <= 5)):.1f} %")
        print(msg, file=summary)
    app.close()
    return 0 if tracked else 1
