"""The metric GTSAM factors on the camera pose: residuals, Jacobians, noise, penalty.

Independent references: residuals against the scalar oracle
(``tests.support.oracles.metrics_reference``, which is ``quadloc.factors.metrics.residual`` for the
metrics without a second implementation) on ellipses projected by
``quadloc.factors.camera.project_ellipsoid`` (and the level set against ``Ellipse.level``
directly); Jacobians against central differences through ``gtsam.Pose3.retract``; GTSAM's weighted
error against ``0.5 * cost / sigma``.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from quadloc.factors import metrics
from quadloc.factors.camera import Camera, Ellipsoid, ellipsoid_depth_margins, project_ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.pose_factors import (
    ROBUST_KERNELS,
    batched_pose_factor,
    make_noise_model,
    pose_factor,
    pose_factors,
)
from quadloc.factors.pose_residuals import (
    ANALYTIC_METRICS,
    DEFAULT_MIN_DEPTH_MARGIN,
    DEFAULT_PENALTY_COST,
    PoseResidualModel,
    expmap_pose3,
)
from quadloc.factors.rotations import invert_pose, rotation_from_quaternion_wxyz
from tests.support.helpers import level, random_ellipsoids, random_rotation, retract, transformed
from tests.support.oracles import metrics_reference

CAMERA = Camera(500.0, 510.0, 320.0, 240.0, 640, 480)


def random_scene(rng: np.random.Generator, n: int) -> list[Ellipsoid]:
    """n ellipsoids 3-6 m in front of an identity camera, semi-axes 0.1-0.4 m."""
    return random_ellipsoids(rng, n, 1.0, 0.7, (0.1, 0.4))


def perturbation(rng: np.random.Generator, rot: float, trans: float) -> np.ndarray:
    """Pose3 tangent [omega, v] with |omega| = rot rad, |v| = trans m, random directions."""
    w, v = rng.normal(size=3), rng.normal(size=3)
    return np.r_[w / np.linalg.norm(w) * rot, v / np.linalg.norm(v) * trans]


def numeric_jacobian(fn, T: np.ndarray, h: float = 1e-6) -> np.ndarray:
    cols = []
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        cols.append((fn(retract(T, e)) - fn(retract(T, -e))) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(11)
    ells = random_scene(rng, 5)
    truth = np.eye(4)
    dets = [project_ellipsoid(CAMERA, invert_pose(truth), e) for e in ells]
    # detections slightly wrong so that residuals are not ~0
    dets = [transformed(d, 0.02, [3.0, -2.0]) for d in dets]
    pose = retract(truth, perturbation(rng, 0.03, 0.08))
    return ells, dets, pose


def test_expmap_matches_gtsam():
    rng = np.random.default_rng(0)
    for scale in (1e-9, 1e-3, 0.5, 2.0):
        xi = rng.normal(size=6) * scale
        np.testing.assert_allclose(expmap_pose3(xi), gtsam.Pose3.Expmap(xi).matrix(),
                                   atol=1e-12)


def test_level_set_residual_matches_independent_level_functions(scene):
    ells, dets, pose = scene
    model = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=pose)
    r = model.evaluate(pose, jacobian=False).residuals
    for j, (d, e) in enumerate(zip(dets, ells, strict=True)):
        proj = project_ellipsoid(CAMERA, invert_pose(pose), e)
        x = model.sample_points[j]
        np.testing.assert_allclose(r[j], level(d, x) - level(proj, x), atol=1e-9)
        # the same layout as quadloc.factors.metrics (samples fixed at the initial pose)
        np.testing.assert_allclose(r[j], metrics.residual("level_set", d, proj), atol=1e-9)
        np.testing.assert_allclose(x, metrics.level_set_sample_points(d, proj), atol=1e-9)


@pytest.mark.parametrize("options", [{}, {"n_azimuths": 8, "n_levels": 3, "scale": 1.5},
                                     {"adaptive": False}])
def test_batched_sampling_is_the_metrics_layout(options):
    """Far-away projections (adaptive area grows), swapped axes (b > a), custom layouts."""
    rng = np.random.default_rng(21)
    ells = random_scene(rng, 6)
    truth = np.eye(4)
    dets = [project_ellipsoid(CAMERA, truth, e) for e in ells]
    dets = [Ellipse(d.cx + 40.0 * j, d.cy - 15.0 * j, d.b, d.a, d.angle + 0.5 * np.pi)
            if j % 2 else Ellipse(d.cx + 40.0 * j, d.cy, d.a, d.b, d.angle)
            for j, d in enumerate(dets)]
    model = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=truth,
                              metric_options=options)
    r = model.evaluate(truth, jacobian=False).residuals
    for j, (d, e) in enumerate(zip(dets, ells, strict=True)):
        proj = project_ellipsoid(CAMERA, truth, e)
        np.testing.assert_allclose(model.sample_points[j],
                                   metrics.level_set_sample_points(d, proj, **options),
                                   rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(r[j], metrics.residual("level_set", d, proj, **options),
                                   rtol=1e-9, atol=1e-9)
    if options.get("adaptive", True):
        assert model.sampling_scale.max() > metrics.DEFAULT_LEVEL_SET_SCALE


def test_samples_of_a_detection_touching_the_border_are_not_grown():
    """At a start far off the adaptive areas grow for the misalignment (the metrics' adaptive
    layout) except that of a detection touching the image border (``camera.border_touching``:
    probably truncated, its centre is not the projection's even at the true pose), whose
    samples keep the metrics' fixed layout."""
    rng = np.random.default_rng(5)
    ells = random_scene(rng, 5)
    truth = np.eye(4)
    dets = [project_ellipsoid(CAMERA, truth, e) for e in ells]
    # the first detection moved to touch the left border (bbox from x = 1 px)
    d0 = dets[0]
    dets[0] = Ellipse(1.0 + d0.a, d0.cy, d0.a, d0.b, 0.0)
    far = retract(truth, perturbation(rng, 0.3, 0.4))
    model = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=far)
    boxes = np.array([d.bbox() for d in dets])  # independent of the rule's formula
    flags = (boxes[:, 0] < 4.0) | (boxes[:, 1] < 4.0) | (boxes[:, 2] > CAMERA.width - 4.0) \
        | (boxes[:, 3] > CAMERA.height - 4.0)
    assert flags[0] and not flags[1:].any()
    camera_from_world = invert_pose(far)
    grown = []
    for j, (d, e) in enumerate(zip(dets, ells, strict=True)):
        proj = project_ellipsoid(CAMERA, camera_from_world, e)
        grown.append(metrics.level_set_sampling_scale(d, proj))
        want = metrics.level_set_sample_points(d, proj, adaptive=not flags[j])
        np.testing.assert_allclose(model.sample_points[j], want, rtol=1e-12, atol=1e-9)
    assert grown[0] > 2.0 * metrics.DEFAULT_LEVEL_SET_SCALE  # would have grown
    assert model.sampling_scale[0] == metrics.DEFAULT_LEVEL_SET_SCALE
    np.testing.assert_allclose(model.sampling_scale[1:], grown[1:], rtol=1e-12)
    assert max(grown[1:]) > metrics.DEFAULT_LEVEL_SET_SCALE


