"""A map's own calibration from the user's recording (issue 30): does ``quadloc calibrate`` make
covariance and confidence mean what they say for a detector other than the default one?

Usage::

    python -m bench.map_calibration [--seeds 21,22,23] [--frames 2000] [--holdout-every 2]
                                    [--detectors sharp,noisy] [--json PATH] [--write-results]

Per seed and detector:

1. a recording of the Chess room (``bench.map_building.simulated_recording``: the real
   ground-truth walk resampled to ``--frames`` poses, drifting app poses, detections of the
   detector below, 5 % wrong labels, 0.2 spurious detections per frame) with
   ``holdout_every``: every k-th frame is held out of the build;
2. the map is built from the other frames (the app's poses, as the service builds it);
3. :func:`quadloc.service.localization.map_calibration.fit_map_calibration` on the held-out
   frames, their APP poses the reference (what a user has): NEES and confidence calibration
   error before (shipped constants, every held-out frame) and after (cross-fitted: each frame
   localized with a calibration fitted on the other 4 of 5 folds; the stored calibration is
   fitted on all of them).

Detectors (``tests.support.simulate.SimulationConfig``; the shipped constants were fitted on
the default one, centre noise 0.04 sqrt(ab), log-axis noise 0.06, angle 4 deg): ``sharp``
(0.02, 0.03, 2 deg) and ``noisy`` (0.08, 0.12, 8 deg).

The calibration error is the expected calibration error of ``confidence`` over the localized
held-out answers in 10 equal-width bins, against success = within 10 cm and 5 deg of the app
pose; ``calibration_error_floor`` is what a perfectly calibrated confidence shows on the same
answers by sampling alone (``map_calibration.calibration_error_floor``).

Tuning and reporting: seeds 11 and 12 were looked at while choosing the protocol (the fit's
single operating point ``map_calibration.USER_FIT_SETTINGS``; then, for issue 30's last
item, the cross-fitted report and 2000 frames: seed 11 of both detectors); the figures of
docs/results.md are on seeds 21-23 (and none of them are those of the shipped constants:
bench.trust tunes on 0-9 and 100-109). 2000 frames rather than 3000: with the current map
building, seed 21's 3000-frame 'sharp' map put 97 % of the held-out answers more than 10 cm
from the app poses (3 % success: a degenerate test of the confidence), a map-building matter
left open.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.map_building import simulated_recording
from quadloc.maps.building.build import build_map
from quadloc.maps.building.recording import BuildLimits
from quadloc.maps.compiled import compile_map
from quadloc.service.app.builds import recording_of, validate_recording
from quadloc.service.app.conversions import held_out_frames_from_wire
from quadloc.service.localization.map_calibration import ReferenceFrame, fit_map_calibration
from tests.support.simulate import SimulationConfig

DETECTORS = {
    "default": {},
    "sharp": {"center_noise": 0.02, "axis_log_noise": 0.03,
              "angle_noise_rad": math.radians(2.0)},
    "noisy": {"center_noise": 0.08, "axis_log_noise": 0.12,
              "angle_noise_rad": math.radians(8.0)},
}


def run(seed: int, detector: str, frames: int, holdout_every: int, log: Any = print
        ) -> dict[str, Any]:
    cfg = SimulationConfig(wrong_label_probability=0.05, spurious_rate=0.2,
                           **DETECTORS[detector])  # type: ignore[arg-type]
    doc, _, _, _ = simulated_recording(seed, frames, cfg, holdout_every=holdout_every)
    t = time.monotonic()
    limits = BuildLimits(max_frames=10 * frames, max_detections=100 * frames)
    scene, _ = build_map(recording_of(doc, limits), map_id="calibration-bench")
    camera, held = held_out_frames_from_wire(validate_recording(doc))
    refs = [ReferenceFrame(fid, T, dets) for fid, T, dets in held]
    t_build = time.monotonic() - t
    t = time.monotonic()
    cal = fit_map_calibration(refs, compile_map(scene), camera)
    out = {"seed": seed, "detector": detector, "objects": len(scene.objects),
           "held_out_frames": len(refs), "fit_frames": cal.fit_frames,
           "report_frames": cal.after.frames,
           "before": dataclasses.asdict(cal.before), "after": dataclasses.asdict(cal.after),
           "covariance_scale": cal.constants.covariance_scale[cal.key],
           "s2_floor": cal.constants.s2_floor[cal.key], "key": cal.key,
           "build_s": round(t_build, 1), "calibrate_s": round(time.monotonic() - t, 1)}
    log(f"seed {seed} {detector}: NEES {cal.before.mean_nees} -> {cal.after.mean_nees}, "
        f"ECE {cal.before.calibration_error} -> {cal.after.calibration_error}")
    return out


def _f(v: float | None, fmt: str = ".2f") -> str:
    return "-" if v is None else format(v, fmt)


def markdown(res: dict[str, Any]) -> str:
    rows = ["| seed | detector | objects | held-out frames (localized) | mean NEES before -> "
            "after (frames within 10 cm) | calibration error before -> after +- sd (sampling "
            "floor) | mean confidence / success after |",
            "|---|---|---|---|---|---|---|"]
    for r in res["runs"]:
        b, a = r["before"], r["after"]
        rows.append(f"| {r['seed']} | {r['detector']} | {r['objects']} | {a['frames']} "
                    f"({a['localized']}) | {_f(b['mean_nees'])} -> {_f(a['mean_nees'])} "
                    f"({a['nees_frames']}) | {_f(b['calibration_error'], '.3f')} -> "
                    f"{_f(a['calibration_error'], '.3f')} +- "
                    f"{_f(a.get('calibration_error_sd'), '.3f')} "
                    f"({_f(a.get('calibration_error_floor'), '.3f')}) | "
                    f"{_f(a['mean_confidence'])} / {_f(a['success_rate'])} |")
    s = res["summary"]
    return "\n".join([
        "## A map's own calibration from the user's recording", "",
        "A map's own calibration (`quadloc calibrate`, issue 30) on recordings made with a "
        "detector other than the default one: the map is built without every k-th frame "
        f"(k = {res['holdout_every']}, {res['frames']} frames); those frames (app poses as "
        "reference) fit the covariance scale and confidence model "
        "(`quadloc.service.localization.calibration_fit`) and report, cross-fitted: each "
        "frame localized with a calibration fitted on the other 4 of 5 folds (chunks of 25 "
        "consecutive frames). Mean NEES over the localized frames within 10 cm (6 = a "
        "well-scaled 6-DoF covariance); calibration error = expected calibration error of "
        "`confidence` over the localized frames, 10 equal-width bins, success = within 10 cm "
        "and 5 deg of the app pose; its sampling floor = the mean error of a perfectly "
        "calibrated confidence on the same frames (outcomes drawn from the confidences, 200 "
        "draws); sd = its sampling standard deviation by a moving-block bootstrap (blocks of 25 "
        "consecutive frames: outcomes along a walk are correlated, the app poses drift "
        "slowly). Seeds 21-23 are held out (the protocol was chosen on seeds 11 and 12).",
        "", *rows, "",
        "Per recording after calibration: mean NEES from "
        + (" to ".join(_f(v) for v in s["nees_after_range"]) if s["nees_after_range"] else "-")
        + " (target [4, 9]), calibration error at most "
        f"{_f(s['max_calibration_error_after'], '.3f')} (target <= 0.05)."])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="21,22,23")
    ap.add_argument("--frames", type=int, default=2000)
    ap.add_argument("--holdout-every", type=int, default=2)
    ap.add_argument("--detectors", default="sharp,noisy")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--write-results", action="store_true")
    ap.add_argument("--combine", type=Path, nargs="+", metavar="JSON",
                    help="instead of running: the runs of these --json files (parts of the "
                         "default command run in parallel, e.g. one per seed and detector)")
    ap.add_argument("--note", action="append", default=[],
                    help="with --combine: a sentence for the results section (e.g. a part "
                         "that did not finish, and why)")
    args = ap.parse_args(argv)
    log = lambda m: print(m, file=sys.stderr)  # noqa: E731
    if args.combine:
        parts = [json.loads(p.read_text()) for p in args.combine]
        runs = [r for part in parts for r in part["runs"]]
        args.frames, args.holdout_every = parts[0]["frames"], parts[0]["holdout_every"]
    else:
        runs = [run(int(s), d, args.frames, args.holdout_every, log)
                for d in args.detectors.split(",") for s in args.seeds.split(",")]
    after = [r["after"]["mean_nees"] for r in runs if r["after"]["mean_nees"] is not None]
    res = {"frames": args.frames, "holdout_every": args.holdout_every, "runs": runs,
           "summary": {
               "mean_nees_after": float(np.mean(after)) if after else None,
               "nees_after_range": [min(after), max(after)] if after else None,
               "max_calibration_error_after": max(
                   (r["after"]["calibration_error"] for r in runs
                    if r["after"]["calibration_error"] is not None), default=None)}}
    text = json.dumps(res, indent=2)
    if args.json:
        args.json.write_text(text)
    print(text)
    if args.write_results:
        from bench.results_doc import update_results_section

        if args.combine:  # the parts' command: the default one, split by seed and detector
            cmd = ("python -m bench.map_calibration --seeds "
                   + ",".join(sorted({str(r["seed"]) for r in runs})) + " --detectors "
                   + ",".join(sorted({r["detector"] for r in runs})) + " --write-results")
        else:
            cmd = "python -m bench.map_calibration " + " ".join(
                argv if argv is not None else sys.argv[1:])
        text = markdown(res)
        if args.note:
            text += "\n\n" + " ".join(args.note)
        update_results_section("map_calibration", text, command=cmd.strip())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
