"""The paper's Table I: 2D rigid registration of two ellipses with each of the nine metrics.

Usage::

    python -m bench.registration_2d [--pairs N] [--seed S] [--json PATH] [--workers W]
                                    [--write-results]

Problem (paper section "Ellipse 2D registration")
-------------------------------------------------
For each pair, ``E_ref`` is random:

* centre uniform in ``[200, 440] x [200, 280]`` px (inside a 640 x 480 image),
* major semi-axis ``a ~ U(25, 80)`` px, minor ``b = a * U(0.3, 0.65)`` (never close to a circle,
  even after the detection noise, so the orientation is always defined),
* angle ``~ U(-pi, pi)``.

``E`` is ``E_ref`` rotated about its own centre by ``theta0 ~ U(-180, 180)`` degrees and
translated by ``t0 ~ U(-60, 60)^2`` px. With detection noise, each semi-axis of ``E`` is then
scaled independently by ``U(0.83, 1.2)`` (centre and axis directions unchanged).

The unknown is a ``gtsam.Pose2`` ``(x, y, theta)`` acting on ``E`` as
``T(E, pose) = E rotated by theta about its centre, then translated by (x, y)``; we solve the
paper's ``argmin Delta(T(E, pose), E_ref)``, i.e. ``metrics.residual(name, detection=T(E, pose),
projection=E_ref)``, with one ``gtsam.CustomFactor`` (central-difference numerical Jacobian
through ``Pose2.retract``) and ``gtsam.LevenbergMarquardtOptimizer`` from the identity.
LM settings: ``maxIterations = 100``, ``relativeErrorTol = 1e-10``, ``absoluteErrorTol = 1e-16``
(error is ``1/2 ||r||^2``, so LM runs on until the decrease is at rounding level for the
zero-residual problems and stops after a 1e-10 relative decrease otherwise), default lambda
schedule (initial 1e-5, upper bound 1e5: a flat cost ends the solve when lambda saturates) and
**diagonal (Marquardt) damping** ``lambda diag(J^T J)``: the unknowns mix pixels and radians, and
plain ``lambda I`` damping is not scale invariant. Measured on 40 pairs (no noise), diagonal
damping cut giou's mean position error from 38 to 13 px and its iterations from 100 (the cap) to
38, algebraic/frobenius from 9.4 to 2.1 px, and changed nothing for the smooth metrics.
level_set uses the adaptive sampling scale of the initial pair, frozen for the solve.

Errors. The true transform is the rigid one, ``(x, y) = -t0`` and ``theta = -theta0``, with and
without noise (the noise scales the axes about the centre along the axis directions, so aligning
centres and axes is still the right answer). Position error = ``|t_est - (-t0)|`` px (= the
distance between the registered centre and ``E_ref``'s centre); rotation error = the angle
between ``theta_est`` and ``-theta0`` modulo 180 degrees (an ellipse is symmetric under a half
turn), in degrees, in ``[0, 90]``. We report the means (as the paper does) and the medians.

qbbox needs an image: we use the 640 x 480 image the centres are drawn in; every ellipse of the
benchmark (with noise and at the start) lies inside it, so qbbox equals bbox except when LM
iterates push the ellipse across the border.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

import gtsam
import numpy as np

from quadloc.factors.conics import Ellipse
from quadloc.factors.metrics import (
    CONIC_METRICS,
    METRIC_NAMES,
    conic_residuals,
    level_set_sampling_scale,
    overlap_residual,
    residual,
)

IMAGE_SIZE = (640, 480)
MAX_ITERATIONS = 100
NUMERICAL_STEP = np.array([1e-5, 1e-5, 1e-7])  # Pose2 tangent [vx px, vy px, omega rad]

#: The paper's Table I (mean position error px, mean rotation error degrees), 10000 pairs.
PAPER_TABLE = {
    "giou": {"no_noise": (13.32, 6.42), "noise": (15.11, 12.44)},
    "bbox": {"no_noise": (1.0e-7, 22.87), "noise": (1.2e-5, 29.66)},
    "algebraic": {"no_noise": (2.49, 21.69), "noise": (5.05, 32.30)},
    "frobenius": {"no_noise": (2.59, 22.08), "noise": (5.04, 32.30)},
    "wasserstein": {"no_noise": (9.8e-4, 7.8e-4), "noise": (7.9e-4, 4.6e-4)},
    "bhattacharyya": {"no_noise": (2.0e-2, 3.9e-3), "noise": (1.7e-2, 2.5e-3)},
    "level_set": {"no_noise": (1.0e-6, 1.0e-6), "noise": (2.9e-4, 2.7e-5)},
}
CONDITIONS = ("no_noise", "noise")


def make_pairs(n: int, seed: int) -> dict[str, np.ndarray]:
    """Random pairs (see module docstring): ref params (n, 5), theta0 (n,) rad, t0 (n, 2) px,
    noise scales (n, 2)."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(25.0, 80.0, n)
    ref = np.column_stack([rng.uniform(200.0, 440.0, n), rng.uniform(200.0, 280.0, n), a,
                           a * rng.uniform(0.3, 0.65, n), rng.uniform(-math.pi, math.pi, n)])
    theta0 = np.radians(rng.uniform(-180.0, 180.0, n))
    t0 = rng.uniform(-60.0, 60.0, (n, 2))
    noise = rng.uniform(0.83, 1.2, (n, 2))
    return {"ref": ref, "theta0": theta0, "t0": t0, "noise": noise}