@pytest.mark.parametrize("metric", metrics.METRIC_NAMES)
def test_factor_residual_equals_metric_residual(scene, metric):
    ells, dets, pose = scene
    values = gtsam.Values()
    values.insert(7, gtsam.Pose3(pose))
    opts = {"image_size": (CAMERA.width, CAMERA.height)} if metric == "qbbox" else {}
    for d, e in list(zip(dets, ells, strict=True))[:3]:
        f = pose_factor(metric, 7, d, e, CAMERA, initial_world_from_camera=pose,
                        metric_options=opts)
        proj = project_ellipsoid(CAMERA, invert_pose(pose), e)
        expected = np.asarray(metrics_reference.residual(metric, d, proj, **opts))
        got = f.unwhitenedError(values)
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9)
        # unit noise: GTSAM error = 0.5 ||r||^2 (= 0.5 * metric cost but for iou / giou)
        assert f.error(values) == pytest.approx(0.5 * float(expected @ expected),
                                                rel=1e-9, abs=1e-12)
        if metric not in ("iou", "giou"):
            assert f.error(values) == pytest.approx(
                0.5 * metrics.cost(metric, d, proj, **opts), rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_level_set_analytic_jacobian_matches_numerical(seed):
    rng = np.random.default_rng(seed)
    ells = random_scene(rng, 6)
    dets = [transformed(project_ellipsoid(CAMERA, np.eye(4), e), 0.05, [4.0, 1.0])
            for e in ells]
    pose = retract(np.eye(4), perturbation(rng, 0.05, 0.2))
    model = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=pose)
    ev = model.evaluate(pose, jacobian=True)
    assert ev.valid.all()
    num = numeric_jacobian(lambda T: model.evaluate(T, jacobian=False).residuals.copy(), pose)
    scale = np.abs(num).max()
    np.testing.assert_allclose(ev.jacobians, num, atol=1e-6 * scale)


