"""Reconstruction of ellipsoids from multi-view ellipses (Rubino linear + GTSAM LM).

Views are synthesised by projecting the Chess map's own ellipsoids with the 108 real
ground-truth poses of tests/support/data/chess_test_poses.json (R, t camera_from_world, snapped
to rotations).
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from quadloc.factors.camera import Camera, Ellipsoid, project_ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.ellipsoid_factors import ellipsoid_views_factor
from quadloc.factors.ellipsoid_residuals import dual_quadric, stack_samples
from quadloc.factors.rotations import invert_pose, pose_matrix, snap_to_rotation
from quadloc.maps.demo import load_demo_map
from quadloc.maps.reconstruct import (
    FrameObservations,
    LabelledEllipse,
    ReconstructionError,
    build_scene_map,
    contour_samples,
    degenerate_shape_reason,
    dual_quadric_jacobians,
    ellipsoid_errors,
    reconstruct_ellipsoid,
    refine_ellipsoid,
    view_residuals,
)
from tests.support.helpers import level, surface_points
from tests.support.reference_data import load_chess_poses
from tests.support.scenes import visible_frames


@pytest.fixture(scope="module")
def chess_views() -> tuple[Camera, list[np.ndarray]]:
    cam, cfw, _ = load_chess_poses()
    return cam, cfw


def _spread(idx: list[int], k: int = 8) -> list[int]:
    return idx[:: max(1, len(idx) // k)][:k]


# --------------------------------------------------------------------------- Jacobians


def _random_state(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    R = snap_to_rotation(rng.normal(size=(3, 3)))
    return R, rng.normal(size=3) * 0.5, rng.uniform(0.1, 0.5, size=3)


def test_dual_quadric_jacobians_match_central_differences() -> None:
    R, c, axes = _random_state(1)
    J = dual_quadric_jacobians(R, c, axes)
    pose = gtsam.Pose3(gtsam.Rot3(R), c)
    h = 1e-6
    for k in range(9):
        d = np.zeros(9)
        d[k] = h

        def q(delta: np.ndarray) -> np.ndarray:
            p = pose.retract(delta[:6])
            return dual_quadric(p.rotation().matrix(), np.asarray(p.translation()),
                                 axes * np.exp(delta[6:]))

        numeric = (q(d) - q(-d)) / (2 * h)
        np.testing.assert_allclose(J[k], numeric, atol=1e-8, err_msg=f"parameter {k}")


def test_factor_jacobian_matches_numerical_derivative() -> None:
    cam = Camera(520.0, 515.0, 320.0, 240.0, 640, 480)
    R, c, axes = _random_state(2)
    cfw = pose_matrix(np.eye(3), -c + np.array([0.1, -0.2, 3.0]))  # ellipsoid ~3 m ahead
    P = cam.projection_matrix(cfw)
    observed = project_ellipsoid(cam, cfw, Ellipsoid(c + 0.05, axes * 1.1, R))
    pk, ak = gtsam.symbol("e", 0), gtsam.symbol("a", 0)
    # the reconstruction's factor: the shared one, samples in homogeneous pixels, the camera
    # given by its projection K [R|t] (one view, unit weight)
    padded = np.vstack([P, [0.0, 0.0, 0.0, 1.0]])[None]
    factor = ellipsoid_views_factor(stack_samples([contour_samples(observed, 7)]), np.ones(1),
                                    [(pk, ak)], [0], camera_from_world=padded)
    values = gtsam.Values()
    values.insert(pk, gtsam.Pose3(gtsam.Rot3(R), c))
    values.insert(ak, np.log(axes))
    A, b = factor.linearize(values).jacobian()
    assert A.shape == (7, 9)
    r0 = factor.unwhitenedError(values)
    np.testing.assert_allclose(-b, r0, rtol=1e-12)
    assert np.abs(r0).max() > 1e-3  # not at the optimum: a meaningful derivative
    # the rows are minus Phi_pred - 1 at the contour points, computed independently: the
    # predicted dual conic C* = P Q* P^T, Phi_pred(x) = 1 - C*[2,2] x~^T C*^-1 x~
    C = P @ dual_quadric(R, c, axes) @ P.T
    xh = np.column_stack([observed.contour_points(7), np.ones(7)])
    phi_pred = 1.0 - C[2, 2] * np.einsum("mi,ij,mj->m", xh, np.linalg.inv(C), xh)
    np.testing.assert_allclose(r0, -(phi_pred - 1.0), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(view_residuals(Ellipsoid(c, axes, R), [observed], P[None], 7)[0],
                               phi_pred - 1.0, rtol=1e-9, atol=1e-12)

    def residual(delta: np.ndarray) -> np.ndarray:
        v = gtsam.Values()
        v.insert(pk, values.atPose3(pk).retract(delta[:6]))
        v.insert(ak, values.atVector(ak) + delta[6:])
        return factor.unwhitenedError(v)

    h = 1e-6
    numeric = np.column_stack([(residual(h * e) - residual(-h * e)) / (2 * h) for e in np.eye(9)])
    np.testing.assert_allclose(A, numeric, rtol=1e-5, atol=1e-7 * np.abs(numeric).max())


# --------------------------------------------------------------------------- exact views


def test_exact_views_recover_every_chess_ellipsoid(chess_views) -> None:
    cam, cfw = chess_views
    for obj in load_demo_map().objects:
        E = obj.ellipsoid
        sel = _spread(visible_frames(cam, cfw, E))
        assert len(sel) >= 5, obj.object_id
        ellipses = [project_ellipsoid(cam, cfw[i], E) for i in sel]
        res = reconstruct_ellipsoid(ellipses, [invert_pose(cfw[i]) for i in sel], cam)
        err = ellipsoid_errors(res.ellipsoid, E)
        assert err["center_m"] < 1e-6, (obj.object_id, err)
        assert err["axes_m"] < 1e-6, (obj.object_id, err)
        assert err["orientation_deg"] < 1e-4, (obj.object_id, err)
        assert err["shape_rel"] < 1e-6, (obj.object_id, err)
        assert res.rms_level_residual < 1e-9
        # Independent check: sampled surface points project inside every observed ellipse,
        # and the silhouette touches it (max level ~ 1).
        X = surface_points(res.ellipsoid, 24, 12)
        for i, e in zip(sel[:3], ellipses[:3], strict=True):
            levels = level(e, cam.project_points(cfw[i], X))
            assert levels.max() <= 1 + 1e-6 and levels.max() > 0.95


def test_refinement_converges_from_a_perturbed_start(chess_views) -> None:
    cam, cfw = chess_views
    E = load_demo_map().objects[4].ellipsoid
    sel = _spread(visible_frames(cam, cfw, E))
    ellipses = [project_ellipsoid(cam, cfw[i], E) for i in sel]
    P = np.array([cam.projection_matrix(cfw[i]) for i in sel])
    rot = gtsam.Rot3.Expmap(np.array([0.1, -0.05, 0.08])).matrix()
    start = Ellipsoid(E.center + np.array([0.05, -0.04, 0.03]), E.axes * [1.2, 0.85, 1.1],
                      E.rotation @ rot)
    before = np.sqrt(np.mean(view_residuals(start, ellipses, P) ** 2))
    refined, iterations = refine_ellipsoid(start, ellipses, P)
    err = ellipsoid_errors(refined, E)
    assert before > 0.05 and iterations > 1
    assert err["center_m"] < 1e-7 and err["axes_m"] < 1e-7 and err["orientation_deg"] < 1e-5


def test_boxes_are_accepted_as_inscribed_ellipses(chess_views) -> None:
    cam, cfw = chess_views
    E = load_demo_map().objects[7].ellipsoid
    sel = _spread(visible_frames(cam, cfw, E))
    boxes = [project_ellipsoid(cam, cfw[i], E).bbox() for i in sel]
    wfc = [invert_pose(cfw[i]) for i in sel]
    from_boxes = reconstruct_ellipsoid(boxes, wfc, cam)
    from_ellipses = reconstruct_ellipsoid([Ellipse.from_bbox(*b) for b in boxes], wfc, cam)
    np.testing.assert_allclose(from_boxes.ellipsoid.center, from_ellipses.ellipsoid.center)
    # Boxes lose the orientation in the image: an approximation, but a close one here.
    assert ellipsoid_errors(from_boxes.ellipsoid, E)["center_m"] < 0.01


# --------------------------------------------------------------------------- degenerate views


def test_degenerate_view_sets_fail_clearly(chess_views) -> None:
    cam, cfw = chess_views
    E = load_demo_map().objects[4].ellipsoid
    sel = _spread(visible_frames(cam, cfw, E))
    ells = [project_ellipsoid(cam, cfw[i], E) for i in sel]
    wfc = [invert_pose(cfw[i]) for i in sel]
    with pytest.raises(ReconstructionError, match="at least 3") as exc:
        reconstruct_ellipsoid(ells[:2], wfc[:2], cam)
    assert exc.value.reason == "too_few_views"
    with pytest.raises(ReconstructionError) as exc:
        reconstruct_ellipsoid(ells[:3], wfc[:2], cam)
    assert exc.value.reason == "bad_input"
    # Three cameras 1 mm apart: the rays through the object are parallel to 0.1 degree.
    base = cfw[sel[0]]
    shifted = [base @ pose_matrix(np.eye(3), [dx, 0.0, 0.0]) for dx in (0.0, 1e-3, 2e-3)]
    near = [project_ellipsoid(cam, T, E) for T in shifted]
    with pytest.raises(ReconstructionError, match="nearly parallel") as exc:
        reconstruct_ellipsoid(near, [invert_pose(T) for T in shifted], cam)
    assert exc.value.reason == "near_parallel_rays"
    # Views of three different objects are not the views of one ellipsoid.
    objs = load_demo_map().objects
    mixed, mixed_poses = [], []
    for obj in (objs[2], objs[5], objs[8]):
        i = visible_frames(cam, cfw, obj.ellipsoid)[0]
        mixed.append(project_ellipsoid(cam, cfw[i], obj.ellipsoid))
        mixed_poses.append(invert_pose(cfw[i]))
    # Neither start yields an ellipsoid of the views (the linear quadric is not one; from the
    # sphere, LM shrinks it to a ~2 mm ellipsoid that reproduces none of the ellipses): refused,
    # naming both attempts.
    with pytest.raises(ReconstructionError, match=r"linear: .*sphere: .*misses") as exc:
        reconstruct_ellipsoid(mixed, mixed_poses, cam)
    assert exc.value.reason == "inconsistent_views"
    # ... and reported per object by build_scene_map (skip mode), the map keeps the others
    frames = [FrameObservations(T, cam, [LabelledEllipse("mix", "Chair", e)])
              for T, e in zip(mixed_poses, mixed, strict=True)]
    frames += [FrameObservations(wfc[k], cam, [LabelledEllipse("chair", "Chair", ells[k])])
               for k in range(len(ells))]
    scene, report = build_scene_map(frames, map_id="m", name="m", on_failure="skip")
    assert [o.object_id for o in scene.objects] == ["chair"]
    reason, message = report.failures["mix"]
    assert reason == "inconsistent_views" and "RMS level residual" in message


def test_degenerate_shapes_are_named() -> None:
    """A 1.7 mm-thin ellipsoid (inside the map's 1 mm limit) is no object's shape."""
    thin = Ellipsoid(np.zeros(3), np.array([0.25, 0.15, 0.0017]))
    assert "smallest below" in degenerate_shape_reason(thin)
    assert degenerate_shape_reason(Ellipsoid(np.zeros(3), np.array([0.25, 0.15, 0.003]))) is None
    assert "outside" in degenerate_shape_reason(Ellipsoid(np.zeros(3), np.full(3, 5e-4)))
    # the flattest Chess object passes
    for obj in load_demo_map().objects:
        assert degenerate_shape_reason(obj.ellipsoid) is None


# --------------------------------------------------------------------------- noisy views


def test_noisy_views_stay_close(chess_views) -> None:
    """Regression bound with 1.5 px centre, 2 % axes and 1.5 deg angle noise (fixed seed)."""
    cam, cfw = chess_views
    rng = np.random.default_rng(5)
    objects = load_demo_map().objects
    for obj in (objects[3], objects[6], objects[9]):
        E = obj.ellipsoid
        sel = _spread(visible_frames(cam, cfw, E), 10)
        noisy = []
        for i in sel:
            e = project_ellipsoid(cam, cfw[i], E)
            noisy.append(Ellipse(e.cx + rng.normal(0, 1.5), e.cy + rng.normal(0, 1.5),
                                 e.a * (1 + rng.normal(0, 0.02)), e.b * (1 + rng.normal(0, 0.02)),
                                 e.angle + np.radians(rng.normal(0, 1.5))))
        res = reconstruct_ellipsoid(noisy, [invert_pose(cfw[i]) for i in sel], cam)
        err = ellipsoid_errors(res.ellipsoid, E)
        assert err["center_m"] < 0.02, (obj.object_id, err)
        assert err["shape_rel"] < 0.5, (obj.object_id, err)
        if res.linear_ellipsoid is not None:  # LM never ends above its start
            assert res.rms_level_residual <= res.linear_rms_level_residual + 1e-12


# --------------------------------------------------------------------------- whole map


def test_build_scene_map_from_labelled_frames(chess_views) -> None:
    cam, cfw = chess_views
    demo = load_demo_map()
    frames = []
    objects = demo.objects[2:]  # the TVs are only seen within a 10 degree cone: left out
    visible = {o.object_id: set(visible_frames(cam, cfw, o.ellipsoid)) for o in objects}
    chosen = {o.object_id: set(_spread(sorted(visible[o.object_id]), 5)) for o in objects}
    for i in sorted(set().union(*chosen.values())):
        dets = [LabelledEllipse(o.object_id, o.category,
                                project_ellipsoid(cam, cfw[i], o.ellipsoid))
                for o in objects if i in chosen[o.object_id]]
        frames.append(FrameObservations(invert_pose(cfw[i]), cam, dets))
    # One object seen in only two frames and one wrongly labelled detection.
    T = [frames[0].world_from_camera, frames[1].world_from_camera]
    frames[0] = FrameObservations(T[0], cam, [*frames[0].detections,
                                              LabelledEllipse("ghost", "Chair",
                                                              box=(10, 10, 50, 60))])
    frames[1] = FrameObservations(T[1], cam, [*frames[1].detections,
                                              LabelledEllipse("ghost", "Chair",
                                                              box=(12, 10, 52, 60))])
    first = frames[2].detections[0]
    frames[2] = FrameObservations(frames[2].world_from_camera, cam,
                                  [LabelledEllipse(first.object_id,
                                                   "Timer" if first.label != "Timer" else "TV",
                                                   first.ellipse),
                                   *frames[2].detections[1:]])
    with pytest.raises(ReconstructionError, match="'ghost'"):
        build_scene_map(frames, map_id="rebuilt", name="Rebuilt", categories=demo.categories)
    scene, report = build_scene_map(frames, map_id="rebuilt", name="Rebuilt",
                                    categories=demo.categories, on_failure="skip")
    assert report.failures["ghost"][0] == "too_few_views"
    assert first.object_id in report.label_disagreements
    assert sorted(o.object_id for o in scene.objects) == sorted(o.object_id for o in objects)
    for obj in scene.objects:
        truth = demo.object_by_id(obj.object_id)
        assert obj.category == truth.category  # majority vote beats the one wrong label
        err = ellipsoid_errors(obj.ellipsoid, truth.ellipsoid)
        assert err["center_m"] < 1e-6 and err["shape_rel"] < 1e-6, (obj.object_id, err)
    assert scene.metadata["built_by"] == "quadloc.maps.reconstruct.build_scene_map"


def test_per_view_sigmas_downweight_a_bad_view(chess_views) -> None:
    cam, cfw = chess_views
    E = load_demo_map().objects[6].ellipsoid
    sel = _spread(visible_frames(cam, cfw, E), 6)
    ells = [project_ellipsoid(cam, cfw[i], E) for i in sel]
    bad = ells[2]
    ells[2] = Ellipse(bad.cx + 25.0, bad.cy - 15.0, bad.a * 1.3, bad.b, bad.angle + 0.3)
    wfc = [invert_pose(cfw[i]) for i in sel]
    plain = ellipsoid_errors(reconstruct_ellipsoid(ells, wfc, cam).ellipsoid, E)
    sigmas = [1.0] * len(sel)
    sigmas[2] = 1e3
    weighted = ellipsoid_errors(reconstruct_ellipsoid(ells, wfc, cam, sigmas=sigmas).ellipsoid, E)
    assert plain["center_m"] > 1e-3
    assert weighted["center_m"] < 0.1 * plain["center_m"]


def test_log_axes_prior_bounds_a_narrow_baseline(chess_views) -> None:
    cam, cfw = chess_views
    E = load_demo_map().objects[0].ellipsoid  # a TV: views within a 7 degree cone
    sel = _spread(visible_frames(cam, cfw, E), 10)
    wfc = [invert_pose(cfw[i]) for i in sel]
    rng = np.random.default_rng(11)
    exact = [project_ellipsoid(cam, cfw[i], E) for i in sel]
    res = reconstruct_ellipsoid(exact, wfc, cam)
    assert res.max_ray_angle_deg < 10
    assert ellipsoid_errors(res.ellipsoid, E)["center_m"] < 1e-6  # exact data: still exact
    noisy = [Ellipse(e.cx + rng.normal(0, 2), e.cy + rng.normal(0, 2),
                     e.a * (1 + rng.normal(0, 0.03)), e.b * (1 + rng.normal(0, 0.03)),
                     e.angle + np.radians(rng.normal(0, 2))) for e in exact]
    with_prior = reconstruct_ellipsoid(noisy, wfc, cam, log_axes_prior_sigma=0.5)
    err = ellipsoid_errors(with_prior.ellipsoid, E)
    assert err["center_m"] < 0.25 and err["shape_rel"] < 1.0, err