def transformed(e: np.ndarray, x: float, y: float, theta: float) -> Ellipse:
    """``T(E, pose)``: rotate ``E`` (params (5,)) by ``theta`` about its centre, translate."""
    return Ellipse(e[0] + x, e[1] + y, e[2], e[3], e[4] + theta)


def _residuals_fn(name: str, moving: np.ndarray, ref: Ellipse, options: dict):
    """``poses`` (list of Pose2) -> residual rows (len(poses), m) of ``T(E, pose)`` against
    ``E_ref``: one batched call for the metrics that have a batched form (the smooth conic
    metrics and iou / giou, whose one-pair calls are N = 1 views of the same code), else one
    :func:`quadloc.factors.metrics.residual` per pose."""
    def params(poses: list[gtsam.Pose2]) -> np.ndarray:
        return np.array([transformed(moving, p.x(), p.y(), p.theta()).params() for p in poses])

    if name in CONIC_METRICS:
        mu, S = ref.gaussian()
        Cn = ref.dual_conic()

        def f(poses: list[gtsam.Pose2]) -> np.ndarray:
            n = len(poses)
            return conic_residuals(name, params(poses), np.broadcast_to(Cn, (n, 3, 3)),
                                   gaussians=(np.broadcast_to(mu, (n, 2)),
                                              np.broadcast_to(S, (n, 2, 2))))[0]
    elif name in ("iou", "giou"):
        ref_params = ref.params()

        def f(poses: list[gtsam.Pose2]) -> np.ndarray:
            return overlap_residual(name, params(poses),
                                    np.broadcast_to(ref_params, (len(poses), 5)))[0]
    else:
        def f(poses: list[gtsam.Pose2]) -> np.ndarray:
            return np.array([residual(name, transformed(moving, p.x(), p.y(), p.theta()), ref,
                                      **options) for p in poses])
    return f


def make_factor(name: str, moving: np.ndarray, ref: Ellipse, key: int,
                options: dict) -> gtsam.CustomFactor:
    """CustomFactor on one Pose2 with the metric's residual and a central-difference Jacobian
    (the pose and its 6 perturbations evaluated in one batched call where the metric allows)."""
    f = _residuals_fn(name, moving, ref, options)
    m = f([gtsam.Pose2()]).shape[1]
    noise = gtsam.noiseModel.Unit.Create(m)
    steps = [s * d for d in np.diag(NUMERICAL_STEP) for s in (1.0, -1.0)]

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H) -> np.ndarray:
        pose = values.atPose2(this.keys()[0])
        if H is None:
            return f([pose])[0]
        rows = f([pose] + [pose.retract(d) for d in steps])
        H[0] = ((rows[1::2] - rows[2::2]) / (2.0 * NUMERICAL_STEP[:, None])).T
        return rows[0]

    return gtsam.CustomFactor(noise, [key], error)