@pytest.mark.parametrize("seed", [4, 5])
def test_level_set_is_invariant_to_the_world_frame_and_matches_the_metric(seed):
    """The level set's evaluation runs in the world frame (A^-1 by Sherman-Morrison, then
    rotated into the camera): re-expressing the map and the pose in another world frame (large
    rotation and translation) must not change the residuals nor the Jacobians (camera-frame
    tangent), and the Jacobians equal central differences of ``quadloc.factors.metrics.residual``
    with the model's (grown) sample layout."""
    rng = np.random.default_rng(seed)
    ells = random_scene(rng, 6)
    dets = [transformed(project_ellipsoid(CAMERA, np.eye(4), e), 0.05, [25.0, -10.0])
            for e in ells]
    pose = retract(np.eye(4), perturbation(rng, 0.05, 0.2))
    W = np.eye(4)
    W[:3, :3] = random_rotation(rng)
    W[:3, 3] = rng.uniform(-5.0, 5.0, 3)
    moved_ells = [Ellipsoid(W[:3, :3] @ e.center + W[:3, 3], e.axes, W[:3, :3] @ e.rotation)
                  for e in ells]
    moved_pose = W @ pose
    ref = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=pose)
    model = PoseResidualModel("level_set", dets, moved_ells, CAMERA,
                              initial_world_from_camera=moved_pose)
    assert model.sampling_grown
    np.testing.assert_allclose(model.sampling_scale, ref.sampling_scale, rtol=1e-12)
    ev, ev_ref = model.evaluate(moved_pose), ref.evaluate(pose)
    assert ev.valid.all()
    np.testing.assert_allclose(ev.residuals, ev_ref.residuals, atol=1e-9)
    np.testing.assert_allclose(ev.jacobians, ev_ref.jacobians,
                               atol=1e-9 * np.abs(ev_ref.jacobians).max())

    def fn(T):
        cfw = invert_pose(T)
        return np.array([metrics.residual("level_set", d, project_ellipsoid(CAMERA, cfw, e),
                                          scale=s, adaptive=False)
                         for d, e, s in zip(dets, moved_ells, model.sampling_scale,
                                            strict=True)])

    np.testing.assert_allclose(ev.residuals, fn(moved_pose), atol=1e-9)
    num = numeric_jacobian(fn, moved_pose, h=1e-6)
    np.testing.assert_allclose(ev.jacobians, num, atol=1e-6 * np.abs(num).max())


@pytest.mark.parametrize("metric", ["algebraic", "frobenius", "wasserstein", "bhattacharyya",
                                    "bbox", "qbbox", "iou", "giou"])
def test_smooth_metric_jacobians_match_numerical(scene, metric):
    """Analytic Jacobians against central differences of ``quadloc.factors.metrics.residual``.

    qbbox has no analytic Jacobian: its model uses central differences too, so for it this is
    only a PLUMBING check (right pose perturbation, step and row order), not a check of
    derivative formulas."""
    assert set(ANALYTIC_METRICS) == {"level_set", "algebraic", "frobenius", "wasserstein",
                                     "bhattacharyya", "bbox", "iou", "giou"}
    ells, dets, pose = scene
    model = PoseResidualModel(metric, dets, ells, CAMERA, initial_world_from_camera=pose)
    ev = model.evaluate(pose, jacobian=True)

    def fn(T):
        return np.array([metrics.residual(metric, d, project_ellipsoid(CAMERA, invert_pose(T), e),
                                          **model.options)
                         for d, e in zip(dets, ells, strict=True)])

    num = numeric_jacobian(fn, pose, h=1e-5)
    np.testing.assert_allclose(ev.jacobians, num, rtol=1e-4, atol=1e-5 * np.abs(num).max())


@pytest.mark.parametrize("metric", ["level_set", "algebraic", "frobenius", "wasserstein",
                                    "bhattacharyya", "bbox"])
