"""Map building internals: association (geometric and by track id), joint refinement (recovers
the truth from exact views, size prior, unconstrained axes flagged, camera refinement with
between factors), the time budget."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from quadloc.factors.budget import Deadline
from quadloc.factors.camera import Ellipsoid, project_ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import invert_pose
from quadloc.maps.building.association import associate
from quadloc.maps.building.build import BuildTimeoutError, build_map
from quadloc.maps.building.joint import refine_jointly
from quadloc.maps.building.recording import Observation, OdometryNoise
from quadloc.maps.reconstruct import ellipsoid_errors
from quadloc.service.app.builds import recording_of as parse_recording
from quadloc.service.app.errors import AppError
from tests.service.api.test_api_build import CAM, OBJECTS, _look_at, _recording


def _rotz(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def test_geometric_association_is_exact_rejects_outliers_and_reports() -> None:
    rec_doc, truth = _recording(24)
    # a spurious detection in every 6th frame, and one wrong label
    for i in range(0, 24, 6):
        rec_doc["frames"][i]["detections"].append(
            {"label": "Box", "ellipse": {"cx": 600, "cy": 30, "a": 12, "b": 8, "angle": 0.3}})
        truth[i].append(None)
    rec_doc["frames"][5]["detections"][2]["label"] = "Box"  # a Lamp labelled Box
    truth[5][2] = "wrong"
    rec = parse_recording(rec_doc)
    T = np.array([f.world_from_camera for f in rec.frames])
    objects, rejected = associate(rec.observations, T, rec.camera)
    assert len(objects) == 3
    for h in objects:
        ids = {truth[rec.observations[k].frame][rec.observations[k].index]
               for k in h.observations}
        assert len(ids) == 1 and None not in ids and "wrong" not in ids
        assert len(h.observations) >= 23
    rejected_truth = {truth[rec.observations[k].frame][rec.observations[k].index]
                      for k in rejected}
    assert rejected_truth <= {None, "wrong"} and None in rejected_truth


def test_track_ids_are_used_when_given() -> None:
    rec_doc, truth = _recording(12)
    for f, ids in zip(rec_doc["frames"], truth, strict=True):
        for d, oid in zip(f["detections"], ids, strict=True):
            d["track_id"] = f"trk-{oid}"
    rec = parse_recording(rec_doc)
    objects, rejected = associate(rec.observations, np.array(
        [f.world_from_camera for f in rec.frames]), rec.camera)
    assert sorted(h.source for h in objects) == ["track:trk-a", "track:trk-b", "track:trk-c"]
    assert not rejected


def _views(ell: Ellipsoid, eyes: list[np.ndarray], target: np.ndarray):
    poses = [_look_at(e, target) for e in eyes]
    obs = [Observation(i, 0, "X", project_ellipsoid(CAM, invert_pose(T), ell))
           for i, T in enumerate(poses)]
    return np.array(poses), obs


def test_joint_refinement_recovers_exact_ellipsoids_from_a_perturbed_start() -> None:
    rng = np.random.default_rng(3)
    truths = [Ellipsoid(np.array([0.3, 0.0, 2.0]), np.array([0.2, 0.12, 0.08]), _rotz(30)),
              Ellipsoid(np.array([-0.3, 0.1, 2.2]), np.array([0.1, 0.15, 0.09]), _rotz(-20))]
    eyes = [np.array([2.0 * math.sin(a), 0.3 * math.cos(2 * a), 2.1 - 2.0 * math.cos(a)])
            for a in np.radians(np.linspace(-40, 40, 15))]
    poses = np.array([_look_at(e, np.array([0.0, 0.0, 2.1])) for e in eyes])
    obs, objects = [], []
    for k, ell in enumerate(truths):
        idx = []
        for i, T in enumerate(poses):
            idx.append(len(obs))
            obs.append(Observation(i, k, "X", project_ellipsoid(CAM, invert_pose(T), ell)))
        start = Ellipsoid(ell.center + rng.normal(0, 0.03, 3), ell.axes * 1.2,
                          ell.rotation @ _rotz(8))
        objects.append(("X", idx, start))
    res = refine_jointly(CAM, poses, obs, objects, max_iterations=50)
    for est, truth, q in zip(res.ellipsoids, truths, res.quality, strict=True):
        err = ellipsoid_errors(est, truth)
        assert err["center_m"] < 1e-5 and err["axes_m"] < 1e-5, err
        assert q.n_views == 15 and q.rms_level_residual < 1e-5 and not q.unconstrained_axes
        assert 60 < q.view_spread_deg < 90  # rays from cameras spread over +-40 deg
    # constrained axes get no prior: the default result is the unregularised one
    res2 = refine_jointly(CAM, poses, obs, objects, max_iterations=50,
                          unconstrained_prior_sigma=None)
    for a, b in zip(res.ellipsoids, res2.ellipsoids, strict=True):
        np.testing.assert_allclose(a.axes, b.axes, rtol=1e-9)


def test_narrow_cone_flags_the_depth_axis_and_a_size_prior_constrains_it() -> None:
    ell = Ellipsoid(np.array([0.0, 0.0, 3.0]), np.array([0.3, 0.2, 0.02]))  # flat, facing z
    eyes = [np.array([0.1 * math.sin(a), 0.1 * math.cos(a), 0.0])
            for a in np.linspace(0, 2 * math.pi, 9)[:-1]]  # a cone of ~4 degrees
    poses, obs = _views(ell, eyes, ell.center)
    start = Ellipsoid(ell.center, np.array([0.28, 0.21, 0.05]))
    res = refine_jointly(CAM, poses, obs, [("X", list(range(len(obs))), start)])
    q = res.quality[0]
    assert q.view_spread_deg < 5
    assert 2 in q.unconstrained_axes  # the smallest (depth) semi-axis
    assert 0 not in q.unconstrained_axes  # the visible extent is constrained
    from quadloc.maps.building.recording import SizePrior

    res2 = refine_jointly(CAM, poses, obs, [("X", list(range(len(obs))), start)],
                          size_priors={"X": SizePrior(0.02, 0.05)})
    # the prior pulls every log semi-axis to 2 cm: the unobserved one gets there
    assert abs(res2.ellipsoids[0].axes.min() - 0.02) < 0.01


def test_camera_refinement_moves_noisy_app_poses_towards_the_truth() -> None:
    """Exact detections seen from the true poses; app poses = truth with independent noise
    (0.3 deg, 5 mm) on every frame but the first. Object-level bundle adjustment (between
    factors from the noisy app poses) brings cameras and objects closer to the truth."""
    from quadloc.factors.pose_residuals import expmap_pose3

    rec_doc, _ = _recording(16)
    for f in rec_doc["frames"]:
        for d in f["detections"]:
            d["sigma"] = 1e-4  # exact detections: a level-set std of 0.01
    rec = parse_recording(rec_doc)
    rng = np.random.default_rng(7)
    truth = [f.world_from_camera for f in rec.frames]
    noisy = [truth[0]] + [T @ expmap_pose3(np.r_[rng.normal(0, math.radians(0.3), 3),
                                                 rng.normal(0, 0.005, 3)]) for T in truth[1:]]
    rec_noisy = replace(rec, frames=tuple(replace(f, world_from_camera=T)
                                          for f, T in zip(rec.frames, noisy, strict=True)))
    objects, _ = associate(rec_noisy.observations, np.array(noisy), CAM)
    init = [(h.label, h.observations, h.ellipsoid) for h in objects]
    fixed = refine_jointly(CAM, np.array(noisy), rec_noisy.observations, init)
    ba = refine_jointly(CAM, np.array(noisy), rec_noisy.observations, init, refine_cameras=True,
                        odometry=OdometryNoise(0.0, 0.0, math.radians(0.5), 0.01))

    def cam_err(poses: np.ndarray) -> float:
        return float(np.mean([np.linalg.norm(P[:3, 3] - T[:3, 3])
                              for P, T in zip(poses, truth, strict=True)]))

    def obj_err(ells: list[Ellipsoid]) -> float:
        return float(np.mean([min(np.linalg.norm(e.center - t.center)
                                  for _, t in OBJECTS.values()) for e in ells]))

    assert cam_err(ba.world_from_camera) < 0.5 * cam_err(np.array(noisy))
    assert obj_err(ba.ellipsoids) < obj_err(fixed.ellipsoids)
    assert ba.final_error < fixed.final_error


def test_time_budget_fails_the_build() -> None:
    rec = parse_recording(_recording(8)[0])
    with pytest.raises(BuildTimeoutError):
        build_map(rec, map_id="x", deadline=Deadline.wall_budget(-1.0))


def test_box_detections_are_accepted() -> None:
    rec_doc, _ = _recording(6)
    d = rec_doc["frames"][0]["detections"][0]
    e = Ellipse(**d.pop("ellipse"))
    x0, y0, x1, y1 = e.bbox()
    d["box"] = {"xmin": x0, "ymin": y0, "xmax": x1, "ymax": y1}
    rec = parse_recording(rec_doc)
    assert rec.observations[0].ellipse.angle == 0.0
    assert math.isclose(rec.observations[0].ellipse.a, (x1 - x0) / 2)


def test_axis_floor_is_one_sided_with_the_right_jacobian() -> None:
    import gtsam

    from quadloc.maps.building.joint import _floor_factor

    key = gtsam.symbol("l", 0)
    f = _floor_factor(key, math.log(0.01), 0.1)
    v = gtsam.Values()
    v.insert(key, np.log(np.array([0.2, 0.05, 0.002])))  # only the last axis is below 1 cm
    r = f.unwhitenedError(v)
    np.testing.assert_allclose(r, [0.0, 0.0, math.log(0.01) - math.log(0.002)], rtol=1e-12)
    A, _ = f.linearize(v).jacobian()
    h = 1e-6
    numeric = []
    for e in np.eye(3):
        vp, vm = gtsam.Values(), gtsam.Values()
        vp.insert(key, v.atVector(key) + h * e)
        vm.insert(key, v.atVector(key) - h * e)
        numeric.append((f.unwhitenedError(vp) - f.unwhitenedError(vm)) / (2 * h) / 0.1)
    np.testing.assert_allclose(A, np.column_stack(numeric), atol=1e-6)
    above = gtsam.Values()
    above.insert(key, np.log(np.array([0.2, 0.05, 0.02])))
    assert f.error(above) == 0.0


def test_odometry_noise_is_parsed_validated_and_a_random_walk() -> None:
    doc, _ = _recording(4)
    rec = parse_recording(doc)
    assert rec.refine_camera_poses is True and rec.odometry_noise == OdometryNoise()
    rec = parse_recording({**doc, "odometry_noise": {"translation_m_per_sqrt_m": 0.03}})
    assert rec.odometry_noise.translation_m_per_sqrt_m == 0.03
    assert rec.odometry_noise.rotation_rad_per_sqrt_m == OdometryNoise().rotation_rad_per_sqrt_m
    with pytest.raises(AppError) as exc:
        parse_recording({**doc, "odometry_noise": {"translation_m_per_sqrt_m": -1, "bogus": 1,
                                                   "rotation_rad_per_step": "x"}})
    fields = {e["field"] for e in exc.value.errors}
    assert fields == {"odometry_noise.translation_m_per_sqrt_m", "odometry_noise.bogus",
                      "odometry_noise.rotation_rad_per_step"}
    with pytest.raises(AppError) as exc:
        parse_recording({**doc, "odometry_noise": {"translation_m_per_step": 0}})
    assert exc.value.errors[0]["field"] == "odometry_noise.translation_m_per_step"
    # variances add over path length and steps: two halves compose to the whole
    n = OdometryNoise(0.01, 0.02, 0.003, 0.004)
    whole = n.sigmas(2.0, 6)
    half = n.sigmas(1.0, 3)
    np.testing.assert_allclose(whole**2, 2 * half**2, rtol=1e-12)
    np.testing.assert_allclose(whole[:3], math.sqrt(0.01**2 * 2 + 0.003**2 * 6), rtol=1e-12)
    np.testing.assert_allclose(whole[3:], math.sqrt(0.02**2 * 2 + 0.004**2 * 6), rtol=1e-12)


def test_joint_refinement_survives_a_trial_step_that_collapses_an_object() -> None:
    # Detections 10x smaller than the start's projections: LM trial steps shrink the log
    # semi-axes by hundreds while the object stays in front of the cameras, and the projected
    # conic is singular in floating point (a LinAlgError before views of a degenerate ellipsoid
    # were invalid). The step is rejected (the factor's penalty) and the refinement finds an
    # object about 10x smaller (the detections' ellipses are the start's scaled about their
    # centres, not exactly the projections of one ellipsoid: mm-level errors; the start is
    # 8 cm off in semi-axes).
    start = Ellipsoid(np.array([0.0, 0.0, 2.0]), np.array([0.15, 0.1, 0.08]))
    eyes = [np.array([2.0 * math.sin(a), 0.0, 2.0 - 2.0 * math.cos(a)])
            for a in np.radians(np.linspace(-40, 40, 15))]
    poses = np.array([_look_at(e, start.center) for e in eyes])
    obs = []
    for i, T in enumerate(poses):
        p = project_ellipsoid(CAM, invert_pose(T), start)
        obs.append(Observation(i, 0, "X", Ellipse(p.cx, p.cy, 0.1 * p.a, 0.1 * p.b, p.angle)))
    res = refine_jointly(CAM, poses, obs, [("X", list(range(len(obs))), start)])
    small = Ellipsoid(start.center, 0.1 * start.axes, start.rotation)
    err = ellipsoid_errors(res.ellipsoids[0], small)
    assert err["center_m"] < 0.01 and err["axes_m"] < 0.005, err
