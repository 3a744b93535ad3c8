"""IoU / GIoU as refinement metrics on the real Chess map (issue 14, part 1), against level set.

For each of the 108 real poses (``tests/support/data``), with the TRUE associations (this measures
the refinement alone, not the hypothesis search):

* exact detections (``SimulationConfig.exact()``, every object overlapping the image), start
  0.1 m / 5 degrees off the truth (``tests.support.reference_data.perturb_pose``): the position
  error after ``refine()``, which must be <= 1e-6 m on every frame;
* noisy detections (``SimulationConfig()``: truncation, occlusion, misses, noise, sigma),
  same kind of start: the share of solves that end ``converged`` (not capped by the iteration
  limit), the position error, and the refinement CPU time (``time.process_time``; the solve is
  single-threaded), whose median is compared with level set's in the same run.

Frames with fewer than 3 detections are skipped (a pose is not determined). Prints a table
and JSON (``--json PATH``); ``--write-results`` replaces its section of ``docs/results.md``.
``--from-json PATH`` re-renders an earlier run without solving; ``--before-json PATH`` adds
the table of another run (e.g. the same command on an earlier commit, started together) as
"before"; ``--notes PATH`` appends a markdown file (observations from other benches of the
same session, each stating its command) to the section.

``--eval-cost`` measures instead the cost of ONE model evaluation (residuals and Jacobians of
all pairs at a pose) of a 7-pair Chess frame, and of its exact areas alone
(``quadloc.factors.overlap.quadrant_sums``, as that evaluation calls it), for iou and giou; with
``--compare-tree DIR`` the same measurement runs alternately in another checkout (its own
``.venv``), so that both are timed in the same period.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench.results_doc import REPO_ROOT, tree_python, tree_version, update_results_section
from quadloc.maps.compiled import compile_map
from quadloc.service.localization.refine import refine
from tests.support.errors import pose_errors
from tests.support.reference_data import load_chess_map, load_chess_world_from_camera, perturb_pose
from tests.support.simulate import SimulationConfig, simulate_frame

METRICS = ("iou", "giou", "level_set")
EXACT_TOLERANCE_M = 1e-6


#: model evaluations computed (not memoised) since the start, counted by :func:`_counting`
_EVALUATIONS = [0]


def _counting() -> None:
    """Count the model's computed evaluations (every metric ends one in ``_saturate``); the
    wrapper only counts (its time is part of the CPU measured, a few us per solve)."""
    from quadloc.factors.pose_residuals import PoseResidualModel

    saturate = PoseResidualModel._saturate
    if getattr(saturate, "_counts", False):
        return

    def counted(self, ev):
        _EVALUATIONS[0] += 1
        return saturate(self, ev)

    counted._counts = True
    PoseResidualModel._saturate = counted


def _solve(frame, compiled, camera, start, metric):
    ids = [compiled.index_of(o) for o in frame.object_ids]
    ells = [compiled.ellipsoids[i] for i in ids]
    n0 = _EVALUATIONS[0]
    t = time.process_time()
    res = refine(list(frame.detections), ells, camera, start, metric)
    ms = (time.process_time() - t) * 1e3
    return res, ms, _EVALUATIONS[0] - n0


def run(seed: int = 1, frames: int = 108, log=print) -> dict:
    compiled = compile_map(load_chess_map())
    camera, poses, _ = load_chess_world_from_camera()
    poses = poses[:frames]
    rng = np.random.default_rng(seed)
    out: dict = {"seed": seed, "frames": len(poses), "start": "0.1 m / 5 deg",
                 "metrics": {m: {"exact_pos_m": [], "noisy_pos_m": [], "noisy_status": [],
                                 "noisy_cpu_ms": [], "exact_cpu_ms": [],
                                 "noisy_iterations": [], "noisy_evaluations": []}
                             for m in METRICS}}
    _counting()
    noisy_cfg = SimulationConfig()
    for i, truth in enumerate(poses):
        exact = simulate_frame(compiled, camera, truth, int(i), SimulationConfig.exact())
        noisy = simulate_frame(compiled, camera, truth, rng, noisy_cfg)
        start = perturb_pose(truth, rng, 0.10, 5.0)
        for m in METRICS:
            rec = out["metrics"][m]
            if len(exact) >= 3:
                res, ms, _ = _solve(exact, compiled, camera, start, m)
                rec["exact_pos_m"].append(pose_errors(res.world_from_camera, truth)[0])
                rec["exact_cpu_ms"].append(ms)
            if len(noisy) >= 3:
                res, ms, evaluations = _solve(noisy, compiled, camera, start, m)
                rec["noisy_pos_m"].append(pose_errors(res.world_from_camera, truth)[0])
                rec["noisy_status"].append(res.status)
                rec["noisy_cpu_ms"].append(ms)
                rec["noisy_iterations"].append(int(res.iterations))
                rec["noisy_evaluations"].append(evaluations)
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
            "noisy_iterations_median": float(np.median(rec["noisy_iterations"])),
            "noisy_evaluations_median": float(np.median(rec["noisy_evaluations"])),
            "noisy_evaluations_per_iteration": float(np.sum(rec["noisy_evaluations"])
                                                     / max(np.sum(rec["noisy_iterations"]), 1)),
        }
    out["summary"] = summary
    return out


def eval_cost(reps: int = 400, seed: int = 3, blocks: int = 10) -> dict:
    """CPU ms (``time.process_time``) of one iou / giou model evaluation (Jacobians included,
    each at a new pose near the start, so nothing is memoised) of the first noisy Chess frame
    with 7 detections, and of the exact areas of that evaluation alone (the
    ``quadloc.factors.overlap.quadrant_sums`` calls it makes, replayed); ``reps`` of each, timed in
    ``blocks`` alternating blocks, the fastest block's mean."""
    import quadloc.factors.metrics as fm
    from quadloc.factors.pose_residuals import PoseResidualModel, expmap_pose3

    compiled = compile_map(load_chess_map())
    camera, poses, _ = load_chess_world_from_camera()
    rng = np.random.default_rng(seed)
    for truth in poses:
        frame = simulate_frame(compiled, camera, truth, rng, SimulationConfig())
        if len(frame) == 7:
            break
    ells = [compiled.ellipsoids[compiled.index_of(o)] for o in frame.object_ids]
    start = perturb_pose(truth, rng, 0.05, 2.0)
    out: dict = {"pairs": len(frame)}
    for metric in ("iou", "giou"):
        model = PoseResidualModel(metric, [d.ellipse for d in frame.detections], ells, camera,
                                  initial_world_from_camera=start)
        poses_ = [start @ expmap_pose3(rng.normal(0.0, 1e-3, 6)) for _ in range(reps)]
        # the areas' entry point in quadloc.factors.metrics (quadrant_areas_batch before issue 14's
        # compiled kernels: --compare-tree runs this file on older code)
        entry = "quadrant_sums" if hasattr(fm, "quadrant_sums") else "quadrant_areas_batch"
        calls, original = [], getattr(fm, entry)

        def recording(*args, _calls=calls, _original=original, **kwargs):
            _calls.append((args, kwargs))
            return _original(*args, **kwargs)

        setattr(fm, entry, recording)
        try:
            model.evaluate(poses_[0])
        finally:
            setattr(fm, entry, original)
        whole, areas = math.inf, math.inf
        block = max(reps // blocks, 1)
        for b in range(blocks):  # the fastest block of each: the least disturbed by other jobs
            t = time.process_time()
            for T in poses_[b * block:(b + 1) * block]:
                model.evaluate(T)
            whole = min(whole, (time.process_time() - t) / block)
            t = time.process_time()
            for _ in range(block):
                for args, kwargs in calls:
                    original(*args, **kwargs)
            areas = min(areas, (time.process_time() - t) / block)
        out[metric] = {"evaluation_ms": 1e3 * whole, "areas_ms": 1e3 * areas,
                       "area_calls": len(calls)}
    return out


def compare_eval_cost(other_tree: str, rounds: int = 5) -> dict:
    """:func:`eval_cost` here and in ``other_tree`` (this file run by its ``.venv``, its code
    on the path), alternately ``rounds`` times; the median of each."""
    runs: dict[str, list[dict]] = {"this": [], "other": []}
    for _ in range(rounds):
        runs["this"].append(eval_cost())
        env = dict(os.environ, PYTHONPATH=other_tree)
        res = subprocess.run([tree_python(Path(other_tree)), os.path.abspath(__file__),
                              "--eval-cost"], cwd=other_tree,
                             env=env, capture_output=True, text=True, check=True)
        runs["other"].append(json.loads(res.stdout))
    out: dict = {"this_tree": tree_version(REPO_ROOT), "other_tree": tree_version(Path(other_tree)),
                 "rounds": rounds}
    for side, results in runs.items():
        out[side] = {m: {k: float(np.median([r[m][k] for r in results]))
                         for k in ("evaluation_ms", "areas_ms")} for m in ("iou", "giou")}
    return out


INTRO = (
    "Residual: the metric's `Delta` split over the four quadrants of the detection's frame (4 "
    "non-negative rows summing to `Delta`), with exact analytic Jacobians (boundary integrals "
    "of the exact areas, `factors/overlap.py`; checked against central differences in "
    "`tests/factors/test_metrics.py`). The areas of all pairs of a frame are computed in one "
    "call of "
    "a compiled kernel (`quadloc.factors.overlap.quadrant_sums`, numba, `factors/jit.py`; "
    "equal to the "
    "scalar reference construction to ~1e-9, `tests/factors/test_overlap_batch.py`; "
    "docs/design/factors.md, \"Compiled kernels\", \"Exact ellipse areas\"), and so are the "
    "rows (`quadloc.factors.metrics._overlap_rows`) and the projections' dual conics. iou: a pair "
    "whose ellipses are "
    "disjoint gets the giou rows (the hull gap term, informative when disjoint; every "
    "overlapping pair, hence the optimum, keeps the iou rows; `factors/metrics.py`, iou). "
    "Stopping: besides GTSAM's tolerances, iou/giou stop after an ACCEPTED LM iteration that "
    "decreased the error by less than 1e-3 of it "
    "(`quadloc.service.localization.refine.OVERLAP_RELATIVE_ERROR_TOL`); their LM's lambda follows "
    "Nielsen's gain-ratio update, damping lambda I "
    "(`quadloc.service.localization.refine.OVERLAP_NIELSEN_DAMPING`). Model evaluations: those "
    "computed (not memoised) per solve, rejected LM trials included. CPU times are "
    "`time.process_time` of `refine()` on a machine shared with other jobs: compare the ratio "
    "to level set, measured in the same run.")


def _table(result: dict) -> list[str]:
    lines = ["| metric | exact: max error (m) / within 1e-6 m | noisy: converged / capped | "
             "noisy: within 5 / 10 cm, median error | CPU ms median / p90 | x level set | "
             "LM iterations (median, noisy) | model evaluations (median; per LM iteration) |",
             "|---|---|---|---|---|---|---|---|"]
    for m, s in result["summary"].items():
        its = s.get("noisy_iterations_median")
        evs = s.get("noisy_evaluations_median")
        evs = "–" if evs is None else f"{evs:.0f}; {s['noisy_evaluations_per_iteration']:.2f}"
        lines.append(
            f"| {m} | {s['exact_max_pos_m']:.1e} / {100 * s['exact_within_1e-6_m']:.1f}% | "
            f"{100 * s['noisy_converged']:.1f}% / {100 * s['noisy_capped']:.1f}% | "
            f"{100 * s['noisy_within_5cm']:.1f}% / {100 * s['noisy_within_10cm']:.1f}%, "
            f"{100 * s['noisy_median_pos_m']:.2f} cm | {s['cpu_ms_median']:.1f} / "
            f"{s['cpu_ms_p90']:.1f} | {s['cpu_ratio_to_level_set']:.1f} | "
            f"{'–' if its is None else f'{its:.0f}'} | {evs} |")
    return lines


def _targets(result: dict) -> str:
    """The issue's targets (14, part 1) checked on ``result``."""
    parts = []
    for m in ("iou", "giou"):
        s = result["summary"].get(m)
        if s is None:
            continue
        exact_ok = s["exact_within_1e-6_m"] == 1.0
        conv_ok = s["noisy_converged"] >= 0.95
        cpu_ok = s["cpu_ratio_to_level_set"] <= 5.0
        parts.append(
            f"{m}: exact within 1e-6 m on every frame {'met' if exact_ok else 'NOT met'} "
            f"({round(s['exact_within_1e-6_m'] * s['exact_frames'])}/{s['exact_frames']}); "
            f"converged >= 95 % {'met' if conv_ok else 'NOT met'} "
            f"({100 * s['noisy_converged']:.1f} %); median CPU <= 5 x level set "
            f"{'met' if cpu_ok else 'NOT met'} ({s['cpu_ratio_to_level_set']:.1f} x)")
    return "Targets (issue 14, part 1): " + "; ".join(parts) + "."


def markdown(result: dict, before: dict | None = None,
             before_label: str = "") -> str:
    lines = [INTRO, "",
             f"Seed {result['seed']}, {result['frames']} real poses, true "
             f"associations, starts {result['start']} off; CPU time of `refine()`.", ""]
    lines += _table(result)
    lines += ["", _targets(result)]
    if before is not None:
        lines += ["", f"Before ({before_label}; same command, started together with the run "
                      "above):", ""]
        lines += _table(before)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frames", type=int, default=108)
    ap.add_argument("--json", default=None)
    ap.add_argument("--write-results", action="store_true")
    ap.add_argument("--from-json", default=None,
                    help="do not run: re-render the table from the JSON of an earlier run")
    ap.add_argument("--before-json", default=None,
                    help="also render this run's JSON as 'before' (e.g. an earlier commit)")
    ap.add_argument("--before-label", default="an earlier commit",
                    help="what the --before-json run was (shown in the table heading)")
    ap.add_argument("--notes", default=None,
                    help="append this markdown file to the section (runs of other benches)")
    ap.add_argument("--command", default=None,
                    help="with --from-json: the command line of that run, for the results text")
    ap.add_argument("--eval-cost", action="store_true",
                    help="only the cost of one model evaluation and of its areas (7 pairs)")
    ap.add_argument("--compare-tree", default=None,
                    help="with --eval-cost: also measure in this checkout, alternately")
    args = ap.parse_args(argv)
    if args.eval_cost:
        cost = compare_eval_cost(args.compare_tree) if args.compare_tree else eval_cost()
        print(json.dumps(cost, indent=2))
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(cost, fh)
        return 0
    if args.from_json:
        with open(args.from_json) as fh:
            result = json.load(fh)
        command: str | None = (args.command
                               or f"python -m bench.overlap_refinement --seed {result['seed']}")
    else:
        result = run(args.seed, args.frames, log=lambda s: print(s, file=sys.stderr))
        command = None  # this process's own command line
    before = None
    if args.before_json:
        with open(args.before_json) as fh:
            before = json.load(fh)
    table = markdown(result, before, args.before_label)
    if args.notes:
        with open(args.notes) as fh:
            table += "\n\n" + fh.read().strip()
    print(table)
    print(json.dumps(result["summary"], indent=2))
    if args.json and not args.from_json:
        with open(args.json, "w") as fh:
            json.dump(result, fh)
    if args.write_results:
        update_results_section(
            "overlap_refinement",
            "## IoU / GIoU refinement on the Chess map (issue 14, part 1)\n\n" + table,
            command=command)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
