"""Benchmark: reconstruct the Chess map's ellipsoids from synthetic views at real poses.

Views: the 108 real ground-truth poses of ``chess_test_poses.json`` (R, t camera_from_world,
snapped to rotations). An object is "visible" in a frame when the ellipsoid is entirely in front
of the camera and its image centre is inside the 640x480 image; ``--views`` of those frames,
evenly spaced in sequence order, are used. Observations are the exact projections, then noisy
versions; each object is reconstructed with ``quadloc.maps.reconstruct.reconstruct_ellipsoid``
(linear Rubino estimate + GTSAM LM refinement) and compared with the map's ellipsoid
(``ellipsoid_errors``: matched over the 24 axis symmetries).

Usage: ``.venv/bin/python -m bench.reconstruction [--trials 10] [--views 10] [--seed 0]
[--json FILE] [--write-results]``: prints the section; only ``--write-results`` writes it into
the "reconstruction" section of docs/results.md (as ``bench.registration_2d`` does).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from quadloc.factors.camera import Camera, Ellipsoid, project_ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import invert_pose
from quadloc.maps.demo import load_demo_map
from quadloc.maps.reconstruct import (
    ReconstructionError,
    _rays,
    ellipsoid_errors,
    max_ray_angle_deg,
    reconstruct_ellipsoid,
)
from tests.support.reference_data import load_chess_poses
from tests.support.scenes import visible_frames


def load_views() -> tuple[Camera, list[np.ndarray]]:
    cam, cfw, _ = load_chess_poses()
    return cam, cfw



def ellipse_noise(sigma_px: float, sigma_rel: float, sigma_deg: float) -> Callable:
    def corrupt(e: Ellipse, rng: np.random.Generator) -> Ellipse:
        return Ellipse(e.cx + rng.normal(0, sigma_px), e.cy + rng.normal(0, sigma_px),
                       e.a * (1 + rng.normal(0, sigma_rel)), e.b * (1 + rng.normal(0, sigma_rel)),
                       e.angle + np.radians(rng.normal(0, sigma_deg)))
    return corrupt


def box_noise(sigma_px: float) -> Callable:
    def corrupt(e: Ellipse, rng: np.random.Generator) -> np.ndarray:
        box = e.bbox() + rng.normal(0, sigma_px, size=4)
        return box
    return corrupt


#: View sets whose rays through the object span less than this (degrees) are "narrow".
NARROW_DEG = 15.0

_HEADER = ("| setting | view set | solved | centre err cm (median / p90) "
           "| semi-axes err cm (median / p90) | orientation err deg (median / p90) "
           "| shape rel. err (median) | time ms (median, this row) |\n"
           "|---|---|---|---|---|---|---|---|")


def run(trials: int, n_views: int, seed: int) -> tuple[str, dict]:
    cam, cfw = load_views()
    scene = load_demo_map()
    rng = np.random.default_rng(seed)
    settings: list[tuple[str, Callable | None, dict]] = [
        ("exact ellipses", None, {}),
        ("ellipses, noise 2 px / 3 % / 2 deg", ellipse_noise(2.0, 0.03, 2.0), {}),
        ("ellipses, noise 2 px / 3 % / 2 deg, linear only", ellipse_noise(2.0, 0.03, 2.0),
         {"refine": False}),
        ("boxes (inscribed ellipses), corner noise 2 px", box_noise(2.0), {}),
        ("ellipses, noise 2 px / 3 % / 2 deg, log-axes prior 0.5", ellipse_noise(2.0, 0.03, 2.0),
         {"log_axes_prior_sigma": 0.5}),
    ]
    per_object = []
    for obj in scene.objects:
        idx = visible_frames(cam, cfw, obj.ellipsoid)
        sel = idx[:: max(1, len(idx) // n_views)][:n_views]
        per_object.append((obj, idx, sel))
    spreads = {o.object_id: _spread_deg(cam, cfw, sel, o.ellipsoid) for o, _i, sel in per_object}
    group_of = {k: ("narrow" if v < NARROW_DEG else "wide") for k, v in spreads.items()}
    raw: dict = {"trials": trials, "views": n_views, "seed": seed, "settings": {}}
    rows = []
    for label, corrupt, options in settings:
        stats: dict[str, list] = {"spread": [], "wide": [], "narrow": []}
        failures: dict[str, int] = {}
        times: dict[str, list[float]] = {"wide": [], "narrow": []}
        for obj, _idx, sel in per_object:
            E = obj.ellipsoid
            exact = [project_ellipsoid(cam, cfw[i], E) for i in sel]
            wfc = [invert_pose(cfw[i]) for i in sel]
            for _ in range(1 if corrupt is None else trials):
                obs = exact if corrupt is None else [corrupt(e, rng) for e in exact]
                t0 = time.perf_counter()
                try:
                    res = reconstruct_ellipsoid(obs, wfc, cam, **options)
                except ReconstructionError as exc:
                    failures[exc.reason] = failures.get(exc.reason, 0) + 1
                    stats[group_of[obj.object_id]].append(None)
                    continue
                times[group_of[obj.object_id]].append(time.perf_counter() - t0)
                stats[group_of[obj.object_id]].append(ellipsoid_errors(res.ellipsoid, E))
        raw["settings"][label] = {k: v for k, v in stats.items() if k != "spread"}
        for group in ("wide", "narrow"):
            errs = [e for e in stats[group] if e is not None]
            n_all = len(stats[group])
            if n_all == 0:
                continue
            if not errs:
                rows.append(f"| {label} | {group} | 0/{n_all} | - | - | - | - | - |")
                continue

            def med(key: str, errs: list = errs) -> float:
                return float(np.median([e[key] for e in errs]))

            def p90(key: str, errs: list = errs) -> float:
                return float(np.percentile([e[key] for e in errs], 90))

            rows.append(
                f"| {label} | {group} | {len(errs)}/{n_all} | "
                f"{med('center_m') * 100:.3g} / {p90('center_m') * 100:.3g} | "
                f"{med('axes_m') * 100:.3g} / {p90('axes_m') * 100:.3g} | "
                f"{med('orientation_deg'):.3g} / {p90('orientation_deg'):.3g} | "
                f"{med('shape_rel'):.3g} | "
                f"{np.median(times[group]) * 1000:.1f} |"
            )
        if failures:
            rows.append(f"| ↳ failures | | {', '.join(f'{k}: {v}' for k, v in failures.items())}"
                        f" | | | | | |")
    views_table = "\n".join(
        f"| {o.object_id} | {o.category} | {len(idx)} | {len(sel)} | "
        f"{spreads[o.object_id]:.1f} |" for o, idx, sel in per_object)

    def describe(group: str) -> str:
        ids = [k for k, g in group_of.items() if g == group]
        if not ids:
            return "none"
        vals = [spreads[k] for k in ids]
        return f"objects {', '.join(ids)}: {min(vals):.0f}-{max(vals):.0f} deg"

    md = f"""## Reconstruction of the Chess ellipsoids (`bench/reconstruction.py`)

