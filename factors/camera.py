"""The pinhole camera, the ellipsoids it sees, and their projection ``C* = P Q* P^T``.

Conventions (used everywhere in QuadLoc)
----------------------------------------
* An ellipsoid is ``(center, axes, rotation)``: ``center`` in world metres, ``axes`` the three
  **semi**-axes in metres along the columns of ``rotation`` (ellipsoid frame -> world frame).
  Dual quadric ``Q* = T diag(a^2, b^2, c^2, -1) T^T`` with ``T = [[rotation, center], [0, 1]]``.
* The camera maps world points with ``camera_from_world`` (4x4, OpenCV axes: +X right, +Y down,
  +Z forward) and its intrinsics ``K`` to pixels (origin at the top-left pixel corner).
* The image of an ellipsoid is an ellipse only if the ellipsoid lies entirely in front of the
  camera (and the camera is outside it): otherwise :class:`DegenerateProjectionError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.conics import (
    DegenerateProjectionError,
    Ellipse,
    params_from_dual_conics,
    sigma_entries,
)
from quadloc.factors.jit import jit, jit_for_kernels
from quadloc.factors.names import GeometryError
from quadloc.factors.rotations import (
    check_rotation,
    finite_array,
    finite_float,
    pose_matrix,
    quaternion_wxyz_from_rotation,
    rotation_from_quaternion_wxyz,
)

__all__ = [
    "BORDER_MARGIN_PX",
    "MIN_DEPTH",
    "TRUNCATED_WEIGHT",
    "Camera",
    "Ellipsoid",
    "border_touching",
    "depth_margin",
    "ellipsoid_depth_margins",
    "project_ellipsoid",
    "project_ellipsoids_dual",
    "projected_gaussians",
    "touches_border",
    "truncation_sigma",
]


#: Smallest depth (metres, camera Z) a point of an ellipsoid may have for a valid projection.
MIN_DEPTH = 1e-6




@dataclass(frozen=True)
class Ellipsoid:
    """An ellipsoid in the world: ``center`` (3,) m, semi-``axes`` (3,) m, ``rotation`` (3, 3).

    ``rotation`` maps ellipsoid coordinates to world coordinates; its columns are the directions
    of the semi-axes. Points ``X`` inside satisfy
    ``(X - center)^T rotation diag(axes^-2) rotation^T (X - center) <= 1``.
    """

    center: FloatArray
    axes: FloatArray
    rotation: FloatArray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", finite_array("Ellipsoid", "center", self.center, (3,)))
        axes = finite_array("Ellipsoid", "axes", self.axes, (3,))
        if np.any(axes <= 0.0):
            raise GeometryError(f"Ellipsoid.axes (semi-axes) must be > 0, got {axes.tolist()}")
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "rotation", check_rotation("Ellipsoid", "rotation", self.rotation))

    @classmethod
    def from_quaternion_wxyz(
        cls, center: Sequence[float], axes: Sequence[float], quaternion_wxyz: Sequence[float]
    ) -> Ellipsoid:
        """Build from a unit quaternion ``(w, x, y, z)`` (ellipsoid frame -> world frame)."""
        return cls(np.asarray(center, float), np.asarray(axes, float),
                   rotation_from_quaternion_wxyz(quaternion_wxyz))

    @property
    def quaternion_wxyz(self) -> FloatArray:
        """Orientation as a unit quaternion ``(w, x, y, z)``, ``w >= 0``."""
        return quaternion_wxyz_from_rotation(self.rotation)

    def dual_quadric(self) -> FloatArray:
        """``Q* = T diag(a^2, b^2, c^2, -1) T^T`` (4x4), ``T = [[rotation, center], [0, 1]]``."""
        T = pose_matrix(self.rotation, self.center)
        return T @ np.diag([*(self.axes**2), -1.0]) @ T.T

    def shape_matrix(self) -> FloatArray:
        """``M = rotation diag(axes^2) rotation^T`` (3x3, m^2): the quadric's inverse shape."""
        return self.rotation @ np.diag(self.axes**2) @ self.rotation.T


