"""Why the level-set refinement takes ~20 LM iterations on ``bench.peer_refine``'s problems
(``bench.refine_convergence``): not its Jacobian nor GTSAM's LM, but the truncated detections.

On exact, untruncated detections the residual vanishes at the true pose and Gauss-Newton
converges quadratically: a handful of iterations, the true pose to rounding. A wrong Jacobian
(checked here against central differences, independently of the analytic derivation) or a bad
lambda schedule would show there too.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.peer_refine import make_problems
from bench.refine_convergence import trace_problem
from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.service.localization.refine import refine
from quadloc.service.localization.types import Detection

#: problems of each kind checked (the first ones of ``bench.peer_refine``, seed 0)
N_PROBLEMS = 6


def _camera(data: dict) -> Camera:
    c = data["camera"]
    return Camera(*c[:4], int(c[4]), int(c[5]))


@pytest.fixture(scope="module")
def exact_problems() -> dict:
    return make_problems(0, clip_to_image=False)


@pytest.fixture(scope="module")
def truncated_problems() -> dict:
    return make_problems(0)


@pytest.mark.parametrize("metric", ["level_set", "bbox"])
def test_exact_detections_converge_in_a_few_iterations_to_the_true_pose(exact_problems, metric):
    cam = _camera(exact_problems)
    for k, p in enumerate(exact_problems["problems"][:N_PROBLEMS]):
        dets = [Detection(Ellipse(*o["ellipse"]), f"o{j}") for j, o in enumerate(p["objects"])]
        ells = [Ellipsoid(np.array(o["center"]), np.array(o["axes"]), np.array(o["rotation"]))
                for o in p["objects"]]
        res = refine(dets, ells, cam, np.array(p["start"]), metric)
        truth = np.array(p["truth"])
        assert res.status == "converged", (k, res.status)
        # both solves of the level set together (bench.refine_convergence: 5.5 on average)
        assert res.iterations <= 8, (k, res.iterations)
        assert np.linalg.norm(res.world_from_camera[:3, 3] - truth[:3, 3]) <= 1e-8, k


@pytest.mark.parametrize("metric", ["level_set", "bbox"])
def test_traced_solve_reproduces_refine_and_the_jacobian_is_right(truncated_problems, metric):
    cam = _camera(truncated_problems)
    for k, p in enumerate(truncated_problems["problems"][:N_PROBLEMS]):
        row = trace_problem(cam, p, metric)
        assert row["iterations"] == row["refine_iterations"], k
        assert row["same_pose_as_refine"], k
        # analytic pose Jacobian against central differences (step 1e-6: truncation error
        # ~1e-12 relative, rounding ~1e-10)
        assert row["jacobian_rel_error"] <= 1e-6, (k, row["jacobian_rel_error"])
        assert row["evaluations"] >= row["iterations"] + 1