def lm_params() -> gtsam.LevenbergMarquardtParams:
    """LM settings of the benchmark (see the module docstring for the reasons)."""
    p = gtsam.LevenbergMarquardtParams()
    p.setDiagonalDamping(True)
    p.setMaxIterations(MAX_ITERATIONS)
    p.setRelativeErrorTol(1e-10)
    p.setAbsoluteErrorTol(1e-16)
    return p


def register(name: str, moving: np.ndarray, ref: Ellipse) -> tuple[gtsam.Pose2, int]:
    """Minimise ``Delta(T(E, pose), E_ref)`` over the Pose2 from the identity."""
    options: dict = {}
    if name == "qbbox":
        options["image_size"] = IMAGE_SIZE
    elif name == "level_set":
        # Adaptive sampling area from the original distance, then frozen.
        s = level_set_sampling_scale(transformed(moving, 0.0, 0.0, 0.0), ref)
        options.update(scale=s, adaptive=False)
    key = gtsam.symbol("x", 0)
    graph = gtsam.NonlinearFactorGraph()
    graph.add(make_factor(name, moving, ref, key, options))
    init = gtsam.Values()
    init.insert(key, gtsam.Pose2())
    opt = gtsam.LevenbergMarquardtOptimizer(graph, init, lm_params())
    result = opt.optimize()
    return result.atPose2(key), opt.iterations()


def errors(pose: gtsam.Pose2, theta0: float, t0: np.ndarray) -> tuple[float, float]:
    """(position error px, rotation error deg modulo 180) against the true ``(-t0, -theta0)``."""
    pos = math.hypot(pose.x() + t0[0], pose.y() + t0[1])
    d = math.degrees(pose.theta() + theta0)
    rot = abs((d + 90.0) % 180.0 - 90.0)
    return pos, rot


def run_chunk(args: tuple[dict[str, np.ndarray], list[str]]) -> dict:
    """Solve every pair of the chunk with every metric and condition."""
    pairs, metrics = args
    n = len(pairs["theta0"])
    out = {m: {c: {"pos": np.empty(n), "rot": np.empty(n), "iters": np.empty(n),
                   "time": np.empty(n)} for c in CONDITIONS} for m in metrics}
    for i in range(n):
        ref_p = pairs["ref"][i]
        ref = Ellipse(*ref_p)
        th0, t0 = float(pairs["theta0"][i]), pairs["t0"][i]
        # E = E_ref rotated about its own centre (only the angle changes), then translated.
        base = np.array([ref_p[0] + t0[0], ref_p[1] + t0[1], ref_p[2], ref_p[3],
                         ref_p[4] + th0])
        noisy = base.copy()
        noisy[2:4] *= pairs["noise"][i]
        for cond, moving in (("no_noise", base), ("noise", noisy)):
            for m in metrics:
                t = time.perf_counter()
                pose, iters = register(m, moving, ref)
                dt = time.perf_counter() - t
                pos, rot = errors(pose, th0, t0)
                rec = out[m][cond]
                rec["pos"][i], rec["rot"][i] = pos, rot
                rec["iters"][i], rec["time"][i] = iters, dt
    return out


def run(n_pairs: int, seed: int, workers: int, metrics: list[str]) -> dict:
    pairs = make_pairs(n_pairs, seed)
    n_chunks = max(1, min(n_pairs, workers * 20))
    bounds = np.linspace(0, n_pairs, n_chunks + 1).astype(int)
    chunks = [({k: v[lo:hi] for k, v in pairs.items()}, metrics)
              for lo, hi in itertools.pairwise(bounds) if hi > lo]
    parts = []
    t0 = time.perf_counter()

    def progress() -> None:
        print(f"  {len(parts)}/{len(chunks)} chunks, {time.perf_counter() - t0:.0f} s",
              file=sys.stderr, flush=True)

    if workers > 1:
        with mp.get_context("fork").Pool(workers) as pool:
            for part in pool.imap(run_chunk, chunks, chunksize=1):
                parts.append(part)
                progress()
    else:
        for c in chunks:
            parts.append(run_chunk(c))
            progress()
    merged: dict = {}
    for m in metrics:
        merged[m] = {}
        for cond in CONDITIONS:
            merged[m][cond] = {k: np.concatenate([p[m][cond][k] for p in parts])
                               for k in ("pos", "rot", "iters", "time")}
    return merged


