"""Geometry helpers an AR app needs before and after calling QuadLoc (numpy; OpenCV for contours).

Conventions (the same as the QuadLoc server)
--------------------------------------------
* Image coordinates are pixels with the origin at the **top-left corner of the top-left pixel**,
  +x right, +y down. The centre of pixel ``(row i, column j)`` is therefore ``(j + 0.5, i + 0.5)``.
  OpenCV puts pixel centres at integer coordinates, so points that come from OpenCV
  (``cv2.findContours``, ``cv2.fitEllipse``, ``cv2.moments`` of an image) are shifted by
  ``+0.5`` px here (argument ``opencv_pixel_coordinates``).
* An ellipse is ``(cx, cy, a, b, angle)``: centre in px, **semi**-axes ``a`` (along the direction
  ``angle``) and ``b`` in px, ``angle`` in **radians** from +x towards +y (clockwise on screen,
  because +y points down). Returned ellipses are canonical: ``a >= b``, ``angle`` in
  ``[-pi/2, pi/2)``.
* Poses are 4x4 homogeneous rigid transforms named by direction: ``world_from_camera`` maps
  camera coordinates to world coordinates (the camera's pose in the map); ``camera_from_world``
  is its inverse (OpenCV's ``[R | t]``). Translations in metres.
* Camera axes: ``opencv`` = +X right, +Y down, +Z forward (QuadLoc's default);
  ``opengl`` = ARKit / ARCore / OpenGL: +X right, +Y up, -Z forward. The change between them is
  the rotation ``F = diag(1, -1, -1)`` (a half turn about X) applied on the camera side:
  ``world_from_camera_opengl = world_from_camera_opencv @ diag(1, -1, -1, 1)``.
* Quaternions are ``quaternion_wxyz`` (scalar first), unit norm, canonical sign ``w >= 0``.
* Covariances of poses are 6x6 in GTSAM's Pose3 tangent order ``[omega (3), v (3)]``
  (radians, metres), right perturbation, expressed in the camera (body) frame.

All pose / quaternion functions accept stacks: leading dimensions ``(...)`` are broadcast.
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import Literal

import numpy as np

from quadloc_sdk.models import Box, Ellipse

__all__ = [
    "OPENCV_FROM_OPENGL",
    "UNITY_CAMERA_FROM_OPENCV",
    "canonical_ellipse",
    "column_major_from_matrix",
    "covariance_opencv_to_opengl",
    "ellipse_from_box",
    "ellipse_from_contour",
    "ellipse_from_mask",
    "ellipse_from_moments",
    "invert_pose",
    "log_variance_from_sigma",
    "matrix_from_column_major",
    "matrix_from_quaternion_wxyz",
    "polygon_moments",
    "pose_matrix_from_quaternion_wxyz",
    "quaternion_wxyz_from_matrix",
    "quaternion_wxyz_from_xyzw",
    "quaternion_wxyz_translation_from_pose",
    "quaternion_xyzw_from_wxyz",
    "session_from_map",
    "sigma_from_log_variance",
    "to_camera_from_world",
    "to_world_from_camera",
    "unity_pose_from_world_from_camera",
    "world_from_camera_opencv_to_opengl",
    "world_from_camera_opengl_to_opencv",
]

#: Camera-side axis change between OpenCV and OpenGL/ARKit camera axes (its own inverse), 3x3.
OPENCV_FROM_OPENGL = np.diag([1.0, -1.0, -1.0])
_FLIP4 = np.diag([1.0, -1.0, -1.0, 1.0])

#: Tolerance on ``max|R R^T - I|`` and ``|det R - 1|`` for the rotation part of a pose.
ORTHONORMAL_TOLERANCE = 1e-6
#: Tolerance on ``| |q| - 1 |`` for a unit quaternion.
QUATERNION_NORM_TOLERANCE = 1e-6


# --------------------------------------------------------------------------- ellipses


def canonical_ellipse(cx: float, cy: float, a: float, b: float, angle: float) -> Ellipse:
    """The same ellipse with ``a >= b`` and ``angle`` (radians) in ``[-pi/2, pi/2)``."""
    if b > a:
        a, b, angle = b, a, angle + math.pi / 2
    angle = (angle + math.pi / 2) % math.pi - math.pi / 2
    return Ellipse(cx=cx, cy=cy, a=a, b=b, angle=angle)


def ellipse_from_box(box: Box | tuple[float, float, float, float]) -> Ellipse:
    """The axis-aligned ellipse **inscribed** in a detection box (what the server does with boxes).

    ``box`` is a :class:`quadloc_sdk.models.Box` or ``(xmin, ymin, xmax, ymax)`` in px (top-left
    origin). Result: centre = box centre, semi-axes = half the box width / height, ``angle = 0``
    (then made canonical, so a tall box gives ``a`` = half height and ``angle = -pi/2``).
    """
    if not isinstance(box, Box):
        if len(box) != 4:
            raise ValueError(f"box: expected (xmin, ymin, xmax, ymax), got {len(box)} values")
        box = Box(xmin=box[0], ymin=box[1], xmax=box[2], ymax=box[3])
    return canonical_ellipse(
        (box.xmin + box.xmax) / 2,
        (box.ymin + box.ymax) / 2,
        (box.xmax - box.xmin) / 2,
        (box.ymax - box.ymin) / 2,
        0.0,
    )


def _ellipse_from_second_moments(
    field: str, mean: np.ndarray, covariance: np.ndarray
) -> Ellipse:
    """Moment-matched ellipse: a uniform filled ellipse with semi-axes ``(a, b)`` has covariance
    ``R diag(a^2, b^2) R^T / 4``, so ``a, b = 2 sqrt(eigenvalues)`` along the eigenvectors."""
    if not np.all(np.isfinite(covariance)) or not np.all(np.isfinite(mean)):
        raise ValueError(f"{field}: moments are not finite")
    eigval, eigvec = np.linalg.eigh(covariance)  # ascending
    if eigval[0] <= 0:
        raise ValueError(f"{field}: the region is degenerate (zero width in some direction)")
    major = eigvec[:, 1]
    angle = math.atan2(major[1], major[0])
    return canonical_ellipse(
        float(mean[0]), float(mean[1]), 2 * math.sqrt(eigval[1]), 2 * math.sqrt(eigval[0]), angle
    )


def ellipse_from_moments(mean: np.ndarray, covariance: np.ndarray, field: str = "region"
                         ) -> Ellipse:
    """The moment-matched ellipse of a region with centroid ``mean`` (2,) and covariance
    ``covariance`` (2, 2) about it (px, px^2): semi-axes ``2 sqrt(eigenvalues)`` (a uniform
    filled ellipse's); ``ValueError`` naming ``field`` for a degenerate region."""
    return _ellipse_from_second_moments(field, np.asarray(mean, float),
                                        np.asarray(covariance, float))


def polygon_moments(points: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Area moments of a simple polygon (Green's theorem): ``(area px^2, centroid (2,),
    covariance about the centroid (2, 2) px^2)``; ``points`` (N, 2), either orientation."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"polygon: expected >= 3 finite points (N, 2), got shape {p.shape}")
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    a = cross.sum() / 2.0
    if not abs(a) > 0:
        raise ValueError("polygon: zero area")
    c = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * a)
    sxx = ((x * x + x * xn + xn * xn) * cross).sum() / (12.0 * a)
    syy = ((y * y + y * yn + yn * yn) * cross).sum() / (12.0 * a)
    sxy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cross).sum() / (24.0 * a)
    cov = np.array([[sxx, sxy], [sxy, syy]]) - np.outer(c, c)
    return abs(float(a)), c, cov


