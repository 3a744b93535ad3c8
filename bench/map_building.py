"""Map building from a synthetic recording of the real Chess scene (issue 16).

Usage::

    python -m bench.map_building [--frames 300] [--seeds 1,2] [--test-frames 108]
                                 [--fixed-cameras] [--json PATH] [--plots DIR] [--write-results]
    python -m bench.map_building --write-recording PATH [--frames N] [--seeds S]
                                 [--holdout-every K]
    python -m bench.map_building --building [--rooms 20] [--sizes 1500,3000,6000]
                                 [--seeds 1001] [--jobs 1] [--write-results]

``--building`` (issue 29): a walk through a generated building of ``--rooms`` perturbed rooms
(:func:`tests.support.buildings.building_recording`: every room visited, then revisits; app
poses drifting over the whole walk), built at each of ``--sizes`` frames (the first frames of
the same walk), each build in its own process (peak RSS of that process). Scores: association
precision / recall per room (as below, the detections of each room's objects), objects merged
across rooms (built objects holding detections of objects of two rooms), median centre error of
the matched objects, relocalization within 10 cm with the built map vs the true building map
(the visited rooms' real Chess poses placed in the room, fresh detections; the built map's
answers judged in its own frame, the recording's drifting odometry frame: the true pose after
the rigid alignment of the room's built objects onto the true ones, and, to show the drift
between rooms left in the map, after one alignment of the whole map: :func:`building_markdown`
says why), build wall / CPU
time, loop closures, proposed zones; and the one-room bench on the same seeds (``--frames``) in
the same run. Seeds 0-999 are for tuning (:data:`tests.support.buildings.TUNE_SEEDS`); report on
others.

Per seed:

1. **Walk.** The 108 real ground-truth poses (``tests/support/data``), in file order, with
   ``--frames`` poses interpolated along the walk between consecutive ones (rotation slerp,
   translation linear): real viewpoints plus the in-between views an app would record.
2. **Odometry-grade poses.** The app's poses are the walk's relative motions with noise per
   step (rotation ``N(0, 0.05 deg)`` about a random axis, translation ``N(0, (1 % step + 1 mm))``
   per axis), chained from the true first pose: they drift like VIO.
3. **Detections** from the TRUE poses by :mod:`tests.support.simulate` (its default detector noise,
   truncation at the border, occlusion, 10 % misses) plus 5 % wrong labels and 0.2 spurious
   detections per frame; no track ids.
4. **Build** with :func:`quadloc.maps.building.build.build_map` from the drifting poses (association
   not given; the recording's defaults: camera poses refined with the default odometry noise,
   or not refined with ``--fixed-cameras``) and time it (progress callbacks' largest gap is
   reported).
5. **Scores.** Association precision / recall over detections: a built object is matched to the
   real object most of its detections come from; a detection is correct when it was assigned
   to the object matched to its true object. Recall's denominator: every correctly labelled
   detection of a real object. Per-object centre / semi-axes error (``ellipsoid_errors``) of the
   matched pairs. **Relocalization**: on the real test frames (fresh detections, a separate seed)
   ``localize()`` (level set) with the built map and with the real map; % of frames within
   5 / 10 cm of the true position.

Seed 0 was used to tune the association thresholds and the default odometry noise; the
results are reported on other seeds.
"""

from __future__ import annotations

import argparse
import gzip
import itertools
import json
import math
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

from bench.chess_eval import eval_options
from quadloc.factors.rotations import pose_matrix, rotation_angle
from quadloc.maps.building.build import build_map
from quadloc.maps.building.recording import BuildLimits, recording_to_dict
from quadloc.maps.compiled import compile_map
from quadloc.maps.reconstruct import ellipsoid_errors
from quadloc.service.app.builds import recording_of
from tests.support.errors import pose_errors
from tests.support.reference_data import load_chess_map, load_chess_world_from_camera
from tests.support.simulate import SimulationConfig, simulate_frame
from tests.support.walks import drifting_odometry, resampled_walk


def _det_json(d) -> dict:
    e = d.ellipse
    out = {"label": d.label, "ellipse": {"cx": e.cx, "cy": e.cy, "a": e.a, "b": e.b,
                                         "angle": e.angle}}
    if d.sigma is not None:
        out["sigma"] = d.sigma
    return out


def simulated_recording(seed: int, n_frames: int, config: SimulationConfig | None = None,
                        **options: object) -> tuple[dict, list, list, list]:
    """Steps 1-3 of the module docstring: ``(recording document (the API dialect), true
    poses, app poses, simulated frames)``; ``config``: the detector (default: the simulator's
    default noise with 5 % wrong labels and 0.2 spurious detections per frame); ``options``:
    the recording's build options (``holdout_every``...)."""
    cm = compile_map(load_chess_map())
    camera, poses, _ = load_chess_world_from_camera()
    rng = np.random.default_rng([seed, 16])
    truth_walk = resampled_walk(poses, n_frames)
    app = drifting_odometry(truth_walk, rng)
    cfg = config or SimulationConfig(wrong_label_probability=0.05, spurious_rate=0.2)
    frames = [simulate_frame(cm, camera, T, rng, cfg) for T in truth_walk]
    doc = recording_to_dict(camera, [(str(i), app[i], [_det_json(d) for d in f.detections])
                                     for i, f in enumerate(frames)],
                            **{"name": "Chess (built)", **options})
    return doc, truth_walk, app, frames


