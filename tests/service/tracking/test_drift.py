"""The systematic part of the odometry drift model (docs/tracking.md, "Odometry drift model"):
``DriftModel.systematic_covariance`` against a hand computation and against sampling the
error model it states (a scale error and a gyro bias, constant over the stretch); in a session,
the answered covariance is the smoother's marginal plus that term since the last
detection-constrained frame, the poses do not change, and the confidence follows."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadloc.factors.rotations import so3_exp
from quadloc.service.localization.confidence import gaussian_tolerance_probability
from quadloc.service.tracking.session import (
    CONSTRAINING_OBJECTS,
    DriftModel,
    SessionOptions,
    TrackingSession,
)
from tests.support.walks import HZ, ChessWalk, chess_walk


def test_systematic_covariance_of_a_straight_walk_by_hand() -> None:
    """10 s at 1 m/s along the camera's x axis (camera = odometry axes): ``D = (10, 0, 0)`` m,
    ``W = integral of t v dt = (50, 0, 0)`` m s. By hand, with ``s`` = 1.5 %, ``b`` = 0.03
    deg/s: rotation variance ``(b 10)^2`` per axis; position variances ``(0.15 m)^2`` along x
    (scale) and ``(50 b)^2`` = (2.62 cm)^2 across (the heading error turns the path);
    ``Cov(theta_y, e_z) = -b^2 10 * 50``, ``Cov(theta_z, e_y) = +b^2 10 * 50``. Tolerance
    1e-15 absolute (closed forms)."""
    drift = DriftModel()
    assert drift.scale_error == 0.015 and drift.gyro_bias_rad_per_s == math.radians(0.03)
    b = math.radians(0.03)
    cov = drift.systematic_covariance(np.eye(4), np.array([10.0, 0, 0]), 10.0,
                                      np.array([50.0, 0, 0]))
    expected = np.zeros((6, 6))
    expected[0, 0] = expected[1, 1] = expected[2, 2] = (10 * b) ** 2
    expected[3, 3] = 0.15 ** 2
    expected[4, 4] = expected[5, 5] = (50 * b) ** 2
    expected[1, 5] = expected[5, 1] = -b * b * 10 * 50
    expected[2, 4] = expected[4, 2] = b * b * 10 * 50
    np.testing.assert_allclose(cov, expected, rtol=0, atol=1e-15)
    assert math.sqrt(cov[4, 4]) == pytest.approx(0.02618, abs=1e-5)
    # turned camera: the same covariance in its own (body) axes, R^T C R per block
    R = so3_exp(np.array([0.3, -1.1, 0.7]))
    T = np.eye(4)
    T[:3, :3] = R
    turned = drift.systematic_covariance(T, np.array([10.0, 0, 0]), 10.0, np.array([50.0, 0, 0]))
    big = np.kron(np.eye(2), R)
    np.testing.assert_allclose(big @ turned @ big.T, expected, rtol=0, atol=1e-15)
    # nothing accumulated, nothing added
    assert not np.any(drift.systematic_covariance(T, np.zeros(3), 0.0, np.zeros(3)))


def test_systematic_covariance_matches_sampling_the_error_model() -> None:
    """A curved 8-s walk with a turning camera; 20,000 draws of the scale error ``s`` ~ N(0,
    1.5 %) and the gyro bias ``b`` ~ N(0, (0.03 deg/s)^2 I): the odometry's pose is built step
    by step (each step's displacement scaled by ``1 + s`` and turned by the accumulated
    rotation error ``exp(b t)``, the orientation turned by it too) and its body-frame error
    ``[log(R^T R_odo), R^T (p_odo - p)]`` sampled. The closed form's entries agree within 4 % of
    the largest variance of their block (sampling: sqrt(2 / 20000) = 1 %)."""
    drift = DriftModel()
    rng = np.random.default_rng(5)
    n_steps = int(8 * HZ)
    t = np.arange(n_steps + 1) / HZ
    p = np.stack([1.2 * t, 2.0 * np.sin(0.4 * t), 0.1 * t], axis=1)
    rotations = so3_exp(np.stack([0.05 * t, 0.3 * t, -0.02 * t], axis=1))
    dp = np.diff(p, axis=0)
    moment = ((t[1:] - t[0])[:, None] * dp).sum(axis=0)
    R_end = rotations[-1]
    T_end = np.eye(4)
    T_end[:3, :3], T_end[:3, 3] = R_end, p[-1]
    cov = drift.systematic_covariance(T_end, p[-1] - p[0], t[-1] - t[0], moment)
    n = 20_000
    s = rng.normal(0.0, drift.scale_error, n)
    bias = rng.normal(0.0, drift.gyro_bias_rad_per_s, (n, 3))
    # p_odo(end) - p(end) = sum_i ((1 + s) exp(b t_i) - I) dp_i, exp(b t_i) to the exact map
    err_p = np.zeros((n, 3))
    for i in range(n_steps):
        E = so3_exp(bias * t[i + 1])  # (n, 3, 3)
        err_p += (1.0 + s)[:, None] * (E @ dp[i]) - dp[i]
    err_rot = bias * t[-1]  # log(exp(b T)) in odometry axes
    sample = np.concatenate([err_rot @ R_end, err_p @ R_end], axis=1)  # rows R^T x
    emp = np.cov(sample.T)
    for blk_a, blk_b in ((slice(0, 3), slice(0, 3)), (slice(3, 6), slice(3, 6)),
                         (slice(0, 3), slice(3, 6))):
        scale = math.sqrt(np.max(np.diag(cov)[blk_a]) * np.max(np.diag(cov)[blk_b]))
        np.testing.assert_allclose(emp[blk_a, blk_b], cov[blk_a, blk_b], rtol=0,
                                   atol=0.04 * scale)


@pytest.fixture(scope="module")
def blind_walk() -> ChessWalk:
    """40 Chess frames; from frame 25 on the detections are dropped (a stretch without
    objects)."""
    return chess_walk(40, seed=30, keep=lambda i, dets: dets if i < 25 else [])


def test_session_answers_the_marginal_plus_the_systematic_drift(blind_walk: ChessWalk) -> None:
    """The same frames with the term off (scale error and gyro bias 0: the smoother's
    marginal alone) and on (the defaults): identical states and poses; on frames after the
    anchor (the commit, or the last frame with an inlier whose window's frames cover >= 2
    objects), the covariances differ by ``systematic_covariance`` computed here from the
    odometry inputs (D, T and W summed by hand; 1e-9 absolute); the confidence is the committed
    place's posterior times the tolerance probability of the answered covariance (1e-9); the
    position variance has grown by the end of the stretch."""
    frames = blind_walk.frames
    drift = DriftModel()

    def run(d: DriftModel) -> list:
        s = TrackingSession(blind_walk.compiled, blind_walk.camera, SessionOptions(drift=d))
        return [s.add_frame(f) for f in frames]

    off = run(DriftModel(scale_error=0.0, gyro_bias_rad_per_s=0.0))
    on = run(drift)
    anchor = None
    recent: list[set[str]] = []  # inlier objects of the window's frames since the commit
    checked = 0
    for k, (a, b) in enumerate(zip(off, on, strict=True)):
        assert (a.state, a.reason) == (b.state, b.reason)
        if a.world_from_camera is None or a.state != "tracking":
            assert b.world_from_camera is None if a.world_from_camera is None else True
            anchor = None
            continue
        assert np.array_equal(a.world_from_camera, b.world_from_camera)
        objects = {m.object_id for m in a.inliers}
        if anchor is None:  # the commit frame anchors
            anchor, recent = k, []
        else:
            recent = [*recent, objects][-SessionOptions().window_frames:]
            if objects and len(set().union(*recent)) >= CONSTRAINING_OBJECTS:
                anchor = k
        p = [frames[j].odom_from_camera[:3, 3] for j in range(anchor, k + 1)]
        ts = [frames[j].timestamp for j in range(anchor, k + 1)]
        W = sum(((ts[j] - ts[0]) * (p[j] - p[j - 1]) for j in range(1, len(p))), np.zeros(3))
        expected = drift.systematic_covariance(frames[k].odom_from_camera, p[-1] - p[0],
                                               ts[-1] - ts[0], W)
        np.testing.assert_allclose(b.covariance - a.covariance, expected, rtol=0, atol=1e-9)
        place = next(c.probability for c in b.candidates
                     if np.array_equal(c.world_from_camera, b.world_from_camera))
        assert b.confidence == pytest.approx(
            place * gaussian_tolerance_probability(b.covariance), abs=1e-9)
        checked += 1
    assert checked >= 30
    # 0.5 s without objects: the term has grown (a few mm; the confidence, already ~1, does
    # not go up)
    assert off[-1].state == "tracking" and on[-1].confidence <= off[-1].confidence
    assert np.trace(on[-1].covariance[3:, 3:]) > np.trace(off[-1].covariance[3:, 3:]) + 1e-7