def _cv2() -> ModuleType:  # lazy: importing OpenCV costs ~0.1-0.3 s; only the contours need it
    import cv2

    return cv2


def ellipse_from_contour(
    contour: np.ndarray,
    *,
    method: Literal["fit", "moments"] = "fit",
    opencv_pixel_coordinates: bool = True,
) -> Ellipse:
    """Ellipse of a closed contour (e.g. one returned by ``cv2.findContours`` for an instance mask).

    ``contour``: points, shape (N, 2) or OpenCV's (N, 1, 2), in px.
    ``opencv_pixel_coordinates``: the points use OpenCV's convention (pixel centres at integer
    coordinates, as from ``cv2.findContours``) and are shifted by +0.5 px into ours (origin at
    the top-left pixel corner); pass ``False`` if they are already in our convention.

    Methods:

    * ``"fit"`` -- ``cv2.fitEllipse``: least-squares algebraic conic fit to the points
      (Fitzgibbon), needs >= 5 points. OpenCV returns ``((cx, cy), (width, height), angle_deg)``
      with FULL axes and degrees; the ``width`` axis is along ``angle_deg`` (from +x towards +y).
      This function converts it to semi-axes and radians. Note: the points of ``findContours``
      are the centres of the boundary pixels, so the fitted semi-axes are about 0.5 px smaller
      than the region's extent.
    * ``"moments"`` -- ``cv2.moments`` of the polygon (area moments by Green's theorem) and the
      moment-matched ellipse (same area centroid and second moments as the polygon, like the
      server's simulator for partially visible objects); needs >= 3 points and a non-zero area.
      Robust to non-elliptic shapes; on the contour of a pixel mask it shares fit's 0.5 px inset.
    """
    pts = np.asarray(contour, dtype=np.float64)
    if pts.ndim == 3 and pts.shape[1] == 1:
        pts = pts[:, 0, :]
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"contour: expected shape (N, 2) or (N, 1, 2), got {np.shape(contour)}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("contour: contains NaN or infinite coordinates")
    if opencv_pixel_coordinates:
        pts = pts + 0.5
    cv2 = _cv2()
    if method == "fit":
        if len(pts) < 5:
            raise ValueError(f"contour: method 'fit' needs at least 5 points, got {len(pts)}")
        (cx, cy), (width, height), angle_deg = cv2.fitEllipse(pts.astype(np.float32))
        if not (width > 0 and height > 0) or not all(map(math.isfinite, (cx, cy, width, height))):
            raise ValueError("contour: cv2.fitEllipse found no ellipse (degenerate points)")
        return canonical_ellipse(cx, cy, width / 2, height / 2, math.radians(angle_deg))
    if method == "moments":
        if len(pts) < 3:
            raise ValueError(f"contour: method 'moments' needs at least 3 points, got {len(pts)}")
        m = cv2.moments(pts.astype(np.float32))
        if not abs(m["m00"]) > 0:
            raise ValueError("contour: the polygon has zero area")
        mean = np.array([m["m10"], m["m01"]]) / m["m00"]
        cov = np.array([[m["mu20"], m["mu11"]], [m["mu11"], m["mu02"]]]) / m["m00"]
        return _ellipse_from_second_moments("contour", mean, cov)
    raise ValueError(f"method: must be 'fit' or 'moments', got {method!r}")