def write_recording(path: Path, seed: int, n_frames: int, holdout_every: int | None) -> dict:
    """Write a simulated recording (the API dialect, gzip when ``path`` ends in ``.gz``,
    rounded to 0.1 mm / 1e-6 / 0.01 px to stay small); returns the document."""
    doc, _, _, _ = simulated_recording(seed, n_frames, name="Chess room (simulated)",
                                       **({"holdout_every": holdout_every} if holdout_every
                                          else {}))
    for f in doc["frames"]:
        pose = f["world_from_camera"]
        pose["quaternion_wxyz"] = [round(x, 7) for x in pose["quaternion_wxyz"]]
        pose["translation_m"] = [round(x, 4) for x in pose["translation_m"]]
        for d in f["detections"]:
            d["ellipse"] = {k: round(v, 2 if k != "angle" else 4) for k, v in d["ellipse"].items()}
            if "sigma" in d:
                d["sigma"] = float(f"{d['sigma']:.3g}")
    text = json.dumps(doc, separators=(",", ":")) + "\n"
    if path.suffix == ".gz":
        path.write_bytes(gzip.compress(text.encode(), mtime=0))
    else:
        path.write_text(text)
    return doc


def run_seed(seed: int, n_frames: int, n_test: int, log=print,
             refine_cameras: bool = True) -> dict:
    from quadloc.service.localization.pipeline import localize

    real = load_chess_map()
    cm = compile_map(real)
    camera, poses, _ = load_chess_world_from_camera()
    doc, truth_walk, app, frames = simulated_recording(seed, n_frames)
    from dataclasses import replace

    # the recording's defaults (odometry noise, ...) except, for the ablation, no camera poses
    rec = replace(recording_of(doc, BuildLimits(max_frames=n_frames, max_detections=10 ** 7)),
                  refine_camera_poses=refine_cameras)
    truth_ids = [frames[o.frame].object_ids[o.index] for o in rec.observations]
    truth_label_ok = [frames[o.frame].true_labels[o.index] == o.label
                      for o in rec.observations]
    drift = float(np.linalg.norm(app[-1][:3, 3] - truth_walk[-1][:3, 3]))
    walk_length = float(sum(np.linalg.norm(a[:3, 3] - b[:3, 3])
                            for a, b in itertools.pairwise(truth_walk)))

    stamps: list[float] = []

    def progress(stage: str, pct: float, n: int) -> None:
        stamps.append(time.monotonic())

    t = time.monotonic()
    cpu = time.process_time()
    stamps.append(t)
    scene, built_report = build_map(rec, map_id="chess-built", progress=progress)
    report = built_report.model_dump(mode="json")
    build_s = time.monotonic() - t
    build_cpu_s = time.process_time() - cpu
    stamps.append(time.monotonic())
    max_gap = float(np.max(np.diff(stamps)))

    # association scores
    obs_index = {(o.frame, o.index): k for k, o in enumerate(rec.observations)}
    assigned: dict[int, str] = {}
    for obj in report["objects"]:
        for d in obj["detections"]:
            assigned[obs_index[(d["frame_index"], d["detection_index"])]] = obj["object_id"]
    match: dict[str, str] = {}
    for obj in report["objects"]:
        ids = [truth_ids[obs_index[(d["frame_index"], d["detection_index"])]]
               for d in obj["detections"]]
        match[obj["object_id"]] = Counter(ids).most_common(1)[0][0]
    correct = sum(1 for k, oid in assigned.items() if truth_ids[k] == match[oid]
                  and truth_ids[k] is not None)
    relevant = sum(1 for k in range(len(truth_ids))
                   if truth_ids[k] is not None and truth_label_ok[k])
    correct_relevant = sum(1 for k, oid in assigned.items() if truth_ids[k] == match[oid]
                           and truth_ids[k] is not None and truth_label_ok[k])
    precision = correct / max(1, len(assigned))
    recall = correct_relevant / max(1, relevant)
    # per-object errors (the matched real object; duplicates counted)
    real_by_id = {o.object_id: o for o in real.objects}
    built_by_id = {o.object_id: o for o in scene.objects}
    per_object = []
    for oid, rid in match.items():
        if oid not in built_by_id or rid is None:
            continue
        err = ellipsoid_errors(built_by_id[oid].ellipsoid, real_by_id[rid].ellipsoid)
        q = next(o["quality"] for o in report["objects"] if o["object_id"] == oid)
        per_object.append({"built": oid, "real": rid, "center_m": err["center_m"],
                           "axes_m": err["axes_m"], "axes_rel": err["axes_rel"],
                           "n_views": q["n_views"], "view_spread_deg": q["view_spread_deg"],
                           "unconstrained_axes": q["unconstrained_axes"]})
    matched_real = {m for m in match.values() if m is not None}
    # The built map lives in the app's (drifting) frame: also evaluate it after the rigid
    # alignment of its object centres onto the real ones (Kabsch; the frame choice is arbitrary,
    # the drift's non-rigid part stays).
    # Only objects whose axes the views constrain (the flagged ones, e.g. the TV seen within
    # a narrow cone, can be off by decimetres along the viewing direction).
    constrained = {o["object_id"] for o in report["objects"]
                   if not o["quality"]["unconstrained_axes"]}
    pairs = [(built_by_id[o].ellipsoid.center, real_by_id[r].ellipsoid.center)
             for o, r in match.items() if o in built_by_id and r is not None
             and o in constrained and list(match.values()).count(r) == 1]
    T_align = kabsch(np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
    aligned = transform_scene(scene, T_align)
    aligned_by_id = {o.object_id: o for o in aligned.objects}
    for entry in per_object:
        err = ellipsoid_errors(aligned_by_id[entry["built"]].ellipsoid,
                               real_by_id[entry["real"]].ellipsoid)
        entry["aligned_center_m"] = err["center_m"]
    # relocalization on the real test frames, fresh detections
    cm_built = compile_map(scene)
    cm_aligned = compile_map(aligned)
    test_rng = np.random.default_rng([seed, 1016])
    test_idx = np.linspace(0, len(poses) - 1, min(n_test, len(poses))).astype(int)
    err_real, err_built, err_aligned = [], [], []
    for i in test_idx:
        f = simulate_frame(cm, camera, poses[i], test_rng, SimulationConfig())
        for target, errs in ((cm, err_real), (cm_built, err_built),
                             (cm_aligned, err_aligned)):
            r = localize(f.detections, target, camera, eval_options(seed=seed))
            errs.append(pose_errors(r.world_from_camera if r.localized else None, poses[i])[0])
    er, eb, ea = np.array(err_real), np.array(err_built), np.array(err_aligned)
    out = {
        "seed": seed, "frames": n_frames, "detections": len(rec.observations),
        "app_pose_drift_end_m": drift, "walk_length_m": walk_length,
        "build_s": build_s, "build_cpu_s": build_cpu_s, "max_progress_gap_s": max_gap,
        "timings_s": report["timings_s"], "refinement": report["refinement"],
        "objects_built": len(scene.objects), "real_objects": len(real.objects),
        "real_objects_found": len(matched_real),
        "association": {"precision": precision, "recall": recall,
                        "assigned": len(assigned), "relevant": relevant,
                        "rejected": len(report["rejected_detections"])},
        "per_object": per_object,
        "relocalization": {
            "test_frames": len(test_idx),
            "real_map": {"within_5cm": float(np.mean(er <= 0.05)),
                         "within_10cm": float(np.mean(er <= 0.10))},
            "built_map": {"within_5cm": float(np.mean(eb <= 0.05)),
                          "within_10cm": float(np.mean(eb <= 0.10))},
            "built_map_aligned": {"within_5cm": float(np.mean(ea <= 0.05)),
                                  "within_10cm": float(np.mean(ea <= 0.10)),
                                  "alignment_rotation_deg": math.degrees(float(
                                      rotation_angle(T_align[:3, :3], np.eye(3)))),
                                  "alignment_translation_m": float(np.linalg.norm(
                                      T_align[:3, 3]))},
        },
        "_scene": scene.to_dict(),
    }
    log(f"seed {seed}: P={precision:.3f} R={recall:.3f} objects {len(scene.objects)} "
        f"build {build_s:.1f}s reloc real {out['relocalization']['real_map']} "
        f"built {out['relocalization']['built_map']}")
    return out


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Rigid 4x4 ``T`` minimising ``sum |T src_i - dst_i|^2`` (points (n, 3), n >= 3)."""
    cs, cd = src.mean(0), dst.mean(0)
    U, _, Vt = np.linalg.svd((src - cs).T @ (dst - cd))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return pose_matrix(R, cd - R @ cs)


#: :func:`trimmed_kabsch`: a pair is left out of the alignment when its residual exceeds this
#: many times the median residual (and :data:`TRIM_FLOOR_M`).
TRIM_FACTOR = 2.5
TRIM_FLOOR_M = 0.02


def trimmed_kabsch(src: np.ndarray, dst: np.ndarray, rounds: int = 3) -> tuple[np.ndarray, int]:
    """:func:`kabsch` refitted ``rounds`` times without the pairs whose residual exceeds
    ``max(TRIM_FACTOR x median residual, TRIM_FLOOR_M)``: the frame the majority of the objects
    agree on, which one badly built object (e.g. a TV 0.2 m off) does not tilt. Returns the 4x4
    transform and how many pairs were left out."""
    keep = np.ones(len(src), dtype=bool)
    T = kabsch(src, dst)
    for _ in range(rounds):
        T = kabsch(src[keep], dst[keep])
        res = np.linalg.norm(src @ T[:3, :3].T + T[:3, 3] - dst, axis=1)
        new = res <= max(TRIM_FACTOR * float(np.median(res)), TRIM_FLOOR_M)
        if new.sum() < 3 or (new == keep).all():
            break
        keep = new
    return T, int((~keep).sum())


def transform_scene(scene, T: np.ndarray):
    """The map with every ellipsoid moved by the rigid ``T`` (4x4)."""
    from dataclasses import replace

    from quadloc.factors.camera import Ellipsoid
    from quadloc.maps.model import MapObject

    objs = tuple(MapObject(o.object_id, o.category, Ellipsoid(
        T[:3, :3] @ o.ellipsoid.center + T[:3, 3], o.ellipsoid.axes,
        T[:3, :3] @ o.ellipsoid.rotation)) for o in scene.objects)
    return replace(scene, objects=objs)


def make_plot(result: dict, out_dir: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from quadloc.maps.model import scene_map_from_dict

    real = load_chess_map()
    built = scene_map_from_dict(result["_scene"])
    fig, ax = plt.subplots(figsize=(6, 6))
    t = np.linspace(0, 2 * np.pi, 100)
    for scene, color, name in ((real, "k", "real"), (built, "tab:red", "built")):
        for k, o in enumerate(scene.objects):
            e = o.ellipsoid
            # top view: the outline of the ellipsoid projected on the XY plane (+Z up)
            M = (e.rotation * e.axes**2) @ e.rotation.T
            w, v = np.linalg.eigh(M[:2, :2])
            pts = (v * np.sqrt(w)) @ np.stack([np.cos(t), np.sin(t)]) + e.center[:2, None]
            ax.plot(pts[0], pts[1], color=color, lw=1.2,
                    label=name if k == 0 else None, ls="-" if name == "real" else "--")
            if name == "real":
                ax.text(e.center[0], e.center[1], o.category, fontsize=7)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"Chess, top view: built from {result['frames']} frames (seed {result['seed']})")
    ax.legend()
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "map_building_top_view.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def verdicts(results: dict) -> str:
    """The issue's targets, checked on every seed (computed, not written by hand)."""
    seeds = results["seeds"]
    pr = all(r["association"]["precision"] >= 0.95 and r["association"]["recall"] >= 0.95
             for r in seeds)
    gaps = [100 * (r["relocalization"]["real_map"]["within_10cm"]
                   - r["relocalization"]["built_map"]["within_10cm"]) for r in seeds]
    gaps_al = [100 * (r["relocalization"]["real_map"]["within_10cm"]
                      - r["relocalization"]["built_map_aligned"]["within_10cm"]) for r in seeds]
    t = max(r["build_s"] for r in seeds)
    gap = max(r["max_progress_gap_s"] for r in seeds)

    def ok(flag: bool) -> str:
        return "met" if flag else "NOT met"

    return "\n".join([
        "Targets (issue 16), over these seeds:",
        f"- association precision and recall >= 0.95: {ok(pr)}.",
        f"- relocalization with the built map within 5 points of the real map at 10 cm: as "
        f"built {ok(max(gaps) <= 5)} (real minus built: "
        f"{', '.join(f'{g:+.1f}' for g in gaps)} points), after the rigid alignment "
        f"{ok(max(gaps_al) <= 5)} ({', '.join(f'{g:+.1f}' for g in gaps_al)} points).",
        f"- 300 frames built in <= 30 s with progress at least every 2 s: "
        f"{ok(t <= 30 and gap <= 2)} (slowest {t:.1f} s, largest gap between progress "
        f"reports {gap:.2f} s).",
    ])


def _pct2(d: dict) -> str:
    return f"{d['within_5cm']:.0%} / {d['within_10cm']:.0%}"


def markdown(results: dict, plot: Path | None) -> str:
    header = ["seed", "frames", "detections", "walk (m)", "app drift at end (m)",
              "assoc. precision", "assoc. recall", "real objects found (built)",
              "median centre err (cm)",
              "median centre err after alignment (cm)", "median max semi-axis err (cm)",
              "reloc real map 5/10 cm", "reloc built map 5/10 cm",
              "reloc built map aligned 5/10 cm", "build (s)", "build CPU (s)",
              "max progress gap (s)"]
    rows = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in results["seeds"]:
        a, rl, po = r["association"], r["relocalization"], r["per_object"]
        cells = [r["seed"], r["frames"], r["detections"], f"{r['walk_length_m']:.1f}",
                 f"{r['app_pose_drift_end_m']:.3f}",
                 f"{a['precision']:.3f}", f"{a['recall']:.3f}",
                 f"{r['real_objects_found']}/{r['real_objects']} ({r['objects_built']})",
                 f"{np.median([o['center_m'] for o in po]) * 100:.1f}",
                 f"{np.median([o['aligned_center_m'] for o in po]) * 100:.1f}",
                 f"{np.median([o['axes_m'] for o in po]) * 100:.1f}",
                 _pct2(rl["real_map"]), _pct2(rl["built_map"]), _pct2(rl["built_map_aligned"]),
                 f"{r['build_s']:.1f}", f"{r.get('build_cpu_s', math.nan):.1f}",
                 f"{r['max_progress_gap_s']:.2f}"]
        rows.append("| " + " | ".join(str(c) for c in cells) + " |")
    title = ("Map building from a recording (the default: camera poses refined, object-level "
             "BA)" if results.get("refine_cameras")
             else "Map building without camera-pose refinement (ablation)")
    text = f"""## {title} (bench/map_building.py)

Synthetic walks through the real Chess scene (the 108 real poses + interpolated ones),
odometry-grade app poses (0.05 deg and 1 % + 1 mm noise per step, chained: they drift), detections
simulated from the TRUE poses (default detector noise, truncation, occlusion, 10 % misses, 5 %
wrong labels, 0.2 spurious per frame), no track ids; the map is built from the drifting poses
(camera poses {"refined with the app's relative poses as between factors, the recording's "
               "default odometry noise (quadloc.maps.building.recording.OdometryNoise)"
               if results.get("refine_cameras") else "not refined"}). Relocalization: the real
test frames, fresh detections,
`localize()` (level set) with the real map, the built map as built (app frame), and the built
map after the rigid alignment (Kabsch) of its constrained objects' centres onto the real ones
(the app's frame is arbitrary; the non-rigid part of the drift remains). Seed 0 was used for
tuning; the seeds below are others. Timings on a shared 2-core machine (other jobs may run:
compare within one run).

{chr(10).join(rows)}
"""
    text += "\n" + verdicts(results) + "\n"
    for r in results["seeds"]:
        per = "; ".join(
            f"{o['built']}->{o['real']}: {o['center_m'] * 100:.1f} cm "
            f"({o['aligned_center_m'] * 100:.1f} aligned) / {o['axes_m'] * 100:.1f} cm, "
            f"{o['n_views']} views, {o['view_spread_deg']:.0f} deg"
            + (f", unconstrained axes {o['unconstrained_axes']}" if o["unconstrained_axes"]
               else "")
            for o in r["per_object"])
        text += (f"\nSeed {r['seed']} per object (centre error / largest semi-axis error, "
                 f"views, spread of viewing directions): {per}.\n")
    if plot is not None:
        text += f"\n![built vs real, top view](img/{plot.name})\n"
    return text


def _build_and_score(seed: int, n_rooms: int, n_frames: int, n_test_per_room: int,
                     queue: object) -> None:
    """One building-scale build (``--building``), run in a child process: puts its result
    dict on ``queue``."""
    import resource

    from quadloc.service.localization.pipeline import localize
    from tests.support.buildings import building_recording

    br = building_recording(n_rooms, n_frames, seed)
    doc = recording_to_dict(br.camera, [(str(i), br.app_poses[i],
                                         [_det_json(d) for d in f.detections])
                                        for i, f in enumerate(br.frames)])
    rec = recording_of(doc, BuildLimits(max_frames=n_frames, max_detections=10 ** 7))
    truth = [br.frames[o.frame].object_ids[o.index] for o in rec.observations]
    label_ok = [br.frames[o.frame].true_labels[o.index] == o.label for o in rec.observations]
    stamps: list[float] = []
    t, cpu = time.monotonic(), time.process_time()
    stamps.append(t)
    scene, built_report = build_map(rec, map_id="building-built",
                                    progress=lambda *_: stamps.append(time.monotonic()))
    build_s, build_cpu_s = time.monotonic() - t, time.process_time() - cpu
    stamps.append(time.monotonic())
    report = built_report.model_dump(mode="json")
    obs_index = {(o.frame, o.index): k for k, o in enumerate(rec.observations)}
    zone = br.building.zone_of
    match: dict[str, str | None] = {}
    assigned: dict[int, str] = {}
    merged_across = 0
    for obj in report["objects"]:
        ks = [obs_index[(d["frame_index"], d["detection_index"])] for d in obj["detections"]]
        for k in ks:
            assigned[k] = obj["object_id"]
        match[obj["object_id"]] = Counter(truth[k] for k in ks).most_common(1)[0][0]
        merged_across += len({zone(truth[k]) for k in ks if truth[k] is not None}) > 1
    per_room: dict[str, dict[str, int]] = {}
    for k, tid in enumerate(truth):
        if tid is None:
            continue
        room = per_room.setdefault(zone(tid), {"assigned": 0, "correct": 0, "relevant": 0,
                                               "found": 0})
        ok = k in assigned and match[assigned[k]] == tid
        room["assigned"] += k in assigned
        room["correct"] += ok
        room["relevant"] += label_ok[k]
        room["found"] += ok and label_ok[k]
    for k, oid in assigned.items():  # spurious detections in an object count against it
        if truth[k] is None and match[oid] is not None:
            per_room[zone(match[oid])]["assigned"] += 1
    rooms = {z: {"precision": r["correct"] / max(1, r["assigned"]),
                 "recall": r["found"] / max(1, r["relevant"])} for z, r in per_room.items()}
    real_by_id = {o.object_id: o for o in br.building.scene_map.objects}
    built_by_id = {o.object_id: o for o in scene.objects}
    centre = [ellipsoid_errors(built_by_id[b].ellipsoid, real_by_id[r].ellipsoid)["center_m"]
              for b, r in match.items() if b in built_by_id and r is not None]
    visited = sorted({z for z, _, _ in br.visits})
    camera, chess_poses, _ = load_chess_world_from_camera()
    rooms_by_id = {r.zone_id: r for r in br.building.rooms}
    cm_true, cm_built = br.building.compiled, compile_map(scene)
    test_rng = np.random.default_rng([seed, 1029])
    errs: dict[str, list[float]] = {"true_map": [], "built_map": [],
                                    "built_map_global_aligned": [],
                                    "built_map_room_aligned": []}
    aligned_centre: list[float] = []
    # one rigid alignment of the whole built map (every matched object seen once) onto the
    # truth: the app frame's offset removed, the drift between rooms that the build kept left in
    unique = [(built_by_id[b].ellipsoid.center, real_by_id[r].ellipsoid.center)
              for b, r in match.items() if b in built_by_id and r is not None
              and list(match.values()).count(r) == 1]
    cm_global = compile_map(transform_scene(scene, trimmed_kabsch(
        np.array([p for p, _ in unique]), np.array([q for _, q in unique]))[0])) \
        if len(unique) >= 3 else None
    for z in visited:
        room = rooms_by_id[z]
        # the built map after the rigid alignment of this room's matched objects onto the true
        # ones: how right the map is locally, the drift's far part removed
        pairs = [(built_by_id[b].ellipsoid.center, real_by_id[r].ellipsoid.center)
                 for b, r in match.items() if b in built_by_id and r is not None
                 and zone(r) == z and list(match.values()).count(r) == 1]
        cm_room = None
        if len(pairs) >= 3:
            T_z, _ = trimmed_kabsch(np.array([p for p, _ in pairs]),
                                    np.array([q for _, q in pairs]))
            aligned_centre += [float(np.linalg.norm(T_z[:3, :3] @ p + T_z[:3, 3] - q))
                               for p, q in pairs]
            cm_room = compile_map(transform_scene(scene, T_z))
        for i in np.linspace(0, len(chess_poses) - 1, n_test_per_room).astype(int):
            T = room.world_from_room @ chess_poses[i]
            f = simulate_frame(br.building.room_map(room), camera, T, test_rng,
                               SimulationConfig())
            for name, target in (("true_map", cm_true), ("built_map", cm_built),
                                 ("built_map_global_aligned", cm_global),
                                 ("built_map_room_aligned", cm_room)):
                r = localize(f.detections, target, camera, eval_options(seed=seed)) \
                    if target is not None else None
                errs[name].append(pose_errors(r.world_from_camera if r is not None
                                              and r.localized else None, T)[0])
    drift = [float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
             for a, b in zip(br.app_poses, br.true_poses, strict=True)]
    true_in_visited = sum(len(rooms_by_id[z].object_ids) for z in visited)
    queue.put({  # type: ignore[attr-defined]
        "seed": seed, "rooms": n_rooms, "frames": n_frames, "rooms_visited": len(visited),
        "visits": len(br.visits), "detections": len(rec.observations),
        "app_pose_drift_max_m": max(drift),
        "objects_built": len(scene.objects), "true_objects_in_visited_rooms": true_in_visited,
        "true_objects_found": len({m for m in match.values() if m is not None}),
        "objects_merged_across_rooms": merged_across,
        "precision_min_room": min(r["precision"] for r in rooms.values()),
        "recall_min_room": min(r["recall"] for r in rooms.values()),
        "precision_median_room": float(np.median([r["precision"] for r in rooms.values()])),
        "recall_median_room": float(np.median([r["recall"] for r in rooms.values()])),
        "per_room": rooms,
        "centre_error_median_m": float(np.median(centre)) if centre else math.nan,
        "centre_error_p90_m": float(np.percentile(centre, 90)) if centre else math.nan,
        "centre_error_room_aligned_median_m": float(np.median(aligned_centre))
        if aligned_centre else math.nan,
        "loop_closures": scene.metadata.get("loop_closures"),
        "zones_proposed": len(scene.zones),
        "relocalization_within_10cm": {
            name: float(np.mean(np.array(e) <= 0.10)) for name, e in errs.items()},
        "test_frames": len(errs["true_map"]),
        "build_s": build_s, "build_cpu_s": build_cpu_s,
        "max_progress_gap_s": float(np.max(np.diff(stamps))),
        "timings_s": report["timings_s"],
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    })


def run_building(seeds: list[int], n_rooms: int, sizes: list[int], n_test_per_room: int,
                 log=print, jobs: int = 1) -> list[dict]:
    """``--building``: one build per seed and size, each in its own process (module
    docstring), at most ``jobs`` at once (``--jobs``: the builds then share the CPU, so their
    times grow; the peak RSS stays per build); results in seed, size order."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    tasks = [(seed, n) for seed in seeds for n in sizes]
    results: dict[tuple[int, int], dict] = {}
    running: list[tuple[tuple[int, int], object, object]] = []
    pending = list(tasks)
    while pending or running:
        while pending and len(running) < max(1, jobs):
            seed, n = pending.pop(0)
            queue = ctx.Queue()
            proc = ctx.Process(target=_build_and_score,
                               args=(seed, n_rooms, n, n_test_per_room, queue))
            proc.start()
            running.append(((seed, n), proc, queue))
        time.sleep(1.0)
        for entry in list(running):
            (seed, n), proc, queue = entry
            try:
                result = queue.get(timeout=0.1)  # type: ignore[attr-defined]
            except Exception:  # queue.Empty: the child's result, or its failure
                if not proc.is_alive():  # type: ignore[attr-defined]
                    raise RuntimeError(f"the {n}-frame build of seed {seed} failed (exit "
                                       f"code {proc.exitcode})") from None  # type: ignore
                continue
            proc.join()  # type: ignore[attr-defined]
            running.remove(entry)
            log(f"building seed {seed} {n} frames: {json.dumps(result)[:400]}")
            results[(seed, n)] = result
    return [results[t] for t in tasks]


def building_markdown(results: dict) -> str:
    """The ``map_building_building`` section of docs/results.md."""
    header = ["seed", "frames", "rooms visited (visits)", "detections", "app drift max (m)",
              "objects built / true (found)", "merged across rooms",
              "precision per room min / median", "recall per room min / median",
              "centre err median / p90 (cm)", "centre err room-aligned median (cm)",
              "loop closures", "zones proposed",
              "reloc 10 cm true / built raw / globally aligned / room-aligned", "build (s)",
              "build CPU (s)",
              "peak RSS (MB)"]
    rows = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in results["building"]:
        rl = r["relocalization_within_10cm"]
        rows.append("| " + " | ".join(str(c) for c in [
            r["seed"], r["frames"], f"{r['rooms_visited']} ({r['visits']})", r["detections"],
            f"{r['app_pose_drift_max_m']:.2f}",
            f"{r['objects_built']} / {r['true_objects_in_visited_rooms']} "
            f"({r['true_objects_found']})", r["objects_merged_across_rooms"],
            f"{r['precision_min_room']:.3f} / {r['precision_median_room']:.3f}",
            f"{r['recall_min_room']:.3f} / {r['recall_median_room']:.3f}",
            f"{r['centre_error_median_m'] * 100:.1f} / {r['centre_error_p90_m'] * 100:.1f}",
            f"{r.get('centre_error_room_aligned_median_m', math.nan) * 100:.1f}",
            r["loop_closures"], r["zones_proposed"],
            f"{rl['true_map']:.0%} / {rl['built_map']:.0%} / "
            f"{rl.get('built_map_global_aligned', math.nan):.0%} / "
            f"{rl.get('built_map_room_aligned', math.nan):.0%}", f"{r['build_s']:.0f}",
            f"{r['build_cpu_s']:.0f}", f"{r['peak_rss_mb']:.0f}"]) + " |")
    one = ["| " + " | ".join(["seed", "frames", "precision", "recall", "objects built / real",
                              "reloc 10 cm real / built", "build (s)"]) + " |",
           "|" + "---|" * 7]
    for r in results["one_room"]:
        one.append("| " + " | ".join(str(c) for c in [
            r["seed"], r["frames"], f"{r['association']['precision']:.3f}",
            f"{r['association']['recall']:.3f}",
            f"{r['objects_built']} / {r['real_objects']}",
            f"{r['relocalization']['real_map']['within_10cm']:.0%} / "
            f"{r['relocalization']['built_map']['within_10cm']:.0%}",
            f"{r['build_s']:.1f}"]) + " |")
    big = [r for r in results["building"] if r["frames"] >= 6000]

    def ok(flag: bool) -> str:
        return "met" if flag else "NOT met"

    reloc = [r["relocalization_within_10cm"] for r in big]
    merged_ok = all(r["objects_merged_across_rooms"] == 0 for r in big)
    pr_ok = all(r["precision_min_room"] >= 0.95 and r["recall_min_room"] >= 0.95 for r in big)
    reloc_ok = all(100 * (r["true_map"] - r["built_map_room_aligned"]) <= 5 for r in reloc)
    reloc_global_ok = all(100 * (r["true_map"] - r.get("built_map_global_aligned", 0.0)) <= 5
                          for r in reloc)
    cost_ok = all(r["build_s"] <= 600 and r["peak_rss_mb"] <= 2048 for r in big)
    verdict = "\n".join([
        "Targets (issue 29) on the >= 6,000-frame builds above:",
        f"- 0 objects merged across rooms: {ok(merged_ok)}.",
        f"- association precision and recall >= 0.95 in every room: {ok(pr_ok)}.",
        "- relocalization with the built map within 5 points of the true map at 10 cm, judged "
        f"in the built map's frame around the camera (room-aligned): {ok(reloc_ok)}; judged "
        f"after one alignment of the whole map (drift between rooms counted): "
        f"{ok(reloc_global_ok)}.",
        f"- build <= 10 min and peak memory <= 2 GB: {ok(cost_ok)}.",
    ]) if big else "No build of >= 6,000 frames in this run."
    return f"""## Map building at building scale (bench/map_building.py --building)

A walk through a generated building of perturbed copies of the Chess room
(`tests.support.buildings.building_recording`: every room once, row by row, then revisits; in a
room the real Chess walk placed in it, between rooms a transit seeing nothing), app poses
drifting over the whole walk (per step rotation N(0, 0.05 deg), translation N(0, 1 % of the
step + 1 mm) per axis, chained, never reset), detections simulated from the true poses (default
detector noise, truncation, occlusion, 10 % misses, 5 % wrong labels, 0.2 spurious per frame),
no track ids. Each size is the first frames of the same walk, built in its own process (peak
RSS of that process, recording included). Per room: the detections of that room's objects.
Relocalization: 5 real Chess poses per visited room, placed in the room, fresh detections,
`localize()` with the true building map and with the built one, the answer compared with the
true pose. The built map is in the recording's frame (the app's odometry frame, which starts at
the true first pose and drifts: up to "app drift max" from the truth), so its answers must be
judged in that frame. "Raw": the built map as it is, against the true pose (not meaningful at
building scale: it counts the app's drift as error). "Globally aligned": after one rigid
alignment (Kabsch) of all matched objects onto the truth, which removes the frame offset and
leaves the drift between rooms the build did not correct. "Room-aligned" (the reference of the
target): after the rigid alignment of that room's matched objects onto the true ones, i.e.
the true pose expressed in the built map's own frame around the camera; this is what a client
relocalizing with the built map gets right or wrong relative to the map's objects (and
content placed in it); also its centre error. Both alignments are trimmed (refitted without
the objects whose residual exceeds 2.5x the median and 2 cm): one badly built object, the TV
of every room, 0.15-0.22 m off, tilted an untrimmed room alignment by enough to put every
other object 4-5 cm off and the answers about 10 cm off. Held-out seeds (tuning used seed 1).
Timings on the shared 2-core machine under load; with `--jobs` N > 1, N builds ran at once and
their times include that sharing.