def test_analytic_jacobians_at_the_exact_solution(metric):
    """Zero residual (detection == projection): equal eigenvalues / zero angles, the branch
    where the covariance is computed."""
    rng = np.random.default_rng(31)
    ells = random_scene(rng, 4)
    truth = retract(np.eye(4), perturbation(rng, 0.02, 0.05))
    dets = [project_ellipsoid(CAMERA, invert_pose(truth), e) for e in ells]
    model = PoseResidualModel(metric, dets, ells, CAMERA, initial_world_from_camera=truth)
    ev = model.evaluate(truth)
    assert np.abs(ev.residuals).max() < 1e-6 * max(1.0, np.abs(ev.jacobians).max())

    def fn(T):
        return np.array([metrics.residual(metric, d, project_ellipsoid(CAMERA, invert_pose(T), e),
                                          **({"scale": s, "adaptive": False}
                                             if metric == "level_set" else {}))
                         for d, e, s in zip(dets, ells, getattr(model, "sampling_scale",
                                                               [0] * 4), strict=True)])

    num = numeric_jacobian(fn, truth, h=1e-5)
    np.testing.assert_allclose(ev.jacobians, num, rtol=1e-4, atol=1e-5 * np.abs(num).max())


def test_factor_linearization_uses_the_model_jacobian(scene):
    """GTSAM's linearized factor = whitened (J, -r) of the model (shape (m, 6), no transpose)."""
    ells, dets, pose = scene
    sigma = 2.5
    f = pose_factor("level_set", 3, dets[0], ells[0], CAMERA, sigma=sigma,
                    initial_world_from_camera=pose)
    values = gtsam.Values()
    values.insert(3, gtsam.Pose3(pose))
    A, b = f.linearize(values).jacobian()
    model = PoseResidualModel("level_set", dets[:1], ells[:1], CAMERA,
                              initial_world_from_camera=pose)
    ev = model.evaluate(pose)
    np.testing.assert_allclose(A, ev.jacobians[0] / math.sqrt(sigma), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(b, -ev.residuals[0] / math.sqrt(sigma), rtol=1e-10, atol=1e-12)


def test_sigma_scales_error_as_equation_8(scene):
    ells, dets, pose = scene
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3(pose))
    proj = project_ellipsoid(CAMERA, invert_pose(pose), ells[1])
    cost = metrics.cost("level_set", dets[1], proj)
    for sigma in (0.1, 1.0, 7.0):
        f = pose_factor("level_set", 0, dets[1], ells[1], CAMERA, sigma=sigma,
                        initial_world_from_camera=pose)
        assert f.error(values) == pytest.approx(0.5 * cost / sigma, rel=1e-9)


def test_shared_factors_and_batched_factor_agree(scene):
    ells, dets, pose = scene
    sigmas = [0.5, 1.0, None, 3.0, 2.0]
    fs, model = pose_factors("level_set", 0, dets, ells, CAMERA, sigmas=sigmas,
                             initial_world_from_camera=pose)
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3(pose))
    per = [f.error(values) for f in fs]
    costs = model.costs(pose)
    expected = [0.5 * c / (1.0 if s is None else s) for c, s in zip(costs, sigmas, strict=True)]
    np.testing.assert_allclose(per, expected, rtol=1e-9)
    batched = batched_pose_factor(0, model, sigmas)
    assert batched.error(values) == pytest.approx(sum(per), rel=1e-9)
    # memoised evaluation: a second pose gives fresh values, not stale ones
    other = retract(pose, np.r_[0.0, 0.0, 0.01, 0.02, 0.0, 0.0])
    v2 = gtsam.Values()
    v2.insert(0, gtsam.Pose3(other))
    fresh = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=pose)
    np.testing.assert_allclose([f.error(v2) for f in fs],
                               0.5 * fresh.costs(other) / [1.0 if s is None else s
                                                           for s in sigmas], rtol=1e-9)


@pytest.mark.parametrize("kernel", ROBUST_KERNELS)
def test_robust_kernels_downweight_large_residuals(scene, kernel):
    ells, dets, pose = scene
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3(pose))
    plain = pose_factor("level_set", 0, dets[2], ells[2], CAMERA, initial_world_from_camera=pose)
    cost = 2 * plain.error(values)
    k = 0.1 * math.sqrt(cost)  # the residual norm is 10 k: deep in the robust regime
    robust = pose_factor("level_set", 0, dets[2], ells[2], CAMERA, robust=kernel, robust_scale=k,
                         initial_world_from_camera=pose)
    assert robust.error(values) < 0.5 * plain.error(values)
    # with a huge threshold the kernel is quadratic: same error
    wide = pose_factor("level_set", 0, dets[2], ells[2], CAMERA, robust=kernel,
                       robust_scale=1e6 * math.sqrt(cost), initial_world_from_camera=pose)
    assert wide.error(values) == pytest.approx(plain.error(values), rel=1e-6)