def summarize(merged: dict) -> dict:
    """JSON summary ``{metric: {condition: {pos, rot, median_pos, median_rot, ...}}}``."""
    out: dict = {}
    for m, conds in merged.items():
        out[m] = {}
        for cond, rec in conds.items():
            out[m][cond] = {
                "pos": float(np.mean(rec["pos"])),
                "rot": float(np.mean(rec["rot"])),
                "median_pos": float(np.median(rec["pos"])),
                "median_rot": float(np.median(rec["rot"])),
                "success_rate": float(np.mean((rec["pos"] < 0.1) & (rec["rot"] < 0.1))),
                "mean_iterations": float(np.mean(rec["iters"])),
                "at_iteration_cap": float(np.mean(rec["iters"] >= MAX_ITERATIONS)),
                "mean_time_ms": float(1e3 * np.mean(rec["time"])),
            }
    return out


def _fmt(x: float | None) -> str:
    if x is None:
        return "–"
    if x == 0.0:
        return "0"
    if abs(x) >= 0.01:
        return f"{x:.2f}"
    return f"{x:.1e}"


def markdown_table(summary: dict) -> str:
    head = ("| metric | pos no-noise (paper) | rot no-noise (paper) | pos noise (paper) "
            "| rot noise (paper) | median pos / rot, noise | success no-noise / noise "
            "| at iteration cap | ms/solve |\n|---|---|---|---|---|---|---|---|---|")
    rows = [head]
    for m, conds in summary.items():
        paper = PAPER_TABLE.get(m)
        cells = []
        for cond in CONDITIONS:
            for j, key in enumerate(("pos", "rot")):
                ref = _fmt(paper[cond][j]) if paper else "–"
                cells.append(f"{_fmt(conds[cond][key])} ({ref})")
        nz = conds["noise"]
        med = f"{_fmt(nz['median_pos'])} / {_fmt(nz['median_rot'])}"
        succ = (f"{100 * conds['no_noise']['success_rate']:.1f}% / "
                f"{100 * nz['success_rate']:.1f}%")
        cap = (f"{100 * conds['no_noise']['at_iteration_cap']:.1f}% / "
               f"{100 * nz['at_iteration_cap']:.1f}%")
        ms = 0.5 * (conds["no_noise"]["mean_time_ms"] + nz["mean_time_ms"])
        rows.append(f"| {m} | " + " | ".join(cells) + f" | {med} | {succ} | {cap} | {ms:.1f} |")
    return "\n".join(rows)


def _disjoint_start_share(n_pairs: int, seed: int) -> float:
    """Share of the pairs whose start (``E``, no noise) does not overlap ``E_ref``."""
    from quadloc.factors.overlap import intersection_areas

    pairs = make_pairs(n_pairs, seed)
    starts = np.array([transformed(ref_p, float(t0[0]), float(t0[1]), float(th0)).params()
                       for ref_p, th0, t0 in zip(pairs["ref"], pairs["theta0"], pairs["t0"],
                                                 strict=True)])
    return float(np.mean(intersection_areas(starts, pairs["ref"]) <= 0.0))


