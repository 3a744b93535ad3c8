"""SDK geometry helpers against independent computations (rasters, closed forms, scipy, expm)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from quadloc.factors.conics import Ellipse as RefEllipse
from quadloc_sdk import geometry as g
from quadloc_sdk.models import Box, Ellipse
from tests.support.helpers import angle_diff, level

RNG = np.random.default_rng(20261121)


def _dual_conic(e: Ellipse | RefEllipse) -> np.ndarray:
    return RefEllipse(e.cx, e.cy, e.a, e.b, e.angle).dual_conic()


def _raster(e: RefEllipse, shape: tuple[int, int]) -> np.ndarray:
    """Pixels whose CENTRE (j + 0.5, i + 0.5) lies inside the ellipse (independent of the SDK)."""
    ii, jj = np.mgrid[0 : shape[0], 0 : shape[1]]
    centres = np.stack([jj + 0.5, ii + 0.5], axis=-1)
    return (level(e, centres) <= 1.0).astype(np.uint8)


def _random_pose() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=int(RNG.integers(1 << 30))).as_matrix()
    T[:3, 3] = RNG.normal(size=3) * 2
    return T


# --------------------------------------------------------------------------- box -> ellipse


@pytest.mark.parametrize("box", [(10, 20, 110, 60), (5.5, 7.25, 25.5, 107.25), (0, 0, 1, 1)])
def test_box_to_inscribed_ellipse_matches_reference_and_touches_box(box):
    e = g.ellipse_from_box(box)
    ref = RefEllipse.from_bbox(*box)
    np.testing.assert_allclose(_dual_conic(e), ref.dual_conic(), atol=1e-9)
    # Inscribed: its own bounding box is the detection box, and a >= b canonical form.
    np.testing.assert_allclose(RefEllipse(e.cx, e.cy, e.a, e.b, e.angle).bbox(), box, atol=1e-9)
    assert e.a >= e.b and -math.pi / 2 <= e.angle < math.pi / 2


def test_box_model_and_bad_boxes():
    e = g.ellipse_from_box(Box(xmin=0, ymin=0, xmax=4, ymax=10))
    assert (e.a, e.b) == (5, 2) and math.isclose(abs(e.angle), math.pi / 2)
    with pytest.raises(ValueError, match="xmax"):
        g.ellipse_from_box((10, 0, 5, 3))
    with pytest.raises(ValueError, match="xmin, ymin, xmax, ymax"):
        g.ellipse_from_box((1, 2, 3))
    with pytest.raises(ValueError):
        g.ellipse_from_box((0, 0, float("nan"), 1))


# --------------------------------------------------------------------------- mask / contour


ELLIPSES = [
    RefEllipse(160.3, 120.7, 60.0, 25.0, 0.0),
    RefEllipse(150.0, 110.0, 70.0, 30.0, 0.6),
    RefEllipse(140.2, 130.9, 55.0, 20.0, -1.2),
    RefEllipse(170.0, 125.0, 40.0, 18.0, math.pi / 2 - 0.05),
    RefEllipse(150.0, 120.0, 45.0, 35.0, 2.5),  # angle outside [-pi/2, pi/2): same set as 2.5-pi
]


@pytest.mark.parametrize("ref", ELLIPSES)
def test_mask_moments_recovers_rasterized_ellipse(ref):
    mask = _raster(ref, (260, 320))
    e = g.ellipse_from_mask(mask, method="moments")
    assert math.hypot(e.cx - ref.cx, e.cy - ref.cy) < 0.1  # a 0.5 px shift would fail
    assert abs(e.a - ref.a) < 0.3 and abs(e.b - ref.b) < 0.3
    assert angle_diff(e.angle, ref.angle) < math.radians(0.5)
    # Area of the moment ellipse equals the pixel count (a uniform ellipse's moments are exact).
    assert abs(math.pi * e.a * e.b - mask.sum()) / mask.sum() < 0.01


@pytest.mark.parametrize("ref", ELLIPSES)
def test_mask_fit_and_contour_fit_follow_opencv_conventions(ref):
    mask = _raster(ref, (260, 320))
    e = g.ellipse_from_mask(mask, method="fit")
    # Boundary-pixel centres are inset by ~0.5 px: the fit is at most ~1 px small, never larger.
    assert math.hypot(e.cx - ref.cx, e.cy - ref.cy) < 0.15
    assert -1.2 < e.a - ref.a < 0.2 and -1.2 < e.b - ref.b < 0.2
    assert angle_diff(e.angle, ref.angle) < math.radians(1.0)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    e2 = g.ellipse_from_contour(contours[0], method="fit")
    assert e2 == e
    e3 = g.ellipse_from_contour(contours[0], method="moments")
    assert math.hypot(e3.cx - ref.cx, e3.cy - ref.cy) < 0.15
    assert abs(e3.a - ref.a) < 1.2 and abs(e3.b - ref.b) < 1.2
    assert angle_diff(e3.angle, ref.angle) < math.radians(1.0)


@pytest.mark.parametrize("ref", ELLIPSES)
def test_contour_of_exact_points_is_recovered_exactly(ref):
    pts = ref.contour_points(720)
    fit = g.ellipse_from_contour(pts, method="fit", opencv_pixel_coordinates=False)
    np.testing.assert_allclose(_dual_conic(fit), ref.dual_conic(), rtol=1e-4, atol=1e-3)
    mom = g.ellipse_from_contour(pts, method="moments", opencv_pixel_coordinates=False)
    # A 720-gon inscribed in the ellipse: area/moment deficit ~ (2 pi / 720)^2 / 6 ~ 1e-5.
    assert abs(mom.a - ref.a) / ref.a < 1e-4 and abs(mom.b - ref.b) / ref.b < 1e-4
    assert math.hypot(mom.cx - ref.cx, mom.cy - ref.cy) < 1e-3
    assert angle_diff(mom.angle, ref.angle) < 1e-4
    # The OpenCV-coordinates flag shifts by exactly half a pixel.
    shifted = g.ellipse_from_contour(pts - 0.5, method="fit", opencv_pixel_coordinates=True)
    assert math.isclose(shifted.cx, fit.cx, abs_tol=1e-3)
    assert math.isclose(shifted.cy, fit.cy, abs_tol=1e-3)


def test_contour_and_mask_errors_name_the_argument():
    with pytest.raises(ValueError, match="contour: expected shape"):
        g.ellipse_from_contour(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="at least 5 points"):
        g.ellipse_from_contour(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="zero area"):
        g.ellipse_from_contour(np.array([[0, 0], [1, 1], [2, 2.0]]), method="moments")
    with pytest.raises(ValueError, match="method"):
        g.ellipse_from_contour(np.zeros((6, 2)), method="hough")
    with pytest.raises(ValueError, match="NaN"):
        g.ellipse_from_contour(np.full((6, 2), np.nan))
    with pytest.raises(ValueError, match="mask: no non-zero"):
        g.ellipse_from_mask(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="mask: expected a 2-D"):
        g.ellipse_from_mask(np.zeros((4, 4, 3)))
    line = np.zeros((10, 10))
    line[5, 2:8] = 1  # one pixel high: still a valid (thin) region thanks to the 1/12 term
    thin = g.ellipse_from_mask(line)
    assert math.isclose(thin.b, 2 * math.sqrt(1 / 12)) and math.isclose(thin.cy, 5.5)


# --------------------------------------------------------------------------- sigma


def test_sigma_from_log_variance_closed_form_and_round_trip():
    alpha = np.linspace(-8, 8, 33)
    np.testing.assert_allclose(g.sigma_from_log_variance(alpha), np.sqrt(np.exp(alpha)))
    np.testing.assert_allclose(g.log_variance_from_sigma(g.sigma_from_log_variance(alpha)), alpha)
    assert isinstance(g.sigma_from_log_variance(0.0), float)
    assert g.sigma_from_log_variance(0.0) == 1.0
    assert math.isclose(g.sigma_from_log_variance(math.log(4.0)), 2.0)
    with pytest.raises(ValueError, match="log_variance"):
        g.sigma_from_log_variance(float("inf"))
    with pytest.raises(ValueError, match="sigma"):
        g.log_variance_from_sigma(0.0)


# --------------------------------------------------------------------------- poses


def test_invert_pose_and_direction_helpers_against_linalg_inv():
    poses = np.stack([_random_pose() for _ in range(5)])
    inv = g.invert_pose(poses)
    np.testing.assert_allclose(inv, np.linalg.inv(poses), atol=1e-12)
    np.testing.assert_allclose(g.to_world_from_camera(poses[0]), np.linalg.inv(poses[0]),
                               atol=1e-12)
    np.testing.assert_allclose(g.to_camera_from_world(g.to_world_from_camera(poses[1])), poses[1],
                               atol=1e-12)
    # camera centre of camera_from_world [R|t] is -R^T t
    R, t = poses[2][:3, :3], poses[2][:3, 3]
    np.testing.assert_allclose(g.to_world_from_camera(poses[2])[:3, 3], -R.T @ t, atol=1e-12)


def test_pose_validation_messages():
    with pytest.raises(ValueError, match=r"pose: expected shape"):
        g.invert_pose(np.eye(3))
    bad = np.eye(4)
    bad[0, 0] = 2
    with pytest.raises(ValueError, match="not a proper rotation"):
        g.invert_pose(bad)
    reflect = np.diag([1.0, 1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="not a proper rotation"):
        g.world_from_camera_opencv_to_opengl(reflect)
    bottom = np.eye(4)
    bottom[3, 0] = 1
    with pytest.raises(ValueError, match="last row"):
        g.invert_pose(bottom)
    with pytest.raises(ValueError, match="NaN"):
        g.invert_pose(np.full((4, 4), np.nan))


def test_opencv_opengl_flip_keeps_centre_and_flips_camera_axes():
    world_from_cv = _random_pose()
    world_from_gl = g.world_from_camera_opencv_to_opengl(world_from_cv)
    np.testing.assert_allclose(world_from_gl[:3, 3], world_from_cv[:3, 3])  # same centre
    assert np.isclose(np.linalg.det(world_from_gl[:3, :3]), 1.0)
    # A world point 2 m in front of the OpenCV camera (+Z forward) and 0.3 m below (+Y down)...
    p_cv = np.array([0.1, 0.3, 2.0, 1.0])
    X = world_from_cv @ p_cv
    p_gl = np.linalg.inv(world_from_gl) @ X
    # ...is in front (-Z forward) and below (+Y up -> negative Y) in OpenGL camera axes.
    np.testing.assert_allclose(p_gl, [0.1, -0.3, -2.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(g.world_from_camera_opengl_to_opencv(world_from_gl), world_from_cv,
                               atol=1e-15)
    np.testing.assert_allclose(g.OPENCV_FROM_OPENGL @ g.OPENCV_FROM_OPENGL, np.eye(3))


def _hat(xi: np.ndarray) -> np.ndarray:
    """se(3) matrix of a GTSAM-ordered tangent [omega, v]."""
    w, v = xi[:3], xi[3:]
    H = np.zeros((4, 4))
    H[:3, :3] = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
    H[:3, 3] = v
    return H


def test_covariance_flip_matches_perturbations_through_expm():
    world_from_cv = _random_pose()
    F = np.diag([1.0, -1.0, -1.0, 1.0])
    L = RNG.normal(size=(6, 6))
    cov_cv = L @ L.T * 1e-3
    cov_gl = g.covariance_opencv_to_opengl(cov_cv)
    # Each perturbed OpenCV pose T exp(xi), expressed with OpenGL axes, is T F exp(xi_gl):
    # solve xi_gl for random xi, then the linear map's action on the covariance must agree.
    J = np.zeros((6, 6))
    for k in range(6):
        xi = np.zeros(6)
        xi[k] = 1e-6
        perturbed_gl = world_from_cv @ expm(_hat(xi)) @ F
        delta = np.linalg.inv(world_from_cv @ F) @ perturbed_gl  # = exp(hat(xi_gl))
        H = delta - np.eye(4)
        J[:, k] = np.array([H[2, 1], H[0, 2], H[1, 0], *H[:3, 3]]) / 1e-6
    np.testing.assert_allclose(cov_gl, J @ cov_cv @ J.T, atol=1e-9)
    np.testing.assert_allclose(g.covariance_opencv_to_opengl(cov_gl), cov_cv)
    with pytest.raises(ValueError, match="covariance"):
        g.covariance_opencv_to_opengl(np.eye(5))


def test_session_from_map_recovers_alignment():
    session_from_map_true = _random_pose()
    map_from_camera = _random_pose()
    session_from_camera = session_from_map_true @ map_from_camera
    np.testing.assert_allclose(g.session_from_map(session_from_camera, map_from_camera),
                               session_from_map_true, atol=1e-12)


def test_quaternion_matrix_conversions_against_scipy():
    rots = Rotation.random(200, random_state=7)
    # add near-180-degree rotations about each axis and the identity (Shepperd pivots)
    extra = Rotation.from_rotvec(np.array([[math.pi - 1e-9, 0, 0], [0, math.pi, 0],
                                           [0, 0, math.pi], [0, 0, 0],
                                           [1.0, 1.0, 1.0]]) * np.array([[1], [1], [1], [1],
                                                                         [math.pi / math.sqrt(3)]]))
    rots = Rotation.concatenate([rots, extra])
    mats = rots.as_matrix()
    xyzw = rots.as_quat()
    wxyz_ref = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    wxyz_ref *= np.where(wxyz_ref[:, :1] < 0, -1, 1)
    q = g.quaternion_wxyz_from_matrix(mats)
    assert q.shape == (205, 4) and np.all(q[:, 0] >= 0)
    # sign is only ambiguous when w == 0: compare up to sign there
    sign = np.where(np.sum(q * wxyz_ref, axis=1) < 0, -1, 1)[:, None]
    np.testing.assert_allclose(q, sign * wxyz_ref, atol=1e-9)
    np.testing.assert_allclose(g.matrix_from_quaternion_wxyz(wxyz_ref), mats, atol=1e-12)
    # single quaternion in, single matrix out; round trips through 4x4 poses
    T = g.pose_matrix_from_quaternion_wxyz(q[3], [1.0, 2.0, 3.0])
    assert T.shape == (4, 4)
    q_back, t_back = g.quaternion_wxyz_translation_from_pose(T)
    np.testing.assert_allclose(q_back, q[3], atol=1e-12)
    np.testing.assert_allclose(t_back, [1, 2, 3])


def test_quaternion_validation():
    with pytest.raises(ValueError, match="unit norm"):
        g.matrix_from_quaternion_wxyz([1.0, 1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 4\)"):
        g.matrix_from_quaternion_wxyz([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="not a proper rotation"):
        g.quaternion_wxyz_from_matrix(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="translation"):
        g.pose_matrix_from_quaternion_wxyz([1.0, 0, 0, 0], [0.0, float("nan"), 0])


# --------------------------------------------------------------------------- properties

finite = st.floats(-1e3, 1e3, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(cx=st.floats(-500, 1500), cy=st.floats(-500, 1500), a=st.floats(2, 400),
       ratio=st.floats(0.1, 1.0), angle=st.floats(-10, 10))
def test_fit_recovers_any_exact_ellipse(cx, cy, a, ratio, angle):
    ref = RefEllipse(cx, cy, a, a * ratio, angle)
    fit = g.ellipse_from_contour(ref.contour_points(256), opencv_pixel_coordinates=False)
    scale = max(1.0, a)
    assert math.hypot(fit.cx - cx, fit.cy - cy) < 1e-3 * scale
    assert abs(fit.a - ref.canonical().a) < 1e-3 * scale
    assert abs(fit.b - ref.canonical().b) < 1e-3 * scale
    if ratio < 0.95:  # the angle of a near-circle is meaningless
        assert angle_diff(fit.angle, angle) < 1e-3


@settings(max_examples=100, deadline=None)
@given(q=st.tuples(finite, finite, finite, finite).filter(lambda v: np.linalg.norm(v) > 1e-3),
       t=st.tuples(finite, finite, finite))
def test_pose_quaternion_round_trip_and_flip_involution(q, t):
    q = np.asarray(q) / np.linalg.norm(q)
    T = g.pose_matrix_from_quaternion_wxyz(q, t)
    q2, t2 = g.quaternion_wxyz_translation_from_pose(T)
    assert q2[0] >= 0  # canonical sign (only ambiguous when w == 0: then up to sign)
    np.testing.assert_allclose(q2, q if np.dot(q, q2) >= 0 else -q, atol=1e-9)
    np.testing.assert_allclose(t2, t)
    gl = g.world_from_camera_opencv_to_opengl(T)
    np.testing.assert_allclose(g.world_from_camera_opengl_to_opencv(gl), T, atol=1e-12)
    np.testing.assert_allclose(g.invert_pose(g.invert_pose(T)), T, atol=1e-9)
