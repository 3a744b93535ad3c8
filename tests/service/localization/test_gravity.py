"""A client's gravity direction: a factor on the pose's tilt (``quadloc.factors.gravity_factor``), a
test of candidates and a veto of tilted answers (``quadloc.service.localization.gravity``,
``Gravity``, ``tests.support.simulate.simulate_gravity``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadloc.factors.gravity_factor import GravityMeasurement, gravity_factor
from quadloc.factors.pose_factors import pose3
from quadloc.factors.pose_residuals import expmap_pose3
from quadloc.factors.rotations import invert_pose
from quadloc.maps.compiled import compile_map
from quadloc.service.localization.confidence import TOLERANCE_ROTATION_DEG
from quadloc.service.localization.gravity import (
    GRAVITY_GATE_SIGMAS,
    answer_gate_deg,
    tilt_errors_deg,
)
from quadloc.service.localization.pipeline import localize
from quadloc.service.localization.refine import refine
from quadloc.service.localization.types import (
    Gravity,
    LocalizationInputError,
    LocalizationOptions,
    PosePrior,
)
from tests.support.errors import pose_errors
from tests.support.reference_data import load_chess_map, load_chess_world_from_camera
from tests.support.simulate import SimulationConfig, reduce_frame, simulate_frame, simulate_gravity

CM = compile_map(load_chess_map())
UP = CM.scene_map.up
CAMERA, POSES, _ = load_chess_world_from_camera()
OPTS = LocalizationOptions(time_budget_ms=None)


def _true_gravity(world_from_camera: np.ndarray, sigma_deg: float = 2.0) -> Gravity:
    """The exact down direction of a pose, in its camera axes."""
    return Gravity(-(world_from_camera[:3, :3].T @ UP), sigma_deg)


def _tilted(world_from_camera: np.ndarray, angle_deg: float) -> np.ndarray:
    """The pose rotated by ``angle_deg`` about a camera axis perpendicular to the map's up:
    its up direction tilts by exactly that angle."""
    up_c = world_from_camera[:3, :3].T @ UP
    axis = np.cross(up_c, [0.0, 0.0, 1.0])
    w = math.radians(angle_deg) * axis / np.linalg.norm(axis)
    return world_from_camera @ expmap_pose3(np.r_[w, 0.0, 0.0, 0.0])


def test_tilt_error_is_the_roll_and_pitch_not_the_yaw():
    T = POSES[10]
    g = _true_gravity(T)
    assert tilt_errors_deg(invert_pose(T), UP, g) == pytest.approx(0.0, abs=1e-6)
    for angle in (3.0, 20.0, 90.0, 170.0):
        for axis in (0, 2):  # pitch (camera x) and roll (optical axis z)
            w = np.zeros(6)
            w[axis] = math.radians(angle)
            tilted = T @ expmap_pose3(w)
            # the camera's rotation relative to the truth moves its up by at most the angle;
            # about an axis perpendicular to up, by exactly the angle
            up_c = T[:3, :3].T @ UP
            e = np.zeros(3)
            e[axis] = 1.0
            expected = math.degrees(math.acos(np.clip(
                (up_c @ up_c - (up_c @ e) ** 2) * math.cos(math.radians(angle))
                + (up_c @ e) ** 2, -1, 1)))
            got = tilt_errors_deg(invert_pose(tilted), UP, g)
            assert got == pytest.approx(expected, abs=1e-6)
    # a rotation about the world's vertical (yaw) does not tilt
    c, s = math.cos(0.7), math.sin(0.7)
    yaw = np.eye(4)
    yaw[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    assert tilt_errors_deg(invert_pose(yaw @ T), UP, g) == pytest.approx(0.0, abs=1e-6)
    # vectorised over poses (4x4 or 3x3)
    stack = np.array([invert_pose(_tilted(T, a)) for a in (0.0, 10.0, 30.0)])
    np.testing.assert_allclose(tilt_errors_deg(stack, UP, g), [0.0, 10.0, 30.0], atol=1e-6)
    np.testing.assert_allclose(tilt_errors_deg(stack[:, :3, :3], UP, g), [0.0, 10.0, 30.0],
                               atol=1e-6)
    assert answer_gate_deg(g) == TOLERANCE_ROTATION_DEG + GRAVITY_GATE_SIGMAS * 2.0


def test_gravity_validation_names_the_field():
    g = Gravity([0.0, 2.0, 0.0], 1.5)
    np.testing.assert_allclose(g.direction_camera, [0.0, 1.0, 0.0])
    assert not g.direction_camera.flags.writeable
    for bad in ([0.0, 0.0, 0.0], [1.0, math.nan, 0.0], [1.0, 2.0], "up"):
        with pytest.raises(LocalizationInputError, match=r"^gravity\.direction:"):
            Gravity(bad)  # type: ignore[arg-type]
    for bad in (0.0, -1.0, 31.0, math.nan, True):
        with pytest.raises(LocalizationInputError, match=r"^gravity\.sigma_deg:"):
            Gravity([0.0, 1.0, 0.0], bad)  # type: ignore[arg-type]
    f = simulate_frame(CM, CAMERA, POSES[0], 0, SimulationConfig())
    with pytest.raises(LocalizationInputError, match=r"^gravity:"):
        localize(f.detections, CM, CAMERA, OPTS, None, [0.0, 1.0, 0.0])  # type: ignore[arg-type]


def test_simulated_gravity_has_the_stated_tilt_distribution():
    """Per-axis Gaussian tilt of sigma: the tilt angle is Rayleigh(sigma), mean sigma
    sqrt(pi / 2); unit vectors."""
    T = POSES[20]
    gen = np.random.default_rng(0)
    down = -(T[:3, :3].T @ UP)
    g = np.array([simulate_gravity(T, UP, 2.0, gen) for _ in range(4000)])
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)
    tilt = np.degrees(np.arccos(np.clip(g @ down, -1, 1)))
    assert np.mean(tilt) == pytest.approx(2.0 * math.sqrt(math.pi / 2), rel=0.03)
    assert np.mean(tilt > 6.0) == pytest.approx(math.exp(-4.5), abs=0.006)


def _measurement(world_from_camera: np.ndarray, sigma_deg: float = 2.0) -> GravityMeasurement:
    return GravityMeasurement(_true_gravity(world_from_camera).direction_camera, -UP,
                              math.radians(sigma_deg))


def test_gravity_factor_error_is_the_tilt_and_its_jacobian_matches_central_differences():
    """The factor's error norm is the tilt angle's sine (GTSAM's ``Unit3.error``: the
    predicted down projected on the tangent plane of the map's down),
    zero at a pose agreeing with the measurement and under yaw; its whitened Jacobian (GTSAM's
    analytic one) matches central differences on ``retract`` and leaves the position out."""
    import gtsam

    T = POSES[12]
    m = _measurement(T, sigma_deg=2.0)
    f = gravity_factor(0, m)

    def error(pose: np.ndarray) -> np.ndarray:
        v = gtsam.Values()
        v.insert(0, pose3(pose))
        return np.asarray(f.unwhitenedError(v))

    np.testing.assert_allclose(error(T), 0.0, atol=1e-12)
    c, s_ = math.cos(1.1), math.sin(1.1)
    yaw = np.eye(4)
    yaw[:3, :3] = [[c, -s_, 0], [s_, c, 0], [0, 0, 1]]
    np.testing.assert_allclose(error(yaw @ T), 0.0, atol=1e-12)
    for angle in (0.5, 4.0, 25.0):
        tilted = _tilted(T, angle)
        assert tilt_errors_deg(invert_pose(tilted), UP, _true_gravity(T)) == pytest.approx(
            angle, abs=1e-6)
        assert np.linalg.norm(error(tilted)) == pytest.approx(math.sin(math.radians(angle)),
                                                              rel=1e-9)
    at = _tilted(T, 7.0)
    v = gtsam.Values()
    v.insert(0, pose3(at))
    A, _ = f.linearize(v).jacobian()  # whitened: J / sigma
    h = 1e-6
    numeric = np.column_stack([
        (error(at @ expmap_pose3(h * e)) - error(at @ expmap_pose3(-h * e))) / (2 * h)
        for e in np.eye(6)])
    np.testing.assert_allclose(A * m.sigma_rad, numeric, atol=1e-7)
    np.testing.assert_allclose(A[:, 3:], 0.0, atol=0)


def test_gravity_measurement_validation_names_the_field():
    for kw, field in (({"down_camera": [0.0, 0.0, 0.0]}, "down_camera"),
                      ({"down_world": [1.0, math.inf, 0.0]}, "down_world"),
                      ({"down_world": [1.0, 0.0]}, "down_world"),
                      ({"sigma_rad": 0.0}, "sigma_rad"), ({"sigma_rad": math.nan}, "sigma_rad")):
        args = {"down_camera": [0.0, 1.0, 0.0], "down_world": [0.0, 0.0, -1.0],
                "sigma_rad": 0.03, **kw}
        with pytest.raises(ValueError, match=rf"^{field}:"):
            GravityMeasurement(**args)
    g = GravityMeasurement([0.0, 3.0, 0.0], [0.0, 0.0, -2.0], 0.03)
    np.testing.assert_allclose(g.down_camera, [0.0, 1.0, 0.0])
    np.testing.assert_allclose(g.down_world, [0.0, 0.0, -1.0])
    f = simulate_frame(CM, CAMERA, POSES[0], 0, SimulationConfig())
    ells = [CM.scene_map.object_by_id(o).ellipsoid for o in f.object_ids]
    with pytest.raises(ValueError, match=r"^gravity: must be a GravityMeasurement"):
        refine(f.detections, ells, CAMERA, POSES[0], gravity=[0.0, 1.0, 0.0])  # type: ignore


def test_refine_with_gravity_keeps_the_optimum_and_adds_only_tilt_information():
    """Exact detections and the exact gravity: the same optimum as without; the factor's
    information (``fixed_information``) is rank 2, in the rotation block, perpendicular to the
    vertical (yaw is not observed), and the covariance shrinks (never grows) by it."""
    T = POSES[50]
    f = simulate_frame(CM, CAMERA, T, 50, SimulationConfig.exact())
    ells = [CM.scene_map.object_by_id(o).ellipsoid for o in f.object_ids]
    start = T @ expmap_pose3(np.r_[0.03, -0.02, 0.04, 0.05, -0.04, 0.03])
    plain = refine(f.detections, ells, CAMERA, start)
    got = refine(f.detections, ells, CAMERA, start, gravity=_measurement(T))
    assert plain.fixed_information is None and plain.gravity_chi2 == 0.0
    np.testing.assert_allclose(got.world_from_camera, plain.world_from_camera, atol=1e-9)
    assert got.gravity_chi2 == pytest.approx(0.0, abs=1e-12)
    info = got.fixed_information
    np.testing.assert_allclose(info[3:], 0.0, atol=0)
    np.testing.assert_allclose(info[:, 3:], 0.0, atol=0)
    eig = np.linalg.eigvalsh(info[:3, :3])
    assert eig[0] == pytest.approx(0.0, abs=1e-6 * eig[-1])
    np.testing.assert_allclose(eig[1:], 1.0 / math.radians(2.0) ** 2, rtol=1e-6)
    up_camera = T[:3, :3].T @ UP
    np.testing.assert_allclose(info[:3, :3] @ up_camera, 0.0, atol=1e-6 * eig[-1])
    # the covariance is the inverse of the detections' information plus the factor's
    np.testing.assert_allclose(np.linalg.inv(got.covariance),
                               np.linalg.inv(plain.covariance) + info, rtol=1e-6,
                               atol=1e-6 * eig[-1])


@pytest.mark.parametrize(("metric", "robust"), [("bbox", "huber"), ("iou", None),
                                               ("wasserstein", None)])
def test_gravity_factor_with_other_metrics_and_kernels(metric, robust):
    """The factor joins any metric's graph (batched or per-detection robust factors): exact
    detections and gravity give the optimum found without it, and a covariance that includes
    the factor's information."""
    T = POSES[70]
    f = simulate_frame(CM, CAMERA, T, 70, SimulationConfig.exact())
    ells = [CM.scene_map.object_by_id(o).ellipsoid for o in f.object_ids]
    start = T @ expmap_pose3(np.r_[0.02, 0.01, -0.02, 0.03, 0.02, -0.02])
    plain = refine(f.detections, ells, CAMERA, start, metric, robust=robust)
    got = refine(f.detections, ells, CAMERA, start, metric, robust=robust,
                 gravity=_measurement(T))
    assert got.status == "converged" and got.covariance is not None
    np.testing.assert_allclose(got.world_from_camera, plain.world_from_camera, atol=1e-6)
    np.testing.assert_allclose(np.linalg.inv(got.covariance),
                               np.linalg.inv(plain.covariance) + got.fixed_information,
                               rtol=1e-4, atol=1e-4 * np.abs(got.fixed_information).max())


def test_consistent_gravity_barely_moves_the_answer_and_a_tilted_one_vetoes():
    """The true gravity leaves the answer within a millimetre of the answer without it, with
    a covariance no larger (the tilt directions tighter); a gravity 30 deg off makes it
    ``gravity_mismatch`` (the detections outweigh the factor), with the candidate in
    ``alternatives`` and the tilt in ``evidence``."""
    T = POSES[30]
    f = simulate_frame(CM, CAMERA, T, 30, SimulationConfig())
    plain = localize(f.detections, CM, CAMERA, OPTS)
    assert plain.localized
    with_g = localize(f.detections, CM, CAMERA, OPTS, gravity=_true_gravity(T))
    assert with_g.localized and with_g.reason is None
    assert np.linalg.norm(with_g.world_from_camera[:3, 3] - plain.world_from_camera[:3, 3]) \
        < 1e-3
    # no larger (up to the answers' slightly different s^2 and linearisation points)
    scale = np.linalg.eigvalsh(plain.covariance)[-1]
    assert np.all(np.linalg.eigvalsh(plain.covariance - with_g.covariance) > -1e-4 * scale)
    assert with_g.evidence["gravity"] == 1.0 and plain.evidence["gravity"] == 0.0
    assert with_g.evidence["tilt_error_deg"] < answer_gate_deg(_true_gravity(T))
    off = localize(f.detections, CM, CAMERA, OPTS, gravity=_true_gravity(_tilted(T, 30.0)))
    assert not off.localized and off.reason == "gravity_mismatch"
    assert off.world_from_camera is None and off.confidence == 0.0
    assert off.evidence["tilt_error_deg"] > answer_gate_deg(_true_gravity(T))
    assert np.linalg.norm(off.alternatives[0].world_from_camera[:3, 3]
                          - plain.world_from_camera[:3, 3]) < 0.05


def test_a_prior_answer_against_gravity_leaves_the_search_from_scratch_to_decide():
    """A prior whose refined answer disagrees with the measured gravity is not used (the search
    from scratch runs); with the true gravity the prior path is unchanged."""
    T = POSES[40]
    f = simulate_frame(CM, CAMERA, T, 40, SimulationConfig())
    prior = PosePrior(T, np.diag([math.radians(5.0) ** 2] * 3 + [0.1**2] * 3))
    good = localize(f.detections, CM, CAMERA, OPTS, prior, _true_gravity(T))
    assert good.localized and good.used_prior
    bad = localize(f.detections, CM, CAMERA, OPTS, prior, _true_gravity(_tilted(T, 30.0)))
    assert not bad.localized and bad.reason == "gravity_mismatch" and not bad.used_prior


def test_measured_gravity_resolves_two_detection_frames():
    """Frames reduced to 2 detections (seeds not used for tuning), simulated IMU gravity
    (1 deg, declared 2 deg), every verified pose returned: with gravity in the solve, fewer
    answers more than 0.5 m off and more within 10 cm (``bench.trust``: 2-detection frames
    within 10 cm 50 -> 68 of 216, > 0.5 m off 78 -> 15 on tuning seeds)."""
    good = {False: 0, True: 0}
    wrong = {False: 0, True: 0}
    for i in range(0, len(POSES), 4):
        f = simulate_frame(CM, CAMERA, POSES[i], 700_000 + i, SimulationConfig())
        dets = reduce_frame(f.detections, f.object_ids, 2, np.random.default_rng(i))
        if dets is None:
            continue
        g = Gravity(simulate_gravity(POSES[i], UP, 1.0, i), 2.0)
        opts = LocalizationOptions(time_budget_ms=None, on_ambiguity="best", min_confidence=0.0)
        for with_g in (False, True):
            r = localize(dets, CM, CAMERA, opts, gravity=g if with_g else None)
            pos, _ = pose_errors(r.world_from_camera if r.localized else None, POSES[i])
            good[with_g] += pos <= 0.1
            wrong[with_g] += r.localized and pos > 0.5
    assert good[True] > good[False]
    assert wrong[True] < wrong[False]