def discussion(summary: dict, n_pairs: int, seed: int) -> str:
    """"Where and why" text under the table; every number in it comes from ``summary`` (this
    run), from :data:`PAPER_TABLE`, or from the pairs of this ``n_pairs`` / ``seed``."""
    def v(m: str, cond: str, key: str) -> float:
        return float(summary[m][cond][key])

    def pct(x: float) -> str:
        return f"{100.0 * x:.1f} %"

    def paper(m: str, cond: str, j: int) -> str:
        return _fmt(PAPER_TABLE[m][cond][j]) if m in PAPER_TABLE else "–"

    has = summary.__contains__
    out = ["### Where and why our numbers differ from the paper's", ""]
    smooth = [m for m in ("level_set", "wasserstein", "bhattacharyya") if has(m)]
    if smooth:
        worst = max(max(v(m, "no_noise", "pos"), v(m, "no_noise", "rot")) for m in smooth)
        out.append(
            f"* **{', '.join(smooth)}, no noise: at most {_fmt(worst)} (px or degrees, mean) "
            "instead of the paper's 1e-6 .. 2e-2.** These are zero-residual problems. LM on a "
            "residual that is *smooth at the optimum* converges quadratically, and our "
            "tolerances (`absoluteErrorTol = 1e-16` on `1/2 |r|^2`) let it run to rounding "
            "level. The paper does not give its optimiser's stopping rule; near a zero minimum "
            "a scalar cost has a vanishing gradient, so a gradient-based stop lands at about "
            "the square root of its tolerance, consistent with its values. Our residual forms "
            "matter here: Wasserstein is split exactly into centre, semi-axis and angle terms, "
            "Bhattacharyya uses the spectral form `h(log N)` (module docstring of "
            "`factors/metrics.py`); `sqrt(cost)` residuals would have a cone at the optimum "
            "and converge only linearly.")
    if smooth:
        parts = [f"{m} reaches {_fmt(v(m, 'noise', 'pos'))} px / {_fmt(v(m, 'noise', 'rot'))}"
                 f" degrees (mean)" for m in ("wasserstein", "bhattacharyya") if has(m)]
        text = ("* **With noise** the rigid truth is still the optimum (the noisy `E` keeps the "
                "centre and the axis directions of the rotated `E_ref`, and these metrics, "
                "including the level-set sample layout, share the ellipses' mirror symmetries), "
                "so exact recovery is possible" + (": " + "; ".join(parts) if parts else "") +
                ".")
        if has("level_set"):
            text += (
                f" Level set: {_fmt(v('level_set', 'noise', 'pos'))} px but a mean rotation "
                f"error of {_fmt(v('level_set', 'noise', 'rot'))} degrees against the paper's "
                f"{paper('level_set', 'noise', 1)}, while our median is "
                f"{_fmt(v('level_set', 'noise', 'median_rot'))} degrees. The mean comes from "
                f"the {pct(v('level_set', 'noise', 'at_iteration_cap'))} of noisy level-set "
                f"solves that hit the {MAX_ITERATIONS}-iteration cap: with a non-zero residual "
                "at the optimum the Gauss-Newton Hessian `J^T J` underestimates the rotational "
                "curvature (on the cases we traced), so the angle oscillates around the optimum "
                "with a slowly shrinking amplitude. Our first Wasserstein residual (a "
                "polar-factor form `vec(S_D^1/2 - S_P^1/2 U)`) had the same defect and was "
                "replaced by the exact form, which fixed it. For the level set (whose residual "
                "is fixed by the paper's definition) more iterations would shrink the tail. The "
                "camera-pose factors use the same residual, so refinements from noisy "
                "detections may show the same slow tail.")
        out.append(text)
    boxes = [m for m in ("bbox", "qbbox") if has(m)]
    if boxes:
        rots = " / ".join(_fmt(v(m, "no_noise", "rot")) for m in boxes)
        prot = " / ".join(paper(m, "no_noise", 1) for m in boxes)
        m0 = boxes[0]
        pos_n = " / ".join(_fmt(v(m, "noise", "pos")) for m in boxes)
        med_n = " / ".join(_fmt(v(m, "noise", "median_pos")) for m in boxes)
        ppos = " / ".join(paper(m, "noise", 0) for m in boxes)
        out.append(
            f"* **{' / '.join(boxes)}: rotation error {rots} degrees (paper {prot}), position "
            "exact without noise.** This is the same failure as in the paper: an ellipse at "
            "angle `theta` and its mirror image at `-theta` have the same axis-aligned box, so "
            f"about {pct(1.0 - v(m0, 'no_noise', 'success_rate'))} of the starts (those not "
            "recovered) converge to the mirrored orientation; the box centre is the ellipse "
            "centre, so the position is exact. With noise the box no longer pins the angle at "
            f"all ({pct(v(m0, 'noise', 'success_rate'))} within 0.1 px and 0.1 degree). "
            f"**With noise the mean position error is {pos_n} px (paper {ppos}) while the "
            f"median is {med_n} px.** The box cost separates: `|r|^2 = 2 |c_D - c_P|^2 + 2 "
            "|h_D(theta) - h_P|^2` (`h` the box half-sizes), so the centre optimum is exact at "
            "every angle and a few solves stop early with a centre error of pixels: we traced "
            "the outliers of the first 1000 pairs of seed 0 and all of them stop with the "
            "moving ellipse within a fraction of a degree of axis-aligned (0 or 90 degrees), "
            "where `dh/dtheta = 0` but "
            "the half-sizes cannot match (noise), i.e. on a saddle of the cost in `theta`. "
            "There `J^T J` has almost no `theta` entry, the Gauss-Newton step in `theta` is "
            "huge and, the cost being concave along `theta`, always increases the cost; LM "
            "damps `(x, y)` and `theta` together, so the well-determined centre step is "
            "rejected with it until lambda saturates or the accepted decreases fall below the "
            "relative tolerance (raising lambda's upper bound does not help: the centre step "
            "shrinks with it). A gradient-based optimiser, as the paper presumably used, "
            "follows the large centre gradient and is not held there. qbbox equals bbox here "
            "because every ellipse lies inside the 640 x 480 image, so the truncation never "
            "acts (the truncation itself is tested in `tests/factors/test_metrics.py`).")
    alg = [m for m in ("algebraic", "frobenius") if has(m)]
    if alg:
        def pr(cond: str) -> str:
            return " / ".join(f"{_fmt(v(m, cond, 'pos'))} px, {_fmt(v(m, cond, 'rot'))} deg"
                              for m in alg)

        def pp(cond: str) -> str:
            return " / ".join(f"{paper(m, cond, 0)} px, {paper(m, cond, 1)} deg" for m in alg)

        out.append(
            f"* **{' / '.join(alg)}: {pr('no_noise')} (paper {pp('no_noise')}); noise "
            f"{pr('noise')} (paper {pp('noise')}).** Same behaviour, not the same numbers: "
            "these costs depend on absolute image coordinates (`C*00 = Sigma00 - cx^2`, with "
            "`cx` = 200-440 px the centre terms dominate the shape terms), so the results "
            "depend on where the ellipses sit in the image and on their sizes, which the paper "
            "does not state. Frobenius differs from the vectorised form only by sqrt(2) "
            "weights on the off-diagonal elements, hence the near-identical rows (as in the "
            "paper). We minimise the *squared* Frobenius norm (the paper's `Delta_fro` is the "
            "norm; same minimiser for one pair, and a smooth least-squares residual).")
    if has("giou"):
        out.append(
            f"* **giou: {_fmt(v('giou', 'no_noise', 'pos'))} px, "
            f"{_fmt(v('giou', 'no_noise', 'rot'))} degrees (paper "
            f"{paper('giou', 'no_noise', 0)}, {paper('giou', 'no_noise', 1)}); noise "
            f"{_fmt(v('giou', 'noise', 'pos'))} px, {_fmt(v('giou', 'noise', 'rot'))} degrees "
            f"(paper {paper('giou', 'noise', 0)}, {paper('giou', 'noise', 1)}): far better "
            "than the paper.** The residual is not a function of the scalar cost: `1 - GIoU` "
            "is split over the four quadrants of the detection's frame (4 non-negative rows, "
            "exact areas, `factors/metrics.py` iou / giou); each row is a degree-1 cone at the "
            "optimum, for which the Gauss-Newton step is exact once the rows have full rank, "
            f"so {pct(v('giou', 'no_noise', 'success_rate'))} of the no-noise solves and "
            f"{pct(v('giou', 'noise', 'success_rate'))} of the noisy ones reach 0.1 px / 0.1 "
            f"degree (noisy median {_fmt(v('giou', 'noise', 'median_pos'))} px). The means "
            "come from the few failures: the 6 no-noise failures among the first 600 pairs "
            "of seed 0 all end with the centre right and the ellipse turned by 90 degrees, "
            "the symmetric cross position where the rotational gradient vanishes and "
            "Gauss-Newton's `J^T J` does not see that the cost is largest along the rotation "
            "there. With noise the optimum has a non-zero residual and "
            f"{pct(v('giou', 'noise', 'at_iteration_cap'))} of the solves use all "
            f"{MAX_ITERATIONS} iterations (the errors are small: see the median).")
    if has("iou"):
        disjoint = _disjoint_start_share(n_pairs, seed)
        out.append(
            f"* **iou (not in the paper):** {pct(disjoint)} of the starts have disjoint "
            "ellipses, where `1 - IoU = 1` is flat and LM cannot move (this benchmark "
            "evaluates the metric itself; the camera-pose factors give a disjoint pair the "
            "giou rows instead); "
            f"{pct(1.0 - v('iou', 'no_noise', 'success_rate') - disjoint)} of the no-noise "
            "solves fail otherwise, and the overlapping starts that succeed converge as giou's.")
    return "\n".join(out) + "\n"