Each of the 11 ellipsoids of the Chess map is reconstructed from {n_views} views at real
ground-truth poses (`chess_test_poses.json`, frames where the ellipsoid is entirely in front of
the camera and its image centre inside the image, evenly spaced), by
`quadloc.maps.reconstruct.reconstruct_ellipsoid`: Rubino et al.'s linear dual-quadric estimate
(normalised image and world coordinates), then GTSAM Levenberg-Marquardt on a Pose3 + log-axes
with the level-set residual (16 contour samples per view; the refinement also starts from a
sphere at the triangulated centre and keeps the better result). Errors against the map's
ellipsoid, matched over the 24 axis symmetries: centre (Euclidean), semi-axes (largest absolute
error), orientation (rotation angle), shape (relative Frobenius error of `R diag(axes^2) R^T`).
Noise: centre `N(0, sigma_px)` per coordinate, semi-axes `x (1 + N(0, rel))`, angle
`N(0, deg)`; boxes: the projected ellipse's bounding box, corners `+ N(0, 2 px)`, replaced by
the inscribed axis-aligned ellipse (the paper built its map from such boxes).
{trials} noise draws per object and setting, seed {seed}. "wide": view sets whose viewing rays
span >= {NARROW_DEG:g} deg ({describe("wide")}); "narrow": the others ({describe("narrow")}).
Times: median wall clock per solved
object of the row's setting and view-set group (linear estimate + both LM refinements) on the
shared 2-core machine, noisy between runs.

