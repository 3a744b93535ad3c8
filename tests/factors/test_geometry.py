"""Geometry core: conic / dual conic / Gaussian round trips, projections checked against
independent computations (the tangent cone of a sphere, sampled ellipsoid surfaces), degenerate
projections and validation messages."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadloc.factors.camera import (
    BORDER_MARGIN_PX,
    Camera,
    Ellipsoid,
    border_touching,
    project_ellipsoid,
    touches_border,
)
from quadloc.factors.conics import (
    DegenerateProjectionError,
    Ellipse,
    dual_conics_from_params,
    ellipse_params,
    level_values,
    params_from_dual_conics,
)
from quadloc.factors.names import GeometryError
from quadloc.factors.rotations import (
    invert_pose,
    pose_matrix,
    quaternion_wxyz_from_rotation,
    rotation_from_quaternion_wxyz,
    snap_to_rotation,
)
from tests.support.helpers import ellipse_from_primal_conic, level, primal_conic, transformed
from tests.support.reference_data import load_chess_poses, load_chess_scene_json

ellipses = st.builds(
    Ellipse,
    cx=st.floats(-500, 1500), cy=st.floats(-500, 1500),
    a=st.floats(1.0, 300.0), b=st.floats(1.0, 300.0),
    angle=st.floats(-2 * math.pi, 2 * math.pi),
)


def same_ellipse(e1: Ellipse, e2: Ellipse, tol: float = 1e-7) -> bool:
    """Same point set: compare the normalised dual conics (independent of a/b/angle labels)."""
    scale = max(1.0, e1.cx**2 + e1.cy**2 + e1.a**2 + e1.b**2)
    return bool(np.allclose(e1.dual_conic(), e2.dual_conic(), atol=tol * scale, rtol=0))


# --------------------------------------------------------------------------- conics


@settings(max_examples=60, deadline=None)
@given(ellipses, st.floats(0.01, 100.0), st.sampled_from([-1.0, 1.0]))
def test_primal_conic_round_trip_any_scale_and_sign(e: Ellipse, scale: float, sign: float):
    C = primal_conic(e)
    back = ellipse_from_primal_conic(sign * scale * C)
    assert same_ellipse(e, back)
    assert back.a >= back.b and -math.pi / 2 <= back.angle < math.pi / 2  # canonical output


@settings(max_examples=60, deadline=None)
@given(ellipses, st.floats(0.01, 100.0))
def test_dual_conic_is_inverse_of_primal_and_normalised(e: Ellipse, scale: float):
    Cd = e.dual_conic()
    assert Cd[2, 2] == -1.0
    inv = np.linalg.inv(primal_conic(e))
    np.testing.assert_allclose(Cd, inv / -inv[2, 2], rtol=1e-7, atol=1e-7 * np.abs(Cd).max())
    assert same_ellipse(Ellipse.from_dual_conic(scale * Cd), e)


@settings(max_examples=60, deadline=None)
@given(ellipses)
def test_gaussian_round_trip_and_covariance_axes(e: Ellipse):
    mu, S = e.gaussian()
    np.testing.assert_allclose(mu, [e.cx, e.cy])
    # Independent: the eigenvalues of Sigma are a^2, b^2 and Sigma = A^-1.
    np.testing.assert_allclose(np.sort(np.linalg.eigvalsh(S)), np.sort([e.a**2, e.b**2]),
                               rtol=1e-9)
    np.testing.assert_allclose(S @ e.shape_matrix(), np.eye(2), atol=1e-9)
    assert same_ellipse(Ellipse.from_gaussian(mu, S), e)


@settings(max_examples=40, deadline=None)
@given(ellipses)
def test_contour_level_and_bbox_against_dense_contour(e: Ellipse):
    pts = e.contour_points(4096)
    np.testing.assert_allclose(level(e, pts), 1.0, rtol=1e-9)
    assert abs(level(e, e.center)) < 1e-12
    box = e.bbox()
    dense = np.array([pts[:, 0].min(), pts[:, 1].min(), pts[:, 0].max(), pts[:, 1].max()])
    # The dense contour is inside the box and reaches it to within the sampling step.
    assert np.all(dense[:2] >= box[:2] - 1e-9) and np.all(dense[2:] <= box[2:] + 1e-9)
    step = 2 * math.pi / 4096 * max(e.a, e.b)
    np.testing.assert_allclose(dense, box, atol=step**2 / max(e.b, 1e-9) + 1e-9)


def test_border_rule_against_the_dense_contour():
    """``border_touching`` (batched) and ``touches_border`` (one ellipse) against the extent of
    4096 contour points: an ellipse touches when its contour comes within BORDER_MARGIN_PX of
    an image side (cases within 0.05 px of the threshold, below the contour's sampling error
    of ~1e-3 px here, are skipped)."""
    cam = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)
    rng = np.random.default_rng(3)
    P = np.column_stack([rng.uniform(-60, 700, 4000), rng.uniform(-60, 540, 4000),
                         rng.uniform(1, 150, 4000), rng.uniform(1, 150, 4000),
                         rng.uniform(-4, 4, 4000)])
    got = border_touching(P, cam)
    checked = 0
    for p, flag in zip(P, got, strict=True):
        e = Ellipse(*p)
        pts = e.contour_points(4096)
        gap = min(pts[:, 0].min(), pts[:, 1].min(), cam.width - pts[:, 0].max(),
                  cam.height - pts[:, 1].max()) - BORDER_MARGIN_PX
        if abs(gap) < 0.05:
            continue
        assert flag == (gap < 0.0) == touches_border(e, cam), (p, gap)
        checked += 1
    assert checked > 3900 and 0.2 < got.mean() < 0.8


@settings(max_examples=40, deadline=None)
@given(ellipses, st.floats(-4, 4), st.floats(-100, 100), st.floats(-100, 100))
def test_transformed_moves_points_rigidly(e: Ellipse, ang: float, tx: float, ty: float):
    moved = transformed(e, ang, (tx, ty))
    R = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    pts = e.contour_points(16) @ R.T + [tx, ty]
    np.testing.assert_allclose(level(moved, pts), 1.0, rtol=1e-7)


def test_canonical_keeps_the_point_set():
    e = Ellipse(10.0, -3.0, 5.0, 9.0, 2.5)
    c = e.canonical()
    assert c.a == 9.0 and c.b == 5.0 and -math.pi / 2 <= c.angle < math.pi / 2
    assert same_ellipse(e, c)


def test_batched_helpers_match_single_ellipse_methods():
    rng = np.random.default_rng(4)
    es = [Ellipse(*rng.uniform(-50, 50, 2), *rng.uniform(1, 30, 2), rng.uniform(-3, 3))
          for _ in range(7)]
    P = ellipse_params(es)
    duals = dual_conics_from_params(P)
    for e, D in zip(es, duals, strict=True):
        np.testing.assert_allclose(D, e.dual_conic(), atol=1e-9)
    back = params_from_dual_conics(duals * rng.uniform(0.1, 10.0, (7, 1, 1)))
    for e, p in zip(es, back, strict=True):
        assert same_ellipse(e, Ellipse(*p))
    pts = rng.uniform(-60, 60, (7, 5, 2))
    lv = level_values(P, pts)
    for j, e in enumerate(es):
        np.testing.assert_allclose(lv[j], level(e, pts[j]), rtol=1e-12)


def test_non_ellipse_dual_conics_raise():
    hyperbola = np.diag([1.0, -1.0, -1.0])  # x^2 - y^2 = 1 (its own dual up to sign)
    with pytest.raises(DegenerateProjectionError) as exc:
        Ellipse.from_dual_conic(np.linalg.inv(hyperbola))
    assert exc.value.reason == "degenerate_conic"
    parabola_dual = np.array([[1.0, 0, 0], [0, 1.0, 0.5], [0, 0.5, 0.0]])
    with pytest.raises(DegenerateProjectionError):
        Ellipse.from_dual_conic(parabola_dual)


# --------------------------------------------------------------------------- rotations


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1))
def test_quaternion_round_trip(q):
    q = np.asarray(q) / np.linalg.norm(q)
    R = rotation_from_quaternion_wxyz(q)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(R) - 1.0) < 1e-12
    back = quaternion_wxyz_from_rotation(R)
    assert back[0] >= 0.0
    assert min(np.abs(back - q).max(), np.abs(back + q).max()) < 1e-9  # q and -q: same R
    np.testing.assert_allclose(rotation_from_quaternion_wxyz(back), R, atol=1e-9)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_half_turn_quaternion_sign_is_unique(axis):
    q = np.zeros(4)
    q[1 + axis] = -1.0  # w = 0: q and -q are the same half-turn
    back = quaternion_wxyz_from_rotation(rotation_from_quaternion_wxyz(q))
    np.testing.assert_allclose(back, -q, atol=1e-12)


def test_snap_and_invert_pose():
    rng = np.random.default_rng(0)
    q = np.array([0.9, 0.1, -0.3, 0.3])
    R = rotation_from_quaternion_wxyz(q / np.linalg.norm(q))
    noisy = R + 1e-4 * rng.normal(size=(3, 3))
    S = snap_to_rotation(noisy)
    np.testing.assert_allclose(S @ S.T, np.eye(3), atol=1e-12)
    assert np.abs(S - R).max() < 1e-3
    T = pose_matrix(R, [1.0, -2.0, 3.0])
    np.testing.assert_allclose(invert_pose(T) @ T, np.eye(4), atol=1e-12)


# --------------------------------------------------------------------------- projection

CAM = Camera(520.0, 530.0, 320.0, 240.0, 640, 480)


def sphere_image_conic(camera: Camera, center_cam: np.ndarray, radius: float) -> np.ndarray:
    """Point conic (pixels) of a sphere's outline, from its tangent cone (independent formula).

    A ray ``d`` touches the sphere when the angle between ``d`` and the centre ``X`` is
    ``asin(r / |X|)``: ``(d . X)^2 = |d|^2 (|X|^2 - r^2)``, i.e. ``d^T (X X^T - (|X|^2 - r^2) I) d
    = 0``; with ``d = K^-1 x~`` the conic in pixels is ``K^-T (...) K^-1``.
    """
    X = np.asarray(center_cam, dtype=float)
    C = np.outer(X, X) - (X @ X - radius**2) * np.eye(3)
    Kinv = np.linalg.inv(camera.K)
    return -(Kinv.T @ C @ Kinv)  # sign: negative inside


def test_sphere_on_the_optical_axis_projects_to_the_closed_form_circle():
    r, z = 0.5, 3.0
    e = project_ellipsoid(Camera(500.0, 500.0, 320.0, 240.0, 640, 480), np.eye(4),
                          Ellipsoid(np.array([0.0, 0.0, z]), np.array([r, r, r])))
    expected = 500.0 * r / math.sqrt(z * z - r * r)
    assert abs(e.cx - 320.0) < 1e-9 and abs(e.cy - 240.0) < 1e-9
    assert abs(e.a - expected) < 1e-9 and abs(e.b - expected) < 1e-9


@settings(max_examples=40, deadline=None)
@given(st.floats(-1.5, 1.5), st.floats(-1.0, 1.0), st.floats(2.5, 8.0), st.floats(0.1, 0.8),
       st.floats(-3, 3), st.floats(-1, 1), st.floats(-1, 1))
def test_sphere_projection_matches_its_tangent_cone(x, y, z, r, yaw, tx, ty):
    # World sphere seen by a camera with a rotated, translated pose (camera_from_world).
    R = rotation_from_quaternion_wxyz(np.array([math.cos(yaw / 2), 0.0, math.sin(yaw / 2), 0.0]))
    camera_from_world = pose_matrix(R, [tx, ty, 0.0])
    center_cam = np.array([x, y, z])
    center_world = R.T @ (center_cam - np.array([tx, ty, 0.0]))
    e = project_ellipsoid(CAM, camera_from_world, Ellipsoid(center_world, np.array([r, r, r])))
    expected = ellipse_from_primal_conic(sphere_image_conic(CAM, center_cam, r))
    assert same_ellipse(e, expected, tol=1e-8)


def _chess():
    """(ellipsoids, camera, camera_from_world 4x4 list) of the real Chess data."""
    scene = load_chess_scene_json()
    ells = [Ellipsoid(np.array(o["ellipsoid"]["center"]), np.array(o["ellipsoid"]["axes"]),
                      np.array(o["ellipsoid"]["R"])) for o in scene["objects"]]
    cam, camera_from_world, _ = load_chess_poses()
    return ells, cam, camera_from_world


def test_chess_projections_bound_and_touch_the_sampled_surfaces():
    ells, cam, frames = _chess()
    rng = np.random.default_rng(1)
    checked = 0
    for T in frames[::9]:
        for E in ells:
            try:
                e = project_ellipsoid(cam, T, E)
            except DegenerateProjectionError:
                continue
            # Uniformly random directions on the unit sphere, mapped onto the surface.
            u = rng.normal(size=(20000, 3))
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            pts = (u * E.axes) @ E.rotation.T + E.center
            phi = level(e, cam.project_points(T, pts))
            assert phi.max() <= 1.0 + 1e-9  # every surface point projects inside
            assert phi.max() >= 0.995  # and the outline is reached (touches Phi = 1)
            checked += 1
    assert checked >= 30


def test_degenerate_projections_raise_with_reason():
    E = Ellipsoid(np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.5, 0.5]))
    inside = pose_matrix(np.eye(3), [0.0, 0.0, 0.2])  # camera at (0, 0, -0.2): inside
    with pytest.raises(DegenerateProjectionError) as exc:
        project_ellipsoid(CAM, inside, E)
    assert exc.value.reason == "camera_inside"
    behind = pose_matrix(np.eye(3), [0.0, 0.0, -5.0])  # centre at depth -5
    with pytest.raises(DegenerateProjectionError) as exc:
        project_ellipsoid(CAM, behind, E)
    assert exc.value.reason == "behind_camera"
    crossing = pose_matrix(np.eye(3), [2.0, 0.0, 0.3])  # centre at depth 0.3 < extent 0.5
    with pytest.raises(DegenerateProjectionError) as exc:
        project_ellipsoid(CAM, crossing, E)
    assert exc.value.reason == "crosses_image_plane"
    # Just in front: a valid ellipse.
    ok = pose_matrix(np.eye(3), [0.0, 0.0, 0.6])
    assert project_ellipsoid(CAM, ok, E).a > 0


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: Ellipse(0, 0, -1.0, 1.0, 0.0), "Ellipse.a"),
        (lambda: Ellipse(0, 0, 1.0, 0.0, 0.0), "Ellipse.b"),
        (lambda: Ellipse(float("nan"), 0, 1.0, 1.0, 0.0), "Ellipse.cx"),
        (lambda: Ellipse(0, float("inf"), 1.0, 1.0, 0.0), "Ellipse.cy"),
        (lambda: Ellipse(0, 0, 1.0, 1.0, "x"), "Ellipse.angle"),
        (lambda: Ellipsoid(np.zeros(3), np.array([1.0, -1.0, 1.0])), "Ellipsoid.axes"),
        (lambda: Ellipsoid(np.zeros(2), np.ones(3)), "Ellipsoid.center"),
        (lambda: Ellipsoid(np.zeros(3), np.ones(3), np.eye(3) * 1.01), "Ellipsoid.rotation"),
        (lambda: Ellipsoid(np.zeros(3), np.ones(3), np.diag([1.0, 1.0, -1.0])),
         "Ellipsoid.rotation"),
        (lambda: Camera(0.0, 500.0, 320.0, 240.0, 640, 480), "Camera.fx"),
        (lambda: Camera(500.0, 500.0, 320.0, 240.0, 0, 480), "Camera.width"),
        (lambda: Camera(500.0, 500.0, 320.0, 240.0, 640, 480.5), "Camera.height"),
        (lambda: Camera(500.0, 500.0, 320.0, 240.0, "wide", 480), "Camera.width"),
        (lambda: Camera(500.0, 500.0, 320.0, 240.0, 640, float("inf")), "Camera.height"),
        (lambda: rotation_from_quaternion_wxyz([1.0, 0.1, 0.0, 0.0]), "quaternion_wxyz"),
        (lambda: Ellipse.from_bbox(10, 0, 5, 10), "xmax > xmin"),
    ],
)
def test_validation_messages_name_the_field(make, field):
    with pytest.raises(GeometryError) as exc:
        make()
    assert field in str(exc.value)
    assert isinstance(exc.value, ValueError)


# --------------------------------------------------------------------------- Camera.from_matrix


def test_camera_from_matrix_round_trip() -> None:
    K = np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]])
    cam = Camera.from_matrix(K, 640, 480)
    np.testing.assert_array_equal(cam.K, K)


@pytest.mark.parametrize("K", [
    [[500.0, 2.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]],  # skew: was dropped silently
    [[500.0, 0.0, 320.0], [0.0, 510.0, 240.0]],  # 2x3: was read as if 3x3
    np.eye(4) * 500.0,  # 4x4: was read as if 3x3
    [[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 2.0]],  # not normalised
    [[500.0, 0.0, 320.0], [0.0, 510.0, math.nan], [0.0, 0.0, 1.0]],
])
def test_camera_from_matrix_rejects_what_it_cannot_represent(K) -> None:
    with pytest.raises(GeometryError, match=r"\bK\b"):
        Camera.from_matrix(np.asarray(K), 640, 480)


def test_canonical_quaternion_tie_break_for_half_turns() -> None:
    from quadloc.factors.rotations import canonical_quaternion_wxyz

    q = np.array([0.0, 0.0, -0.6, 0.8])
    for s in (1.0, -1.0):
        got = canonical_quaternion_wxyz(s * q)
        np.testing.assert_array_equal(got, [0.0, 0.0, 0.6, -0.8])
        assert math.copysign(1.0, got[0]) == 1.0 and math.copysign(1.0, got[1]) == 1.0
    np.testing.assert_allclose(
        quaternion_wxyz_from_rotation(rotation_from_quaternion_wxyz(q)), [0, 0, 0.6, -0.8],
        atol=1e-12)
    np.testing.assert_array_equal(canonical_quaternion_wxyz([-0.5, 0.5, 0.5, 0.5]),
                                  [0.5, -0.5, -0.5, -0.5])


def test_so3_exp_is_gtsams_rot3_expmap_batched():
    """quadloc.factors.rotations.so3_exp (batched Rodrigues, series below 1e-8 rad) against GTSAM's
    Rot3.Expmap, for random, tiny (1e-10 rad) and zero rotation vectors; skew(w) @ u = w x u."""
    import gtsam

    from quadloc.factors.rotations import skew, so3_exp

    rng = np.random.default_rng(3)
    w = np.vstack([rng.normal(0, 1.5, (20, 3)), rng.normal(0, 1e-10, (3, 3)), np.zeros((1, 3))])
    R = so3_exp(w)
    assert R.shape == (24, 3, 3)
    for wi, Ri in zip(w, R, strict=True):
        np.testing.assert_allclose(Ri, gtsam.Rot3.Expmap(wi).matrix(), atol=1e-14)
    u = rng.normal(size=(24, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", skew(w), u), np.cross(w, u), atol=1e-15)
    np.testing.assert_allclose(so3_exp(w[0]), R[0], atol=1e-15)  # one vector: (3, 3)