def ellipse_from_mask(
    mask: np.ndarray, *, method: Literal["moments", "fit"] = "moments"
) -> Ellipse:
    """Ellipse of a binary instance mask (H, W) -- any dtype, non-zero = object.

    * ``"moments"`` (default) -- moment-matched ellipse of the pixel region: each pixel is a unit
      square centred at ``(j + 0.5, i + 0.5)``, so the region's covariance is the pixel centres'
      covariance plus ``1/12`` on the diagonal (a unit square's own variance). Exact for the
      union of squares; uses every pixel (all connected components), robust to ragged masks.
    * ``"fit"`` -- ``cv2.fitEllipse`` on the largest external contour (see
      :func:`ellipse_from_contour`).
    """
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"mask: expected a 2-D array (H, W), got shape {m.shape}")
    binary = (m != 0).astype(np.uint8)
    if not binary.any():
        raise ValueError("mask: no non-zero pixel")
    if method == "moments":
        rows, cols = np.nonzero(binary)
        centres = np.stack([cols + 0.5, rows + 0.5], axis=1)
        mean = centres.mean(axis=0)
        d = centres - mean
        cov = d.T @ d / len(centres) + np.eye(2) / 12.0
        return _ellipse_from_second_moments("mask", mean, cov)
    if method == "fit":
        cv2 = _cv2()
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        largest = max(contours, key=len)
        return ellipse_from_contour(largest, method="fit", opencv_pixel_coordinates=True)
    raise ValueError(f"method: must be 'moments' or 'fit', got {method!r}")


# --------------------------------------------------------------------------- uncertainty


def sigma_from_log_variance(log_variance: float | np.ndarray) -> float | np.ndarray:
    """Detector log-variance ``alpha = log sigma^2`` -> ``sigma = exp(alpha / 2)`` (vectorised)."""
    alpha = np.asarray(log_variance, dtype=float)
    if not np.all(np.isfinite(alpha)):
        raise ValueError("log_variance: must be finite")
    sigma = np.exp(alpha / 2)
    return float(sigma) if sigma.ndim == 0 else sigma


def log_variance_from_sigma(sigma: float | np.ndarray) -> float | np.ndarray:
    """Inverse of :func:`sigma_from_log_variance`: ``alpha = 2 log sigma`` (``sigma > 0``)."""
    s = np.asarray(sigma, dtype=float)
    if not np.all(np.isfinite(s)) or not np.all(s > 0):
        raise ValueError("sigma: must be finite and > 0")
    alpha = 2 * np.log(s)
    return float(alpha) if alpha.ndim == 0 else alpha