@dataclass(frozen=True)
class Camera:
    """Pinhole camera: focal lengths ``fx, fy`` px, principal point ``cx, cy`` px, image size."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, finite_float("Camera", name, getattr(self, name)))
        for name in ("fx", "fy"):
            if getattr(self, name) <= 0:
                raise GeometryError(f"Camera.{name} must be > 0, got {getattr(self, name)}")
        for name in ("width", "height"):
            v = getattr(self, name)
            try:
                ok = not isinstance(v, bool) and float(v).is_integer() and v > 0
            except (TypeError, ValueError, OverflowError):
                ok = False
            if not ok:
                raise GeometryError(f"Camera.{name} must be a positive integer, got {v!r}")
            object.__setattr__(self, name, int(v))

    @classmethod
    def from_matrix(cls, K: FloatArray, width: int, height: int) -> Camera:
        """From a 3x3 intrinsic matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (pixels).

        Raises ``GeometryError`` naming ``K`` for another shape, non-finite entries, a nonzero
        skew ``K[0, 1]`` (this pinhole model has none: dropping it would move every point) or
        any other entry off that pattern (``K[1, 0]``, last row ``[0, 0, 1]``).
        """
        try:
            M = np.array(K, dtype=float)
        except (TypeError, ValueError) as exc:
            raise GeometryError("Camera.from_matrix: K must be a numeric 3x3 matrix") from exc
        if M.shape != (3, 3) or not np.all(np.isfinite(M)):
            raise GeometryError(
                f"Camera.from_matrix: K must be a finite 3x3 matrix, got shape {M.shape}")
        if M[0, 1] != 0.0:
            raise GeometryError(
                f"Camera.from_matrix: K has skew K[0, 1] = {M[0, 1]:g}; only zero skew is "
                "supported")
        if M[1, 0] != 0.0 or M[2, 0] != 0.0 or M[2, 1] != 0.0 or M[2, 2] != 1.0:
            raise GeometryError(
                "Camera.from_matrix: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got "
                f"{M.tolist()}")
        return cls(M[0, 0], M[1, 1], M[0, 2], M[1, 2], width, height)

    @property
    def K(self) -> FloatArray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def projection_matrix(self, camera_from_world: FloatArray) -> FloatArray:
        """``P = K [R | t]`` (3x4) from the 4x4 ``camera_from_world`` transform."""
        P: FloatArray = self.K @ np.asarray(camera_from_world, dtype=float)[:3, :]
        return P

    def project_points(self, camera_from_world: FloatArray, points_world: FloatArray) -> FloatArray:
        """Pixels (N, 2) of world points (N, 3); points must be in front of the camera."""
        T = np.asarray(camera_from_world, dtype=float)
        pc = np.asarray(points_world, dtype=float) @ T[:3, :3].T + T[:3, 3]
        uv = pc @ self.K.T
        pixels: FloatArray = uv[:, :2] / uv[:, 2:3]
        return pixels


#: A detection whose bounding box comes within this many pixels of the image border (or crosses
#: it) is taken as truncated (:func:`touches_border`).
BORDER_MARGIN_PX = 4.0
#: Residual weight of a detection touching the image border (:func:`border_touching`) where
#: views of the same objects are fused: map building's joint refinement and a tracking
#: session's window. Its ellipse is that of the visible part, a bias that consecutive views
#: share, which fusing would otherwise average as if it were independent noise (its noise
#: std is divided by it, its ``sigma`` by its square). Tuning: docs/design/maps.md (map
#: building), docs/tracking.md, "The factor graph" (sessions).
TRUNCATED_WEIGHT = 0.3


def border_touching(params: FloatArray, camera: Camera,
                    margin_px: float = BORDER_MARGIN_PX) -> BoolArray:
    """(N,) bool: ellipse ``j`` of ``params`` (N, 5) (px, rad) has an axis-aligned bounding box
    (half-sizes ``sqrt(Sigma_00)``, ``sqrt(Sigma_11)``, :func:`quadloc.factors.conics.
    sigma_entries`) that comes within ``margin_px`` (px) of the image border or crosses it: the
    object is probably truncated, and a detector then gives an ellipse of its visible part,
    which no pose projects exactly. The one place of this rule (map building down-weights such
    views; pose refinement does not grow their level-set samples)."""
    P = np.asarray(params, dtype=float).reshape(-1, 5)
    s00, _, s11 = sigma_entries(P[:, 2], P[:, 3], P[:, 4])
    hx, hy = np.sqrt(s00), np.sqrt(s11)
    out: BoolArray = ((P[:, 0] - hx < margin_px) | (P[:, 1] - hy < margin_px)
                      | (P[:, 0] + hx > camera.width - margin_px)
                      | (P[:, 1] + hy > camera.height - margin_px))
    return out


def touches_border(ellipse: Ellipse, camera: Camera, margin_px: float = BORDER_MARGIN_PX) -> bool:
    """:func:`border_touching` of one ellipse (px)."""
    return bool(border_touching(ellipse.params(), camera, margin_px)[0])


def truncation_sigma(sigma: FloatArray, truncated: BoolArray,
                     weight: float = TRUNCATED_WEIGHT) -> FloatArray:
    """(N,) the ``sigma`` (N,) views are weighted with where views of the same objects are
    fused: divided by ``weight^2`` (:data:`TRUNCATED_WEIGHT`) where ``truncated`` (N,) bool
    (:func:`border_touching`), so that such a view's residual weight ``1 / sqrt(sigma)`` is
    multiplied by ``weight`` and its information ``1 / sigma`` by ``weight^2``; unchanged
    elsewhere. The one place of this rule (map building's joint refinement, a tracking
    session's window)."""
    s = np.asarray(sigma, dtype=float)
    out: FloatArray = np.where(truncated, s / (weight * weight), s)
    return out


def depth_margin(center_depth: FloatArray, axis_variance: FloatArray) -> FloatArray:
    """Smallest camera-frame depth (m) of an ellipsoid: ``z_c - sqrt(d^T S d)``, from its
    centre's depth ``z_c`` (m) and ``d^T S d`` (m^2), its shape matrix ``S = R diag(axes^2)
    R^T`` along the camera's optical axis ``d`` (``S_c[2, 2]`` in the camera frame); any
    matching shapes. The one place of this formula (the pose factors, the map-building
    factors and :func:`ellipsoid_depth_margins` call it; the kernels call its compiled form
    :data:`depth_margin_kernel`, with scalars)."""
    return center_depth - np.sqrt(np.maximum(axis_variance, 0.0))


#: :func:`depth_margin` compiled, for the kernels (``camera.depth_margin_kernel(z, v)``)
depth_margin_kernel = jit_for_kernels(depth_margin, "depth_margin_kernel")


def ellipsoid_depth_margins(
    camera_from_world: FloatArray, centers: FloatArray, shape_matrices: FloatArray
) -> FloatArray:
    """Smallest camera-frame depth (m) of each ellipsoid: ``z_c - sqrt(n^T M n)``, shape
    (..., N) for poses (..., 4, 4) (or ``[R | t]`` (..., 3, 4)).

    The projection is an ellipse exactly when this is positive (the whole ellipsoid is in front
    of the camera's principal plane, which also puts the camera outside it).
    ``centers`` (N, 3) world metres; ``shape_matrices`` (N, 3, 3) = ``R diag(axes^2) R^T``.
    """
    T = np.asarray(camera_from_world, dtype=float)
    r3 = T[..., 2, :3]
    zc: FloatArray = r3 @ np.asarray(centers).T + T[..., 2, 3, None]
    spread: FloatArray = np.einsum("...i,nij,...j->...n", r3, shape_matrices, r3)
    return depth_margin(zc, spread)


@jit
def _projected_gaussians_kernel(
    P: FloatArray, T: FloatArray, centers: FloatArray, shape_matrices: FloatArray,
    dual_quadrics: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
           BoolArray]:
    """:func:`projected_gaussians`' pose x ellipsoid loop: per (h, s), the entries of ``C* = P
    Q* P^T`` normalised to ``Cn[2, 2] = -1``, the centre ``mu = -Cn[:2, 2]`` and ``Sigma =
    Cn[:2, :2] + mu mu^T`` (the entries of :func:`gaussians_from_dual_conics`), the centre's
    depth and the variance along the optical axis (for :func:`depth_margin`), and whether
    ``C*[2, 2] != 0`` and ``Sigma`` is positive definite."""
    n_h, n_s = P.shape[0], centers.shape[0]
    mx, my = np.empty((n_h, n_s)), np.empty((n_h, n_s))
    s00, s01, s11 = np.empty((n_h, n_s)), np.empty((n_h, n_s)), np.empty((n_h, n_s))
    zc, var = np.empty((n_h, n_s)), np.empty((n_h, n_s))
    ok = np.empty((n_h, n_s), dtype=np.bool_)
    PQ = np.empty((3, 4))
    for h in range(n_h):
        for s in range(n_s):
            Q = dual_quadrics[s]
            for i in range(3):
                for b in range(4):
                    PQ[i, b] = (P[h, i, 0] * Q[0, b] + P[h, i, 1] * Q[1, b]
                                + P[h, i, 2] * Q[2, b] + P[h, i, 3] * Q[3, b])
            c00, c01, c11, c02, c12, c22 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            for b in range(4):
                c00 += PQ[0, b] * P[h, 0, b]
                c01 += PQ[0, b] * P[h, 1, b]
                c11 += PQ[1, b] * P[h, 1, b]
                c02 += PQ[0, b] * P[h, 2, b]
                c12 += PQ[1, b] * P[h, 2, b]
                c22 += PQ[2, b] * P[h, 2, b]
            w = -c22
            ok_w = w != 0.0
            if not ok_w:
                w = 1.0
            x, y = -c02 / w, -c12 / w
            a00, a01, a11 = c00 / w + x * x, c01 / w + x * y, c11 / w + y * y
            mx[h, s], my[h, s], s00[h, s], s01[h, s], s11[h, s] = x, y, a00, a01, a11
            ok[h, s] = ok_w and a00 * a11 - a01 * a01 > 0.0 and a00 > 0.0
            z, v = T[h, 2, 3], 0.0
            for i in range(3):
                z += T[h, 2, i] * centers[s, i]
                for j in range(3):
                    v += T[h, 2, i] * shape_matrices[s, i, j] * T[h, 2, j]
            zc[h, s], var[h, s] = z, v
    return mx, my, s00, s01, s11, zc, var, ok


def projected_gaussians(
    camera: Camera, camera_from_world: FloatArray, centers: FloatArray,
    shape_matrices: FloatArray, dual_quadrics: FloatArray, min_depth: float = MIN_DEPTH,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, BoolArray, FloatArray]:
    """Projections of S ellipsoids at H poses as separate entries (the RANSAC scorer's, the
    P2E residuals' and the tracker's batched projection; a compiled kernel).

    Args:
        camera_from_world: (H, 4, 4), or ``[R | t]`` (H, 3, 4).
        centers, shape_matrices, dual_quadrics: (S, 3), (S, 3, 3), (S, 4, 4) world frame.

    Returns:
        ``(mu_x, mu_y, s00, s01, s11, valid, P)``: the projected ellipses' centres (px) and
        ``A^-1`` entries (px^2), each (H, S); ``valid`` (H, S): the ellipsoid entirely at
        depth > ``min_depth`` (:func:`depth_margin`) and a real ellipse; ``P = K [R | t]``
        (H, 3, 4).
    """
    # fresh C-ordered copies: the kernel is compiled for that one array type
    T = np.array(camera_from_world, dtype=float, order="C")
    P = np.ascontiguousarray(camera.K @ T[:, :3, :])
    mx, my, s00, s01, s11, zc, var, ok = _projected_gaussians_kernel(
        P, T, np.array(centers, dtype=float, order="C"),
        np.array(shape_matrices, dtype=float, order="C"),
        np.array(dual_quadrics, dtype=float, order="C"))
    return mx, my, s00, s01, s11, ok & (depth_margin(zc, var) > min_depth), P


def project_ellipsoids_dual(
    camera: Camera, camera_from_world: FloatArray, dual_quadrics: FloatArray
) -> FloatArray:
    """Projected dual conics ``C* = P Q* P^T`` (N, 3, 3), unnormalised, for (N, 4, 4) quadrics.

    No validity check: use :func:`ellipsoid_depth_margins` (or :func:`project_ellipsoid`).
    """
    P = camera.projection_matrix(camera_from_world)
    conics: FloatArray = np.einsum("ij,njk,lk->nil", P, np.asarray(dual_quadrics, dtype=float), P)
    return conics


def project_ellipsoid(
    camera: Camera, camera_from_world: FloatArray, ellipsoid: Ellipsoid,
    min_depth: float = MIN_DEPTH,
) -> Ellipse:
    """The image ellipse of ``ellipsoid`` seen with the 4x4 ``camera_from_world`` pose.

    Raises ``DegenerateProjectionError`` when the ellipsoid is not entirely at depth
    ``> min_depth`` (metres): behind the camera, crossing its principal plane, or containing it.
    """
    T = np.asarray(camera_from_world, dtype=float)
    margin = float(
        ellipsoid_depth_margins(T, ellipsoid.center[None], ellipsoid.shape_matrix()[None])[0]
    )
    if not margin > min_depth:
        cam_world = -T[:3, :3].T @ T[:3, 3]
        d = ellipsoid.rotation.T @ (cam_world - ellipsoid.center) / ellipsoid.axes
        zc = float(T[2, :3] @ ellipsoid.center + T[2, 3])
        if float(d @ d) <= 1.0:
            reason, what = "camera_inside", "the camera is inside the ellipsoid"
        elif zc <= 0.0:
            reason, what = "behind_camera", "the ellipsoid is behind the camera"
        else:
            reason = "crosses_image_plane"
            what = "the ellipsoid crosses the camera's principal plane"
        raise DegenerateProjectionError(
            reason, f"projection is not an ellipse: {what} (smallest depth {margin:.3g} m)"
        )
    Cd = project_ellipsoids_dual(camera, T, ellipsoid.dual_quadric()[None])
    return Ellipse(*params_from_dual_conics(Cd)[0])
