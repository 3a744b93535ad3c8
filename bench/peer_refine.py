"""Pose refinement speed against a compiled peer: gtsam-quadrics' C++ ``BoundingBoxFactor``.

``python -m bench.peer_refine [--peer PATH] [--compare-tree DIR] [--rounds R] [--repeats K]
[--seed S] [--json PATH] [--write-results]``

Problems (issue 14, part 3): the real Chess map at its 108 real poses, exact detections (the
projections of the map ellipsoids, objects whose projection is an ellipse), starts 0.1 m /
5 deg off (``tests.support.reference_data.perturb_pose``, seed ``--seed``). Each solver refines the
pose only (map fixed) and is timed per problem as the median CPU time of ``--repeats`` calls;
the table gives the median (p90) over the problems, the accuracy the largest distance between
refined and true camera centre.

* QuadLoc: ``quadloc.service.localization.refine.refine`` with ``level_set`` and ``bbox`` (the whole
  call: validation, graph, GTSAM LM, covariance).
* Peer (optional): pose-only LM (GTSAM defaults) over gtsam-quadrics' ``BoundingBoxFactor``
  with each quadric held fixed, graph build + ``optimize()``, C++ (``-O3``). It is never a
  dependency: without ``--peer`` (or ``QUADLOC_PEER_REFINE``) the bench says so and skips it.
* ``--compare-tree DIR``: QuadLoc as checked out in DIR (e.g. ``git worktree add /tmp/before
  <commit>``) timed in the same run, for before/after figures.

Every timed solver runs in its own subprocess, once per round, the rounds interleaved so that
the shared machine's load hits them alike; a problem's time is its median over all calls.

Building the peer (in a directory ``PEER_DIR`` outside the repository; nothing of it is
committed; GTSAM 4.2's C++ library is most of it: ~15 min on 2 idle cores, far longer on a
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

The driver reads the problems on stdin (``fx fy skew cx cy``, the problem count, then per
problem the start and true ``world_from_camera`` 4x4 row-major, the object count and per
object its ``world_from_object`` 4x4, semi-axes and measured box ``xmin ymin xmax ymax``) and
prints per problem ``cpu_ms wall_ms position_error_m iterations``. A peer solve counts as
converged only if LM iterated (``0 < iterations < 100``, GTSAM's default cap): from starts
0.1 m off, 0 iterations means that LM rejected its first step and gave up.
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
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script (``--worker``) from another tree's PYTHONPATH
    sys.path.append(str(REPO))

PEER_DRIVER_SOURCE = r"""
#include <gtsam_quadrics/geometry/BoundingBoxFactor.h>
#include <gtsam_quadrics/geometry/ConstrainedDualQuadric.h>
#include <gtsam/nonlinear/LevenbergMarquardtOptimizer.h>
#include <gtsam/nonlinear/NonlinearFactorGraph.h>
#include <algorithm>
#include <chrono>
#include <ctime>
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
  int repeats = argc > 1 ? std::atoi(argv[1]) : 5;
  double fx, fy, s, cx, cy;
  std::cin >> fx >> fy >> s >> cx >> cy;
  auto K = boost::make_shared<Cal3_S2>(fx, fy, s, cx, cy);
  int P;
  std::cin >> P;
  auto noise = noiseModel::Isotropic::Sigma(4, 1.0);
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
    std::vector<double> cpu, wall;
    Values result;
    size_t iters = 0;
    for (int rep = 0; rep < repeats; ++rep) {
      std::clock_t c0 = std::clock();
      auto w0 = std::chrono::steady_clock::now();
      NonlinearFactorGraph graph;
      for (int j = 0; j < n; ++j)
        graph.emplace_shared<FixedQuadricBoxFactor>(
            BoundingBoxFactor(boxes[j], K, 0, 1, noise), qs[j], 0, noise);
      Values init;
      init.insert(0, start);
      LevenbergMarquardtParams params;  // GTSAM defaults
      LevenbergMarquardtOptimizer opt(graph, init, params);
      result = opt.optimize();
      iters = opt.iterations();
      cpu.push_back(1e3 * double(std::clock() - c0) / CLOCKS_PER_SEC);
      wall.push_back(1e-6 * std::chrono::duration_cast<std::chrono::nanoseconds>(
                                std::chrono::steady_clock::now() - w0).count());
    }
    std::sort(cpu.begin(), cpu.end());
    std::sort(wall.begin(), wall.end());
    Pose3 T = result.at<Pose3>(0);
    double err = (T.translation() - truth.translation()).norm();
    std::cout.precision(17);
    std::cout << cpu[cpu.size() / 2] << " " << wall[wall.size() / 2] << " " << err << " "
              << iters << "\n";
  }
  return 0;
}
"""

METRICS = ("level_set", "bbox")


def make_problems(seed: int) -> dict:
    """The 108 exact Chess problems as plain data (JSON-able, read by every worker)."""
    from quadloc.factors.rotations import invert_pose
    from tests.support.reference_data import (
        exact_projections,
        load_chess_map,
        load_chess_poses,
        perturb_pose,
    )

    ells = [o.ellipsoid for o in load_chess_map().objects]
    cam, camera_from_world, _ = load_chess_poses()
    rng = np.random.default_rng(seed)
    problems = []
    for cfw in camera_from_world:
        truth = invert_pose(cfw)
        objs = [{"center": e.center.tolist(), "axes": list(map(float, e.axes)),
                 "rotation": np.asarray(e.rotation).tolist(),
                 "ellipse": list(map(float, det.params())), "box": det.bbox().tolist()}
                for det, e in exact_projections(cam, cfw, ells)]
        problems.append({"truth": truth.tolist(),
                         "start": perturb_pose(truth, rng, 0.10, 5.0).tolist(),
                         "objects": objs})
    return {"camera": [cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height],
            "problems": problems}


def worker(path: Path, metric: str, repeats: int) -> list[dict]:
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
        cpu = []
        for _ in range(repeats):
            c0 = time.process_time()
            res = refine(dets, ells, cam, start, metric)
            cpu.append((time.process_time() - c0) * 1e3)
        out.append({"cpu_ms": cpu,
                    "error_m": float(np.linalg.norm(res.world_from_camera[:3, 3]
                                                    - truth[:3, 3])),
                    "iterations": res.iterations, "status": res.status})
    return out


def peer_input(data: dict) -> str:
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


def run_peer(binary: Path, data: dict, repeats: int) -> list[dict]:
    out = subprocess.run([str(binary), str(repeats)], input=peer_input(data), text=True,
                         capture_output=True, check=True).stdout.split("\n")
    rows = [line.split() for line in out if line.strip()]
    return [{"cpu_ms": [float(r[0])], "error_m": float(r[2]), "iterations": int(r[3]),
             "status": peer_status(int(r[3]))} for r in rows]


#: GTSAM's default ``LevenbergMarquardtParams.maxIterations`` (the peer's LM cap).
PEER_MAX_ITERATIONS = 100


def peer_status(iterations: int) -> str:
    """The peer LM's outcome from its iteration count: ``converged`` only if it iterated and
    stopped by itself (``0 < iterations < PEER_MAX_ITERATIONS``)."""
    if iterations <= 0:
        return "no_iteration"
    return "max_iterations" if iterations >= PEER_MAX_ITERATIONS else "converged"


def run_worker(tree: Path, problems: Path, metric: str, repeats: int) -> list[dict]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--worker", str(problems),
         "--metric", metric, "--repeats", str(repeats)],
        env=env, cwd=str(tree), text=True, capture_output=True, check=True)
    return json.loads(out.stdout)


def summarise(rounds: list[list[dict]]) -> dict:
    n = len(rounds[0])
    per_problem = [float(np.median([t for r in rounds for t in r[i]["cpu_ms"]]))
                   for i in range(n)]
    last = rounds[-1]
    return {"cpu_median_ms": float(np.median(per_problem)),
            "cpu_p90_ms": float(np.percentile(per_problem, 90)),
            "max_error_m": max(r["error_m"] for r in last),
            "median_error_m": float(np.median([r["error_m"] for r in last])),
            "mean_iterations": float(np.mean([r["iterations"] for r in last])),
            "converged": float(np.mean([r["status"] == "converged" for r in last])),
            "not_iterated": int(sum(r["iterations"] == 0 for r in last)),
            "problems": n}


def run(seed: int, rounds: int, repeats: int, peer: Path | None,
        compare_tree: Path | None) -> dict:
    data = make_problems(seed)
    solvers: dict[str, object] = {}
    if compare_tree is not None:
        from bench.results_doc import tree_version

        label = f"before ({tree_version(compare_tree)})"
        for m in METRICS:
            solvers[f"{label} {m}"] = (compare_tree, m)
    for m in METRICS:
        solvers[f"QuadLoc {m}"] = (REPO, m)
    if peer is not None:
        solvers["peer BoundingBoxFactor (C++)"] = peer
    results: dict[str, list[list[dict]]] = {k: [] for k in solvers}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "problems.json"
        path.write_text(json.dumps(data))
        for _ in range(rounds):
            for name, how in solvers.items():
                if isinstance(how, Path):
                    results[name].append(run_peer(how, data, repeats))
                else:
                    tree, metric = how  # type: ignore[misc]
                    results[name].append(run_worker(tree, path, metric, repeats))
    out = {"seed": seed, "rounds": rounds, "repeats": repeats,
           "python": platform.python_version(), "peer_built": peer is not None,
           "solvers": {k: summarise(v) for k, v in results.items()}}
    if peer is not None:
        ref = out["solvers"]["peer BoundingBoxFactor (C++)"]["cpu_median_ms"]
        for v in out["solvers"].values():
            v["x_peer"] = v["cpu_median_ms"] / ref
    return out


def markdown(res: dict, command: str) -> str:
    lines = ["## Refinement speed against a compiled peer (issue 14, part 3)", "",
             f"Command: `{command}` (seed {res['seed']}, {res['rounds']} interleaved rounds x "
             f"{res['repeats']} calls per problem, CPU time; CPython {res['python']}; "
             "2-core machine shared with other jobs: compare within this table only). "
             "108 exact Chess problems, starts 0.1 m / 5 deg off; see `bench/peer_refine.py`.",
             ""]
    if not res["peer_built"]:
        lines += ["The peer was not built in this run (see `bench/peer_refine.py` for how).", ""]
    peer = res["peer_built"]
    lines.append("| solver | CPU ms median / p90 | max / median position error (m) | "
                 "mean iterations | converged |" + (" x peer |" if peer else ""))
    lines.append("|---|---|---|---|---|" + ("---|" if peer else ""))
    for name, v in res["solvers"].items():
        row = (f"| {name} | {v['cpu_median_ms']:.2f} / {v['cpu_p90_ms']:.2f} | "
               f"{v['max_error_m']:.1e} / {v['median_error_m']:.1e} | "
               f"{v['mean_iterations']:.1f} | {100 * v['converged']:.0f}% |")
        if peer:
            row += f" {v['x_peer']:.2f} |"
        lines.append(row)
    lines += ["", *summary_lines(res)]
    return "\n".join(lines)


def summary_lines(res: dict) -> list[str]:
    """Sentences computed from the table: QuadLoc's level set against the peer and against the
    compared tree, and the peer's solves that did not iterate."""
    solvers = res["solvers"]
    ours = solvers["QuadLoc level_set"]["cpu_median_ms"]
    out = []
    before = [k for k in solvers if k.startswith("before") and k.endswith("level_set")]
    if before:
        b = solvers[before[0]]["cpu_median_ms"]
        out.append(f"Level set, this tree against {before[0][:-len(' level_set')]}: median "
                   f"{ours:.2f} ms against {b:.2f} ms ({b / ours:.2f}x faster).")
    peer = solvers.get("peer BoundingBoxFactor (C++)")
    if peer is not None:
        p = peer["cpu_median_ms"]
        verdict = "met" if ours <= p else "not met"
        out.append(f"Target (level-set refinement no slower than the C++ peer): {verdict}, "
                   f"{ours:.2f} ms against {p:.2f} ms ({ours / p:.2f}x the peer's time).")
        if peer["not_iterated"]:
            out.append(f"The peer did not iterate on {peer['not_iterated']} of "
                       f"{peer['problems']} problems (GTSAM's LM gave up at its first step; "
                       "counted as not converged, their error is the start's).")
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--peer", type=Path, default=os.environ.get("QUADLOC_PEER_REFINE"))
    ap.add_argument("--compare-tree", type=Path, default=None)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--write-results", action="store_true")
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
              args.compare_tree)
    print(json.dumps(res, indent=2))
    if args.json:
        args.json.write_text(json.dumps(res, indent=2))
    if args.write_results:
        from bench.results_doc import update_results_section

        command = "python -m bench.peer_refine " + " ".join(argv if argv is not None
                                                             else sys.argv[1:])
        update_results_section("peer_refine", markdown(res, command.strip()))


if __name__ == "__main__":
    main()
