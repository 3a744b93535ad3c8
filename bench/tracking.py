"""Tracking sessions vs single-frame ``localize`` on 30 Hz walks through the real Chess poses.

    python -m bench.tracking [--seeds 0 1] [--max-frames N] [--smoother isam2|batch]
                             [--window 30] [--json PATH] [--write-results]

Walks: the 108 real ground-truth poses (``tests.support.reference_data``; chunks of 12 poses 0.1 s
apart) in order, joined by smooth 30 Hz interpolation (SLERP + cubic Hermite positions; gaps
travelled at <= 0.4 m/s and <= 45 deg/s). Detections: ``tests.support.simulate.simulate_frame``
(truncation, occlusion, misses, sigma). "Sparse" stretches: in every other 3-second stretch
each frame keeps at most ``seed-random`` 0-2 of its detections (an app looking at few objects).
Odometry (a drift model DIFFERENT from the session's random-walk noise model): the true
relative motions with a 1 % scale error, a constant gyro bias (0.03 deg/s per axis, random
direction), per-step rotation noise 0.1 deg/sqrt(s) and translation noise 0.5 cm/sqrt(m), in an
odometry frame placed at a random rigid offset from the map.

Reported per seed and pooled: % frames within 5 cm / 10 cm and 5 deg (session vs localize on
the SAME frames; a frame without a pose counts as a miss), the same after the session's first
fix, frames with 1-2 detections localized within 10 cm once tracking, frames only the session
localizes within 10 cm, time to first fix, world_from_odom error over time, per-frame update
time (median, p99, CPU process time), memory per session (tracemalloc peak growth).
"""

from __future__ import annotations

import argparse
import gc
import itertools
import json
import math
import os
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

from bench.results_doc import update_results_section
from quadloc.factors.rotations import invert_pose
from quadloc.maps.compiled import compile_map
from quadloc.service.localization.map_calibration import (
    calibration_error,
    calibration_error_floor,
)
from quadloc.service.localization.pipeline import localize
from quadloc.service.localization.types import LocalizationOptions
from quadloc.service.tracking.session import FrameInput, SessionOptions, TrackingSession
from tests.support.building_walks import building_walk
from tests.support.buildings import REPORT_SEEDS, TUNE_SEEDS, Building, make_building
from tests.support.errors import pose_errors
from tests.support.reference_data import load_chess_map, load_chess_poses
from tests.support.simulate import SimulationConfig, simulate_frame
from tests.support.walks import HZ, chess_walk, make_walk, simulate_odometry

ROOT = Path(__file__).resolve().parent.parent




