"""``quadloc track --map ID recording.json``: replay a recorded session in process.

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
from collections.abc import Callable
from typing import Any

__all__ = ["add_track_parser", "cmd_track"]


def add_track_parser(sub: Any, db: Callable[[argparse.ArgumentParser], None]) -> None:
    """Register the ``track`` sub-command on the CLI's sub-parsers."""
    p = sub.add_parser("track", help="replay a recorded tracking session (prints the trajectory)",
                       description=__doc__.split("\n\n", 1)[1],
                       epilog="example:\n  quadloc track --map chess "
                              "docs/examples/track_chess.json\n",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", help="recording JSON ('-' = stdin)")
    p.add_argument("--map", required=True, metavar="ID", help="map id")
    p.add_argument("--json", action="store_true", help="print the frame results as JSON")
    db(p)
    p.set_defaults(func=cmd_track)


def cmd_track(args: argparse.Namespace) -> int:
    import numpy as np
    from pydantic import ValidationError

    from quadloc.service.api.convert import convert_pose
    from quadloc.service.api.errors import ProblemError, field_path
    from quadloc.service.api.routers.sessions import _frame_input, _frame_out, new_session
    from quadloc.service.cli import _die, _invalid, _read_json, _store
    from quadloc.service.schemas.sessions import SessionCreate, SessionFramesIn

    doc = _read_json(args.file)
    if not isinstance(doc, dict):
        return _die(f"{args.file}: must be a JSON object")
    truth = doc.pop("ground_truth_world_from_camera", None)
    try:
        frames = SessionFramesIn.model_validate({"frames": doc.pop("frames", [])})
        create = SessionCreate.model_validate(doc)
    except ValidationError as exc:
        return _invalid([(field_path(e["loc"]), e["msg"]) for e in exc.errors()],
                        f"{args.file}: invalid recording")
    if truth is not None and (not isinstance(truth, list) or len(truth) != len(frames.frames)):
        return _die(f"{args.file}: ground_truth_world_from_camera must have one entry per frame")
    session = new_session(_store(args).compiled(args.map, None), create)
    conv = create.convention
    errors: list[tuple[float, float]] = []
    tracked = 0
    out = []
    for i, f in enumerate(frames.frames):
        try:
            r = session.add_frame(_frame_input(f, conv, f"frames[{i}]."))
        except ProblemError as exc:
            return _die(f"{args.file}: {exc.errors[0]['field']}: {exc.detail}")
        out.append(_frame_out(r, conv).model_dump())
        line = f"{i:5d} {r.state:12s}"
        if r.world_from_camera is not None:
            tracked += 1
            c = r.world_from_camera[:3, 3]
            line += f" xyz=({c[0]:+.3f}, {c[1]:+.3f}, {c[2]:+.3f}) conf={r.confidence:.2f}"
            if truth is not None and truth[i] is not None:
                T = convert_pose(np.array(truth[i], dtype=float), conv, "opencv")
                dp = float(np.linalg.norm(T[:3, 3] - c))
                cosang = (np.trace(T[:3, :3].T @ r.world_from_camera[:3, :3]) - 1) / 2
                da = math.degrees(math.acos(max(-1.0, min(1.0, cosang))))
                errors.append((dp, da))
                line += f" err={dp * 100:.1f}cm/{da:.1f}deg"
        if not args.json:
            print(line)
    summary = sys.stderr if args.json else sys.stdout
    if args.json:
        print(json.dumps(out, indent=1))
    print(f"frames {len(frames.frames)}, tracked {tracked}", file=summary)
    if errors:
        e = np.array(errors)
        msg = (f"trajectory error over {len(e)} frames: position median "
               f"{np.median(e[:, 0]) * 100:.1f} cm, p90 {np.percentile(e[:, 0], 90) * 100:.1f} "
               f"cm; rotation median {np.median(e[:, 1]):.2f} deg; within 10 cm and 5 deg "
               f"{100 * np.mean((e[:, 0] <= 0.1) & (e[:, 1] <= 5)):.1f} %")
        print(msg, file=summary)
    return 0 if tracked else 1