def results_markdown(summary: dict, n_pairs: int, wall_s: float | None,
                     seed: int = 0, workers: int = 2, code: str | None = None) -> str:
    """The ``registration_2d`` section of docs/results.md (``code``: the code version that
    ran, when it is not the checkout's)."""
    timing = f" Wall time {wall_s:.0f} s with {workers} worker process(es)." if wall_s else ""
    if code:
        timing += f" Code: {code}."
    return (
        "## 2D ellipse registration (the paper's Table I)\n\n"
        f"{n_pairs} pairs, every metric, with and without detection "
        f"noise.{timing}\n\n"
        "Mean position error (px) and mean rotation error (degrees, modulo 180) of the "
        "recovered rigid transform; the paper's value in brackets (– : not in the paper). "
        "Success = both errors below 0.1 (px, degrees). Setup, LM settings and the "
        "definition of the errors: docstring of `bench/registration_2d.py`; \"at iteration "
        "cap\" = share of solves that used all 100 LM iterations; ms/solve is the mean over "
        "both conditions on the shared 2-core machine.\n\n"
        + markdown_table(summary) + "\n\n" + discussion(summary, n_pairs, seed)
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", type=int, default=10000, help="number of random pairs")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None, help="write the JSON summary here")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--metrics", default=",".join(METRIC_NAMES),
                    help="comma-separated subset of the metrics")
    ap.add_argument("--write-results", action="store_true",
                    help="write the table into docs/results.md (section registration_2d)")
    ap.add_argument("--from-json", type=Path, default=None,
                    help="do not run: re-render the table from a JSON summary of an earlier run "
                         "(pass the --pairs/--seed it was made with)")
    ap.add_argument("--code", default=None,
                    help="with --from-json: the code version that made it (for the text)")
    ap.add_argument("--wall-s", type=float, default=None,
                    help="with --from-json: the wall time of that run, for the results text")
    args = ap.parse_args(argv)
    metrics = [m.strip() for m in args.metrics.split(",") if m.strip()]
    for m in metrics:
        if m not in METRIC_NAMES:
            ap.error(f"unknown metric {m!r}; valid: {', '.join(METRIC_NAMES)}")
    if args.pairs < 1:
        ap.error("--pairs must be >= 1")
    wall = args.wall_s
    if args.from_json:
        summary = json.loads(args.from_json.read_text())
    else:
        t = time.perf_counter()
        merged = run(args.pairs, args.seed, max(1, args.workers), metrics)
        wall = time.perf_counter() - t
        summary = summarize(merged)
        print(f"{args.pairs} pairs x {len(metrics)} metrics x 2 conditions, seed {args.seed}, "
              f"{args.workers} workers, wall time {wall:.0f} s", file=sys.stderr)
    print(markdown_table(summary))
    if args.json and not args.from_json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(summary, indent=2))
    if args.write_results:
        from bench.results_doc import update_results_section

        update_results_section("registration_2d",
                               results_markdown(summary, args.pairs, wall,
                                                args.seed, args.workers, args.code))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