def test_noise_model_validation():
    with pytest.raises(ValueError, match="robust"):
        make_noise_model(5, robust="tukeyish")
    with pytest.raises(ValueError, match="sigma"):
        make_noise_model(5, sigma=-1.0)
    with pytest.raises(ValueError, match="robust_scale"):
        make_noise_model(5, robust="huber", robust_scale=0.0)
    with pytest.raises(ValueError, match="metric"):
        PoseResidualModel("nope", [], [], CAMERA)


@pytest.mark.parametrize("case", ["behind", "inside", "crossing"])
def test_invalid_projection_penalty_is_bounded_with_usable_jacobian(scene, case):
    ells, dets, _ = scene
    e = ells[0]
    # camera looking along +Z from a position chosen relative to the ellipsoid
    side = 2.0 * float(e.axes.max())
    offset = {"behind": [0.0, 0.0, 2.0], "inside": [0.0, 0.0, 0.0], "crossing": [side, 0.0, 0.0]}
    pose = np.eye(4)
    pose[:3, 3] = e.center + np.array(offset[case])
    model = PoseResidualModel("level_set", dets[:1], [e], CAMERA)
    margin = ellipsoid_depth_margins(invert_pose(pose), e.center[None], e.shape_matrix()[None])
    assert margin[0] < 0
    ev = model.evaluate(pose)
    assert not ev.valid[0]
    cost = float(ev.residuals[0] @ ev.residuals[0])
    # level_set: reference residual max(1, s_max)^2 = 4 Phi units (s_max = 2, not adaptive)
    assert model.penalty_costs[0] == pytest.approx(DEFAULT_PENALTY_COST * 16.0)
    assert model.penalty_costs[0] <= cost < 4 * model.penalty_costs[0]
    assert np.all(np.isfinite(ev.jacobians))
    num = numeric_jacobian(lambda T: model.evaluate(T, jacobian=False).residuals[0].copy(), pose)
    np.testing.assert_allclose(ev.jacobians[0], num, rtol=1e-5, atol=1e-6 * np.abs(num).max())
    # a Gauss-Newton-like small step along -J^T r increases the depth margin
    step = -ev.jacobians[0].T @ ev.residuals[0]
    moved = retract(pose, 1e-3 * step / np.linalg.norm(step))
    margin2 = ellipsoid_depth_margins(invert_pose(moved), e.center[None], e.shape_matrix()[None])
    assert margin2[0] > margin[0]


@pytest.mark.parametrize("metric", metrics.METRIC_NAMES)
def test_every_metric_factor_survives_invalid_projection(scene, metric):
    ells, dets, _ = scene
    pose = np.eye(4)
    pose[:3, 3] = ells[0].center + np.array([0.0, 0.0, 1.0])  # object behind the camera
    opts = {"image_size": (CAMERA.width, CAMERA.height)} if metric == "qbbox" else {}
    model = PoseResidualModel(metric, dets[:2], ells[:2], CAMERA, metric_options=opts)
    ev = model.evaluate(pose)
    assert not ev.valid[0]
    assert np.all(np.isfinite(ev.residuals)) and np.all(np.isfinite(ev.jacobians))
    cost0 = float(ev.residuals[0] @ ev.residuals[0])
    # the penalty is scaled to the metric's units (px^4 for algebraic), never below the default
    assert DEFAULT_PENALTY_COST <= model.penalty_costs[0] <= cost0 < 4 * model.penalty_costs[0]
    # its Jacobian row pushes the depth margin up (d margin / d v_z = -1: move backwards)
    assert np.all(ev.jacobians[0][:, 5] > 0)


def _scene_with_a_close_object(rng: np.random.Generator) -> list[Ellipsoid]:
    """4 objects 3-5 m away plus one 0.2 m in front of the identity camera (semi-axes 8 cm):
    a 10 cm / 5 degree error can put it across the camera's principal plane."""
    out = []
    for _ in range(4):
        q = rng.normal(size=4)
        q = q / np.linalg.norm(q) * np.sign(q[0])
        out.append(Ellipsoid(np.array([rng.uniform(-1, 1), rng.uniform(-0.6, 0.6),
                                       rng.uniform(3, 5)]),
                             rng.uniform(0.15, 0.4, 3), rotation_from_quaternion_wxyz(q)))
    out.append(Ellipsoid(np.array([0.1, 0.05, 0.2]), np.array([0.08, 0.064, 0.08]), np.eye(3)))
    return out