# --------------------------------------------------------------------------- poses


def _check_pose(field: str, pose: np.ndarray) -> np.ndarray:
    T = np.asarray(pose, dtype=float)
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise ValueError(f"{field}: expected shape (..., 4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{field}: contains NaN or infinite values")
    if np.max(np.abs(T[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0]))) > 1e-9:
        raise ValueError(f"{field}: last row must be [0, 0, 0, 1]")
    R = T[..., :3, :3]
    err = np.max(np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)))
    if err > ORTHONORMAL_TOLERANCE or np.max(np.abs(np.linalg.det(R) - 1)) > ORTHONORMAL_TOLERANCE:
        raise ValueError(
            f"{field}: rotation block is not a proper rotation (max|R R^T - I| = {err:.3g})"
        )
    return T


def invert_pose(a_from_b: np.ndarray) -> np.ndarray:
    """``b_from_a`` from a rigid ``a_from_b`` (shape (..., 4, 4)), using ``R^T`` (no ``inv``)."""
    T = _check_pose("pose", a_from_b)
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def to_world_from_camera(camera_from_world: np.ndarray) -> np.ndarray:
    """``world_from_camera`` (camera pose in the map) from ``camera_from_world`` (OpenCV R|t)."""
    return invert_pose(camera_from_world)


def to_camera_from_world(world_from_camera: np.ndarray) -> np.ndarray:
    """``camera_from_world`` (OpenCV ``[R | t]``) from ``world_from_camera`` (the camera pose)."""
    return invert_pose(world_from_camera)


def world_from_camera_opencv_to_opengl(world_from_camera_opencv: np.ndarray) -> np.ndarray:
    """Camera pose with OpenCV camera axes -> the same pose with OpenGL/ARKit/ARCore axes.

    ``world_from_camera_opengl = world_from_camera_opencv @ diag(1, -1, -1, 1)``: the camera
    centre is unchanged; the camera's +Y and +Z axes flip (down -> up, forward -> backward).
    The world frame is untouched. For ``camera_from_world`` multiply on the left instead.
    """
    return _check_pose("world_from_camera", world_from_camera_opencv) @ _FLIP4


def world_from_camera_opengl_to_opencv(world_from_camera_opengl: np.ndarray) -> np.ndarray:
    """Inverse of :func:`world_from_camera_opencv_to_opengl` (the flip is its own inverse)."""
    return _check_pose("world_from_camera", world_from_camera_opengl) @ _FLIP4


def covariance_opencv_to_opengl(covariance: np.ndarray) -> np.ndarray:
    """Re-express a 6x6 body-frame pose covariance ``[omega, v]`` in the flipped camera axes.

    With ``world_from_camera_gl = world_from_camera_cv @ F`` and right perturbations, the tangent
    vectors map as ``xi_gl = blockdiag(F, F) xi_cv`` (``F = diag(1, -1, -1)``, ``F^-1 = F``), so
    ``cov_gl = J cov_cv J^T`` with ``J = diag(1, -1, -1, 1, -1, -1)``. Its own inverse.
    """
    C = np.asarray(covariance, dtype=float)
    if C.shape[-2:] != (6, 6):
        raise ValueError(f"covariance: expected shape (..., 6, 6), got {C.shape}")
    j = np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])
    out: np.ndarray = C * j[:, None] * j[None, :]
    return out


def session_from_map(
    session_from_camera: np.ndarray, map_from_camera: np.ndarray
) -> np.ndarray:
    """Anchor the map in an AR session: ``session_from_camera @ inverse(map_from_camera)``.

    ``session_from_camera``: the AR framework's camera pose for the same frame (e.g. ARKit's
    ``frame.camera.transform``) and ``map_from_camera``: QuadLoc's ``world_from_camera`` --
    both with the SAME camera-axis convention (ask the server for ``output_convention="opengl"``
    or convert with :func:`world_from_camera_opencv_to_opengl`). Map points then go to the
    session with ``session_from_map @ [X, 1]``.
    """
    out: np.ndarray = (_check_pose("session_from_camera", session_from_camera)
                       @ invert_pose(map_from_camera))
    return out


