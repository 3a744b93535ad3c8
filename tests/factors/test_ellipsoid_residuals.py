"""The shared level-set residual (camera AND ellipsoid): equal to localization's, Jacobians
against central differences on the Pose3 / log-axes retractions."""

from __future__ import annotations

import numpy as np
import pytest

from quadloc.factors.camera import Camera, Ellipsoid, project_ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.ellipsoid_residuals import level_set_samples, observation_residual
from quadloc.factors.pose_residuals import PoseResidualModel, expmap_pose3
from quadloc.factors.rotations import invert_pose
from tests.support.helpers import random_rotation

CAM = Camera(500.0, 520.0, 320.0, 240.0, 640, 480)


def _setup(seed: int):
    rng = np.random.default_rng(seed)
    ell = Ellipsoid(rng.normal(0, 0.2, 3), rng.uniform(0.1, 0.4, 3), random_rotation(rng))
    T_wc = np.eye(4)
    T_wc[:3, 3] = ell.center + np.array([0.2, -0.1, -2.5]) + rng.normal(0, 0.1, 3)
    proj = project_ellipsoid(CAM, invert_pose(T_wc), ell)
    det = Ellipse(proj.cx + rng.normal(0, 5), proj.cy + rng.normal(0, 5), proj.a * 1.1,
                  proj.b * 0.9, proj.angle + 0.1)
    return ell, T_wc, det


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_equals_localization_level_set(seed: int) -> None:
    ell, T_wc, det = _setup(seed)
    model = PoseResidualModel("level_set", [det], [ell], CAM,
                              metric_options={"adaptive": False})
    ev = model.evaluate(T_wc)
    s = level_set_samples(det, CAM)
    r, _, J_cam = observation_residual(invert_pose(T_wc), ell.rotation, ell.center, ell.axes, s)
    np.testing.assert_allclose(r, ev.residuals[0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(J_cam, ev.jacobians[0], rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("seed", [3, 4])
def test_jacobians_against_central_differences(seed: int) -> None:
    ell, T_wc, det = _setup(seed)
    s = level_set_samples(det, CAM)
    T_e = np.eye(4)
    T_e[:3, :3], T_e[:3, 3] = ell.rotation, ell.center

    def res(T_wc_: np.ndarray, T_e_: np.ndarray, log_axes: np.ndarray) -> np.ndarray:
        return observation_residual(invert_pose(T_wc_), T_e_[:3, :3], T_e_[:3, 3],
                                    np.exp(log_axes), s, jacobians=False)[0]

    la = np.log(ell.axes)
    _, J_ell, J_cam = observation_residual(invert_pose(T_wc), ell.rotation, ell.center,
                                           ell.axes, s)
    h = 1e-6
    num_ell = np.zeros_like(J_ell)
    num_cam = np.zeros_like(J_cam)
    for k in range(6):
        xi = np.zeros(6)
        xi[k] = h
        num_ell[:, k] = (res(T_wc, T_e @ expmap_pose3(xi), la)
                         - res(T_wc, T_e @ expmap_pose3(-xi), la)) / (2 * h)
        num_cam[:, k] = (res(T_wc @ expmap_pose3(xi), T_e, la)
                         - res(T_wc @ expmap_pose3(-xi), T_e, la)) / (2 * h)
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        num_ell[:, 6 + k] = (res(T_wc, T_e, la + d) - res(T_wc, T_e, la - d)) / (2 * h)
    scale = np.abs(num_ell).max()
    np.testing.assert_allclose(J_ell, num_ell, atol=1e-6 * scale)
    np.testing.assert_allclose(J_cam, num_cam, atol=1e-6 * np.abs(num_cam).max())


def test_zero_at_exact_projection() -> None:
    ell, T_wc, _ = _setup(5)
    proj = project_ellipsoid(CAM, invert_pose(T_wc), ell)
    r, _, _ = observation_residual(invert_pose(T_wc), ell.rotation, ell.center, ell.axes,
                                   level_set_samples(proj, CAM))
    assert np.abs(r).max() < 1e-8


def test_batched_equals_single() -> None:
    from quadloc.factors.ellipsoid_residuals import stack_samples

    ell, T0, det0 = _setup(6)
    Ts, ss = [], []
    for k in range(4):
        T = T0.copy()
        T[:3, 3] += np.array([0.1 * k, -0.05 * k, 0.02 * k])
        Ts.append(invert_pose(T))
        ss.append(level_set_samples(Ellipse(det0.cx + 3 * k, det0.cy, det0.a, det0.b, det0.angle),
                                    CAM))
    r, Je, Jc = observation_residual(np.array(Ts), ell.rotation, ell.center, ell.axes,
                                     stack_samples(ss))
    for k in range(4):
        r1, Je1, Jc1 = observation_residual(Ts[k], ell.rotation, ell.center, ell.axes, ss[k])
        np.testing.assert_allclose(r[k], r1, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Je[k], Je1, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(Jc[k], Jc1, rtol=1e-10, atol=1e-12)