{chr(10).join(rows)}

The one-room bench (`run_seed`, the Chess walk) in the same run:

{chr(10).join(one)}

{verdict}
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--test-frames", type=int, default=108)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--plots", type=Path)
    ap.add_argument("--write-results", action="store_true")
    ap.add_argument("--write-recording", type=Path, metavar="PATH",
                    help="only write the first seed's recording (the API dialect, .gz = gzip) "
                         "with --frames frames and exit")
    ap.add_argument("--holdout-every", type=int, metavar="K",
                    help="with --write-recording: the recording's holdout_every")
    ap.add_argument("--fixed-cameras", action="store_true",
                    help="ablation: do not refine the camera poses (the default refines them, "
                         "object-level bundle adjustment); results go to the section "
                         "map_building_fixed_cameras")
    ap.add_argument("--building", action="store_true",
                    help="the building-scale bench (module docstring); section "
                         "map_building_building")
    ap.add_argument("--rooms", type=int, default=20)
    ap.add_argument("--sizes", default="1500,3000,6000")
    ap.add_argument("--test-per-room", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=1,
                    help="with --building: builds run at once (each in its own process; "
                         "they share the CPU, so their times grow)")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    log = lambda m: print(m, file=sys.stderr)  # noqa: E731
    if args.building:
        sizes = [int(n) for n in args.sizes.split(",")]
        building = {"building": run_building(seeds, args.rooms, sizes, args.test_per_room,
                                             log, args.jobs),
                    "one_room": [{k: v for k, v in run_seed(
                        s, args.frames, args.test_frames, log).items()
                        if not k.startswith("_")} for s in seeds]}
        print(json.dumps(building, indent=2))
        if args.json:
            args.json.write_text(json.dumps(building, indent=2))
        if args.write_results:
            from bench.results_doc import update_results_section

            update_results_section("map_building_building", building_markdown(building))
        return 0
    if args.write_recording:
        doc = write_recording(args.write_recording, seeds[0], args.frames, args.holdout_every)
        print(json.dumps({"recording": str(args.write_recording), "seed": seeds[0],
                          "frames": len(doc["frames"]),
                          "detections": sum(len(f["detections"]) for f in doc["frames"]),
                          "bytes": args.write_recording.stat().st_size}))
        return 0
    refine = not args.fixed_cameras
    results = {"refine_cameras": refine,
               "seeds": [run_seed(s, args.frames, args.test_frames, log, refine)
                         for s in seeds]}
    plot = None
    if (args.plots or args.write_results) and refine:
        plot = make_plot(results["seeds"][0], args.plots or Path("docs/img"))
    public = {"refine_cameras": refine,
              "seeds": [{k: v for k, v in r.items() if not k.startswith("_")}
                        for r in results["seeds"]]}
    text = json.dumps(public, indent=2)
    if args.json:
        args.json.write_text(text)
    print(text)
    if args.write_results:
        from bench.results_doc import update_results_section

        name = "map_building" if refine else "map_building_fixed_cameras"
        update_results_section(name, markdown(results, plot))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
