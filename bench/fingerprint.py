"""Behaviour fingerprint: the outputs of ``localize()``, a tracking session and a map build over
a fixed set of inputs, written as JSON, and a comparison of two such files.

Used around restructurings that must not change behaviour (issue 27): run it on the tree before
and after, then compare::

    python -m bench.fingerprint --output before.json      # on the old tree
    python -m bench.fingerprint --output after.json       # on the new tree
    python -m bench.fingerprint --compare before.json after.json

Inputs (all seeded, time budgets far above any solve so that no budget binds): simulated
detections of 12 real Chess test poses solved with every metric (and ``none``), with and
without sigma weights, with a perturbed prior, with a simulated gravity, reduced to 3 and to 2
detections; a 90-frame tracking walk with odometry; a 60-frame map build. Floats are compared
with a tolerance (``--atol``, default 1e-6: different code paths may round differently; any
change in a decision, a count or a label is reported whatever the tolerance).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

FRAME_STRIDE = 9
BUDGET_MS = 60_000.0


def _f(x: Any) -> Any:
    """JSON-able floats (NaN / inf as strings), nested lists of arrays."""
    if x is None:
        return None
    if isinstance(x, np.ndarray):
        return [_f(v) for v in x.tolist()]
    if isinstance(x, list | tuple):
        return [_f(v) for v in x]
    if isinstance(x, float | np.floating):
        v = float(x)
        return v if math.isfinite(v) else repr(v)
    if isinstance(x, np.integer):
        return int(x)
    return x


def _result(r: Any) -> dict[str, Any]:
    return {
        "localized": r.localized, "reason": r.reason,
        "world_from_camera": _f(r.world_from_camera), "covariance": _f(r.covariance),
        "confidence": _f(r.confidence),
        "inliers": [[m.detection_index, m.object_id, _f(m.iou), _f(m.cost)] for m in r.inliers],
        "metric": r.metric, "hypotheses_evaluated": r.hypotheses_evaluated,
        "used_prior": r.used_prior, "refinement_status": r.refinement_status,
        "pose_source": r.pose_source,
        "alternatives": [[_f(a.world_from_camera), _f(a.confidence), a.n_inliers, _f(a.score)]
                         for a in r.alternatives],
        "evidence": None if r.evidence is None else {k: _f(v) for k, v in
                                                     sorted(r.evidence.items())},
    }


def localize_cases() -> list[dict[str, Any]]:
    from quadloc.factors.rotations import invert_pose
    from quadloc.maps.compiled import compile_map
    from quadloc.service.limits import METRICS, NO_REFINEMENT
    from quadloc.service.localization.pipeline import localize
    from quadloc.service.localization.types import Gravity, LocalizationOptions, PosePrior
    from tests.support.reference_data import load_chess_map, load_chess_poses, perturb_pose
    from tests.support.simulate import SimulationConfig, simulate_frame, simulate_gravity

    cm = compile_map(load_chess_map())
    camera, cfw, _ = load_chess_poses()
    out: list[dict[str, Any]] = []
    for i in range(0, len(cfw), FRAME_STRIDE):
        truth = invert_pose(cfw[i])
        frame = simulate_frame(cm, camera, truth, np.random.default_rng([27, i]),
                               SimulationConfig())
        dets = list(frame.detections)
        if len(dets) < 2:
            continue
        for metric in (*METRICS, NO_REFINEMENT):
            opts = LocalizationOptions(metric=metric, time_budget_ms=BUDGET_MS, seed=i)
            out.append({"case": f"frame{i}/{metric}",
                        **_result(localize(dets, cm, camera, opts))})
        base = LocalizationOptions(time_budget_ms=BUDGET_MS, seed=i)
        out.append({"case": f"frame{i}/no_sigma", **_result(localize(
            dets, cm, camera, LocalizationOptions(use_sigma=False, time_budget_ms=BUDGET_MS,
                                                  seed=i)))})
        rng = np.random.default_rng([27, i, 1])
        prior_T = perturb_pose(truth, rng, 0.05, 3.0)
        cov = np.diag([math.radians(3.0) ** 2] * 3 + [0.05 ** 2] * 3)
        out.append({"case": f"frame{i}/prior", **_result(localize(
            dets, cm, camera, base, PosePrior(prior_T, cov)))})
        g = simulate_gravity(truth, cm.scene_map.up, 1.0, rng)
        out.append({"case": f"frame{i}/gravity", **_result(localize(
            dets, cm, camera, base, None, Gravity(g, 2.0)))})
        for n in (3, 2):
            if len(dets) > n:
                keep = sorted(rng.permutation(len(dets))[:n].tolist())
                out.append({"case": f"frame{i}/reduced{n}", **_result(localize(
                    [dets[k] for k in keep], cm, camera, base))})
    return out


def session_case() -> list[dict[str, Any]]:
    from quadloc.service.tracking.session import SessionOptions, TrackingSession
    from tests.support.walks import chess_walk

    walk = chess_walk(90, seed=2027)
    # no deadline (add_frame's default): the initialisation's sampling must not depend on the load
    session = TrackingSession(walk.compiled, walk.camera, SessionOptions())
    out = []
    for i, frame in enumerate(walk.frames):
        r = session.add_frame(frame)
        out.append({"frame": i, "state": r.state, "world_from_camera": _f(r.world_from_camera),
                    "world_from_odom": _f(r.world_from_odom), "confidence": _f(r.confidence),
                    "covariance": _f(r.covariance),
                    "inliers": [[m.detection_index, m.object_id] for m in r.inliers]})
    return out


def build_case() -> dict[str, Any]:
    from bench.map_building import _det_json
    from quadloc.factors.rotations import invert_pose
    from quadloc.maps.building.build import build_map
    from quadloc.maps.building.recording import recording_to_dict
    from quadloc.maps.compiled import compile_map
    from quadloc.service.app.builds import recording_of
    from tests.support.reference_data import load_chess_map, load_chess_poses
    from tests.support.simulate import SimulationConfig, simulate_frame
    from tests.support.walks import drifting_odometry as odometry
    from tests.support.walks import resampled_walk as walk

    cm = compile_map(load_chess_map())
    camera, cfw, _ = load_chess_poses()
    truth = walk([invert_pose(T) for T in cfw], 60)
    rng = np.random.default_rng([2027, 16])
    app = odometry(truth, rng)
    cfg = SimulationConfig(wrong_label_probability=0.05, spurious_rate=0.2)
    frames = [simulate_frame(cm, camera, T, rng, cfg) for T in truth]
    doc = recording_to_dict(camera, [(str(i), app[i], [_det_json(d) for d in f.detections])
                                     for i, f in enumerate(frames)], name="fingerprint")
    scene, report = build_map(recording_of(doc), map_id="fp")
    report = json.loads(json.dumps(report.model_dump(mode="json"), default=_f))
    return {"objects": [{"object_id": o.object_id, "category": o.category,
                         "center": _f(o.ellipsoid.center), "axes": _f(o.ellipsoid.axes),
                         "rotation": _f(o.ellipsoid.rotation)} for o in scene.objects],
            "report": report}


def fingerprint() -> dict[str, Any]:
    return {"localize": localize_cases(), "session": session_case(), "build": build_case()}


def _diff(a: Any, b: Any, path: str, atol: float, out: list[str]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k in ("timings_ms",) or k.endswith("_s") or k.startswith("time"):
                continue
            if k not in a or k not in b:
                out.append(f"{path}.{k}: only in {'after' if k in b else 'before'}")
                continue
            _diff(a[k], b[k], f"{path}.{k}", atol, out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{path}: length {len(a)} != {len(b)}")
            return
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _diff(x, y, f"{path}[{k}]", atol, out)
    elif (isinstance(a, float | int) and isinstance(b, float | int)
          and not isinstance(a, bool) and not isinstance(b, bool)):
        if not abs(a - b) <= atol * max(1.0, abs(a)):
            out.append(f"{path}: {a!r} != {b!r}")
    elif a != b:
        out.append(f"{path}: {a!r} != {b!r}")


def compare(before: dict[str, Any], after: dict[str, Any], atol: float) -> list[str]:
    """Every difference (a path and the two values) beyond the relative tolerance ``atol``."""
    out: list[str] = []
    _diff(before, after, "", atol, out)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--output", help="write the fingerprint here (JSON)")
    p.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    p.add_argument("--atol", type=float, default=1e-6)
    args = p.parse_args(argv)
    if args.compare:
        a, b = (json.loads(Path(x).read_text()) for x in args.compare)
        diffs = compare(a, b, args.atol)
        for d in diffs[:200]:
            print(d)
        n = sum(len(v) if isinstance(v, list) else 1 for v in a.values())
        print(f"{len(diffs)} difference(s) beyond {args.atol:g} over {n} cases")
        return 1 if diffs else 0
    fp = fingerprint()
    text = json.dumps(fp, indent=0, sort_keys=True)
    if args.output:
        Path(args.output).write_text(text)
    else:
        sys.stdout.write(text)
    print(f"localize cases {len(fp['localize'])}, session frames {len(fp['session'])}, "
          f"built objects {len(fp['build']['objects'])}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
