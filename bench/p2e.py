"""P2E (two ellipse/ellipsoid pairs): recovery of rolled cameras and time per call.

``python -m bench.p2e [--scenes N] [--seed S] [--max-roll DEG] [--compare PATH]``

Scenes (synthetic, seeded; the generator of ``tests/service/localization/test_hypotheses.py``): two
ellipsoids (semi-axes 0.1-0.4 m, random orientations) about 4 m in front of a camera with the test
intrinsics (640 x 480), looking at their midpoint, rolled uniformly within ``+-max_roll``
degrees about the optical axis. For exact projections: share of scenes whose true pose is among
the hypotheses (every entry of ``[R | t]`` within 1e-6), hypotheses per call, mean wall time
per call. For noisy detections (centres + N(0, 1 px), semi-axes x 1.02 / 0.99): median and 90th
percentile of the best hypothesis' camera position error (m).

``--compare PATH``: a Python file defining another ``p2e_hypotheses`` with the same positional
arguments (e.g. the former zero-roll solver saved from git: ``git show
a50365d:service/localization/hypotheses.py > /tmp/old.py``) measured in the same run, on the
same scenes, interleaved (machine load hits both alike).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from pathlib import Path

import numpy as np

from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import invert_pose
from quadloc.service.localization.hypotheses import p2e_hypotheses
from tests.support.scenes import CAM, UP, random_pair_scene


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=60)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--max-roll", type=float, default=30.0)
    ap.add_argument("--compare", type=Path)
    args = ap.parse_args(argv)
    solvers = {"p2e_hypotheses": p2e_hypotheses}
    if args.compare:
        spec = importlib.util.spec_from_file_location("p2e_compare", args.compare)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)  # type: ignore[union-attr]
        solvers[f"{args.compare.name}"] = mod.p2e_hypotheses
    rng = np.random.default_rng(args.seed)
    stats = {k: {"found": 0, "time": 0.0, "hyps": 0, "noisy_err": []} for k in solvers}
    for _ in range(args.scenes):
        E, ells, T_cw = random_pair_scene(rng, roll=math.radians(rng.uniform(-args.max_roll,
                                                                   args.max_roll)))
        noisy = [Ellipse(e.cx + rng.normal(0, 1), e.cy + rng.normal(0, 1), e.a * 1.02,
                         e.b * 0.99, e.angle) for e in ells]
        centre = invert_pose(T_cw)[:3, 3]
        for name, fn in solvers.items():
            t0 = time.perf_counter()
            H = fn(ells, E, CAM, UP)
            stats[name]["time"] += time.perf_counter() - t0
            stats[name]["hyps"] += len(H)
            stats[name]["found"] += int(bool(len(H)) and min(
                float(np.max(np.abs(S - T_cw))) for S in H) < 1e-6)
            Hn = fn(noisy, E, CAM, UP)
            stats[name]["noisy_err"].append(min(
                (float(np.linalg.norm(invert_pose(S)[:3, 3] - centre)) for S in Hn),
                default=math.inf))
    print(f"{args.scenes} scenes, rolls within +-{args.max_roll:g} deg, seed {args.seed}")
    for name, s in stats.items():
        err = np.array(s["noisy_err"])
        print(f"{name}: true pose found {s['found']}/{args.scenes}, "
              f"{s['time'] / args.scenes * 1e3:.1f} ms/call (exact data), "
              f"{s['hyps'] / args.scenes:.2f} hypotheses/call; noisy: position error of the "
              f"best hypothesis median {np.median(err):.3f} m, p90 {np.quantile(err, 0.9):.3f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