def run_seed(seed: int, max_frames: int | None, options: SessionOptions,
             with_localize: bool = True, max_detections: int | None = None) -> dict:
    scene = load_chess_map()
    cm = compile_map(scene)
    camera, cfw, _ = load_chess_poses()
    walk = make_walk([invert_pose(T) for T in cfw])
    if max_frames:
        walk = walk[:max_frames]
    rng = np.random.default_rng(seed)
    odom = simulate_odometry(walk, rng)
    cfg = SimulationConfig()
    session = TrackingSession(cm, camera, options)
    rows = []
    cpu_ms = []
    inputs = []
    for i, (T, To) in enumerate(zip(walk, odom, strict=True)):
        f = simulate_frame(cm, camera, T, rng, cfg)
        dets = list(f.detections)
        sparse = int(i / (3 * HZ)) % 2 == 1
        if sparse and dets:
            keep = int(rng.integers(0, 3))
            dets = [dets[j] for j in rng.permutation(len(dets))[:keep]]
        if max_detections is not None and len(dets) > max_detections:
            dets = [dets[j] for j in rng.permutation(len(dets))[:max_detections]]
        inputs.append(FrameInput(dets, To, i / HZ, str(i)))
        c0 = time.process_time()
        res = session.add_frame(inputs[-1])
        cpu_ms.append((time.process_time() - c0) * 1e3)
        e_s = pose_errors(res.world_from_camera, T)
        wo_err = None
        if res.world_from_odom is not None:
            true_wo = T @ invert_pose(To)
            wo_err = pose_errors(res.world_from_odom, true_wo)[0]
        e_l = (math.inf, math.inf)
        l_xy = None
        if with_localize and len(dets) >= 2:
            r = localize(dets, cm, camera, LocalizationOptions(seed=seed))
            e_l = pose_errors(r.world_from_camera if r.localized else None, T)
            l_xy = r.world_from_camera[:2, 3].tolist() if r.localized else None
        rows.append(dict(i=i, n=len(dets), sparse=sparse, state=res.state,
                         truth_xy=T[:2, 3].tolist(),
                         s_xy=None if res.world_from_camera is None
                         else res.world_from_camera[:2, 3].tolist(),
                         l_xy=l_xy, s_pos=e_s[0], s_rot=e_s[1], l_pos=e_l[0], l_rot=e_l[1],
                         wo=wo_err, conf=res.confidence, cpu_ms=cpu_ms[-1],
                         init=res.timings_ms.get("multi_frame_ransac") is not None))
    return dict(seed=seed, rows=rows, n_frames=len(rows),
                memory=session_memory(cm, camera, options, inputs))


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def session_memory(cm: object, camera: object, options: SessionOptions,
                   inputs: list[FrameInput], minutes: float = 0.0) -> dict:
    """Python heap held by one session after replaying ``inputs`` (tracemalloc: numpy arrays
    and Python objects; GTSAM's C++ graph is not traced, so also the process RSS growth), and,
    with ``minutes``, the RSS / heap every simulated minute of a 30 Hz session replaying the walk
    back and forth with continuous odometry (timestamps keep increasing)."""
    gc.collect()
    tracemalloc.start()
    h0, r0 = tracemalloc.get_traced_memory()[0], _rss_bytes()
    session = TrackingSession(cm, camera, options)
    for f in inputs:
        session.add_frame(f)
    gc.collect()
    out = {"frames": len(inputs), "heap_bytes": tracemalloc.get_traced_memory()[0] - h0,
           "rss_growth_bytes": _rss_bytes() - r0}
    tracemalloc.stop()
    if minutes:
        # tracemalloc would slow this 20-fold: Python object count (pymalloc blocks) and RSS
        n = int(minutes * 60 * HZ)
        seq = inputs + inputs[::-1]
        # odometry continuity on the way back: re-anchor each pass at the last pose sent
        samples = []
        last_T, last_src = None, None
        b0 = sys.getallocatedblocks()
        for k in range(n):
            f = seq[k % len(seq)]
            if last_T is None:
                T = f.odom_from_camera
            else:
                T = last_T @ invert_pose(last_src) @ f.odom_from_camera
            last_T, last_src = T, f.odom_from_camera
            session.add_frame(FrameInput(f.detections, T, (len(inputs) + k) / HZ, None))
            if (k + 1) % int(60 * HZ) == 0:
                gc.collect()
                samples.append({"minute": (k + 1) / (60 * HZ),
                                "pymalloc_blocks": sys.getallocatedblocks() - b0,
                                "rss_bytes": _rss_bytes() - r0, "state": session.state})
        out["long_session"] = samples
    return out


