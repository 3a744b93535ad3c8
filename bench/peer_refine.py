"""Pose refinement speed against a compiled peer: gtsam-quadrics' C++ ``BoundingBoxFactor``.

``python -m bench.peer_refine [--peer PATH] [--compare-tree DIR] [--rounds R] [--repeats K]
[--seed S] [--json PATH] [--write-results]``

Problems (issue 33): the real Chess map at its 108 real poses; per pose the objects the camera
really sees, as ``tests.support.simulate.simulate_frame`` detects them without noise (exact
projections, truncated at the image border: a truncated object is the ellipse of its visible
part, so the optimum is not exactly the true pose), poses seeing fewer than
:data:`MIN_OBJECTS` objects left out; starts 0.1 m / 5 deg off
(``tests.support.reference_data.perturb_pose``, seed ``--seed``). Each solver refines the pose
only (map fixed), ``--repeats`` calls per problem per round.

* QuadLoc: ``quadloc.service.localization.refine.refine`` with ``level_set`` and ``bbox`` (the whole
  call: validation, graph, GTSAM LM, covariance), and its time per stage
  (``RefinementResult.stages_ms``: where the time goes).
* Peer (optional): pose-only LM over gtsam-quadrics' ``BoundingBoxFactor`` with each quadric
  held fixed, graph build + ``optimize()``, C++ (``-O3``), with QuadLoc's LM parameters
  (``quadloc.service.localization.refine``: iteration cap, tolerances, lambda bound, sequential
  Cholesky), so that both stop by the same rule. It is never a dependency: without ``--peer``
  (or ``QUADLOC_PEER_REFINE``) the bench says so and skips it.
* ``--untruncated``: the same poses and starts with exact, untruncated detections (the
  residual vanishes at the true pose; ``bench.refine_convergence``: the level set then needs
  the peer's few iterations), in the results section ``peer_refine_untruncated``: what the
  overhead alone costs against the peer.
* ``--compare-tree DIR``: QuadLoc as checked out in DIR (e.g. ``git worktree add /tmp/before
  <commit>``, then ``make install`` there: its workers run with DIR's own ``.venv``) timed in
  the same run, for before/after figures, and the largest distance
  between its refined camera centres and this tree's (the refinement's result must not change).

Every timed solver runs in its own subprocess, once per round, the rounds interleaved so that
the shared machine's load hits them alike. Times are CPU times, the medians over ALL calls
(every problem, round and repeat). A solve counts as failed when it did not converge (QuadLoc:
its ``status``; the peer: LM did not iterate, or hit the cap); the table's medians are over the
problems every solver solved, the failed ones are counted apart.

GTSAM versions: QuadLoc uses the pip ``gtsam`` wheel of the lock file; the peer's sdist vendors
GTSAM 4.1.1 (the driver prints the version it was compiled against).

Building the peer (in a directory ``PEER_DIR`` outside the repository; nothing of it is
committed; GTSAM's C++ library is most of it: ~15 min on 2 idle cores, far longer on a
loaded machine)::

    apt-get install libboost-all-dev libeigen3-dev cmake g++
    pip download gtsam-quadrics==0.3.0 --no-binary :all: --no-deps -d "$PEER_DIR"
    cd "$PEER_DIR" && tar xzf gtsam_quadrics-0.3.0.tar.gz && mkdir build && cd build
    cmake ../gtsam_quadrics-0.3.0 -DCMAKE_BUILD_TYPE=Release -DBUILD_PYTHON_WRAP=OFF \\
        -DGTSAM_BUILD_TESTS=OFF -DGTSAM_BUILD_EXAMPLES_ALWAYS=OFF -DGTSAM_WITH_TBB=OFF \\
        -DGTSAM_USE_SYSTEM_EIGEN=ON -DGTSAM_BUILD_WITH_MARCH_NATIVE=OFF -DGTSAM_BUILD_PYTHON=OFF
    make -j2 gtsam_quadrics
    # the driver: the C++ program in PEER_DRIVER_SOURCE below, saved as peer_refine.cpp
    g++ -O3 -DNDEBUG -std=c++11 peer_refine.cpp -I../gtsam_quadrics-0.3.0 \\
        -I../gtsam_quadrics-0.3.0/gtsam -Igtsam -I/usr/include/eigen3 \\
        -L. -Lgtsam/gtsam -lgtsam_quadrics -lgtsam -lboost_serialization -lboost_timer \\
        -lboost_chrono -Wl,-rpath,$PWD:$PWD/gtsam/gtsam -o peer_refine
    python -m bench.peer_refine --peer "$PEER_DIR/build/peer_refine"

The driver takes ``repeats max_iterations relative_tol absolute_tol error_tol lambda_upper``
as arguments, reads the problems on stdin (``fx fy skew cx cy``, the problem count, then per
problem the start and true ``world_from_camera`` 4x4 row-major, the object count and per
object its ``world_from_object`` 4x4, semi-axes and measured box ``xmin ymin xmax ymax``),
prints ``gtsam MAJOR.MINOR.PATCH`` and then per problem ``iterations position_error_m`` and
the CPU ms of every repeat. A peer solve counts as converged only if LM iterated
(``0 < iterations < max_iterations``): from starts 0.1 m off, 0 iterations means that LM
rejected its first step and gave up.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script (``--worker``) from another tree's PYTHONPATH
    sys.path.append(str(REPO))

PEER_DRIVER_SOURCE = r"""
#include <gtsam_quadrics/geometry/BoundingBoxFactor.h>
#include <gtsam_quadrics/geometry/ConstrainedDualQuadric.h>
#include <gtsam/config.h>
#include <gtsam/nonlinear/LevenbergMarquardtOptimizer.h>
#include <gtsam/nonlinear/NonlinearFactorGraph.h>
#include <ctime>
#include <cstdlib>
#include <iostream>
#include <vector>
using namespace gtsam;
using namespace gtsam_quadrics;

