"""The refinement's speed-ups change no answer: sequential vs multifrontal elimination, the
memoised level-set camera frame, the per-camera constants of the dual-conic metrics.

References: GTSAM's default (multifrontal) LM on the same graph; freshly built residual models;
``quadloc.factors.metrics.residual`` on ellipses projected by
``quadloc.factors.camera.project_ellipsoid``.
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from quadloc.factors import metrics
from quadloc.factors.camera import Camera, project_ellipsoid
from quadloc.factors.pose_factors import pose3, pose_factors
from quadloc.factors.pose_residuals import PoseResidualModel
from quadloc.factors.rotations import invert_pose
from quadloc.service.localization.refine import _lm_params, _shared_lm_params
from tests.support.reference_data import (
    exact_projections,
    load_chess_map,
    load_chess_poses,
    perturb_pose,
)


def chess_problems(n: int, noise_px: float = 0.0, seed: int = 3):
    """``n`` real Chess problems (every 9th pose): camera, ellipses (exact, or their centres
    moved by ``noise_px``), ellipsoids, start 0.1 m / 5 deg off."""
    ells = [o.ellipsoid for o in load_chess_map().objects]
    cam, camera_from_world, _ = load_chess_poses()
    rng = np.random.default_rng(seed)
    out = []
    for cfw in camera_from_world[::9][:n]:
        pairs = exact_projections(cam, cfw, ells)
        if noise_px:
            pairs = [(type(d)(d.cx + rng.normal(0, noise_px), d.cy + rng.normal(0, noise_px),
                              d.a, d.b, d.angle), e) for d, e in pairs]
        start = perturb_pose(invert_pose(cfw), rng, 0.10, 5.0)
        out.append((cam, [p[0] for p in pairs], [p[1] for p in pairs], start))
    return out


@pytest.mark.parametrize(("metric", "noise_px"), [("level_set", 0.0), ("level_set", 2.0),
                                                  ("bbox", 2.0), ("wasserstein", 2.0)])
def test_sequential_elimination_takes_the_multifrontal_steps_bit_for_bit(metric, noise_px):
    for cam, dets, ells, start in chess_problems(6, noise_px):
        factors, _ = pose_factors(metric, 0, dets, ells, cam, initial_world_from_camera=start,
                                  batched=True)
        graph = gtsam.NonlinearFactorGraph()
        graph.add(factors[0])
        values = gtsam.Values()
        values.insert(0, pose3(start))
        fast = gtsam.LevenbergMarquardtOptimizer(graph, values, _lm_params(50, metric))
        reference_params = _shared_lm_params.__wrapped__(50, False)  # a fresh, unshared copy
        reference_params.setLinearSolverType("MULTIFRONTAL_CHOLESKY")
        reference = gtsam.LevenbergMarquardtOptimizer(graph, values, reference_params)
        got, want = fast.optimize(), reference.optimize()
        assert fast.iterations() == reference.iterations() > 0
        np.testing.assert_array_equal(got.atPose3(0).matrix(), want.atPose3(0).matrix())


def test_memoised_frame_gives_what_a_fresh_model_gives():
    cam, dets, ells, start = chess_problems(1, noise_px=2.0)[0]
    other = perturb_pose(start, np.random.default_rng(1), 0.05, 2.0)
    model = PoseResidualModel("level_set", dets, ells, cam, initial_world_from_camera=start)
    for T in (start, other, start):  # the memo follows the pose
        ev = model.evaluate(T)
        fresh = PoseResidualModel("level_set", dets, ells, cam,
                                  initial_world_from_camera=start).evaluate(T)
        np.testing.assert_array_equal(ev.residuals, fresh.residuals)
        np.testing.assert_array_equal(ev.jacobians, fresh.jacobians)
    model.evaluate(other)
    model.relayout(other)  # the frame memoised at ``other`` lays the samples out
    fresh = PoseResidualModel("level_set", dets, ells, cam, initial_world_from_camera=other)
    np.testing.assert_array_equal(model.sampling_scale, fresh.sampling_scale)
    np.testing.assert_array_equal(model.sample_points, fresh.sample_points)
    np.testing.assert_array_equal(model.evaluate(start).residuals,
                                  fresh.evaluate(start).residuals)


@pytest.mark.parametrize("metric", ["bbox", "wasserstein"])
def test_conic_metrics_use_the_constants_of_their_own_camera(metric):
    cam, dets, ells, start = chess_problems(1)[0]
    cameras = [cam, Camera(cam.fx * 1.3, cam.fy * 0.8, cam.cx + 20.0, cam.cy - 10.0,
                           cam.width, cam.height)]
    for camera in cameras + cameras[::-1]:  # cached per camera, never shared between them
        model = PoseResidualModel(metric, dets, ells, camera)
        r = model.evaluate(start, jacobian=False).residuals
        cfw = invert_pose(start)
        for j, (d, e) in enumerate(zip(dets, ells, strict=True)):
            want = metrics.residual(metric, d, project_ellipsoid(camera, cfw, e))
            np.testing.assert_allclose(r[j], want, rtol=1e-9, atol=1e-9)


def test_compiled_bbox_rows_equal_the_metric_bit_for_bit():
    """The pose path's bbox kernel (``pose_conic_metrics._bbox_kernel``) against the one
    implementation of the metric, ``metrics.conic_residuals("bbox")``, on the same conics."""
    from quadloc.factors.pose_conic_metrics import ConicMetricResiduals

    for cam, dets, ells, start in chess_problems(6, 2.0):
        model = PoseResidualModel("bbox", dets, ells, cam, initial_world_from_camera=start)
        family = model._family
        assert isinstance(family, ConicMetricResiduals)
        frame = model._ellipsoid_arrays.camera_frame(start)
        valid = frame.depth_margins > model.min_depth_margin
        Cn, dCn = family._conics.normalised(frame, valid, True)
        want_r, want_J = metrics.conic_residuals("bbox", model._detection_params, Cn, dCn)
        for jacobian in (True, False):
            rows = family.rows(start, jacobian)
            np.testing.assert_array_equal(rows.residuals[valid], want_r[valid])
            if jacobian:
                np.testing.assert_array_equal(rows.jacobians[valid], want_J[valid])
            else:
                assert rows.jacobians is None