| object | category | frames visible | views used | ray spread (deg) |
|---|---|---|---|---|
{views_table}

{_HEADER}
{chr(10).join(rows)}

{_findings(raw)}
"""
    return md, raw


def _median(raw: dict, setting: str, group: str, key: str) -> float:
    errs = [e[key] for e in raw["settings"][setting][group] if e is not None]
    return float(np.median(errs)) if errs else float("nan")


def _solved(raw: dict, setting: str, group: str) -> str:
    errs = raw["settings"][setting][group]
    return f"{sum(e is not None for e in errs)}/{len(errs)}"


def _findings(raw: dict) -> str:
    """The summary sentences, computed from this run's numbers."""
    exact, noisy = "exact ellipses", "ellipses, noise 2 px / 3 % / 2 deg"
    linear, boxes = f"{noisy}, linear only", "boxes (inscribed ellipses), corner noise 2 px"
    prior = f"{noisy}, log-axes prior 0.5"
    worst_exact = max(e["center_m"] for g in ("wide", "narrow")
                      for e in raw["settings"][exact][g] if e is not None)
    c_ref, c_lin = _median(raw, noisy, "wide", "center_m"), _median(raw, linear, "wide", "center_m")
    s_ref, s_lin = (_median(raw, noisy, "wide", "shape_rel"),
                    _median(raw, linear, "wide", "shape_rel"))
    return (
        f"Findings (computed from this run): exact views recover every ellipsoid (largest centre "
        f"error {worst_exact:.1e} m, all {_solved(raw, exact, 'wide')} + "
        f"{_solved(raw, exact, 'narrow')} solved). Wide view sets with noisy ellipses: median "
        f"centre error {c_ref * 100:.2f} cm after the LM refinement vs {c_lin * 100:.2f} cm for "
        f"the linear estimate alone (shape error {s_ref:.3f} vs {s_lin:.3f}). Boxes: median centre "
        f"error {_median(raw, boxes, 'wide', 'center_m') * 100:.2f} cm, shape error "
        f"{_median(raw, boxes, 'wide', 'shape_rel'):.3f} (a box has no image orientation). The "
        f"narrow view sets are ill-posed under noise (depth along the rays and thickness "
        f"unobservable): solved {_solved(raw, noisy, 'narrow')}, median centre error "
        f"{_median(raw, noisy, 'narrow', 'center_m') * 100:.1f} cm; the linear estimate is never "
        f"an ellipsoid there ({_solved(raw, linear, 'narrow')}); the opt-in log-axes prior "
        f"(biased towards a sphere of the apparent size) solves {_solved(raw, prior, 'narrow')} "
        f"with a median centre error of {_median(raw, prior, 'narrow', 'center_m') * 100:.1f} cm. "
        f"Orientation errors are large for near-spherical objects whose axes are ill-defined; the "
        f"shape error is the frame-free measure."
    )


def _spread_deg(cam: Camera, cfw: list[np.ndarray], sel: list[int], E: Ellipsoid) -> float:
    """Largest angle (deg) between the world rays through the exact projections' centres: the
    same measure (``quadloc.maps.reconstruct._rays`` / ``max_ray_angle_deg``) the reconstruction
    uses to refuse near-parallel views."""
    ells = [project_ellipsoid(cam, cfw[i], E) for i in sel]
    return max_ray_angle_deg(_rays(ells, [cam] * len(sel), np.asarray([cfw[i] for i in sel])))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--views", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--write-results", action="store_true",
                        help="write the section into docs/results.md (section reconstruction)")
    parser.add_argument("--json", type=Path, help="also write the raw errors here")
    args = parser.parse_args(argv)
    md, raw = run(args.trials, args.views, args.seed)
    print(md)
    if args.json:
        args.json.write_text(json.dumps(raw, indent=1, default=float))
    if args.write_results:
        from bench.results_doc import update_results_section

        update_results_section("reconstruction", md)


if __name__ == "__main__":
    main()
