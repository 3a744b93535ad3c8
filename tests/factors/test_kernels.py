"""The compiled numeric kernels (``quadloc.factors.jit``): compiled once, at start-up, for every
request.

Their results are checked where their formulas are (``test_overlap_batch.py`` against the scalar
oracle, ``test_metrics.py`` / ``test_pose_factors.py`` against central differences, Monte Carlo
and the independent metric functions). Here: numba compiles a kernel for each distinct argument
type, a compilation takes seconds, so ``compile_kernels()`` (run by the service before it
serves) must cover every type that the refinements, the metrics and the map building pass; and
a kernel works where numba has no writable cache directory.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

_SCRIPT = textwrap.dedent("""
    import json
    import numpy as np
    from quadloc.factors import camera as camera_module
    from quadloc.factors import (
        metrics,
        overlap,
        pose_conic_metrics,
        pose_frame,
        pose_level_set,
        pose_residuals,
    )
    from quadloc.factors.camera import Camera, Ellipsoid
    from quadloc.factors.conics import Ellipse
    from quadloc.factors.overlap import intersection_areas
    from quadloc.service.localization.refine import refine
    from quadloc.service.localization.types import Detection

    from quadloc.service.localization import hypotheses, scoring
    from quadloc.service.localization.search import compile_search_kernels

    def signatures():
        out = {}
        for module in (overlap, pose_frame, pose_level_set, pose_conic_metrics, metrics,
                       camera_module, scoring, hypotheses):
            for name, value in vars(module).items():
                if hasattr(value, "signatures") and hasattr(value, "py_func"):
                    out[f"{module.__name__}.{name}"] = [str(s) for s in value.signatures]
        return out

    pose_residuals.compile_kernels()
    compile_search_kernels()
    before = signatures()
    # what requests do, with arguments of every origin: read-only, non-contiguous, scalar
    camera = Camera(520.0, 515.0, 322.0, 241.0, 640, 480)
    rng = np.random.default_rng(0)
    ellipsoids = [Ellipsoid(np.array([x, y, 3.0]), np.array([0.3, 0.2, 0.15]), np.eye(3))
                  for x, y in ((-0.5, 0.0), (0.4, 0.2), (0.0, -0.4), (0.6, -0.3))]
    truth = np.eye(4)
    dets = [Detection(Ellipse(*p), "o", sigma=1.0)
            for p in ((233.0, 242.0, 52.0, 34.0, 0.1), (392.0, 276.0, 52.0, 35.0, -0.2),
                      (322.0, 171.0, 52.0, 35.0, 0.3), (426.0, 189.0, 53.0, 35.0, 0.0))]
    start = truth.copy()
    start[:3, 3] += (0.03, -0.02, 0.05)
    start.setflags(write=False)
    for metric in metrics.METRIC_NAMES:
        refine(dets, ellipsoids, camera, start, metric)
        refine(dets, ellipsoids, camera, np.asfortranarray(start), metric, robust="huber")
    p = rng.uniform(1.0, 50.0, (6, 10))
    p.setflags(write=False)
    intersection_areas(p[:, ::2], p[:, 1::2])
    metrics.overlap_residual("giou", p[0, ::2], p[1, ::2], gradient=True)
    metrics.overlap_residual("iou", p[:, ::2], p[:, 1::2], gradient=True, disjoint_hull=True)
    for name in ("iou", "giou"):
        metrics.cost(name, Ellipse(*p[0, :5]), Ellipse(*p[1, :5]))
    # the batched projection (RANSAC, P2E, tracking): [R | t] poses, read-only map arrays
    centers = np.array([e.center for e in ellipsoids])
    shapes = np.array([e.shape_matrix() for e in ellipsoids])
    quadrics = np.array([e.dual_quadric() for e in ellipsoids])
    for arr in (centers, shapes, quadrics):
        arr.setflags(write=False)
    camera_module.projected_gaussians(camera, np.stack([start[:3], truth[:3]]), centers, shapes,
                                 quadrics)
    from tests.support.reference_data import load_chess_map
    from tests.support.simulate import SimulationConfig, simulate_frame
    from quadloc.maps.compiled import compile_map
    from quadloc.service.localization.pipeline import localize
    cm = compile_map(load_chess_map())
    pose = np.eye(4)
    pose[:3, 3] = cm.ellipsoids[0].center - (0.0, 0.0, 2.0)
    frame = simulate_frame(cm, camera, pose, rng, SimulationConfig())
    localize(list(frame.detections), cm, camera)
    print(json.dumps({"before": before, "after": signatures()}))
""")


def test_requests_compile_no_kernel_that_start_up_did_not():
    out = subprocess.run([sys.executable, "-c", _SCRIPT], cwd=REPO, capture_output=True,
                         text=True, timeout=600, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    before, after = result["before"], result["after"]
    assert set(before) >= {"quadloc.factors.overlap._batch",
                           "quadloc.factors.metrics._overlap_rows",
                           "quadloc.factors.camera._projected_gaussians_kernel",
                           "quadloc.factors.pose_level_set._level_set_kernel",
                           "quadloc.factors.pose_frame._camera_frame_kernel",
                           "quadloc.factors.pose_frame._dual_conic_kernel",
                           "quadloc.factors.pose_conic_metrics._bbox_kernel",
                           "quadloc.service.localization.scoring._pair_iou_kernel",
                           "quadloc.service.localization.scoring._greedy_kernel",
                           "quadloc.service.localization.hypotheses._p3p_kernel",
                           "quadloc.service.localization.hypotheses._reprojection_errors"}
    for name, sigs in after.items():
        assert sigs == before.get(name, []), f"{name} was compiled again for a request"


def test_a_kernel_works_without_a_cache_directory():
    """numba caches next to the source file; a function without one (here defined by exec:
    no file; in production, a read-only file system) cannot be cached, and the kernel is then
    compiled in the process instead of failing."""
    from quadloc.factors.jit import _dispatcher

    namespace: dict = {}
    exec("def twice(x):\n    return 2.0 * x\n", namespace)
    assert _dispatcher(namespace["twice"])(1.5) == 3.0


def test_importing_the_factors_does_not_import_numba():
    """Kernels bind at their first call: a process that never calls one (a CLI command on
    maps, the SDK's server-side peers) does not pay numba's import."""
    code = ("import sys, quadloc.factors.metrics, quadloc.factors.pose_residuals, "
            "quadloc.maps.store; "
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                         text=True, timeout=120, check=True)
    assert out.stdout.strip() == "False"
