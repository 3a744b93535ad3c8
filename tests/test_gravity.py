"""A client's gravity direction as a veto of tilted answers (``service.localization.gravity``,
``Gravity``, ``bench.simulate.simulate_gravity``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.chess_eval import load_chess_map, load_chess_world_from_camera, pose_errors
from bench.simulate import SimulationConfig, simulate_frame, simulate_gravity
from bench.trust import reduce_frame
from factors.geometry import invert_pose
from factors.pose_residuals import expmap_pose3
from maps.compiled import compile_map
from service.localization.confidence import TOLERANCE_ROTATION_DEG
from service.localization.gravity import GRAVITY_GATE_SIGMAS, answer_gate_deg, tilt_errors_deg
from service.localization.pipeline import localize
from service.localization.types import (
    Gravity,
    LocalizationInputError,
    LocalizationOptions,
    PosePrior,
)

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


def test_consistent_gravity_changes_nothing_and_a_tilted_one_vetoes():
    """The true gravity leaves the answer exactly as without; a gravity 30 deg off makes it
    ``gravity_mismatch``, with the candidate (same pose, same probability) in
    ``alternatives`` and the tilt in ``evidence``."""
    T = POSES[30]
    f = simulate_frame(CM, CAMERA, T, 30, SimulationConfig())
    plain = localize(f.detections, CM, CAMERA, OPTS)
    assert plain.localized
    with_g = localize(f.detections, CM, CAMERA, OPTS, gravity=_true_gravity(T))
    assert with_g.localized and with_g.reason is None
    np.testing.assert_allclose(with_g.world_from_camera, plain.world_from_camera, atol=1e-12)
    assert with_g.confidence == plain.confidence
    assert with_g.evidence["tilt_error_deg"] < answer_gate_deg(_true_gravity(T))
    off = localize(f.detections, CM, CAMERA, OPTS, gravity=_true_gravity(_tilted(T, 30.0)))
    assert not off.localized and off.reason == "gravity_mismatch"
    assert off.world_from_camera is None and off.confidence == 0.0
    # 30 deg from the true down, so the answer's tilt is 30 deg +- its own (triangle inequality)
    assert abs(off.evidence["tilt_error_deg"] - 30.0) <= with_g.evidence["tilt_error_deg"] + 1e-6
    np.testing.assert_allclose(off.alternatives[0].world_from_camera, plain.world_from_camera)
    assert off.alternatives[0].confidence == pytest.approx(plain.confidence, abs=1e-12)


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


def test_measured_gravity_never_adds_a_wrong_answer():
    """Frames reduced to 2 detections, simulated IMU gravity (1 deg, declared 2 deg): gravity
    only removes answers, and never one within 10 cm and 5 deg."""
    vetoed = 0
    for i in range(0, len(POSES), 4):
        f = simulate_frame(CM, CAMERA, POSES[i], 700_000 + i, SimulationConfig())
        dets = reduce_frame(f.detections, f.object_ids, 2, np.random.default_rng(i))
        if dets is None:
            continue
        g = Gravity(simulate_gravity(POSES[i], UP, 1.0, i), 2.0)
        opts = LocalizationOptions(time_budget_ms=None, on_ambiguity="best", min_confidence=0.0)
        a = localize(dets, CM, CAMERA, opts)
        b = localize(dets, CM, CAMERA, opts, gravity=g)
        assert b.localized <= a.localized
        if a.localized and not b.localized:
            vetoed += 1
            assert b.reason == "gravity_mismatch"
            pos, rot = pose_errors(a.world_from_camera, POSES[i])
            assert not (pos <= 0.1 and rot <= 5.0), (i, pos, rot)
    assert vetoed >= 1