@pytest.mark.parametrize("metric", ["algebraic", "frobenius", "bbox", "wasserstein"])
def test_lm_never_ends_behind_the_camera_when_the_truth_is_valid(metric):
    """Regression: with a fixed penalty cost of 1e8, the px^4-scaled algebraic/frobenius costs
    (~5e10 at these starts) were larger than the penalty, so LM stepped the close object
    behind the camera and stayed there (seeds 4 and 5 ended 'invalid_projection')."""
    from quadloc.service.localization.refine import refine
    from quadloc.service.localization.types import Detection

    truth = np.eye(4)  # world_from_camera
    for seed in range(8):
        rng = np.random.default_rng(seed)
        ells = _scene_with_a_close_object(rng)
        dets = [Detection(project_ellipsoid(CAMERA, invert_pose(truth), e), f"o{j}")
                for j, e in enumerate(ells)]
        start = retract(truth, perturbation(rng, math.radians(5.0), 0.10))
        res = refine(dets, ells, CAMERA, start, metric, max_iterations=50)
        margins = ellipsoid_depth_margins(invert_pose(res.world_from_camera),
                                          np.array([e.center for e in ells]),
                                          np.array([e.shape_matrix() for e in ells]))
        assert res.valid_projection.all() and np.all(margins > 0), (seed, res.status)


@pytest.mark.parametrize("metric", metrics.METRIC_NAMES)
def test_penalty_exceeds_valid_costs_near_the_principal_plane(metric):
    """The module docstring's claim: at the smallest valid margin (just above
    ``min_depth_margin``) the valid cost, from ``quadloc.factors.metrics.cost`` on the independently
    projected ellipse, is below the penalty cost of the same pair just across the boundary."""
    e = Ellipsoid(np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.6, 0.8]), np.eye(3))  # d_s = 1 m
    camera = Camera(1000.0, 1000.0, 320.0, 240.0, 640, 480)
    det = Ellipse(300.0, 260.0, 40.0, 25.0, 0.3)
    # level_set: LM minimises the samples fixed at the start (here s_max = 2), not re-grown
    opts = {"image_size": (camera.width, camera.height)} if metric == "qbbox" else \
        {"adaptive": False} if metric == "level_set" else {}
    model = PoseResidualModel(metric, [det], [e], camera, metric_options=opts)
    assert model.penalty_costs[0] >= DEFAULT_PENALTY_COST
    depth = float(np.sqrt(e.shape_matrix()[2, 2]))
    for lateral in (0.0, 0.3, 1.0):  # m, object centre off the optical axis
        for margin in (2e-3, 1e-2):  # m, above the default min_depth_margin 1e-3
            pose = np.eye(4)  # world_from_camera, looking along +Z at the object
            pose[:3, 3] = [-lateral, 0.0, -(depth + margin)]
            proj = project_ellipsoid(camera, invert_pose(pose), e)
            r = metrics.residual(metric, det, proj, **opts)
            valid_cost = float(r @ r)
            assert model.evaluate(pose).valid[0]
            assert model.costs(pose)[0] == pytest.approx(valid_cost, rel=1e-6)
            # what LM minimises (saturated above P_j / 2) is below the penalty
            fr = model.evaluate(pose).factor_residuals[0]
            assert float(fr @ fr) < model.penalty_costs[0]
            pose[2, 3] += 2 * margin  # the same pose just across: margin -> -margin
            ev = model.evaluate(pose)
            assert not ev.valid[0]
            assert model.penalty_costs[0] <= model.costs(pose)[0]


def _thin_projection_case() -> tuple[PoseResidualModel, np.ndarray]:
    """Level set (s_max = 2, not adaptive): a flat ellipsoid (0.1 mm thick) seen edge-on
    projects to a valid but very thin ellipse (~0.03 px wide): its level-set cost far exceeds
    the penalty (the issue measured 1e10-1e12 against 3.9e9)."""
    e = Ellipsoid(np.array([0.0, 0.0, 3.0]), np.array([0.5, 1e-4, 0.3]), np.eye(3))
    camera = Camera(1000.0, 1000.0, 320.0, 240.0, 640, 480)
    det = Ellipse(300.0, 260.0, 40.0, 25.0, 0.3)
    model = PoseResidualModel("level_set", [det], [e], camera,
                              metric_options={"adaptive": False})
    return model, np.eye(4)