def summarize(rows: list[dict]) -> dict:
    def within(p: str, r: str, cm: float, idx: list[dict]) -> float:
        if not idx:
            return float("nan")
        return 100.0 * np.mean([(x[p] <= cm / 100) and (x[r] <= 5.0) for x in idx])

    first = next((x["i"] for x in rows if x["state"] == "tracking"), None)
    after = [x for x in rows if first is not None and x["i"] >= first]
    track = [x for x in rows if x["state"] == "tracking"]
    few = [x for x in track if 1 <= x["n"] <= 2]
    ok_s = [(x["s_pos"] <= 0.1 and x["s_rot"] <= 5) for x in rows]
    ok_l = [(x["l_pos"] <= 0.1 and x["l_rot"] <= 5) for x in rows]
    cpu = np.array([x["cpu_ms"] for x in rows])
    cpu_track = np.array([x["cpu_ms"] for x in track if not x["init"]])
    wo = [(x["i"] / HZ, x["wo"]) for x in rows if x["wo"] is not None]
    conf = np.array([x["conf"] for x in track])
    okt = np.array([(x["s_pos"] <= 0.1 and x["s_rot"] <= 5) for x in track], dtype=float)
    return {
        "frames": len(rows),
        "session_within_5cm_5deg_pct": within("s_pos", "s_rot", 5, rows),
        "session_within_10cm_5deg_pct": within("s_pos", "s_rot", 10, rows),
        "localize_within_5cm_5deg_pct": within("l_pos", "l_rot", 5, rows),
        "localize_within_10cm_5deg_pct": within("l_pos", "l_rot", 10, rows),
        "after_first_fix": {
            "frames": len(after),
            "session_error_gt_10cm": int(sum(x["s_pos"] > 0.1 for x in after)),
            "localize_error_gt_10cm": int(sum(x["l_pos"] > 0.1 for x in after)),
        },
        "time_to_first_fix_s": None if first is None else first / HZ,
        "tracking_frames_with_1_2_detections": len(few),
        "tracking_1_2_detections_within_10cm_pct": within("s_pos", "s_rot", 10, few),
        "frames_only_session_within_10cm": int(sum(a and not b for a, b in zip(ok_s, ok_l,
                                                                              strict=True))),
        "frames_only_localize_within_10cm": int(sum(b and not a for a, b in zip(ok_s, ok_l,
                                                                               strict=True))),
        "tracking_frames_outside_10cm_5deg": int(sum(1 - okt)) if len(okt) else 0,
        "mean_confidence_tracking": float(conf.mean()) if len(conf) else None,
        "fraction_within_10cm_5deg_tracking": float(okt.mean()) if len(okt) else None,
        "update_cpu_ms_median": float(np.median(cpu)),
        "update_cpu_ms_p99": float(np.percentile(cpu, 99)),
        "tracking_update_cpu_ms_median": float(np.median(cpu_track)) if len(cpu_track) else None,
        "tracking_update_cpu_ms_p99": float(np.percentile(cpu_track, 99))
        if len(cpu_track) else None,
        "world_from_odom_error_m_by_second": _by_second(wo),
    }


