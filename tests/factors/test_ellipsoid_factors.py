"""The ellipsoid-side GTSAM factor (``quadloc.factors.ellipsoid_factors``): rows equal to the shared
residual weighted and Huber-scaled, Jacobian blocks against central differences on the Pose3 /
log-axes retractions, the behind-camera penalty, batched helpers against single evaluations."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from quadloc.factors.camera import Camera, Ellipsoid, ellipsoid_depth_margins, project_ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.ellipsoid_factors import (
    MIN_AXIS_DEPTH_RATIO,
    depth_margins,
    ellipsoid_views_factor,
    huber_row_scale,
    valid_views,
)
from quadloc.factors.ellipsoid_residuals import (
    level_set_samples,
    observation_residual,
    stack_samples,
)
from quadloc.factors.pose_residuals import expmap_pose3
from quadloc.factors.rotations import invert_pose
from tests.support.helpers import random_rotation

CAM = Camera(500.0, 520.0, 320.0, 240.0, 640, 480)


def _scene(seed: int):
    """Two ellipsoids, two cameras ~2.5 m behind them, three views (noisy detections)."""
    rng = np.random.default_rng(seed)
    ells = [Ellipsoid(np.array([0.3 * k, 0.1, 0.0]) + rng.normal(0, 0.05, 3),
                      rng.uniform(0.1, 0.3, 3), random_rotation(rng)) for k in range(2)]
    cams = []
    for k in range(2):
        T = np.eye(4)
        T[:3, :3] = expmap_pose3(np.r_[rng.normal(0, 0.05, 3), 0, 0, 0])[:3, :3]
        T[:3, 3] = np.array([0.15 + 0.2 * k, 0.0, -2.5]) + rng.normal(0, 0.05, 3)
        cams.append(T)
    views = [(0, 0), (1, 0), (0, 1)]  # (object, camera)
    dets = []
    for o, c in views:
        p = project_ellipsoid(CAM, invert_pose(cams[c]), ells[o])
        dets.append(Ellipse(p.cx + rng.normal(0, 4), p.cy + rng.normal(0, 4), p.a * 1.1,
                            p.b * 0.95, p.angle + 0.05))
    return ells, cams, views, dets


def _values(ells, cams, E, L, X) -> gtsam.Values:
    v = gtsam.Values()
    for k, e in enumerate(ells):
        v.insert(E[k], gtsam.Pose3(gtsam.Rot3(e.rotation), e.center))
        v.insert(L[k], np.log(e.axes))
    for k, T in enumerate(cams):
        v.insert(X[k], gtsam.Pose3(T))
    return v


def _numeric(factor: gtsam.CustomFactor, values: gtsam.Values, key: int, dim: int,
             h: float = 1e-6) -> np.ndarray:
    cols = []
    for e in np.eye(dim):
        out = []
        for sgn in (1.0, -1.0):
            v = gtsam.Values(values)
            if dim == 6:
                v.update(key, values.atPose3(key).retract(sgn * h * e))
            else:
                v.update(key, values.atVector(key) + sgn * h * e)
            out.append(factor.unwhitenedError(v))
        cols.append((out[0] - out[1]) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("robust", [None, 0.05])
def test_rows_and_jacobians_refined_cameras(robust: float | None) -> None:
    ells, cams, views, dets = _scene(0)
    E = [gtsam.symbol("e", k) for k in range(2)]
    L = [gtsam.symbol("l", k) for k in range(2)]
    X = [gtsam.symbol("x", k) for k in range(2)]
    samples = stack_samples([level_set_samples(d, CAM) for d in dets])
    w = np.array([1.0, 2.0, 0.5])
    f = ellipsoid_views_factor(samples, w, list(zip(E, L, strict=True)), [o for o, _ in views],
                               camera_keys=X, view_cameras=[c for _, c in views],
                               robust_scale=robust)
    values = _values(ells, cams, E, L, X)
    # rows: the shared residual, weighted (and Huber-scaled per view), view-major
    rows = f.unwhitenedError(values).reshape(3, -1)
    for v, (o, c) in enumerate(views):
        r = observation_residual(invert_pose(cams[c]), ells[o].rotation, ells[o].center,
                                 ells[o].axes, level_set_samples(dets[v], CAM), False)[0]
        s = w[v]
        if robust is not None:
            norm = w[v] * np.linalg.norm(r)
            assert norm > robust  # the kernel is active in this test
            s *= np.sqrt(2 * robust * (norm - robust / 2)) / norm
        np.testing.assert_allclose(rows[v], s * r, rtol=1e-12, atol=1e-14)
    A, _ = f.linearize(values).jacobian()
    assert list(f.keys()) == [E[0], L[0], E[1], L[1], X[0], X[1]]
    # the derivative of the weighted residual; with the kernel, the rows' scale is held
    # constant (iteratively reweighted least squares): the quadratic factor's derivative scaled
    quad = ellipsoid_views_factor(samples, w, list(zip(E, L, strict=True)),
                                  [o for o, _ in views], camera_keys=X,
                                  view_cameras=[c for _, c in views])
    dims = [6, 3, 6, 3, 6, 6]
    numeric = np.column_stack([_numeric(quad, values, k, d) for k, d in
                               zip([E[0], L[0], E[1], L[1], X[0], X[1]], dims, strict=True)])
    row_scale = np.repeat((rows / quad.unwhitenedError(values).reshape(3, -1))[:, 0],
                          rows.shape[1])
    numeric *= row_scale[:, None]
    np.testing.assert_allclose(A, numeric, atol=1e-6 * np.abs(numeric).max())
    assert np.abs(numeric).max() > 1e-2


def test_fixed_cameras_one_object_matches_per_view_evaluation() -> None:
    ells, cams, _, _ = _scene(1)
    e = ells[0]
    dets = [project_ellipsoid(CAM, invert_pose(T), e) for T in cams]
    dets = [Ellipse(d.cx + 3, d.cy - 2, d.a, d.b * 1.05, d.angle) for d in dets]
    ek, lk = gtsam.symbol("e", 0), gtsam.symbol("l", 0)
    cfw = np.array([invert_pose(T) for T in cams])
    f = ellipsoid_views_factor(stack_samples([level_set_samples(d, CAM) for d in dets]),
                               np.ones(2), [(ek, lk)], [0, 0], camera_from_world=cfw)
    v = gtsam.Values()
    v.insert(ek, gtsam.Pose3(gtsam.Rot3(e.rotation), e.center))
    v.insert(lk, np.log(e.axes))
    rows = f.unwhitenedError(v).reshape(2, -1)
    for k in range(2):
        r = observation_residual(cfw[k], e.rotation, e.center, e.axes,
                                 level_set_samples(dets[k], CAM), False)[0]
        np.testing.assert_allclose(rows[k], r, rtol=1e-12, atol=1e-14)
    A, _ = f.linearize(v).jacobian()
    numeric = np.column_stack([_numeric(f, v, ek, 6), _numeric(f, v, lk, 3)])
    np.testing.assert_allclose(A, numeric, atol=1e-6 * np.abs(numeric).max())


def test_view_behind_the_camera_is_a_constant_penalty() -> None:
    ells, cams, _, dets = _scene(2)
    e = ells[0]
    behind = cams[0].copy()
    behind[:3, 3] = e.center + np.array([0.0, 0.0, 2.5])  # looks along +z, object behind it
    ek, lk = gtsam.symbol("e", 0), gtsam.symbol("l", 0)
    cfw = np.array([invert_pose(cams[0]), invert_pose(behind)])
    f = ellipsoid_views_factor(stack_samples([level_set_samples(dets[0], CAM)] * 2),
                               np.array([1.0, 2.0]), [(ek, lk)], [0, 0], camera_from_world=cfw,
                               penalty_cost=100.0)
    v = gtsam.Values()
    v.insert(ek, gtsam.Pose3(gtsam.Rot3(e.rotation), e.center))
    v.insert(lk, np.log(e.axes))
    rows = f.unwhitenedError(v).reshape(2, -1)
    np.testing.assert_allclose(0.5 * np.sum(rows[1] ** 2), 100.0 * 2.0**2, rtol=1e-12)
    A, _ = f.linearize(v).jacobian()
    assert np.all(A.reshape(2, -1, 9)[1] == 0.0)


#: An LM trial point of a map build (bench.map_calibration.run(seed=21, detector="noisy",
#: frames=3000, holdout_every=2)): a weakly observed object's log semi-axes stepped to
#: [-36, -318, -126] while it stayed 1 m in front of the camera; its projected conic was singular.
_COLLAPSED_CAMERA_FROM_WORLD = np.array([
    [0.9949442241930777, 0.08992156491550844, 0.0447225100814, 0.07921944240008807],
    [0.08892517608445157, -0.5818527080886583, -0.808418047267776, 0.4629393957696279],
    [-0.04667230231287294, 0.8083078239464472, -0.5869072822378126, 0.7118258679760492],
    [0.0, 0.0, 0.0, 1.0]])
_COLLAPSED_ROTATION = np.array([
    [0.22290382923681096, -0.650335395252789, -0.7262077916085486],
    [0.2930261455136367, -0.6658006775324217, 0.6861815618644885],
    [-0.9297577969326137, -0.3657503677083137, 0.0421557536315722]])
_COLLAPSED_CENTER = np.array([-1.9042478446168598, 1.973324483329556, 2.3755256781285925])
_COLLAPSED_LOG_AXES = np.array([-36.39045801747006, -318.27222452878124, -126.14521458754044])


def test_collapsed_ellipsoid_is_a_constant_penalty_not_a_singular_matrix() -> None:
    T, R, c = _COLLAPSED_CAMERA_FROM_WORLD, _COLLAPSED_ROTATION, _COLLAPSED_CENTER
    # the detection: the projection of the object with 10 cm semi-axes
    det = level_set_samples(project_ellipsoid(CAM, T, Ellipsoid(c, np.full(3, 0.1), R)), CAM)
    # the trigger: in front of the camera (the old validity test passed), yet unguarded the
    # residual raises
    assert ellipsoid_depth_margins(T, c[None], np.zeros((1, 3, 3)))[0] > 1.0
    with pytest.raises(np.linalg.LinAlgError):
        observation_residual(T, R, c, np.exp(_COLLAPSED_LOG_AXES), det, False)
    ek, lk = gtsam.symbol("e", 0), gtsam.symbol("l", 0)
    f = ellipsoid_views_factor(stack_samples([det, det]), np.array([1.0, 2.0]), [(ek, lk)],
                               [0, 0], camera_from_world=np.stack([T, T]), penalty_cost=100.0,
                               robust_scale=1.0)
    v = gtsam.Values()
    v.insert(ek, gtsam.Pose3(gtsam.Rot3(R), c))
    v.insert(lk, _COLLAPSED_LOG_AXES)
    rows = f.unwhitenedError(v).reshape(2, -1)
    for k, w in enumerate((1.0, 2.0)):  # each view: the documented penalty, penalty_cost w^2
        np.testing.assert_allclose(0.5 * np.sum(rows[k] ** 2), 100.0 * w**2, rtol=1e-12)
    A, _ = f.linearize(v).jacobian()
    assert np.all(A == 0.0)
    # the object with 10 cm semi-axes is a valid view of (near) zero cost: LM rejects the
    # collapsing step
    healthy = gtsam.Values()
    healthy.insert(ek, gtsam.Pose3(gtsam.Rot3(R), c))
    healthy.insert(lk, np.log([0.1, 0.1, 0.1]))
    assert valid_views(T, R, c, np.full(3, 0.1))
    assert f.error(healthy) < 1e-6 * f.error(v)


def test_valid_views_depth_margin_and_smallest_semi_axis() -> None:
    # camera at the origin looking along +z; a sphere-like ellipsoid 2 m ahead: depth 2 m
    cfw = np.eye(4)
    R = np.eye(3)
    c = np.array([0.1, -0.2, 2.0])
    limit = MIN_AXIS_DEPTH_RATIO * 2.0
    assert valid_views(cfw, R, c, np.array([0.3, 0.2, limit * 1.01]))
    assert not valid_views(cfw, R, c, np.array([0.3, 0.2, limit * 0.99]))
    assert not valid_views(cfw, R, c, np.array([0.3, 0.2, 0.0]))
    # a semi-axis reaching the camera's plane (depth margin 2 - 2.1 < 0): invalid
    assert not valid_views(cfw, R, c, np.array([0.3, 0.2, 2.1]))
    # non-finite shapes or centres: invalid
    assert not valid_views(cfw, R, c, np.array([0.3, np.inf, 0.1]))
    assert not valid_views(cfw, R, np.array([0.0, np.nan, 2.0]), np.array([0.3, 0.2, 0.1]))
    # batched: the same answers view by view
    Ts = np.stack([cfw, cfw])
    a = np.array([[0.3, 0.2, limit * 1.01], [0.3, 0.2, limit * 0.99]])
    np.testing.assert_array_equal(valid_views(Ts, np.stack([R, R]), np.stack([c, c]), a),
                                  [True, False])


def test_batched_helpers_equal_single_evaluations() -> None:
    rng = np.random.default_rng(3)
    ells, cams, _, _ = _scene(3)
    Ts = np.array(cams)
    # batched invert_pose against an independent general inverse, pose by pose
    np.testing.assert_allclose(invert_pose(Ts), [np.linalg.inv(T) for T in Ts], atol=1e-12)
    cfw = invert_pose(Ts)
    R = np.array([e.rotation for e in ells])
    c = np.array([e.center for e in ells])
    a = np.array([e.axes for e in ells])
    m = depth_margins(cfw, R, c, a)
    for k in range(2):
        ref = ellipsoid_depth_margins(cfw[k], c[k][None], ells[k].shape_matrix()[None])[0]
        np.testing.assert_allclose(m[k], ref, rtol=1e-12)
    # observation_residual with one ellipsoid per view equals the per-view calls
    dets = [level_set_samples(project_ellipsoid(CAM, cfw[k], ells[k]).__class__(
        300 + rng.normal(), 240.0, 40.0, 25.0, 0.3), CAM) for k in range(2)]
    r, Je, Jc = observation_residual(cfw, R, c, a, stack_samples(dets))
    for k in range(2):
        r1, Je1, Jc1 = observation_residual(cfw[k], R[k], c[k], a[k], dets[k])
        np.testing.assert_allclose(r[k], r1, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(Je[k], Je1, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(Jc[k], Jc1, rtol=1e-10, atol=1e-12)
    # Huber scale: 0.5 (s x)^2 is Huber's cost
    x = np.array([0.1, 1.0, 3.0])
    s = huber_row_scale(x, 1.0)
    np.testing.assert_allclose(0.5 * (s * x) ** 2, [0.005, 0.5, 3.0 - 0.5], rtol=1e-12)