def test_saturated_valid_cost_stays_below_the_penalty_and_reports_the_metric_cost():
    model, pose = _thin_projection_case()
    ev = model.evaluate(pose)
    assert ev.valid[0]
    cost = float(ev.residuals[0] @ ev.residuals[0])
    assert cost > model.penalty_costs[0]  # the case the barrier claim used to miss
    # reported: the metric's own cost; minimised: the saturated one, below the penalty
    assert model.costs(pose)[0] == pytest.approx(cost, rel=1e-12)
    fr = ev.factor_residuals[0]
    # h < 0.9 P; here c is ~3e4 P, so h is 0.9 P up to rounding
    assert model.penalty_costs[0] / 2 < float(fr @ fr) <= 0.9 * model.penalty_costs[0] * (
        1 + 1e-12)
    # the saturated Jacobian is the derivative of the saturated residual
    num = numeric_jacobian(
        lambda T: model.evaluate(T, jacobian=False).factor_residuals[0].copy(), pose, 1e-7)
    np.testing.assert_allclose(ev.factor_jacobians[0], num, rtol=1e-4,
                               atol=1e-5 * np.abs(num).max())
    # in the transition (c = 0.8 P): h(c) = c0 + 0.4 P (1 - exp(-(c - c0) / (0.4 P))), and
    # its Jacobian, with the penalty cost chosen to put the pair there
    det, e = model.detections[0], model.ellipsoids[0]
    ref = model.penalty_costs[0] / DEFAULT_PENALTY_COST  # rho^2 = 16
    mid = PoseResidualModel("level_set", [det], [e], model.camera,
                            metric_options={"adaptive": False},
                            penalty_cost=cost / (0.8 * ref))
    P = mid.penalty_costs[0]
    ev = mid.evaluate(pose)
    fr = ev.factor_residuals[0]
    assert float(fr @ fr) == pytest.approx(
        0.5 * P + 0.4 * P * (1 - math.exp(-(cost - 0.5 * P) / (0.4 * P))), rel=1e-9)
    num = numeric_jacobian(
        lambda T: mid.evaluate(T, jacobian=False).factor_residuals[0].copy(), pose, 1e-8)
    np.testing.assert_allclose(ev.factor_jacobians[0], num, rtol=1e-4,
                               atol=1e-5 * np.abs(num).max())


@pytest.mark.parametrize("metric", ["algebraic", "frobenius"])
def test_an_invalid_pair_does_not_hide_the_other_pairs(scene, metric):
    """Before: one invalid pair cost ~4e19 (px^4 reference), so the other pairs' costs (~1e6)
    were below double precision in the total. Now the change of a valid pair's cost is seen
    in the factor graph's error to 1e-6 relative."""
    ells, dets, _ = scene
    pose = np.eye(4)
    pose[:3, 3] = ells[0].center + np.array([0.0, 0.0, 1.0])  # object 0 behind the camera
    moved = Ellipse(dets[1].cx + 3.0, dets[1].cy, dets[1].a, dets[1].b, dets[1].angle)
    errors, costs = [], []
    for d1 in (dets[1], moved):
        model = PoseResidualModel(metric, [dets[0], d1], ells[:2], CAMERA)
        ev = model.evaluate(pose)
        assert not ev.valid[0] and ev.valid[1]
        factors_, _ = pose_factors(metric, 0, [dets[0], d1], ells[:2], CAMERA, batched=True)
        values = gtsam.Values()
        values.insert(0, gtsam.Pose3(pose))
        errors.append(sum(f.error(values) for f in factors_))
        costs.append(model.costs(pose))
    assert costs[0][0] == costs[1][0]  # the same penalty
    assert costs[1][1] != pytest.approx(costs[0][1], rel=1e-3)
    assert 2 * (errors[1] - errors[0]) == pytest.approx(costs[1][1] - costs[0][1], rel=1e-6)


@pytest.mark.parametrize("sigmas", [[1.0, -1.0, 1.0, 1.0, 1.0], [1.0, math.nan, 1.0, 1.0, 1.0],
                                    [1.0, 1.0], [1.0, True, 1.0, 1.0, 1.0]])