// The peer's BoundingBoxFactor with its quadric held fixed (pose-only problem).
class FixedQuadricBoxFactor : public NoiseModelFactor1<Pose3> {
  BoundingBoxFactor f_;
  ConstrainedDualQuadric q_;
 public:
  FixedQuadricBoxFactor(const BoundingBoxFactor& f, const ConstrainedDualQuadric& q, Key k,
                        const SharedNoiseModel& n)
      : NoiseModelFactor1<Pose3>(n, k), f_(f), q_(q) {}
  Vector evaluateError(const Pose3& pose,
                       boost::optional<Matrix&> H = boost::none) const override {
    return f_.evaluateError(pose, q_, H, boost::none);
  }
};

static Pose3 readPose(std::istream& in) {
  Matrix4 m;
  for (int i = 0; i < 4; ++i) for (int j = 0; j < 4; ++j) in >> m(i, j);
  return Pose3(m);
}

int main(int argc, char** argv) {
  if (argc < 7) {
    std::cerr << "usage: peer_refine repeats max_iterations relative_tol absolute_tol "
                 "error_tol lambda_upper < problems\n";
    return 2;
  }
  int repeats = std::atoi(argv[1]);
  LevenbergMarquardtParams params;  // QuadLoc's (bench/peer_refine.py passes them)
  params.setMaxIterations(std::atoi(argv[2]));
  params.setRelativeErrorTol(std::atof(argv[3]));
  params.setAbsoluteErrorTol(std::atof(argv[4]));
  params.setErrorTol(std::atof(argv[5]));
  params.setlambdaUpperBound(std::atof(argv[6]));
  params.setLinearSolverType("SEQUENTIAL_CHOLESKY");
  std::cout << "gtsam " << GTSAM_VERSION_MAJOR << "." << GTSAM_VERSION_MINOR << "."
            << GTSAM_VERSION_PATCH << "\n";
  double fx, fy, s, cx, cy;
  std::cin >> fx >> fy >> s >> cx >> cy;
  auto K = boost::make_shared<Cal3_S2>(fx, fy, s, cx, cy);
  int P;
  std::cin >> P;
  auto noise = noiseModel::Isotropic::Sigma(4, 1.0);
  std::cout.precision(17);
  for (int p = 0; p < P; ++p) {
    Pose3 start = readPose(std::cin), truth = readPose(std::cin);
    int n;
    std::cin >> n;
    std::vector<ConstrainedDualQuadric> qs;
    std::vector<AlignedBox2> boxes;
    for (int j = 0; j < n; ++j) {
      Pose3 qp = readPose(std::cin);
      Vector3 r;
      std::cin >> r(0) >> r(1) >> r(2);
      double x0, y0, x1, y1;
      std::cin >> x0 >> y0 >> x1 >> y1;
      qs.emplace_back(qp, r);
      boxes.emplace_back(x0, y0, x1, y1);
    }
    std::vector<double> cpu;
    Values result;
    size_t iters = 0;
    for (int rep = 0; rep < repeats; ++rep) {
      std::clock_t c0 = std::clock();
      NonlinearFactorGraph graph;
      for (int j = 0; j < n; ++j)
        graph.emplace_shared<FixedQuadricBoxFactor>(
            BoundingBoxFactor(boxes[j], K, 0, 1, noise), qs[j], 0, noise);
      Values init;
      init.insert(0, start);
      LevenbergMarquardtOptimizer opt(graph, init, params);
      result = opt.optimize();
      iters = opt.iterations();
      cpu.push_back(1e3 * double(std::clock() - c0) / CLOCKS_PER_SEC);
    }
    Pose3 T = result.at<Pose3>(0);
    std::cout << iters << " " << (T.translation() - truth.translation()).norm();
    for (double c : cpu) std::cout << " " << c;
    std::cout << "\n";
  }
  return 0;
}
"""

METRICS = ("level_set", "bbox")
#: Poses whose camera sees fewer objects are left out (a pose needs 3 to be determined).
MIN_OBJECTS = 3
#: The start's offset from the true pose (m, degrees).
START_OFFSET = (0.10, 5.0)
PEER = "peer BoundingBoxFactor (C++)"


def make_problems(seed: int, clip_to_image: bool = True) -> dict[str, Any]:
    """The problems as plain data (JSON-able, read by every worker): per real Chess pose with
    at least :data:`MIN_OBJECTS` objects seen, the objects seen (noise-free detections,
    truncated at the image border; ``clip_to_image=False``: the exact projections of the
    objects that overlap the image, not truncated, the same random draws), the true pose and a
    start."""
    from quadloc.maps.compiled import compile_map
    from tests.support.reference_data import (
        load_chess_map,
        load_chess_world_from_camera,
        perturb_pose,
    )
    from tests.support.simulate import SimulationConfig, simulate_frame

    scene = load_chess_map()
    compiled = compile_map(scene)
    ellipsoids = {o.object_id: o.ellipsoid for o in scene.objects}
    cam, poses, _ = load_chess_world_from_camera()
    rng = np.random.default_rng(seed)
    seen = SimulationConfig.exact(clip_to_image=clip_to_image)
    problems = []
    for truth in poses:
        frame = simulate_frame(compiled, cam, truth, rng, seen)
        if len(frame) < MIN_OBJECTS:
            continue
        objs = []
        for det, oid in zip(frame.detections, frame.object_ids, strict=True):
            e = ellipsoids[oid]
            objs.append({"center": e.center.tolist(), "axes": list(map(float, e.axes)),
                         "rotation": np.asarray(e.rotation).tolist(),
                         "ellipse": list(map(float, det.ellipse.params())),
                         "box": det.ellipse.bbox().tolist()})
        problems.append({"truth": np.asarray(truth).tolist(),
                         "start": perturb_pose(truth, rng, *START_OFFSET).tolist(),
                         "objects": objs})
    return {"camera": [cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height],
            "problems": problems, "poses": len(poses)}


def worker(path: Path, metric: str, repeats: int) -> dict[str, Any]:
    """Time ``refine`` (whichever tree is first on ``sys.path``) on every problem."""
    from quadloc.factors.camera import Camera, Ellipsoid
    from quadloc.factors.conics import Ellipse
    from quadloc.service.localization.refine import refine
    from quadloc.service.localization.types import Detection

    data = json.loads(path.read_text())
    cam = Camera(*data["camera"][:4], int(data["camera"][4]), int(data["camera"][5]))
    out = []
    for p in data["problems"]:
        dets = [Detection(Ellipse(*o["ellipse"]), f"o{j}") for j, o in enumerate(p["objects"])]
        ells = [Ellipsoid(np.array(o["center"]), np.array(o["axes"]), np.array(o["rotation"]))
                for o in p["objects"]]
        start, truth = np.array(p["start"]), np.array(p["truth"])
        refine(dets, ells, cam, start, metric)  # warm-up (imports, caches)
        cpu, stages = [], []
        for _ in range(repeats):
            c0 = time.process_time()
            res = refine(dets, ells, cam, start, metric)
            cpu.append((time.process_time() - c0) * 1e3)
            stages.append(dict(getattr(res, "stages_ms", {})))  # a compared tree may lack it
        out.append({"cpu_ms": cpu, "stages_ms": stages,
                    "position": res.world_from_camera[:3, 3].tolist(),
                    "world_from_camera": res.world_from_camera.tolist(),
                    "error_m": float(np.linalg.norm(res.world_from_camera[:3, 3]
                                                    - truth[:3, 3])),
                    "iterations": res.iterations, "converged": res.status == "converged"})
    return {"gtsam": metadata.version("gtsam"), "problems": out}


def peer_input(data: dict[str, Any]) -> str:
    fx, fy, cx, cy = data["camera"][:4]
    lines = [f"{fx!r} {fy!r} 0 {cx!r} {cy!r}", str(len(data["problems"]))]
    for p in data["problems"]:
        for key in ("start", "truth"):
            lines.append(" ".join(repr(float(v)) for v in np.ravel(p[key])))
        lines.append(str(len(p["objects"])))
        for o in p["objects"]:
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = o["rotation"], o["center"]
            lines.append(" ".join(repr(float(v)) for v in
                                  [*T.ravel(), *o["axes"], *o["box"]]))
    return "\n".join(lines) + "\n"


def peer_arguments(repeats: int) -> list[str]:
    """The driver's arguments: ``repeats`` and QuadLoc's LM parameters (level set and bbox)."""
    from quadloc.service.localization import refine as ql

    return [str(repeats), str(ql.DEFAULT_MAX_ITERATIONS), repr(ql.RELATIVE_ERROR_TOL),
            repr(ql.ABSOLUTE_ERROR_TOL), repr(ql.ERROR_TOL), repr(ql.LAMBDA_UPPER_BOUND)]


def run_peer(binary: Path, data: dict[str, Any], repeats: int) -> dict[str, Any]:
    from quadloc.service.localization.refine import DEFAULT_MAX_ITERATIONS

    lines = subprocess.run([str(binary), *peer_arguments(repeats)], input=peer_input(data),
                           text=True, capture_output=True, check=True).stdout.splitlines()
    version = lines[0].split()[1] if lines and lines[0].startswith("gtsam ") else "unknown"
    rows = [line.split() for line in lines[1:] if line.strip()]
    return {"gtsam": version,
            "problems": [{"cpu_ms": [float(v) for v in r[2:]], "error_m": float(r[1]),
                          "iterations": int(r[0]),
                          "converged": 0 < int(r[0]) < DEFAULT_MAX_ITERATIONS}
                         for r in rows]}


def run_worker(tree: Path, problems: Path, metric: str, repeats: int) -> dict[str, Any]:
    from bench.results_doc import tree_python

    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run(
        [tree_python(tree), str(Path(__file__).resolve()), "--worker", str(problems),
         "--metric", metric, "--repeats", str(repeats)],
        env=env, cwd=str(tree), text=True, capture_output=True, check=True)
    result: dict[str, Any] = json.loads(out.stdout)
    return result


def summarise(rounds: list[dict[str, Any]], common: list[int]) -> dict[str, Any]:
    """One solver's figures over its ``rounds``: CPU median / p90 over all calls of the
    ``common`` problems (those every solver solved), its failed solves apart, the median time
    of each ``refine()`` stage (when the tree reports them)."""
    last = rounds[-1]["problems"]
    n = len(last)
    failed = [i for i in range(n) if not last[i]["converged"]]

    def calls(indices: list[int]) -> list[float]:
        return [t for r in rounds for i in indices for t in r["problems"][i]["cpu_ms"]]

    cpu = calls(common)
    out: dict[str, Any] = {
        "gtsam": rounds[-1]["gtsam"], "problems": n, "common_problems": len(common),
        "calls": len(cpu),
        "cpu_median_ms": float(np.median(cpu)), "cpu_p90_ms": float(np.percentile(cpu, 90)),
        "cpu_median_all_problems_ms": float(np.median(calls(list(range(n))))),
        "max_error_m": max(last[i]["error_m"] for i in common),
        "median_error_m": float(np.median([last[i]["error_m"] for i in common])),
        "mean_iterations": float(np.mean([last[i]["iterations"] for i in common])),
        "failed": len(failed),
        "failed_not_iterated": sum(last[i]["iterations"] == 0 for i in failed),
        "failed_cpu_median_ms": float(np.median(calls(failed))) if failed else None,
    }
    stages = [s for r in rounds for i in common for s in r["problems"][i].get("stages_ms", [])
              if s]
    if stages:
        out["stages_median_ms"] = {k: float(np.median([s[k] for s in stages]))
                                   for k in stages[0]}
    return out


def run(seed: int, rounds: int, repeats: int, peer: Path | None,
        compare_tree: Path | None, untruncated: bool = False) -> dict[str, Any]:
    data = make_problems(seed, clip_to_image=not untruncated)
    solvers: dict[str, tuple[Path, str] | Path] = {}
    if compare_tree is not None:
        from bench.results_doc import tree_version

        label = f"before ({tree_version(compare_tree)})"
        for m in METRICS:
            solvers[f"{label} {m}"] = (compare_tree, m)
    for m in METRICS:
        solvers[f"QuadLoc {m}"] = (REPO, m)
    if peer is not None:
        solvers[PEER] = peer
    results: dict[str, list[dict[str, Any]]] = {k: [] for k in solvers}
    load = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "problems.json"
        path.write_text(json.dumps(data))
        for _ in range(rounds):
            for name, how in solvers.items():
                if isinstance(how, Path):
                    results[name].append(run_peer(how, data, repeats))
                else:
                    results[name].append(run_worker(how[0], path, how[1], repeats))
            load.append(os.getloadavg()[0])
    n = len(data["problems"])
    common = [i for i in range(n)
              if all(r[-1]["problems"][i]["converged"] for r in results.values())]
    out: dict[str, Any] = {
        "seed": seed, "rounds": rounds, "repeats": repeats, "poses": data["poses"],
        "untruncated": untruncated,
        "problems": n, "common_problems": len(common),
        "median_objects": float(np.median([len(p["objects"]) for p in data["problems"]])),
        "python": platform.python_version(), "peer_built": peer is not None,
        "load_average_1min": [round(v, 2) for v in load],
        "solvers": {k: summarise(v, common) for k, v in results.items()}}
    for m in METRICS:  # the refinement's result must not change
        before = [k for k in results if k.startswith("before") and k.endswith(f" {m}")]
        if before:
            a = results[before[0]][-1]["problems"]
            b = results[f"QuadLoc {m}"][-1]["problems"]
            out["solvers"][f"QuadLoc {m}"]["max_position_change_m"] = max(
                float(np.linalg.norm(np.subtract(x["position"], y["position"])))
                for x, y in zip(a, b, strict=True))
    if peer is not None:
        ref = out["solvers"][PEER]["cpu_median_ms"]
        for v in out["solvers"].values():
            v["x_peer"] = v["cpu_median_ms"] / ref
    return out


def markdown(res: dict[str, Any]) -> str:
    peer = res["peer_built"]
    versions = sorted({f"{k}: GTSAM {v['gtsam']}" for k, v in res["solvers"].items()
                       if not k.startswith("before")})
    untruncated = res.get("untruncated", False)
    title = "## Refinement speed against a compiled peer (issue 14, part 3)" if not untruncated \
        else "## Refinement speed against a compiled peer, untruncated detections (issue 33)"
    seen = ("noise-free detections NOT truncated: the exact projections of the objects "
            "overlapping the image") if untruncated \
        else "noise-free detections truncated at the image border"
    lines = [title, "",
             f"Seed {res['seed']}, {res['rounds']} interleaved rounds x "
             f"{res['repeats']} calls per problem, CPU time, medians over all calls (CPython "
             f"{res['python']}; {'; '.join(versions)}; 2-core machine shared with other jobs, "
             f"1-min load average {min(res['load_average_1min'])}-"
             f"{max(res['load_average_1min'])} during the rounds: compare within this table "
             f"only). {res['problems']} of the {res['poses']} real Chess poses (those seeing "
             f"at least {MIN_OBJECTS} objects; median {res['median_objects']:g} objects seen, "
             f"{seen}), starts 0.1 m / 5 deg off; "
             "the peer pose-only with QuadLoc's LM parameters; see `bench/peer_refine.py`.",
             ""]
    if not peer:
        lines += ["The peer was not built in this run (see `bench/peer_refine.py` for how).", ""]
    lines.append(f"Times over the {res['common_problems']} problems every solver solved; "
                 "failed solves counted apart.")
    lines.append("")
    lines.append("| solver | CPU ms median / p90 | max / median position error (m) | "
                 "mean iterations | failed (not iterated) |" + (" x peer |" if peer else ""))
    lines.append("|---|---|---|---|---|" + ("---|" if peer else ""))
    for name, v in res["solvers"].items():
        row = (f"| {name} | {v['cpu_median_ms']:.3f} / {v['cpu_p90_ms']:.3f} | "
               f"{v['max_error_m']:.1e} / {v['median_error_m']:.1e} | "
               f"{v['mean_iterations']:.1f} | {v['failed']} ({v['failed_not_iterated']}) |")
        if peer:
            row += f" {v['x_peer']:.2f} |"
        lines.append(row)
    stage_rows = [(k, v["stages_median_ms"]) for k, v in res["solvers"].items()
                  if "stages_median_ms" in v]
    if stage_rows:
        keys = list(stage_rows[0][1])
        lines += ["", "Where `refine()`'s time goes (median ms per call and stage, "
                  "`RefinementResult.stages_ms`):", "",
                  "| solver | " + " | ".join(keys) + " |", "|---|" + "---|" * len(keys)]
        lines += [f"| {k} | " + " | ".join(f"{s.get(key, 0.0):.3f}" for key in keys) + " |"
                  for k, s in stage_rows]
    lines += ["", *summary_lines(res)]
    return "\n".join(lines)


def summary_lines(res: dict[str, Any]) -> list[str]:
    """Sentences computed from the table: QuadLoc against the peer (targets: level set <= 2x,
    bbox <= 1.5x), against the compared tree, and whether the refined poses changed."""
    solvers = res["solvers"]
    out = []
    for m in METRICS:
        ours = solvers[f"QuadLoc {m}"]
        before = [k for k in solvers if k.startswith("before") and k.endswith(f" {m}")]
        if before:
            b = solvers[before[0]]["cpu_median_ms"]
            out.append(f"{m}, this tree against {before[0][:-len(m) - 1]}: median "
                       f"{ours['cpu_median_ms']:.3f} ms against {b:.3f} ms "
                       f"({b / ours['cpu_median_ms']:.2f}x faster); largest change of a "
                       f"refined camera centre {ours['max_position_change_m']:.1e} m.")
    peer = solvers.get(PEER)
    if peer is not None:
        p = peer["cpu_median_ms"]
        for m, target in (("level_set", 2.0), ("bbox", 1.5)):
            ours = solvers[f"QuadLoc {m}"]["cpu_median_ms"]
            verdict = "met" if ours <= target * p else "not met"
            out.append(f"Target ({m} refine() <= {target:g}x the peer): {verdict}, "
                       f"{ours:.3f} ms against {p:.3f} ms ({ours / p:.2f}x).")
        if peer["failed"]:
            out.append(f"The peer failed {peer['failed']} of {peer['problems']} problems "
                       f"({peer['failed_not_iterated']} where GTSAM's LM gave up at its first "
                       "step), left out of the medians.")
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--peer", type=Path, default=os.environ.get("QUADLOC_PEER_REFINE"))
    ap.add_argument("--compare-tree", type=Path, default=None)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--write-results", action="store_true")
    ap.add_argument("--untruncated", action="store_true",
                    help="exact, untruncated detections (results section peer_refine_untruncated)")
    ap.add_argument("--worker", type=Path, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--metric", default="level_set", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:
        print(json.dumps(worker(args.worker, args.metric, args.repeats)))
        return
    peer = args.peer
    if peer is not None and not Path(peer).is_file():
        print(f"peer binary {peer} not found: skipping the peer (see bench/peer_refine.py)",
              file=sys.stderr)
        peer = None
    elif peer is None:
        print("no --peer given (nor QUADLOC_PEER_REFINE): skipping the gtsam-quadrics peer; "
              "see bench/peer_refine.py for how to build it", file=sys.stderr)
    res = run(args.seed, args.rounds, args.repeats, None if peer is None else Path(peer),
              args.compare_tree, args.untruncated)
    print(json.dumps(res, indent=2))
    if args.json:
        args.json.write_text(json.dumps(res, indent=2))
    if args.write_results:
        from bench.results_doc import update_results_section

        update_results_section("peer_refine_untruncated" if args.untruncated else "peer_refine",
                               markdown(res))


if __name__ == "__main__":
    main()