def _by_second(wo: list[tuple[float, float]]) -> dict[str, float]:
    out: dict[int, list[float]] = {}
    for t, e in wo:
        out.setdefault(int(t // 5) * 5, []).append(e)
    return {f"{k}-{k + 5}s": float(np.median(v)) for k, v in sorted(out.items())}


def recording(seed: int, n_frames: int) -> dict:
    """A recording for ``quadloc track`` (docs/tracking.md format): the first ``n_frames`` of
    the walk of ``seed``, detections simulated, drifting odometry, ground truth included."""
    walk = chess_walk(n_frames, seed)
    camera = walk.camera
    frames = []
    for i, (dets, To) in enumerate(zip((f.detections for f in walk.frames), walk.odometry,
                                       strict=True)):
        frames.append({
            "detections": [{"ellipse": {"cx": round(d.ellipse.cx, 3),
                                        "cy": round(d.ellipse.cy, 3),
                                        "a": round(d.ellipse.a, 3), "b": round(d.ellipse.b, 3),
                                        "angle": round(d.ellipse.angle, 5)},
                            "label": d.label, "sigma": float(f"{d.sigma:.4g}")} for d in dets],
            "odom_from_camera": {"matrix": np.round(To, 7).tolist()},
            "timestamp": round(i / HZ, 4), "frame_id": str(i)})
    return {"camera": {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                       "width": camera.width, "height": camera.height},
            "convention": "opencv", "frames": frames,
            "ground_truth_world_from_camera": [np.round(T, 7).tolist() for T in walk.poses]}


def make_plots(results: list[dict], out_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    rows = results[0]["rows"]
    t = np.array([x["i"] for x in rows]) / HZ
    fig, ax = plt.subplots(figsize=(9, 3.5))
    s = np.array([x["s_pos"] if math.isfinite(x["s_pos"]) else np.nan for x in rows])
    loc = np.array([min(x["l_pos"], 1.0) for x in rows])
    ax.plot(t, loc * 100, ".", ms=2, color="tab:orange", label="single-frame localize")
    ax.plot(t, s * 100, "-", lw=1, color="tab:blue", label="session")
    wo = [(x["i"] / HZ, x["wo"] * 100) for x in rows if x["wo"] is not None]
    if wo:
        ax.plot(*zip(*wo, strict=True), "-", lw=1, color="tab:green",
                label="world_from_odom (translation)")
    for x0 in np.arange(3, t[-1], 6):
        ax.axvspan(x0, x0 + 3, color="0.9", lw=0)
    ax.set_ylim(0, 30)
    ax.set_xlabel("time (s); grey: sparse stretches (0-2 detections)")
    ax.set_ylabel("position error (cm, clipped)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(f"Chess walk, seed {results[0]['seed']}")
    p1 = out_dir / "tracking_error.png"
    fig.tight_layout()
    fig.savefig(p1, dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 5))
    tr = np.array([x["truth_xy"] for x in rows])
    ax.plot(tr[:, 0], tr[:, 1], "-", color="k", lw=2, alpha=0.4, label="ground truth")
    lx = np.array([x["l_xy"] for x in rows if x["l_xy"] is not None]).reshape(-1, 2)
    ax.plot(lx[:, 0], lx[:, 1], ".", ms=2, color="tab:orange", label="single-frame localize")
    sx = np.array([x["s_xy"] if x["s_xy"] is not None else [np.nan, np.nan] for x in rows])
    ax.plot(sx[:, 0], sx[:, 1], "-", lw=1, color="tab:blue", label="session")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, map)")
    ax.set_ylabel("y (m, map)")
    ax.legend(fontsize=8)
    ax.set_title(f"Trajectory (top view), seed {results[0]['seed']}")
    p2 = out_dir / "tracking_trajectory.png"
    fig.tight_layout()
    fig.savefig(p2, dpi=90)
    plt.close(fig)
    return [p1, p2]


def _f(x: object, digits: int = 1) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x:.{digits}f}" if isinstance(x, float) else str(x)


def results_markdown(out: dict, batch: dict | None = None, capped: dict | None = None) -> str:
    """The ``tracking`` section of docs/results.md from a run's JSON (and optionally the
    ``--smoother batch`` run's, for the smoother comparison)."""
    lines = ["## tracking (bench/tracking.py)", "",
             f"Command: `{out['command']}` (2-core shared machine, under load from other "
             "benchmarks: CPU times are process time, compare within the run). Seeds 1 and 2, "
             "whole walk through the 108 real Chess poses at 30 Hz (936 frames, 31 s each); "
             "session parameters set a priori (seed 1's first 300 frames were looked at during "
             "development, no parameter was changed after). Plot: "
             "`docs/img/tracking_error.png`, `docs/img/tracking_trajectory.png`.", "",
             "| seed | frames | session 5 cm/5° | localize 5 cm/5° | session 10 cm/5° | "
             "localize 10 cm/5° | >10 cm after 1st fix: session / localize | 1st fix (s) | "
             "1-2 det. frames within 10 cm (tracking) | only session / only localize "
             "within 10 cm |", "|---|---|---|---|---|---|---|---|---|---|"]
    for seed, r in [*out["per_seed"].items(), ("pooled", out["pooled"])]:
        a = r["after_first_fix"]
        lines.append(
            f"| {seed} | {r['frames']} | {_f(r['session_within_5cm_5deg_pct'])} % | "
            f"{_f(r['localize_within_5cm_5deg_pct'])} % | "
            f"{_f(r['session_within_10cm_5deg_pct'])} % | "
            f"{_f(r['localize_within_10cm_5deg_pct'])} % | {a['session_error_gt_10cm']} / "
            f"{a['localize_error_gt_10cm']} | {_f(r['time_to_first_fix_s'], 2)} | "
            f"{_f(r['tracking_1_2_detections_within_10cm_pct'])} % of "
            f"{r['tracking_frames_with_1_2_detections']} | "
            f"{r['frames_only_session_within_10cm']} / {r['frames_only_localize_within_10cm']} |")
    p = out["pooled"]
    lines += ["", f"Per-frame update, CPU ms (isam2, window {out['window_frames']}): median "
              f"{_f(p['update_cpu_ms_median'], 2)}, p99 {_f(p['update_cpu_ms_p99'], 2)} (all "
              f"frames incl. multi-frame RANSAC); tracking frames only: median "
              f"{_f(p['tracking_update_cpu_ms_median'], 2)}, p99 "
              f"{_f(p['tracking_update_cpu_ms_p99'], 2)}."]
    if batch:
        b = batch["pooled"]
        lines.append(f"Smoothers on the same 300 frames (seed 1): `--smoother batch` "
                     f"(`{batch['command']}`): tracking frames median "
                     f"{_f(b['tracking_update_cpu_ms_median'], 2)} ms, p99 "
                     f"{_f(b['tracking_update_cpu_ms_p99'], 2)} ms, "
                     f"{b['after_first_fix']['session_error_gt_10cm']} frames beyond 10 cm")
        same = out.get("long_session", {}).get("pooled")
        if same:
            lines[-1] += (f"; `isam2` (first pass of the 10-minute run below): median "
                          f"{_f(same['tracking_update_cpu_ms_median'], 2)} ms, p99 "
                          f"{_f(same['tracking_update_cpu_ms_p99'], 2)} ms, "
                          f"{same['after_first_fix']['session_error_gt_10cm']} frames beyond "
                          "10 cm")
        lines[-1] += "."
    if capped:
        lines += ["", f"Every frame limited to {capped['max_detections']} detection(s) "
                  f"(`{capped['command']}`; single-frame localize cannot use any frame): "
                  + "; ".join(
                      f"seed {k}: first fix after {_f(r['time_to_first_fix_s'], 2)} s, "
                      f"{_f(r['session_within_10cm_5deg_pct'])} % of all frames within 10 cm "
                      f"and 5°, {r['after_first_fix']['session_error_gt_10cm']} of "
                      f"{r['after_first_fix']['frames']} frames after the first fix beyond "
                      f"10 cm" for k, r in capped["per_seed"].items()) + "."]
    lines += ["", "Confidence (P within 10 cm and 5° under the posterior) vs outcome, tracking "
              f"frames: mean confidence {_f(p['mean_confidence_tracking'], 3)}, fraction "
              f"actually within {_f(p['fraction_within_10cm_5deg_tracking'], 3)}.", "",
              "world_from_odom translation error (median per 5 s of walk, pooled): " + ", ".join(
                  f"{k}: {v * 100:.1f} cm"
                  for k, v in p["world_from_odom_error_m_by_second"].items()) + "."]
    mem = out.get("memory_per_seed", {})
    if mem:
        lines += ["", "Memory per session after the whole walk (Python heap by tracemalloc; "
                  "process RSS growth includes GTSAM's C++ graph): " + "; ".join(
                      f"seed {k}: heap {v['heap_bytes'] / 1e6:.2f} MB, RSS +"
                      f"{v['rss_growth_bytes'] / 1e6:.2f} MB" for k, v in mem.items()) + "."]
    long = (out.get("long_session") or {}).get("long_session")
    if long:
        cmd = out["long_session"].get("command", out["command"])
        lines += ["", f"{len(long)}-minute session at 30 Hz (`{cmd}`: the walk "
                  "replayed back and forth with continuous odometry): at each minute, Python "
                  "objects alive (pymalloc blocks, relative to the session's start) and process "
                  "RSS growth: " + ", ".join(
                      f"{x['pymalloc_blocks']:+d} blocks / {x['rss_bytes'] / 1e6:+.1f} MB"
                      for x in long) + f" (state at the end: {long[-1]['state']})."]
    return "\n".join(lines)


# ---------------------------------------------------------------------- building walks
def run_building_walk(building: Building, seed: int, options: SessionOptions) -> dict:
    """One walk through a building (tests.support.building_walks): per-frame rows."""
    from_walk = building_walk(building, seed)
    session = TrackingSession(building.compiled, from_walk.camera, options)
    rows = []
    seen: set[str] = set()
    for f, T, room, ids in zip(from_walk.frames, from_walk.poses, from_walk.rooms,
                               from_walk.object_ids, strict=True):
        seen |= {o for o in ids if o is not None}
        c0 = time.process_time()
        res = session.add_frame(f)
        cpu = (time.process_time() - c0) * 1e3
        pos, rot = pose_errors(res.world_from_camera, T)
        cands = [pose_errors(c.world_from_camera, T)[0] for c in res.candidates]
        rows.append(dict(i=res.frame_index, n=len(f.detections), seen=len(seen),
                         state=res.state, reason=res.reason, pos=pos, rot=rot,
                         conf=res.confidence, cpu_ms=cpu, room=room.zone_id,
                         n_candidates=len(res.candidates),
                         true_among_candidates=any(c <= 0.5 for c in cands)))
    return dict(seed=seed, rows=rows, inputs=from_walk.frames, camera=from_walk.camera)


def summarize_walks(walks: list[dict]) -> dict:
    """Per map size and mode: the issue's walk figures (module docstring of
    tests.support.building_walks; frames without a pose count as misses after the fix)."""
    per_walk = []
    for w in walks:
        rows = w["rows"]
        first = next((x["i"] for x in rows if x["state"] == "tracking"), None)
        t3 = next((x["i"] for x in rows if x["seen"] >= 3), None)
        posed = [x for x in rows if math.isfinite(x["pos"])]
        off = [math.isfinite(x["pos"]) and x["pos"] > 0.5 for x in rows]
        run = longest = 0
        for o in off:
            run = run + 1 if o else 0
            longest = max(longest, run)
        after = [x for x in rows if first is not None and x["i"] >= first]
        per_walk.append(dict(
            seed=w["seed"], frames=len(rows),
            first_fix_s=None if first is None else first / HZ,
            fix_after_3_objects_s=None if first is None or t3 is None else (first - t3) / HZ,
            posed=len(posed), off_05=int(sum(off)), longest_off_s=longest / HZ,
            after=len(after),
            after_within_10cm=int(sum(x["pos"] <= 0.1 and x["rot"] <= 5 for x in after)),
            ambiguous=int(sum(x["reason"] == "ambiguous" for x in rows)),
            ambiguous_true_listed=int(sum(x["reason"] == "ambiguous"
                                          and x["true_among_candidates"] for x in rows))))
    frames = sum(p["frames"] for p in per_walk)
    cpu = np.array([x["cpu_ms"] for w in walks for x in w["rows"]])
    fix = [p["fix_after_3_objects_s"] for p in per_walk]
    after = sum(p["after"] for p in per_walk)
    track = [x for w in walks for x in w["rows"] if x["state"] == "tracking"]
    return {
        "walks": len(per_walk), "frames": frames,
        "off_05_frames": sum(p["off_05"] for p in per_walk),
        "off_05_pct": 100.0 * sum(p["off_05"] for p in per_walk) / max(frames, 1),
        "walks_off_05_over_1s": sum(p["longest_off_s"] > 1.0 for p in per_walk),
        "walks_committed": sum(p["first_fix_s"] is not None for p in per_walk),
        "walks_committed_within_5s_of_3_objects_pct": 100.0 * sum(
            f is not None and f <= 5.0 for f in fix) / max(len(fix), 1),
        "first_fix_s_median": float(np.median([p["first_fix_s"] for p in per_walk
                                               if p["first_fix_s"] is not None]))
        if any(p["first_fix_s"] is not None for p in per_walk) else None,
        "after_fix_within_10cm_pct": 100.0 * sum(p["after_within_10cm"] for p in per_walk)
        / after if after else None,
        "ambiguous_frames": sum(p["ambiguous"] for p in per_walk),
        "ambiguous_true_listed": sum(p["ambiguous_true_listed"] for p in per_walk),
        "update_cpu_ms_median": float(np.median(cpu)),
        "update_cpu_ms_p99": float(np.percentile(cpu, 99)),
        "tracking_frames": len(track),
        "mean_confidence_tracking": float(np.mean([x["conf"] for x in track]))
        if track else None,
        "fraction_within_10cm_5deg_tracking": float(np.mean(
            [x["pos"] <= 0.1 and x["rot"] <= 5 for x in track])) if track else None,
        "per_walk": per_walk,
    }


def confidence_reliability(walks: list[dict], edges: tuple[float, ...] = (
        0.0, 0.5, 0.8, 0.9, 0.95, 0.99, 1.0)) -> list[dict]:
    """Tracking frames binned by confidence: mean confidence vs fraction within 10 cm / 5°."""
    track = [x for w in walks for x in w["rows"] if x["state"] == "tracking"]
    out = []
    for lo, hi in itertools.pairwise(edges):
        b = [x for x in track if lo <= x["conf"] < hi or (hi == 1.0 and x["conf"] == 1.0)]
        if b:
            out.append({"bin": f"[{lo}, {hi})", "frames": len(b),
                        "mean_confidence": float(np.mean([x["conf"] for x in b])),
                        "within_10cm_5deg": float(np.mean([x["pos"] <= 0.1 and x["rot"] <= 5
                                                           for x in b]))})
    return out


def confidence_calibration(walks: list[dict]) -> dict:
    """Expected calibration error of the tracking frames' confidence (10 equal-width bins,
    success = within 10 cm / 5°) and the error a calibrated confidence shows on as many
    frames by sampling alone (the shared formulas of map calibration)."""
    track = [x for w in walks for x in w["rows"] if x["state"] == "tracking"]
    p = np.array([x["conf"] for x in track], dtype=float)
    y = np.array([x["pos"] <= 0.1 and x["rot"] <= 5 for x in track], dtype=float)
    return {"frames": len(track), "ece": calibration_error(p, y),
            "ece_floor": calibration_error_floor(p)}


def run_buildings(sizes: list[int], modes: list[str], seeds: list[int], walks: int,
                  options: SessionOptions) -> dict:
    """Every (mode, size): ``walks`` walks per base seed (building seed = base seed, walk seeds
    derived), summaries, memory of one session per size (heap after its walk)."""
    out: dict = {"cases": {}, "reliability": []}
    everything = []
    for mode in modes:
        for n in sizes:
            done = []
            for s in seeds:
                b = make_building(n, mode, s)
                for k in range(walks):
                    done.append(run_building_walk(b, 1000 * s + k, options))
            case = summarize_walks(done)
            w0 = done[0]
            case["memory"] = session_memory(make_building(n, mode, seeds[0]).compiled,
                                            w0["camera"], options, w0["inputs"])
            out["cases"][f"{mode}-{n}"] = case
            everything += done
            print(f"{mode}-{n}: " + json.dumps({k: v for k, v in case.items()
                                                if k != "per_walk"}, default=float),
                  file=sys.stderr)
    out["reliability"] = confidence_reliability(everything)
    out["calibration"] = confidence_calibration(everything)
    return out


def building_markdown(out: dict) -> str:
    """The ``tracking-buildings`` section of docs/results.md."""
    lines = [f"## tracking-buildings-{'-'.join(out['modes'])} (bench/tracking.py --building)", "",
             f"Walks through 2 rooms of generated buildings (tests/support/building_walks.py: "
             f"a start room drawn at random, 30 real Chess poses placed in it, a walk at 1.2 m/s "
             f"to the nearest room, 30 poses there; every third 3-s stretch with 0-2 detections; "
             f"drifting odometry), base seeds {out['seeds']} ({out['seed_set']} seeds), "
             f"{out['walks']} walks per seed. A frame without a pose after the fix counts as a "
             "miss. CPU per frame: process time of `add_frame` (shared 2-core machine).", "",
             "| map | walks | frames | > 0.5 m off | walks > 0.5 m off > 1 s | committed "
             "within 5 s of 3 objects | first fix (median s) | after fix within 10 cm/5° | "
             "ambiguous (true listed) | CPU ms median / p99 | session heap MB |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, c in out["cases"].items():
        lines.append(
            f"| {name} | {c['walks']} | {c['frames']} | {c['off_05_frames']} "
            f"({_f(c['off_05_pct'], 2)} %) | {c['walks_off_05_over_1s']} | "
            f"{_f(c['walks_committed_within_5s_of_3_objects_pct'])} % | "
            f"{_f(c['first_fix_s_median'], 2)} | {_f(c['after_fix_within_10cm_pct'])} % | "
            f"{c['ambiguous_frames']} ({c['ambiguous_true_listed']}) | "
            f"{_f(c['update_cpu_ms_median'], 2)} / {_f(c['update_cpu_ms_p99'], 1)} | "
            f"{c['memory']['heap_bytes'] / 1e6:.2f} |")
    lines += ["", "Confidence of tracking frames (all maps pooled) against the outcome: "
              + "; ".join(
        f"{r['bin']}: {r['frames']} frames, mean {_f(r['mean_confidence'], 3)}, within "
        f"{_f(r['within_10cm_5deg'], 3)}" for r in out["reliability"]) + "."]
    cal = out.get("calibration")
    if cal:
        lines += ["", f"Expected calibration error of that confidence over the {cal['frames']} "
                  f"tracking frames (10 equal-width bins): {_f(cal['ece'], 4)}; a calibrated "
                  f"confidence on as many frames shows {_f(cal['ece_floor'], 4)} by sampling "
                  "alone."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--smoother", default="isam2")
    ap.add_argument("--window", type=int, default=30)
    ap.add_argument("--no-localize", action="store_true")
    ap.add_argument("--long-minutes", type=float, default=0.0,
                    help="also replay a session of this many minutes (memory flatness)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--max-detections", type=int, default=None,
                    help="keep at most this many detections in EVERY frame (e.g. 1)")
    ap.add_argument("--render", type=Path, nargs="+", metavar="JSON",
                    help="only write the docs/results.md section from saved --json outputs "
                         "(the main run, then optionally the --smoother batch run)")
    ap.add_argument("--write-recording", type=Path, metavar="PATH",
                    help="only write a recording of --max-frames frames (seed: first of --seeds)")
    ap.add_argument("--write-results", action="store_true")
    ap.add_argument("--building", action="store_true",
                    help="walks through generated buildings (tests/support/building_walks.py)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[1, 10, 50, 200])
    ap.add_argument("--modes", nargs="+", default=["perturbed", "exact"])
    ap.add_argument("--walks", type=int, default=2, help="walks per base seed (--building)")
    ap.add_argument("--seed-set", choices=["report", "tune"], default="report",
                    help="--building base seeds: the first --n-seeds of REPORT_SEEDS (held "
                         "out) or TUNE_SEEDS (tests/support/buildings.py)")
    ap.add_argument("--n-seeds", type=int, default=2)
    args = ap.parse_args(argv)
    opts = SessionOptions(window_frames=args.window, smoother=args.smoother)
    if args.building:
        seeds = list((REPORT_SEEDS if args.seed_set == "report" else TUNE_SEEDS)[:args.n_seeds])
        bout = run_buildings(args.sizes, args.modes, seeds, args.walks, opts)
        bout.update(command="python -m bench.tracking " + " ".join(
            sys.argv[1:] if argv is None else argv), seeds=seeds, seed_set=args.seed_set,
            walks=args.walks, modes=args.modes)
        print(json.dumps(bout, indent=1, default=float))
        if args.json:
            args.json.write_text(json.dumps(bout, indent=1, default=float))
        if args.write_results:
            update_results_section("tracking-buildings-" + "-".join(args.modes),
                                   building_markdown(bout))
        return bout
    if args.render:
        runs = [json.loads(p.read_text()) for p in args.render]
        main_run = runs[0]
        batch = next((r for r in runs[1:] if r["smoother"] == "batch"), None)
        capped = next((r for r in runs[1:] if r.get("max_detections")), None)
        long = next((r for r in runs[1:] if r.get("long_session")), None)
        if long is not None:
            main_run = {**main_run, "long_session": {**long["long_session"],
                                                     "command": long["command"],
                                                     "pooled": long["pooled"]}}
        update_results_section("tracking", results_markdown(main_run, batch, capped) + (
            "\n\nSection assembled from those runs' JSON by `python -m bench.tracking --render "
            + " ".join(str(p) for p in args.render) + "`."))
        return main_run
    if args.write_recording:
        rec = recording(args.seeds[0], args.max_frames or 90)
        args.write_recording.write_text(json.dumps(rec, separators=(",", ":")))
        return rec
    results = [run_seed(s, args.max_frames, opts, not args.no_localize, args.max_detections)
               for s in args.seeds]
    pooled = summarize([x for r in results for x in r["rows"]])
    out = {"command": "python -m bench.tracking " + " ".join(
        sys.argv[1:] if argv is None else argv),
           "smoother": args.smoother, "window_frames": args.window,
           "max_detections": args.max_detections,
           "per_seed": {r["seed"]: summarize(r["rows"]) for r in results},
           "pooled": pooled,
           "memory_per_seed": {r["seed"]: r["memory"] for r in results}}
    if args.long_minutes:
        cm = compile_map(load_chess_map())
        camera, cfw, _ = load_chess_poses()
        walk = make_walk([invert_pose(T) for T in cfw])[:args.max_frames]
        rng = np.random.default_rng(args.seeds[0])
        odom = simulate_odometry(walk, rng)
        inputs = [FrameInput(list(simulate_frame(cm, camera, T, rng).detections), To, i / HZ)
                  for i, (T, To) in enumerate(zip(walk, odom, strict=True))]
        out["long_session"] = session_memory(cm, camera, opts, inputs, args.long_minutes)
    print(json.dumps(out, indent=1, default=float))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=float))
    if args.write_results:
        make_plots(results, ROOT / "docs" / "img")
        update_results_section("tracking", results_markdown(out))
    return out


if __name__ == "__main__":
    main()
