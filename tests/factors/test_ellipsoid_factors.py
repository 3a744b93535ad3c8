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
    depth_margins,
    ellipsoid_views_factor,
    huber_row_scale,
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