def test_batched_factor_validates_sigmas(scene, sigmas):
    """Before: batched_pose_factor took sqrt of whatever it got (NaN std for -1)."""
    ells, dets, pose = scene
    model = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=pose)
    with pytest.raises(ValueError, match="sigmas"):
        batched_pose_factor(0, model, sigmas)


def test_batched_factor_weights_each_pair_by_its_sigma(scene):
    ells, dets, pose = scene
    sigmas = [0.5, None, 2.0, 1.0, 4.0]
    model = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=pose)
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3(pose))
    costs = model.costs(pose)
    expected = 0.5 * sum(c / (1.0 if s is None else s) for c, s in zip(costs, sigmas, strict=True))
    assert batched_pose_factor(0, model, sigmas).error(values) == pytest.approx(expected, rel=1e-9)


def test_relayout_equals_a_model_built_at_that_pose(scene):
    """refine() re-lays the level-set samples in place; it must equal a fresh model."""
    ells, dets, pose = scene
    rng = np.random.default_rng(5)
    far = retract(pose, perturbation(rng, 0.3, 0.6))  # grows the adaptive sampling areas
    near = retract(pose, perturbation(rng, 0.01, 0.02))
    relaid = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=far)
    relaid.evaluate(near)  # fill the memo, which relayout must drop
    relaid.relayout(near)
    fresh = PoseResidualModel("level_set", dets, ells, CAMERA, initial_world_from_camera=near)
    assert not np.allclose(relaid.sampling_scale, PoseResidualModel(
        "level_set", dets, ells, CAMERA, initial_world_from_camera=far).sampling_scale)
    np.testing.assert_array_equal(relaid.sample_points, fresh.sample_points)
    np.testing.assert_array_equal(relaid.penalty_costs, fresh.penalty_costs)
    a, b = relaid.evaluate(pose), fresh.evaluate(pose)
    np.testing.assert_array_equal(a.residuals, b.residuals)
    np.testing.assert_array_equal(a.jacobians, b.jacobians)
    with pytest.raises(ValueError, match="level_set"):
        PoseResidualModel("wasserstein", dets, ells, CAMERA).relayout(near)


@pytest.mark.parametrize("metric", ["level_set", "bbox"])
def test_kernel_depth_margins_and_validity_match_the_numpy_formula(scene, metric):
    """The margins, validity and (level set) sum of squares that the kernels now compute
    (through depth_margin's compiled form) against the numpy formula
    (``ellipsoid_depth_margins``, independent of the kernels) and numpy sums, with every pair
    valid and with one behind the camera (1e-12 m / 1e-12 relative)."""
    ells, dets, pose = scene
    behind = np.eye(4)
    behind[:3, 3] = ells[0].center + np.array([0.0, 0.0, 0.05])  # inside ellipsoid 0
    centers = np.array([e.center for e in ells])
    shapes = np.array([e.shape_matrix() for e in ells])
    for T in (pose, behind):
        model = PoseResidualModel(metric, dets, ells, CAMERA, initial_world_from_camera=pose)
        ev = model.evaluate(T)
        expected = ellipsoid_depth_margins(invert_pose(T), centers, shapes)
        np.testing.assert_allclose(ev.depth_margins, expected, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(ev.valid, expected > DEFAULT_MIN_DEPTH_MARGIN)
        assert not ev.residuals.flags.writeable and not ev.valid.flags.writeable
        if metric == "level_set":
            rows = model._family.rows(np.array(T), True)
            if ev.valid.all():
                assert rows.sum_squares == pytest.approx(
                    float(np.sum(rows.residuals ** 2)), rel=1e-12)
            else:
                assert rows.sum_squares is None
    assert not ev.valid[0] and ev.valid[1:].all()  # the second pose really has one invalid


def test_depth_margin_stays_numpy_for_python_callers():
    """``depth_margin`` is the numpy function for Python callers (no compilation per array
    type at a request); its compiled form, for the kernels, gives the same value."""
    from quadloc.factors import camera as camera_module

    z, v = np.array([[2.0, 0.5], [1.0, 3.0]]), np.array([[0.25, 1.0], [-1e-3, 4.0]])
    out = camera_module.depth_margin(z, v)
    np.testing.assert_allclose(out, z - np.sqrt(np.maximum(v, 0.0)), rtol=0, atol=0)
    assert not hasattr(camera_module.depth_margin, "signatures")  # not a numba dispatcher
    assert camera_module.depth_margin_kernel(2.0, 0.25) == pytest.approx(1.5, abs=1e-15)
