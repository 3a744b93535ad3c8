"""Minimal pose hypotheses from object correspondences: P3P on centres and P2E (two ellipses).

Both return **camera_from_world** poses as an array of shape (S, 4, 4) (S may be 0): the
OpenCV ``[R | t]`` direction, ``x_cam = R x_world + t``, camera axes +X right, +Y down,
+Z forward. Invert with :func:`quadloc.factors.rotations.invert_pose` for ``world_from_camera``.

* :func:`p3p_hypotheses` — ``cv2.solveP3P`` on three ellipse centres (px) vs the three
  ellipsoid centres (world m); up to 4 solutions (biased by perspective: refinement removes it).
* :func:`p2e_hypotheses` — two ellipse/ellipsoid pairs, 6 DoF (derivation in ``docs/p2e.md``;
  starts and measurements in ``docs/design/localization.md``).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import cv2
import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray, IntArray
from quadloc.factors.camera import MIN_DEPTH, Camera, Ellipsoid, projected_gaussians
from quadloc.factors.conics import Ellipse
from quadloc.factors.jit import jit
from quadloc.factors.rotations import so3_exp

if TYPE_CHECKING:
    from cv2.typing import MatLike

__all__ = ["P3P_REPROJECTION_TOLERANCE_PX", "p2e_hypotheses", "p3p_checked_batch",
           "p3p_grunert_batch", "p3p_hypotheses", "p3p_hypotheses_batch",
           "point_centres", "project_objects", "size_depths"]

_EMPTY = np.zeros((0, 4, 4))


def project_objects(
    camera: Camera, camera_from_world: FloatArray, centers: FloatArray,
    shape_matrices: FloatArray, dual_quadrics: FloatArray, min_depth: float = MIN_DEPTH,
    with_point_centres: bool = True,
) -> tuple[FloatArray, FloatArray, BoolArray, FloatArray | None]:
    """Projections of S ellipsoids at H poses, vectorised (THE batched projection of the RANSAC
    scorer, of the P2E residuals and of the tracker's association; computed by
    :func:`quadloc.factors.camera.projected_gaussians`).

    Args:
        camera_from_world: (H, 4, 4), or ``[R | t]`` (H, 3, 4).
        centers, shape_matrices, dual_quadrics: (S, 3), (S, 3, 3), (S, 4, 4) world frame.

    Returns:
        ``centres`` (H, S, 2) px of the projected ellipses, ``inv_shape`` (H, S, 2, 2) their
        ``A^-1 = R diag(a^2, b^2) R^T`` (px^2, exactly symmetric), ``valid`` (H, S) bool
        (ellipsoid entirely at depth > ``min_depth`` and a real ellipse), ``point_centres``
        (H, S, 2) px: projections of the ellipsoid centres (garbage where the centre is behind
        the camera; None unless ``with_point_centres``).
    """
    mx, my, s00, s01, s11, valid, P = projected_gaussians(
        camera, camera_from_world, centers, shape_matrices, dual_quadrics, min_depth)
    cen = np.stack([mx, my], axis=-1)
    inv_shape = np.stack([s00, s01, s01, s11], axis=-1).reshape(*s00.shape, 2, 2)
    return cen, inv_shape, valid, point_centres(P, centers) if with_point_centres else None


def size_depths(camera: Camera, semi_axes_px: FloatArray,
                object_radius_m: FloatArray | float) -> FloatArray:
    """Depth (m, along the optical axis) at which objects of radius ``object_radius_m`` (...,)
    (the geometric mean of their semi-axes, m) look as large as an ellipse of semi-axes
    ``semi_axes_px`` (2,) or (..., 2) px: ``z = f r / sqrt(a b)`` with ``f`` the mean focal
    length (coarse: exact for a sphere seen near the image centre)."""
    ab = np.asarray(semi_axes_px, dtype=float)
    f = 0.5 * (camera.fx + camera.fy)
    depth: FloatArray = f * np.asarray(object_radius_m, dtype=float) / np.sqrt(
        ab[..., 0] * ab[..., 1])
    return depth


def point_centres(P: FloatArray, centers: FloatArray) -> FloatArray:
    """Pixel projections (H, S, 2) of points ``centers`` (S, 3) (world m) by ``P = K [R | t]``
    (H, 3, 4) (garbage where a point is behind the camera)."""
    hom = P[:, :, :3] @ np.asarray(centers).T + P[:, :, 3:]  # (H, 3, S)
    zh = np.where(np.abs(hom[:, 2]) > 1e-12, hom[:, 2], 1e-12)
    return (hom[:, :2] / zh[:, None]).transpose(0, 2, 1)


def p3p_hypotheses(
    image_points: FloatArray, world_points: FloatArray, camera: Camera
) -> FloatArray:
    """Up to four ``camera_from_world`` poses (S, 4, 4) from three 2D-3D point pairs.

    Args:
        image_points: (3, 2) pixels (ellipse centres).
        world_points: (3, 3) world metres (ellipsoid centres), same order.
        camera: pinhole intrinsics (no distortion).

    Solutions placing any of the three points at depth <= 0 are dropped. Degenerate input
    (collinear points, coincident rays) gives an empty array, never an exception.
    """
    return p3p_hypotheses_batch(np.asarray(image_points, dtype=np.float64).reshape(1, 3, 2),
                                np.asarray(world_points, dtype=np.float64).reshape(1, 3, 3),
                                camera)[0]


def p3p_hypotheses_batch(
    image_points: FloatArray, world_points: FloatArray, camera: Camera
) -> tuple[FloatArray, IntArray]:
    """:func:`p3p_hypotheses` of B samples at once: ``cv2.solveP3P`` per sample, the rotation
    vectors converted and the depths checked for all solutions together (Rodrigues' formula,
    vectorised).

    Args:
        image_points: (B, 3, 2) pixels; world_points: (B, 3, 3) world metres.

    Returns:
        ``(poses (M, 4, 4), sample (M,))``: the ``camera_from_world`` solutions of every
        sample, in sample order, and the sample each came from.
    """
    img = np.ascontiguousarray(np.asarray(image_points, dtype=np.float64).reshape(-1, 3, 2))
    obj = np.ascontiguousarray(np.asarray(world_points, dtype=np.float64).reshape(-1, 3, 3))
    K = camera.K
    rv: list[MatLike] = []  # cv2.solveP3P's rotation / translation vectors (3, 1)
    tv: list[MatLike] = []
    owner: list[int] = []
    for b in range(len(img)):
        try:
            n, rvecs, tvecs = cv2.solveP3P(obj[b], img[b], K, None, flags=cv2.SOLVEPNP_P3P)
        except cv2.error:
            continue
        if n:
            rv.extend(rvecs[:n])
            tv.extend(tvecs[:n])
            owner.extend([b] * n)
    if not rv:
        return _EMPTY, np.zeros(0, dtype=int)
    r = np.concatenate(rv, axis=None, dtype=np.float64).reshape(-1, 3)
    t = np.concatenate(tv, axis=None, dtype=np.float64).reshape(-1, 3)
    sample = np.asarray(owner, dtype=int)
    R = so3_exp(r)
    depth = np.einsum("mpj,mj->mp", obj[sample], R[:, 2]) + t[:, 2, None]
    ok = (np.all(np.isfinite(R), axis=(1, 2)) & np.all(np.isfinite(t), axis=1)
          & np.all(depth > 0.0, axis=1))
    T = np.zeros((int(ok.sum()), 4, 4))
    T[:, :3, :3] = R[ok]
    T[:, :3, 3] = t[ok]
    T[:, 3, 3] = 1.0
    return T, sample[ok]


#: A root of Grunert's quartic whose imaginary part is at most this (relative, at least
#: absolute) is taken as real (then polished by Newton steps; a spurious one only adds a pose
#: that the depth test and the scoring drop).
QUARTIC_IMAG_TOLERANCE = 1e-4


def p3p_grunert_batch(
    image_points: FloatArray, world_points: FloatArray, camera: Camera,
    newton_steps: int = 2, size_depth: FloatArray | None = None, depth_ratio: float = math.inf,
) -> tuple[FloatArray, IntArray]:
    """:func:`p3p_hypotheses_batch` over many samples in one compiled kernel: Grunert's
    quartic in the ratio of two of the distances along the bearing rays (Haralick et al.
    1994, "Review and analysis of solutions of the three point perspective pose estimation
    problem", section 2), all its real roots in closed form (:func:`_quartic_roots_one`),
    polished by ``newton_steps`` Newton steps on the quartic, then the rigid transform of the three
    camera-frame points onto the world points (the two congruent triangles' frames aligned).
    The many-sample search of large maps (:mod:`quadloc.service.localization.constellations`)
    calls it; the same poses as ``cv2.solveP3P`` (tested), in a different order, except in
    symmetric configurations where a root of the quartic is (nearly) double: there it may
    return a pose that does not reproject the three points (a square of objects seen
    head-on: 3 px off; :func:`p3p_checked_batch` falls back to ``cv2.solveP3P`` there).

    Args:
        image_points: (B, 3, 2) pixels; world_points: (B, 3, 3) world metres.
        size_depth: optional (B, 3) depths (m) the points' objects' sizes give
            (:func:`size_depths`): a solution is kept only when each point's depth ``z`` has
            ``1 / depth_ratio < z / size_depth < depth_ratio`` (the test runs in the kernel,
            before a rejected solution's pose is stored). None: no such test.

    Returns:
        ``(poses (M, 4, 4), sample (M,))``: ``camera_from_world`` solutions with all three
        points in front of the camera (and at depths their sizes allow), and the sample each
        came from.
    """
    img = np.asarray(image_points, dtype=np.float64).reshape(-1, 3, 2)
    X = np.asarray(world_points, dtype=np.float64).reshape(-1, 3, 3)
    B = len(img)
    if B == 0:
        return _EMPTY, np.zeros(0, dtype=int)
    j = np.stack([(img[..., 0] - camera.cx) / camera.fx, (img[..., 1] - camera.cy) / camera.fy,
                  np.ones((B, 3))], axis=-1)
    j /= np.linalg.norm(j, axis=-1, keepdims=True)
    zs = np.zeros((0, 3)) if size_depth is None else np.array(size_depth, dtype=np.float64)
    poses, sample, count = _p3p_kernel(np.ascontiguousarray(j), np.array(X), newton_steps,
                                       QUARTIC_IMAG_TOLERANCE, zs.reshape(-1, 3),
                                       float(depth_ratio))
    return poses[:count].copy(), sample[:count].copy()  # not views of the 4 B buffer


#: A compiled P3P solution that reprojects one of its three points further than this (px)
#: from its image point is not exact (:func:`p3p_checked_batch`); exact ones are at ~1e-9 px.
P3P_REPROJECTION_TOLERANCE_PX = 1e-4


def p3p_checked_batch(
    image_points: FloatArray, world_points: FloatArray, camera: Camera
) -> tuple[FloatArray, IntArray]:
    """The poses of :func:`p3p_hypotheses_batch` (``cv2.solveP3P``) at the cost of the
    compiled :func:`p3p_grunert_batch`: its solutions, except for the samples where one of
    them reprojects a point further than :data:`P3P_REPROJECTION_TOLERANCE_PX` (a nearly
    double root of the quartic): those samples are solved by ``cv2.solveP3P``. The RANSAC
    search's P3P (:mod:`quadloc.service.localization.search`).

    Args:
        image_points: (B, 3, 2) pixels; world_points: (B, 3, 3) world metres.

    Returns:
        ``(poses (M, 4, 4), sample (M,))``: ``camera_from_world`` solutions, grouped by
        sample in sample order, and the sample each came from.
    """
    img = np.asarray(image_points, dtype=np.float64).reshape(-1, 3, 2)
    X = np.asarray(world_points, dtype=np.float64).reshape(-1, 3, 3)
    poses, sample = p3p_grunert_batch(img, X, camera)
    if len(poses) == 0:
        return poses, sample
    err = _reprojection_errors(poses, sample, np.ascontiguousarray(img), np.ascontiguousarray(X),
                               camera.fx, camera.fy, camera.cx, camera.cy)
    bad = np.unique(sample[~(err <= P3P_REPROJECTION_TOLERANCE_PX)])
    if len(bad) == 0:
        return poses, sample
    ref, ref_sample = p3p_hypotheses_batch(img[bad], X[bad], camera)
    keep = ~np.isin(sample, bad)
    all_sample = np.concatenate([sample[keep], bad[ref_sample]])
    order = np.argsort(all_sample, kind="stable")
    return np.concatenate([poses[keep], ref])[order], all_sample[order]


@jit
def _reprojection_errors(poses: FloatArray, sample: IntArray, img: FloatArray, X: FloatArray,
                         fx: float, fy: float, cx: float, cy: float) -> FloatArray:
    """Largest pixel distance (per coordinate) of the three world points ``X[sample[m]]``
    (B, 3, 3) m projected by ``poses[m]`` (M, 4, 4) ``camera_from_world`` (pinhole ``fx, fy,
    cx, cy`` px) from their image points ``img[sample[m]]`` (B, 3, 2) px; (M,)."""
    out = np.zeros(poses.shape[0])
    c = np.zeros(3)
    for m in range(poses.shape[0]):
        b = sample[m]
        worst = 0.0
        for k in range(3):
            for i in range(3):
                c[i] = (poses[m, i, 0] * X[b, k, 0] + poses[m, i, 1] * X[b, k, 1]
                        + poses[m, i, 2] * X[b, k, 2] + poses[m, i, 3])
            worst = max(worst, abs(fx * c[0] / c[2] + cx - img[b, k, 0]),
                        abs(fy * c[1] / c[2] + cy - img[b, k, 1]))
        out[m] = worst
    return out


@jit
def _p3p_kernel(j: FloatArray, X: FloatArray, newton_steps: int, imag_tol: float,
                size_depth: FloatArray, depth_ratio: float
                ) -> tuple[FloatArray, IntArray, int]:
    """:func:`p3p_grunert_batch` for unit bearings ``j`` (B, 3, 3) and world points ``X``
    (B, 3, 3): Grunert's quartic, its roots (:func:`_quartic_roots_one`), Newton polish, the
    camera points and the pose from the two triangles' frames; with ``size_depth`` (B, 3)
    (empty: no test) only the solutions whose depths are within ``depth_ratio`` of them.
    Returns poses (4 B, 4, 4), their samples (4 B,) and how many of them are filled."""
    sized = size_depth.shape[0] > 0
    B = X.shape[0]
    poses = np.zeros((4 * B, 4, 4))
    owner = np.zeros(4 * B, dtype=np.intp)
    count = 0
    Y = np.zeros((3, 3))
    dy = np.zeros((2, 3))
    dx = np.zeros((2, 3))
    FY = np.zeros((3, 3))
    FX = np.zeros((3, 3))
    R = np.zeros((3, 3))
    t = np.zeros(3)
    roots = np.zeros(4, dtype=np.complex128)
    for b in range(B):
        a2 = 0.0
        b2 = 0.0
        c2 = 0.0
        ca = 0.0
        cb = 0.0
        cg = 0.0
        for k in range(3):
            a2 += (X[b, 1, k] - X[b, 2, k]) ** 2
            b2 += (X[b, 0, k] - X[b, 2, k]) ** 2
            c2 += (X[b, 0, k] - X[b, 1, k]) ** 2
            ca += j[b, 1, k] * j[b, 2, k]
            cb += j[b, 0, k] * j[b, 2, k]
            cg += j[b, 0, k] * j[b, 1, k]
        if not b2 > 0.0:
            continue
        p = (a2 - c2) / b2
        q = (a2 + c2) / b2
        A4 = (p - 1.0) ** 2 - 4.0 * c2 / b2 * ca ** 2
        A3 = 4.0 * (p * (1.0 - p) * cb - (1.0 - q) * ca * cg + 2.0 * c2 / b2 * ca ** 2 * cb)
        A2 = 2.0 * (p ** 2 - 1.0 + 2.0 * p ** 2 * cb ** 2 + 2.0 * (b2 - c2) / b2 * ca ** 2
                    - 4.0 * q * ca * cb * cg + 2.0 * (b2 - a2) / b2 * cg ** 2)
        A1 = 4.0 * (-p * (1.0 + p) * cb + 2.0 * a2 / b2 * cg ** 2 * cb - (1.0 - q) * ca * cg)
        A0 = (1.0 + p) ** 2 - 4.0 * a2 / b2 * cg ** 2
        if not (abs(A4) > 1e-12 and np.isfinite(A3) and np.isfinite(A2) and np.isfinite(A1)
                and np.isfinite(A0)):
            continue
        _quartic_roots_one(A3 / A4, A2 / A4, A1 / A4, A0 / A4, roots)
        for r in range(4):
            v = roots[r].real
            if abs(roots[r].imag) > imag_tol * max(1.0, abs(v)):
                continue
            for _ in range(newton_steps):
                f = (((A4 * v + A3) * v + A2) * v + A1) * v + A0
                df = ((4.0 * A4 * v + 3.0 * A3) * v + 2.0 * A2) * v + A1
                if abs(df) > 1e-15:
                    step = f / df
                    if np.isfinite(step):
                        v -= step
            if not v > 0.0:
                continue
            u = (((-1.0 + p) * v ** 2 - 2.0 * p * cb * v + 1.0 + p) / (2.0 * (cg - v * ca)))
            s1 = math.sqrt(b2 / (1.0 + v ** 2 - 2.0 * v * cb)) \
                if 1.0 + v ** 2 - 2.0 * v * cb > 0.0 else math.nan
            if not (np.isfinite(u) and np.isfinite(s1) and u > 0.0 and s1 > 0.0):
                continue
            if sized and _clearly_off_depth(j, b, s1, u * s1, v * s1, size_depth, depth_ratio):
                continue  # the exact test below (on the pose) would reject it: no pose built
            for k in range(3):
                Y[0, k] = j[b, 0, k] * s1
                Y[1, k] = j[b, 1, k] * u * s1
                Y[2, k] = j[b, 2, k] * v * s1
                dy[0, k] = Y[1, k] - Y[0, k]
                dy[1, k] = Y[2, k] - Y[0, k]
                dx[0, k] = X[b, 1, k] - X[b, 0, k]
                dx[1, k] = X[b, 2, k] - X[b, 0, k]
            _frame_one(dy[0], dy[1], FY)
            _frame_one(dx[0], dx[1], FX)
            ok = True
            for i in range(3):  # R = FY FX^T, t = Y0 - R X0
                for k in range(3):
                    R[i, k] = FY[i, 0] * FX[k, 0] + FY[i, 1] * FX[k, 1] + FY[i, 2] * FX[k, 2]
                    ok = ok and np.isfinite(R[i, k])
            for i in range(3):
                t[i] = Y[0, i] - (R[i, 0] * X[b, 0, 0] + R[i, 1] * X[b, 0, 1]
                                  + R[i, 2] * X[b, 0, 2])
            for k in range(3):
                z = R[2, 0] * X[b, k, 0] + R[2, 1] * X[b, k, 1] + R[2, 2] * X[b, k, 2] + t[2]
                if not z > 0.0:
                    ok = False
                elif sized:
                    ratio = z / size_depth[b, k]
                    if not (ratio > 1.0 / depth_ratio and ratio < depth_ratio):
                        ok = False
            if not ok:
                continue
            for i in range(3):
                for k in range(3):
                    poses[count, i, k] = R[i, k]
                poses[count, i, 3] = t[i]
            poses[count, 3, 3] = 1.0
            owner[count] = b
            count += 1
    return poses, owner, count


@jit
def _clearly_off_depth(j: FloatArray, b: int, s0: float, s1: float, s2: float,
                       size_depth: FloatArray, depth_ratio: float) -> bool:
    """Whether the camera points ``j[b, k] s_k`` of a P3P solution have a depth outside the
    size-depth interval of :func:`_p3p_kernel` by more than 1e-9 relative (the pose's own
    depths, tested after, differ from these by rounding only): the solution is dropped before
    its pose is built."""
    lo = (1.0 - 1e-9) / depth_ratio
    hi = (1.0 + 1e-9) * depth_ratio
    for k in range(3):
        s = s0 if k == 0 else s1 if k == 1 else s2
        ratio = j[b, k, 2] * s / size_depth[b, k]
        if not (ratio > lo and ratio < hi):
            return True
    return False


@jit
def _frame_one(a: FloatArray, b: FloatArray, F: FloatArray) -> None:
    """:func:`_frames` of one direction pair (3,) into ``F`` (3, 3): the columns
    ``[a, b_perp, a x b_perp]``."""
    na = math.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2)
    for k in range(3):
        F[k, 0] = a[k] / na
    d = b[0] * F[0, 0] + b[1] * F[1, 0] + b[2] * F[2, 0]
    for k in range(3):
        F[k, 1] = b[k] - d * F[k, 0]
    nb = math.sqrt(F[0, 1] ** 2 + F[1, 1] ** 2 + F[2, 1] ** 2)
    for k in range(3):
        F[k, 1] /= nb
    F[0, 2] = F[1, 0] * F[2, 1] - F[2, 0] * F[1, 1]
    F[1, 2] = F[2, 0] * F[0, 1] - F[0, 0] * F[2, 1]
    F[2, 2] = F[0, 0] * F[1, 1] - F[1, 0] * F[0, 1]


#: exp(2 pi i / 3), the cube root of unity of :func:`_quartic_roots_one`.
_OMEGA = cmath.exp(2j * math.pi / 3.0)


@jit
def _quartic_roots_one(a: float, b: float, c: float, d: float, out: np.ndarray) -> None:
    """The four complex roots of ``v^4 + a v^3 + b v^2 + c v + d`` into ``out`` (4,), in closed
    form (Ferrari): the depressed quartic ``y^4 + p y^2 + q y + r`` (``v = y - a / 4``) factored
    as ``(y^2 + p/2 + m)^2 = (s y - q / (2 s))^2``, ``s = sqrt(2 m)``, with ``m`` the
    largest-magnitude root of the resolvent cubic ``m^3 + p m^2 + (p^2/4 - r) m - q^2/8``
    (Cardano). Accurate to a few 1e-8 relative near double roots: callers polish."""
    p = complex(b - 3.0 * a * a / 8.0)
    q = complex(c - a * b / 2.0 + a ** 3 / 8.0)
    r = complex(d - a * c / 4.0 + a * a * b / 16.0 - 3.0 * a ** 4 / 256.0)
    B_ = p
    C_ = p * p / 4.0 - r
    D_ = -q * q / 8.0
    P = C_ - B_ * B_ / 3.0
    Q = 2.0 * B_ ** 3 / 27.0 - B_ * C_ / 3.0 + D_
    root = cmath.sqrt(Q * Q / 4.0 + P ** 3 / 27.0)
    u3 = -Q / 2.0 + root
    if abs(-Q / 2.0 - root) > abs(u3):
        u3 = -Q / 2.0 - root
    u = cmath.exp(cmath.log(u3) / 3.0) if abs(u3) > 0.0 else 0j
    m = 0j
    uk = u
    for k in range(3):
        if k > 0:
            uk = uk * _OMEGA  # u omega^k, omega the cube root of unity
        mk = (uk - P / (3.0 * uk) if abs(uk) > 0.0 else 0j) - B_ / 3.0
        if abs(mk) > abs(m):
            m = mk
    s = cmath.sqrt(2.0 * m)
    if abs(s) > 0.0:
        qs = q / s
        e1 = cmath.sqrt(-2.0 * p - 2.0 * m - 2.0 * qs)
        e2 = cmath.sqrt(-2.0 * p - 2.0 * m + 2.0 * qs)
        out[0] = (s + e1) / 2.0
        out[1] = (s - e1) / 2.0
        out[2] = (-s + e2) / 2.0
        out[3] = (-s - e2) / 2.0
    else:  # q = 0: the biquadratic
        disc = cmath.sqrt(p * p - 4.0 * r)
        ya, yb = cmath.sqrt((-p + disc) / 2.0), cmath.sqrt((-p - disc) / 2.0)
        out[0] = ya
        out[1] = -ya
        out[2] = yb
        out[3] = -yb
    for k in range(4):
        out[k] -= a / 4.0


# ----------------------------------------------------------------------------------- P2E

#: Camera rolls (degrees, about the optical axis, relative to a camera whose +X axis is
#: horizontal) at which :func:`p2e_hypotheses` starts. Handheld cameras stay within them
#: (7-Scenes Chess: |roll| <= 22 deg); the 6-DoF refinement covers the 10 deg between starts.
ROLL_STARTS_DEG = (-30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0)
#: Depth ratios scanned per roll and pitch branch (log-spaced over +-1 around the size guess).
N_RATIO_SAMPLES = 13
#: Starts refined per (roll, pitch branch): the depth ratios with the smallest ellipse residual.
STARTS_PER_GROUP = 2
#: Levenberg-Marquardt iterations of the batched 6-DoF refinement of every start.
LM_ITERATIONS = 15
#: Hypotheses returned at most (distinct, smallest ellipse residual first).
MAX_P2E_HYPOTHESES = 4
#: Two refined starts are one hypothesis when no entry of their ``[R | t]`` differs by more
#: than this (rotation entries unitless, translation metres).
DEDUPE_TOLERANCE = 1e-4
_FD_STEP = 1e-7  # forward-difference step of the LM Jacobian (rad, m)


def _frames(a: FloatArray, b: FloatArray) -> FloatArray:
    """Orthonormal frames ``[a, b_perp, a x b_perp]`` (..., 3, 3) (columns) of direction pairs
    (..., 3) (Gram-Schmidt): ``R = F(a_to, b_to) F(a_from, b_from)^T`` maps ``a_from`` to
    ``a_to`` exactly and ``b_from`` as close as possible to ``b_to``."""
    e1 = a / np.linalg.norm(a, axis=-1, keepdims=True)
    e2 = b - np.sum(b * e1, axis=-1, keepdims=True) * e1
    e2 = e2 / np.linalg.norm(e2, axis=-1, keepdims=True)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=-1)


class _PairProblem:
    """Two detections and their ellipsoids: the 10 ellipse residuals of camera poses.

    Per detection ``i``: ``(c_proj - c_det) / sqrt(a b)`` (2, centre offset in units of the
    detection's size) and ``log(L^-1 Sigma_proj L^-T)`` (3: the entries 00, 11 and
    ``sqrt(2)`` x 01 of the matrix logarithm, ``Sigma_det = L L^T`` its Cholesky factor) — zero
    exactly when the projected ellipse equals the detection, invariant to the image position
    and scale of the detection, smooth (no angle wrap, no ``a``/``b`` swap)."""

    def __init__(self, ellipses: Sequence[Ellipse], ellipsoids: Sequence[Ellipsoid],
                 camera: Camera) -> None:
        self.camera = camera
        self.X: FloatArray = np.array([e.center for e in ellipsoids])
        self.Q: FloatArray = np.array([e.dual_quadric() for e in ellipsoids])
        self.M: FloatArray = np.array([e.shape_matrix() for e in ellipsoids])
        self.c_det: FloatArray = np.array([e.center for e in ellipses])
        self.size: FloatArray = np.array([math.sqrt(e.a * e.b) for e in ellipses])
        self.L_inv: FloatArray = np.array([np.linalg.inv(np.linalg.cholesky(e.gaussian()[1]))
                               for e in ellipses])

    def residuals(self, R: FloatArray, t: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Residuals (N, 10) of ``camera_from_world = [R | t]`` (R (N, 3, 3), t (N, 3)) and
        their validity (N,): both ellipsoids entirely in front of the camera (rows of invalid
        poses are not meaningful)."""
        Rt = np.concatenate([R, t[:, :, None]], axis=2)  # camera_from_world (N, 3, 4)
        mu, S, valid, _ = project_objects(self.camera, Rt, self.X, self.M, self.Q, MIN_DEPTH,
                                          with_point_centres=False)
        valid = np.all(valid, axis=1)
        rc = (mu - self.c_det) / self.size[:, None]
        W = self.L_inv @ S @ self.L_inv.transpose(0, 2, 1)
        m = 0.5 * (W[..., 0, 0] + W[..., 1, 1])
        d = np.sqrt((0.5 * (W[..., 0, 0] - W[..., 1, 1])) ** 2 + W[..., 0, 1] ** 2)
        lo = m - d
        valid &= np.all(lo > 0.0, axis=1)
        l1 = np.log(np.maximum(m + d, 1e-300))
        l2 = np.log(np.maximum(lo, 1e-300))
        # log of a symmetric 2x2 matrix: alpha I + beta (W - m I) (eigen-decomposition in closed
        # form; beta -> 1/m for equal eigenvalues)
        alpha = 0.5 * (l1 + l2)
        close = d <= 1e-9 * np.abs(m)
        beta = np.where(close, 1.0 / np.where(m != 0, m, 1.0),
                        (l1 - l2) / np.where(close, 1.0, 2.0 * d))
        shape = np.stack([alpha + beta * (W[..., 0, 0] - m), alpha + beta * (W[..., 1, 1] - m),
                          math.sqrt(2.0) * beta * W[..., 0, 1]], axis=-1)
        r = np.concatenate([rc, shape], axis=-1).reshape(len(R), 10)
        return r, valid & np.all(np.isfinite(r), axis=1)


def _lm_batch(problem: _PairProblem, R: FloatArray, t: FloatArray, iterations: int
              ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Levenberg-Marquardt (Marquardt's diagonal damping) on the 10 residuals of every start at
    once. Pose update ``[R | t] <- [Exp(w) R | Exp(w) t + v]`` (a left perturbation
    ``(w, v)`` in the camera frame); forward-difference Jacobian. Returns the final R, t and
    squared residual norms (inf for starts that never had a valid projection)."""
    n = len(R)
    r, ok = problem.residuals(R, t)
    cost = np.where(ok, np.sum(r * r, axis=1), np.inf)
    lam = np.full(n, 1e-3)
    active = ok.copy()
    need_jac = ok.copy()
    J = np.zeros((n, 10, 6))
    h = _FD_STEP
    E = so3_exp(h * np.eye(3))
    for _ in range(iterations):
        idx = np.flatnonzero(active & need_jac)
        if idx.size:
            Ri, ti = R[idx], t[idx]
            Rk = np.concatenate([E[:, None] @ Ri[None], np.broadcast_to(Ri, (3, *Ri.shape))])
            tk = np.concatenate([ti[None] @ E.transpose(0, 2, 1),
                                 ti[None] + h * np.eye(3)[:, None, :]])
            rk, okk = problem.residuals(Rk.reshape(-1, 3, 3), tk.reshape(-1, 3))
            rk, okk = rk.reshape(6, idx.size, 10), okk.reshape(6, idx.size)
            J[idx] = ((rk - r[idx][None]) / h).transpose(1, 2, 0)
            active[idx[~np.all(okk, axis=0)]] = False  # at the validity boundary: keep as is
        a = np.flatnonzero(active)
        if a.size == 0:
            break
        Ja, ra = J[a], r[a]
        Jt = Ja.transpose(0, 2, 1)
        A = Jt @ Ja
        g = (Jt @ ra[:, :, None])[:, :, 0]
        diag = np.diagonal(A, axis1=1, axis2=2) + 1e-12
        step = -np.linalg.solve(A + (lam[a, None] * diag)[:, :, None] * np.eye(6),
                                g[:, :, None])[:, :, 0].astype(np.float64, copy=False)
        Ea = so3_exp(step[:, :3])
        Rn = Ea @ R[a]
        tn = (Ea @ t[a][:, :, None])[:, :, 0] + step[:, 3:]
        rn, okn = problem.residuals(Rn, tn)
        cn = np.where(okn, np.sum(rn * rn, axis=1), np.inf)
        acc = cn < cost[a]
        good = a[acc]
        R[good], t[good], r[good], cost[good] = Rn[acc], tn[acc], rn[acc], cn[acc]
        lam[good] = np.maximum(lam[good] * 0.1, 1e-9)
        lam[a[~acc]] *= 10.0
        need_jac[:] = False
        need_jac[good] = True
        done = acc & ((np.max(np.abs(step), axis=1) < 1e-12) | (cn < 1e-24))
        active[a[done]] = False
        active[lam > 1e8] = False
    return R, t, cost


def p2e_hypotheses(
    ellipses: Sequence[Ellipse],
    ellipsoids: Sequence[Ellipsoid],
    camera: Camera,
    up_world: FloatArray,
    *,
    rolls_deg: Sequence[float] = ROLL_STARTS_DEG,
    n_ratio_samples: int = N_RATIO_SAMPLES,
    iterations: int = LM_ITERATIONS,
    max_hypotheses: int = MAX_P2E_HYPOTHESES,
    starts_per_group: int = STARTS_PER_GROUP,
) -> FloatArray:
    """Camera poses from two ellipse/ellipsoid pairs (6 DoF; derivation in ``docs/p2e.md``).

    Starts at ``n_ratio_samples`` depth ratios x camera rolls ``rolls_deg`` x both pitch
    branches (the best ``starts_per_group`` per roll and branch), each refined by a batched
    6-DoF LM (``iterations``) on the 10 ellipse residuals of :class:`_PairProblem`; converged
    starts are merged (:data:`DEDUPE_TOLERANCE`).

    Args:
        ellipses: two detected ellipses (px).
        ellipsoids: the two matched ellipsoids (world m), same order.
        camera: pinhole intrinsics.
        up_world: the map's up direction (3,), any norm (only used for the starts).

    Returns:
        ``camera_from_world`` poses (S, 4, 4), S in 0..``max_hypotheses``, smallest ellipse
        residual first, each with both ellipsoids entirely in front of the camera. Degenerate
        configurations (coincident centres, one centre straight above the other: the rotation
        about their common vertical is unobservable from the starts) give an empty array.
    """
    if len(ellipses) != 2 or len(ellipsoids) != 2:
        raise ValueError("p2e_hypotheses needs exactly two ellipses and two ellipsoids")
    up = np.asarray(up_world, dtype=float)
    up = up / np.linalg.norm(up)
    problem = _PairProblem(ellipses, ellipsoids, camera)
    X = problem.X
    dist = float(np.linalg.norm(X[1] - X[0]))
    if dist < 1e-9:
        return _EMPTY
    v_w = (X[1] - X[0]) / dist
    kappa = float(v_w @ up)
    if abs(kappa) > 1.0 - 1e-9:
        return _EMPTY
    R, t, group = _p2e_starts(ellipses, ellipsoids, camera, X, dist, v_w, up, kappa,
                              np.radians(np.asarray(rolls_deg, dtype=float)), n_ratio_samples)
    if len(R) == 0:
        return _EMPTY
    # per (roll, pitch branch) only the depth ratios whose ellipses fit best are refined
    r0, ok0 = problem.residuals(R, t)
    cost0 = np.where(ok0, np.sum(r0 * r0, axis=1), np.inf)
    order = np.lexsort((cost0, group))
    rank = np.empty(len(order), dtype=int)
    first = np.r_[0, np.flatnonzero(np.diff(group[order])) + 1]
    rank[order] = np.arange(len(order)) - np.repeat(first, np.diff(np.r_[first, len(order)]))
    sel = (rank < starts_per_group) & np.isfinite(cost0)
    if not sel.any():
        return _EMPTY
    R, t = R[sel], t[sel]
    R, t, cost = _lm_batch(problem, R, t, iterations)
    order = np.argsort(cost, kind="stable")
    out: list[FloatArray] = []
    for i in order:
        if not math.isfinite(cost[i]) or len(out) >= max_hypotheses:
            break
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R[i], t[i]
        if all(np.max(np.abs(T - S)) > DEDUPE_TOLERANCE for S in out):
            out.append(T)
    return np.array(out) if out else _EMPTY


def _p2e_starts(
    ellipses: Sequence[Ellipse], ellipsoids: Sequence[Ellipsoid], camera: Camera,
    X: FloatArray, dist: float, v_w: FloatArray, up: FloatArray, kappa: float,
    rolls: FloatArray, n_ratio_samples: int,
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Start poses ``(R (N, 3, 3), t (N, 3), group (N,))`` of :func:`p2e_hypotheses`
    (``docs/p2e.md`` steps 1-5): depth ratios x rolls x pitch branches, vectorised; ``group``
    numbers the (roll, pitch branch) of each start."""
    K_inv = np.linalg.inv(camera.K)
    rays = np.column_stack([np.array([e.center for e in ellipses]), np.ones(2)]) @ K_inv.T
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    # depth guess: a sphere of the ellipsoid's volume seen with the detection's mean semi-axis
    f = math.sqrt(camera.fx * camera.fy)
    r_eq = np.array([float(np.prod(e.axes)) ** (1.0 / 3.0) for e in ellipsoids])
    s_img = np.array([math.sqrt(e.a * e.b) for e in ellipses])
    log_depth0 = np.log(r_eq * np.sqrt(1.0 + (f / s_img) ** 2))
    rho = np.exp(log_depth0[1] - log_depth0[0] + np.linspace(-1.0, 1.0, n_ratio_samples))
    diff = rho[:, None] * rays[1] - rays[0]  # (S, 3): P_2 - P_1 in units of lambda_1
    span = np.linalg.norm(diff, axis=1)
    keep = span > 1e-12
    rho, diff, span = rho[keep], diff[keep], span[keep]
    lam1 = dist / span
    P_c = np.stack([lam1[:, None] * rays[0], (lam1 * rho)[:, None] * rays[1]], axis=1)
    v_c = diff / span[:, None]
    # roll r about the optical axis: u_c = Rz(r) (0, -cos p, sin p) and u_c . v_c = kappa,
    # i.e. the zero-roll pitch equation for Rz(r)^T v_c: A sin(p - phi) = kappa
    c, s = np.cos(rolls), np.sin(rolls)
    Rz = np.zeros((len(rolls), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    v_r = np.einsum("lji,sj->sli", Rz, v_c)  # (S, L, 3)
    amp = np.hypot(v_r[..., 1], v_r[..., 2])
    phi = np.arctan2(v_r[..., 1], v_r[..., 2])
    asin = np.arcsin(np.clip(kappa / np.maximum(amp, 1e-300), -1.0, 1.0))
    p = np.stack([phi + asin, phi + math.pi - asin], axis=-1)  # (S, L, 2) both branches
    valid = (amp > 1e-9)[..., None] & (np.cos(p) > 1e-9)
    u0 = np.stack([np.zeros_like(p), -np.cos(p), np.sin(p)], axis=-1)
    u_c = np.einsum("lij,slbj->slbi", Rz, u0)
    vc = np.broadcast_to(v_c[:, None, None, :], u_c.shape)
    R = _frames(u_c, vc) @ _frames(up, v_w).T  # R up = u_c, R v_w = v_c
    t = np.mean(P_c[:, None, None] - np.einsum("slbij,oj->slboi", R, X), axis=3)
    group = np.broadcast_to(np.arange(2 * len(rolls)).reshape(1, -1, 2), valid.shape)
    return R[valid], t[valid], group[valid]
