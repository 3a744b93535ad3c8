"""IoU / GIoU as refinement metrics on the real Chess map (issue 14, part 1), against level set.

For each of the 108 real poses (``bench/data``), with the TRUE associations (this measures the
refinement alone, not the hypothesis search):

* exact detections (``SimulationConfig.exact()``, every object overlapping the image), start
  0.1 m / 5 degrees off the truth (``bench.reference_data.perturb_pose``): the position error
  after ``refine()``, which must be <= 1e-6 m on every frame;
* noisy detections (``SimulationConfig()``: truncation, occlusion, misses, noise, sigma),
  same kind of start: the share of solves that end ``converged`` (not capped by the iteration
  limit), the position error, and the refinement CPU time (``time.process_time``; the solve is
  single-threaded), whose median is compared with level set's in the same run.

Frames with fewer than 3 detections are skipped (a pose is not determined). Prints a table
and JSON (``--json PATH``); ``--write-results`` replaces its section of ``docs/results.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from bench.chess_eval import load_chess_world_from_camera, pose_errors
from bench.reference_data import load_chess_map, perturb_pose
from bench.results_doc import update_results_section
from bench.simulate import SimulationConfig, simulate_frame
from maps.compiled import compile_map
from service.localization.refine import refine

METRICS = ("iou", "giou", "level_set")
EXACT_TOLERANCE_M = 1e-6


def _solve(frame, compiled, camera, start, metric):
    ids = [compiled.index_of(o) for o in frame.object_ids]
    ells = [compiled.ellipsoids[i] for i in ids]
    t = time.process_time()
    res = refine(list(frame.detections), ells, camera, start, metric)
    return res, (time.process_time() - t) * 1e3


def run(seed: int = 1, frames: int = 108, log=print) -> dict:
    compiled = compile_map(load_chess_map())
    camera, poses, _ = load_chess_world_from_camera()
    poses = poses[:frames]
    rng = np.random.default_rng(seed)
    out: dict = {"seed": seed, "frames": len(poses), "start": "0.1 m / 5 deg",
                 "metrics": {m: {"exact_pos_m": [], "noisy_pos_m": [], "noisy_status": [],
                                 "noisy_cpu_ms": [], "exact_cpu_ms": []} for m in METRICS}}
    noisy_cfg = SimulationConfig()
    for i, truth in enumerate(poses):
        exact = simulate_frame(compiled, camera, truth, int(i), SimulationConfig.exact())
        noisy = simulate_frame(compiled, camera, truth, rng, noisy_cfg)
        start = perturb_pose(truth, rng, 0.10, 5.0)
        for m in METRICS:
            rec = out["metrics"][m]
            if len(exact) >= 3:
                res, ms = _solve(exact, compiled, camera, start, m)
                rec["exact_pos_m"].append(pose_errors(res.world_from_camera, truth)[0])
                rec["exact_cpu_ms"].append(ms)
            if len(noisy) >= 3:
                res, ms = _solve(noisy, compiled, camera, start, m)
                rec["noisy_pos_m"].append(pose_errors(res.world_from_camera, truth)[0])
                rec["noisy_status"].append(res.status)
                rec["noisy_cpu_ms"].append(ms)
        if (i + 1) % 20 == 0:
            log(f"  {i + 1}/{len(poses)} frames")
    summary = {}
    ls_median = float(np.median(out["metrics"]["level_set"]["noisy_cpu_ms"]))
    for m, rec in out["metrics"].items():
        ep, npos = np.array(rec["exact_pos_m"]), np.array(rec["noisy_pos_m"])
        status = np.array(rec["noisy_status"])
        median_ms = float(np.median(rec["noisy_cpu_ms"]))
        summary[m] = {
            "exact_frames": int(ep.size),
            "exact_max_pos_m": float(ep.max()),
            "exact_within_1e-6_m": float(np.mean(ep <= EXACT_TOLERANCE_M)),
            "noisy_frames": int(npos.size),
            "noisy_converged": float(np.mean(status == "converged")),
            "noisy_capped": float(np.mean(status == "max_iterations")),
            "noisy_within_5cm": float(np.mean(npos <= 0.05)),
            "noisy_within_10cm": float(np.mean(npos <= 0.10)),
            "noisy_median_pos_m": float(np.median(npos)),
            "cpu_ms_median": median_ms,
            "cpu_ms_p90": float(np.percentile(rec["noisy_cpu_ms"], 90)),
            "cpu_ratio_to_level_set": median_ms / ls_median,
        }
    out["summary"] = summary
    return out


def markdown(result: dict, command: str) -> str:
    lines = [f"Command: `{command}` (seed {result['seed']}, {result['frames']} real poses, true "
             f"associations, starts {result['start']} off; CPU time of `refine()`).", "",
             "| metric | exact: max error (m) / within 1e-6 m | noisy: converged / capped | "
             "noisy: within 5 / 10 cm, median error | CPU ms median / p90 | x level set |",
             "|---|---|---|---|---|---|"]
    for m, s in result["summary"].items():
        lines.append(
            f"| {m} | {s['exact_max_pos_m']:.1e} / {100 * s['exact_within_1e-6_m']:.1f}% | "
            f"{100 * s['noisy_converged']:.1f}% / {100 * s['noisy_capped']:.1f}% | "
            f"{100 * s['noisy_within_5cm']:.1f}% / {100 * s['noisy_within_10cm']:.1f}%, "
            f"{100 * s['noisy_median_pos_m']:.2f} cm | {s['cpu_ms_median']:.1f} / "
            f"{s['cpu_ms_p90']:.1f} | {s['cpu_ratio_to_level_set']:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frames", type=int, default=108)
    ap.add_argument("--json", default=None)
    ap.add_argument("--write-results", action="store_true")
    args = ap.parse_args(argv)
    result = run(args.seed, args.frames, log=lambda s: print(s, file=sys.stderr))
    table = markdown(result, "python -m bench.overlap_refinement " + " ".join(argv or sys.argv[1:]))
    print(table)
    print(json.dumps(result["summary"], indent=2))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh)
    if args.write_results:
        update_results_section("overlap_refinement",
                               "## IoU / GIoU refinement on the Chess map (issue 14)\n\n" + table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