def matrix_from_quaternion_wxyz(quaternion_wxyz: np.ndarray) -> np.ndarray:
    """3x3 rotation(s) from unit quaternion(s) ``(w, x, y, z)``, shape (..., 4) -> (..., 3, 3).

    The norm must be 1 within ``QUATERNION_NORM_TOLERANCE`` (then renormalised).
    """
    q = np.asarray(quaternion_wxyz, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternion_wxyz: expected shape (..., 4), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("quaternion_wxyz: contains NaN or infinite values")
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.max(np.abs(n - 1.0)) > QUATERNION_NORM_TOLERANCE:
        raise ValueError(f"quaternion_wxyz: must have unit norm, got |q| = {np.ravel(n)[:4]}")
    w, x, y, z = np.moveaxis(q / n, -1, 0)
    R = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )
    return R.reshape((*q.shape[:-1], 3, 3))


def quaternion_wxyz_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion(s) ``(w, x, y, z)``, ``w >= 0``, of rotation matrices (..., 3, 3).

    Shepperd's method, vectorised: for each matrix the largest of ``4w^2, 4x^2, 4y^2, 4z^2`` is
    taken from the diagonal and the other components from the off-diagonal sums/differences, so
    no division by a small number happens (stable near 180-degree rotations).
    """
    R = np.asarray(rotation, dtype=float)
    if R.ndim < 2 or R.shape[-2:] != (3, 3):
        raise ValueError(f"rotation: expected shape (..., 3, 3), got {R.shape}")
    _check_pose("rotation", _embed(R))
    r = R.reshape(-1, 3, 3)
    d0, d1, d2 = r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]
    # Each row: 4 * (w, x, y, z) * (the chosen component), one row per candidate pivot.
    cand = np.stack(
        [
            np.stack([1 + d0 + d1 + d2, r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0],
                      r[:, 1, 0] - r[:, 0, 1]], -1),
            np.stack([r[:, 2, 1] - r[:, 1, 2], 1 + d0 - d1 - d2, r[:, 0, 1] + r[:, 1, 0],
                      r[:, 0, 2] + r[:, 2, 0]], -1),
            np.stack([r[:, 0, 2] - r[:, 2, 0], r[:, 0, 1] + r[:, 1, 0], 1 - d0 + d1 - d2,
                      r[:, 1, 2] + r[:, 2, 1]], -1),
            np.stack([r[:, 1, 0] - r[:, 0, 1], r[:, 0, 2] + r[:, 2, 0], r[:, 1, 2] + r[:, 2, 1],
                      1 - d0 - d1 + d2], -1),
        ],
        axis=1,
    )  # (n, 4 pivots, 4 components)
    pivot = np.argmax(np.stack([1 + d0 + d1 + d2, 1 + d0 - d1 - d2, 1 - d0 + d1 - d2,
                                1 - d0 - d1 + d2], -1), axis=-1)
    q = cand[np.arange(len(r)), pivot]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    out: np.ndarray = q.reshape((*R.shape[:-2], 4))
    return out


def _embed(R: np.ndarray) -> np.ndarray:
    T = np.zeros((*R.shape[:-2], 4, 4))
    T[..., :3, :3] = R
    T[..., 3, 3] = 1.0
    return T


def pose_matrix_from_quaternion_wxyz(
    quaternion_wxyz: np.ndarray, translation: np.ndarray
) -> np.ndarray:
    """4x4 pose(s) ``[[R(q), t], [0, 1]]`` from ``quaternion_wxyz`` (..., 4) and ``translation``
    (..., 3) in metres. The direction (e.g. ``world_from_camera``) is the caller's to name."""
    R = matrix_from_quaternion_wxyz(quaternion_wxyz)
    t = np.asarray(translation, dtype=float)
    if t.shape[-1:] != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"translation: expected finite values of shape (..., 3), got {t.shape}")
    shape = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros((*shape, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def quaternion_wxyz_translation_from_pose(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(quaternion_wxyz (..., 4), translation (..., 3))`` of 4x4 pose(s); inverse of
    :func:`pose_matrix_from_quaternion_wxyz`."""
    T = _check_pose("pose", pose)
    return quaternion_wxyz_from_matrix(T[..., :3, :3]), T[..., :3, 3].copy()


# --------------------------------------------------------------------------- other layouts


def quaternion_xyzw_from_wxyz(quaternion_wxyz: np.ndarray) -> np.ndarray:
    """``(x, y, z, w)`` (scalar LAST: ARKit/simd, ARCore, Unity, Eigen's coeffs(), ROS) from
    ``(w, x, y, z)`` (scalar first: QuadLoc, GTSAM, Eigen's constructor), shape (..., 4)."""
    q = np.asarray(quaternion_wxyz, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternion_wxyz: expected shape (..., 4), got {q.shape}")
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def quaternion_wxyz_from_xyzw(quaternion_xyzw: np.ndarray) -> np.ndarray:
    """``(w, x, y, z)`` from ``(x, y, z, w)``; inverse of :func:`quaternion_xyzw_from_wxyz`."""
    q = np.asarray(quaternion_xyzw, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternion_xyzw: expected shape (..., 4), got {q.shape}")
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def column_major_from_matrix(matrix: np.ndarray) -> list[float]:
    """The 16 entries of a 4x4 matrix in column-major order (column 0 top to bottom, then
    column 1, ...): what ``simd_float4x4(columns:)``, Unity's ``Matrix4x4`` (m00, m10, m20,
    m30, m01, ...), OpenGL/glm and three.js ``Matrix4.fromArray`` expect. QuadLoc's ``matrix``
    field is row-major (a list of rows): ``matrix[r][c]`` is row ``r``, column ``c``."""
    M = np.asarray(matrix, dtype=float)
    if M.shape != (4, 4):
        raise ValueError(f"matrix: expected shape (4, 4), got {M.shape}")
    return [float(x) for x in M.T.reshape(16)]


def matrix_from_column_major(values: np.ndarray) -> np.ndarray:
    """4x4 matrix from its 16 entries in column-major order (inverse of
    :func:`column_major_from_matrix`)."""
    v = np.asarray(values, dtype=float)
    if v.shape != (16,):
        raise ValueError(f"values: expected 16 numbers, got shape {v.shape}")
    return v.reshape(4, 4).T.copy()


#: Unity camera axes (+X right, +Y up, +Z forward, left-handed) from OpenCV camera axes
#: (+X right, +Y down, +Z forward): a reflection of Y.
UNITY_CAMERA_FROM_OPENCV = np.diag([1.0, -1.0, 1.0])
_UNITY_WORLD_FROM_MAP = {
    # right-handed Y-up world (ARKit/ARCore session, glTF): mirror Z (what AR Foundation does)
    "y": np.diag([1.0, 1.0, -1.0]),
    # right-handed Z-up world (the demo Chess map, ROS, Blender): swap Y and Z
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]),
}


def unity_pose_from_world_from_camera(
    world_from_camera: np.ndarray,
    convention: Literal["opencv", "opengl"] = "opencv",
    world_up: Literal["y", "z"] = "z",
) -> tuple[np.ndarray, np.ndarray]:
    """A QuadLoc ``world_from_camera`` as a Unity ``Transform``: ``(position (3,),
    rotation_xyzw (4,))`` for ``transform.localPosition`` / ``transform.localRotation =
    new Quaternion(x, y, z, w)`` of a camera object parented to the map's root.

    Unity is LEFT-handed (+X right, +Y up, +Z forward for both the world and a camera), QuadLoc
    right-handed, so no rotation converts them: two reflections do. With ``M_w`` the world-side
    reflection (``world_up="y"``: ``(x, y, z) -> (x, y, -z)``, as AR Foundation does for the AR
    session; ``world_up="z"``: ``(x, y, z) -> (x, z, y)``, for a Z-up map such as the demo) and
    ``M_c = diag(1, -1, 1)`` from OpenCV camera axes to Unity's::

        R_unity = M_w R_cv M_c,   position = M_w t

    so that a camera-frame point ``p`` lands where the map point ``world_from_camera @ p`` lands
    after ``M_w``. ``convention`` is the camera axes of the given pose (``opengl`` poses are
    first turned back to OpenCV axes). Units stay metres (Unity's default unit).
    """
    if world_up not in _UNITY_WORLD_FROM_MAP:
        raise ValueError(f"world_up: must be 'y' or 'z', got {world_up!r}")
    if convention not in ("opencv", "opengl"):
        raise ValueError(f"convention: must be 'opencv' or 'opengl', got {convention!r}")
    T = _check_pose("world_from_camera", world_from_camera)
    if T.shape != (4, 4):
        raise ValueError(f"world_from_camera: expected one 4x4 pose, got {T.shape}")
    if convention == "opengl":
        T = T @ _FLIP4
    M_w = _UNITY_WORLD_FROM_MAP[world_up]
    R_unity = M_w @ T[:3, :3] @ UNITY_CAMERA_FROM_OPENCV
    return M_w @ T[:3, 3], quaternion_xyzw_from_wxyz(quaternion_wxyz_from_matrix(R_unity))
