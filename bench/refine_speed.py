"""Speed and accuracy of the pose refinement, every metric, against the paper's BFGS baseline.

``python -m bench.refine_speed [--json PATH] [--trials T] [--seed S] [--write-results]``

Scenes (synthetic, seeded): N = 3, 5, 8, 16 ellipsoids (semi-axes 0.08-0.35 m, random
orientations) 2-6 m in front of a camera with the Chess intrinsics (640 x 480), each fully in
front of the camera with its projected centre inside the image. Detections are the exact
projections corrupted by detection noise (centre +N(0, 1.5 px), semi-axes x(1 + N(0, 0.03)),
angle +N(0, 1 deg)), no sigma. Start: the true pose moved 10 cm and rotated 5 degrees (random
directions). Accuracy = distance between refined and true camera centres (m); with noisy
detections this is the metric's accuracy, not the solver's.

For every metric and N: median / p90 wall time of one
:func:`quadloc.service.localization.refine.refine` call (graph build, LM, covariance), median CPU
time of the same call (robust to the shared machine's load), mean LM iterations, median position
error, fraction ``status == converged``.

Baseline (paper-style, same run): ``scipy.optimize.minimize(method="BFGS")`` with its default
finite-difference gradient (2-point, default ``eps``) and default ``gtol = 1e-5``, over the same
level-set cost (same fixed sample points: ``scale = s_max`` of the start, ``adaptive=False``),
computed with a Python loop over objects (``project_ellipsoid`` + ``quadloc.factors.metrics.cost``),
on the pose parametrised as ``world_from_camera = T0 @ Exp(x)``, ``x`` in R^6.

Convergence basin (level set): exact detections of the real Chess map from its 108 real poses,
starts 5 deg / 10 cm up to 30 deg / 75 cm away; fraction refined back within 1e-6 m.

Design comparison (level set): the same LM solve with (a) ONE batched factor (Diagonal noise),
(b) one factor per detection sharing one memoised evaluation, (c) one factor per detection each
evaluating itself; timings interleaved so machine load hits all three alike.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
from pathlib import Path

import gtsam
import numpy as np
from scipy.optimize import minimize

from quadloc.factors import metrics
from quadloc.factors.camera import Camera, Ellipsoid, ellipsoid_depth_margins, project_ellipsoid
from quadloc.factors.conics import DegenerateProjectionError, Ellipse
from quadloc.factors.pose_factors import pose_factor, pose_factors
from quadloc.factors.pose_residuals import expmap_pose3
from quadloc.factors.rotations import invert_pose, rotation_from_quaternion_wxyz
from quadloc.service.localization.refine import _lm_params, refine
from quadloc.service.localization.types import Detection
from tests.support.reference_data import (
    CHESS_SCENE_PATH,
    load_chess_map,
    load_chess_poses,
    perturb_pose,
)

SIZES = (3, 5, 8, 16)
CAMERA = Camera(532.57, 531.54, 320.0, 240.0, 640, 480)
#: trials per (metric, N); the slow exact-area metrics get fewer
TRIALS = {"level_set": 40, "iou": 5, "giou": 5}
DEFAULT_TRIALS = 10
BFGS_TRIALS = 8


def make_scene(rng: np.random.Generator, n: int) -> list[Ellipsoid]:
    """n ellipsoids in front of the identity camera pose (camera frame = world frame)."""
    out: list[Ellipsoid] = []
    while len(out) < n:
        z = rng.uniform(2.0, 6.0)
        u, v = rng.uniform(40, CAMERA.width - 40), rng.uniform(40, CAMERA.height - 40)
        center = np.array([(u - CAMERA.cx) / CAMERA.fx * z, (v - CAMERA.cy) / CAMERA.fy * z, z])
        q = rng.normal(size=4)
        q = q / np.linalg.norm(q) * np.sign(q[0])
        e = Ellipsoid(center, rng.uniform(0.08, 0.35, 3), rotation_from_quaternion_wxyz(q))
        if ellipsoid_depth_margins(np.eye(4), e.center[None], e.shape_matrix()[None])[0] > 0.3:
            out.append(e)
    return out


def noisy(rng: np.random.Generator, e: Ellipse) -> Ellipse:
    return Ellipse(e.cx + rng.normal(0, 1.5), e.cy + rng.normal(0, 1.5),
                   e.a * (1 + rng.normal(0, 0.03)), e.b * (1 + rng.normal(0, 0.03)),
                   e.angle + math.radians(rng.normal(0, 1.0)))


def make_trials(seed: int, n: int, count: int) -> list[dict]:
    rng = np.random.default_rng([seed, n])
    trials = []
    for _ in range(count):
        ells = make_scene(rng, n)
        truth = np.eye(4)
        dets = [Detection(noisy(rng, project_ellipsoid(CAMERA, truth, e)), f"o{j}")
                for j, e in enumerate(ells)]
        trials.append({"ells": ells, "dets": dets, "truth": truth,
                       "start": perturb_pose(truth, rng, 0.10, 5.0)})
    return trials


def position_error(T: np.ndarray, truth: np.ndarray) -> float:
    return float(np.linalg.norm(T[:3, 3] - truth[:3, 3]))


# --------------------------------------------------------------------------- baseline


def bfgs_refine(dets: list[Detection], ells: list[Ellipsoid], T0: np.ndarray
                ) -> tuple[np.ndarray, int]:
    """Paper-style: scipy BFGS, finite-difference gradient, Python loop over the objects."""
    cfw0 = invert_pose(T0)
    scales = []
    for d, e in zip(dets, ells, strict=True):
        try:
            proj = project_ellipsoid(CAMERA, cfw0, e)
        except DegenerateProjectionError:
            proj = None
        scales.append(metrics.level_set_sampling_scale(d.ellipse, proj))

    def cost(x: np.ndarray) -> float:
        cfw = invert_pose(T0 @ expmap_pose3(x))
        total = 0.0
        for d, e, s in zip(dets, ells, scales, strict=True):
            try:
                proj = project_ellipsoid(CAMERA, cfw, e)
            except DegenerateProjectionError:
                return 1e8
            total += metrics.cost("level_set", d.ellipse, proj, scale=s, adaptive=False)
        return total

    res = minimize(cost, np.zeros(6), method="BFGS")
    return T0 @ expmap_pose3(res.x), int(res.nit)


# --------------------------------------------------------------------------- design comparison


def lm_solve(factors: list, T0: np.ndarray) -> np.ndarray:
    graph = gtsam.NonlinearFactorGraph()
    for f in factors:
        graph.add(f)
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3(T0))
    return gtsam.LevenbergMarquardtOptimizer(graph, values, _lm_params(50)).optimize()


def design_comparison(trials: list[dict]) -> dict[str, dict[str, float]]:
    def batched(t: dict) -> None:
        fs, _ = pose_factors("level_set", 0, [d.ellipse for d in t["dets"]], t["ells"], CAMERA,
                             initial_world_from_camera=t["start"], batched=True)
        lm_solve(fs, t["start"])

    def shared(t: dict) -> None:
        fs, _ = pose_factors("level_set", 0, [d.ellipse for d in t["dets"]], t["ells"], CAMERA,
                             initial_world_from_camera=t["start"])
        lm_solve(fs, t["start"])

    def separate(t: dict) -> None:
        fs = [pose_factor("level_set", 0, d.ellipse, e, CAMERA,
                          initial_world_from_camera=t["start"])
              for d, e in zip(t["dets"], t["ells"], strict=True)]
        lm_solve(fs, t["start"])

    designs = {"batched_one_factor": batched, "per_detection_shared_cache": shared,
               "per_detection_separate": separate}
    wall: dict[str, list[float]] = {k: [] for k in designs}
    cpu: dict[str, list[float]] = {k: [] for k in designs}
    for t in trials:
        for name, fn in designs.items():
            w0, c0 = time.perf_counter(), time.process_time()
            fn(t)
            wall[name].append((time.perf_counter() - w0) * 1e3)
            cpu[name].append((time.process_time() - c0) * 1e3)
    return {k: {"median_ms": float(np.median(wall[k])), "cpu_median_ms": float(np.median(cpu[k]))}
            for k in designs}


# --------------------------------------------------------------------------- convergence basin

BASIN_STARTS = ((5.0, 0.10), (10.0, 0.30), (15.0, 0.40), (20.0, 0.50), (30.0, 0.75))


def chess_basin(seed: int) -> dict[str, dict[str, float]] | None:
    """Level-set refinement from exact detections of the real Chess map at its 108 real poses,
    started rot_deg / trans_m away (random directions): fraction back within 1e-6 m."""
    if not CHESS_SCENE_PATH.exists():
        return None
    ells = [o.ellipsoid for o in load_chess_map().objects]
    cam, camera_from_world, _ = load_chess_poses()
    rng = np.random.default_rng(seed)
    out = {}
    for rot, trans in BASIN_STARTS:
        ok, ms = 0, []
        for cfw in camera_from_world:
            truth = invert_pose(cfw)
            dets, objs = [], []
            for j, e in enumerate(ells):
                try:
                    dets.append(Detection(project_ellipsoid(cam, cfw, e), f"o{j}"))
                    objs.append(e)
                except DegenerateProjectionError:
                    continue
            res = refine(dets, objs, cam, perturb_pose(truth, rng, trans, rot))
            ok += position_error(res.world_from_camera, truth) < 1e-6
            ms.append(res.time_ms)
        out[f"{rot:g}deg_{trans:g}m"] = {"success_fraction": ok / len(camera_from_world),
                                         "median_ms": float(np.median(ms)),
                                         "frames": len(camera_from_world)}
    return out


# --------------------------------------------------------------------------- main


def run(seed: int, trials_override: int | None) -> dict:
    out: dict = {"refine": {m: {} for m in metrics.METRIC_NAMES}, "baseline_bfgs": {},
                 "speedup_vs_bfgs": {}, "design_level_set_lm_only": {}}
    for n in SIZES:
        counts = {m: trials_override or TRIALS.get(m, DEFAULT_TRIALS)
                  for m in metrics.METRIC_NAMES}
        trials = make_trials(seed, n, max([*counts.values(), BFGS_TRIALS]))
        refine(trials[0]["dets"], trials[0]["ells"], CAMERA, trials[0]["start"])  # warm-up
        # trials interleaved across metrics, so that a burst of load from other jobs on the
        # machine hits every metric alike instead of one (metric, N) cell
        rec: dict[str, dict[str, list]] = {
            m: {"wall": [], "cpu": [], "its": [], "err": [], "conv": []}
            for m in metrics.METRIC_NAMES}
        for i, t in enumerate(trials):
            for metric in metrics.METRIC_NAMES:
                if i >= counts[metric]:
                    continue
                w0, c0 = time.perf_counter(), time.process_time()
                res = refine(t["dets"], t["ells"], CAMERA, t["start"], metric)
                rec[metric]["wall"].append((time.perf_counter() - w0) * 1e3)
                rec[metric]["cpu"].append((time.process_time() - c0) * 1e3)
                rec[metric]["its"].append(res.iterations)
                rec[metric]["err"].append(position_error(res.world_from_camera, t["truth"]))
                rec[metric]["conv"].append(res.status == "converged")
        for metric in metrics.METRIC_NAMES:
            wall, cpu, its, err, conv = (rec[metric][k]
                                         for k in ("wall", "cpu", "its", "err", "conv"))
            out["refine"][metric][str(n)] = {
                "median_ms": float(np.median(wall)), "p90_ms": float(np.percentile(wall, 90)),
                "cpu_median_ms": float(np.median(cpu)), "iterations": float(np.mean(its)),
                "position_error_m": float(np.median(err)),
                "converged_fraction": float(np.mean(conv)), "trials": len(wall),
            }
        wall, cpu, its, err = [], [], [], []
        for t in trials[:BFGS_TRIALS]:
            w0, c0 = time.perf_counter(), time.process_time()
            T, nit = bfgs_refine(t["dets"], t["ells"], t["start"])
            wall.append((time.perf_counter() - w0) * 1e3)
            cpu.append((time.process_time() - c0) * 1e3)
            its.append(nit)
            err.append(position_error(T, t["truth"]))
        out["baseline_bfgs"][str(n)] = {
            "median_ms": float(np.median(wall)), "p90_ms": float(np.percentile(wall, 90)),
            "cpu_median_ms": float(np.median(cpu)), "iterations": float(np.mean(its)),
            "position_error_m": float(np.median(err)), "trials": len(wall),
        }
        ls = out["refine"]["level_set"][str(n)]
        out["speedup_vs_bfgs"][str(n)] = out["baseline_bfgs"][str(n)]["median_ms"] / \
            ls["median_ms"]
        out["design_level_set_lm_only"][str(n)] = design_comparison(trials[:20])
    out["chess_basin_level_set"] = chess_basin(seed)
    return out


def markdown(res: dict) -> str:
    lines = ["## Pose refinement speed (`refine_speed`)", "",
             f"Run on {platform.python_implementation()} "
             f"{platform.python_version()}, numpy {np.__version__}, a 2-core shared machine ("
             "wall times vary by up to ~40% between runs: compare within one run). "
             "Scenes, noise and baseline are described in `bench/refine_speed.py`.", "",
             "### Level-set refinement vs the paper's BFGS baseline (same run)", "",
             "| N | level-set median (ms) | p90 (ms) | CPU median (ms) | LM iterations | "
             "position error (m) | BFGS median (ms) | BFGS CPU median (ms) | BFGS iterations | "
             "BFGS position error (m) | speed-up (wall) | speed-up (CPU) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for n in SIZES:
        r, b = res["refine"]["level_set"][str(n)], res["baseline_bfgs"][str(n)]
        lines.append(f"| {n} | {r['median_ms']:.2f} | {r['p90_ms']:.2f} | "
                     f"{r['cpu_median_ms']:.2f} | {r['iterations']:.1f} | "
                     f"{r['position_error_m']:.4f} | {b['median_ms']:.0f} | "
                     f"{b['cpu_median_ms']:.0f} | {b['iterations']:.0f} | "
                     f"{b['position_error_m']:.4f} | {res['speedup_vs_bfgs'][str(n)]:.0f}x | "
                     f"{b['cpu_median_ms'] / r['cpu_median_ms']:.0f}x |")
    ls8, ls16 = res["refine"]["level_set"]["8"], res["refine"]["level_set"]["16"]
    sp8 = res["speedup_vs_bfgs"]["8"]

    def verdict(ok: bool) -> str:
        return "met" if ok else "MISSED"

    lines += ["", "Targets (2-core machine): level-set median <= 2 ms at N=8: "
              f"{ls8['median_ms']:.2f} ms, {verdict(ls8['median_ms'] <= 2.0)}; <= 3 ms at "
              f"N=16: {ls16['median_ms']:.2f} ms, {verdict(ls16['median_ms'] <= 3.0)}; >= 100x "
              f"faster than BFGS at N=8: {sp8:.0f}x, {verdict(sp8 >= 100)}. The CPU-time column "
              "is what the refinement itself costs; wall time above it is time the process "
              "waited for a core (other jobs on the machine)."]
    lines += ["", "### Every metric: median wall ms / p90 ms / LM iterations / median position "
              "error (m) / converged fraction", "",
              "| metric | " + " | ".join(f"N={n}" for n in SIZES) + " |",
              "|---|" + "---|" * len(SIZES)]
    for m in metrics.METRIC_NAMES:
        cells = []
        for n in SIZES:
            r = res["refine"][m][str(n)]
            cells.append(f"{r['median_ms']:.1f} / {r['p90_ms']:.1f} / {r['iterations']:.1f} / "
                         f"{r['position_error_m']:.3f} / {r['converged_fraction']:.2f}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    basin = res.get("chess_basin_level_set")
    if basin:
        lines += ["", "### Convergence basin: real Chess poses, exact detections, level set", "",
                  "Exact projections of the Chess map from its 108 real ground-truth poses; "
                  "start rotated / moved by the given amounts (random directions); success = "
                  "refined camera centre within 1e-6 m of the truth.", "",
                  "| start offset | success | median ms |", "|---|---|---|"]
        for key, v in basin.items():
            rot, trans = key.split("_")
            lines.append(f"| {rot.replace('deg', ' deg')} / {trans.replace('m', ' m')} | "
                         f"{v['success_fraction'] * v['frames']:.0f} / {v['frames']} | "
                         f"{v['median_ms']:.2f} |")
    lines += ["", "### Factor design (level set, LM solve only, median wall / CPU ms)", "",
              "| N | one batched factor | per-detection, shared memoised evaluation | "
              "per-detection, separate evaluations |", "|---|---|---|---|"]
    for n in SIZES:
        d = res["design_level_set_lm_only"][str(n)]
        cells = [f"{d[k]['median_ms']:.2f} / {d[k]['cpu_median_ms']:.2f}"
                 for k in ("batched_one_factor", "per_detection_shared_cache",
                           "per_detection_separate")]
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    lines += ["", "Design chosen (`factors/pose_factors.py`): every detection's residual comes "
              "from ONE vectorised evaluation of all pairs per pose (`PoseResidualModel`, "
              "memoised on the pose value, Jacobians computed eagerly for analytic metrics). "
              "`refine()` wraps it in one batched factor (Diagonal noise with std "
              "`sqrt(sigma_j)` per detection block: exactly the per-detection weights) when no "
              "robust kernel is asked for, and in one factor per detection slicing the shared "
              "evaluation when one is (a robust kernel must see one detection's residual). "
              "Separate per-detection evaluations (the usual 'one factor per object') cost "
              "N times the numpy calls, see the last column.",
              "", "Notes: the baseline's cost per function evaluation is N projections "
              "(`project_ellipsoid`, validated `Ellipse`) and N `metrics.cost` calls, and BFGS "
              "needs 7 evaluations per iteration for its forward-difference gradient; the ratio, "
              "not the absolute time, is what this run shows (a shared machine). Position errors "
              "are dominated by the simulated detection noise (all metrics reach similar "
              "accuracy; the level set's advantages in the paper concern partially visible "
              "objects and detector errors, not Gaussian noise). `iou`/`giou` compute the exact "
              "areas and their gradients of all pairs per evaluation (one call of a compiled "
              "kernel, `quadloc.factors.overlap.quadrant_sums`) and take more LM iterations at "
              "their kinked noisy optimum, and `qbbox` uses central differences (12 extra metric "
              "evaluations per pair per linearisation), hence their times."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", type=Path, default=None, help="write the results as JSON here")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--trials", type=int, default=None,
                    help="trials per (metric, N) (default: 40 level set, 5 iou/giou, 10 others)")
    ap.add_argument("--write-results", action="store_true",
                    help="write the refine_speed section of docs/results.md")
    args = ap.parse_args(argv)
    command = "python -m bench.refine_speed" + (f" --seed {args.seed}" if args.seed else "") + (
        f" --trials {args.trials}" if args.trials else "") + " --write-results"
    res = run(args.seed, args.trials)
    res["command"] = command
    md = markdown(res)
    print(md)
    if args.json:
        args.json.write_text(json.dumps(res, indent=2))
    if args.write_results:
        from bench.results_doc import update_results_section

        update_results_section("refine_speed", md)


if __name__ == "__main__":
    main()
