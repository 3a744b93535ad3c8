"""Rotations and rigid poses, and the checks of the numbers they are built from.

Conventions (used everywhere in QuadLoc)
----------------------------------------
* Poses are named by direction. ``camera_from_world`` is a 4x4 homogeneous matrix mapping world
  points into the camera frame (OpenCV's ``[R | t]``); ``world_from_camera`` is its inverse.
* Camera axes are OpenCV's: +X right, +Y down, +Z forward.
* Quaternions are ``quaternion_wxyz`` (scalar first), unit norm, canonical sign ``w >= 0``.
* Angles are in radians; rotation vectors (``so3_exp``) are axis * angle.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import SupportsFloat, cast

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.names import GeometryError

__all__ = [
    "DOCUMENT_ROTATION_TOLERANCE",
    "ORTHONORMAL_TOLERANCE",
    "QUATERNION_NORM_TOLERANCE",
    "ROTATION_EXACT_TOLERANCE",
    "canonical_quaternion_wxyz",
    "check_pose",
    "check_rotation",
    "exact_norm",
    "finite_array",
    "finite_float",
    "invert_pose",
    "pose_matrix",
    "quaternion_wxyz_from_rotation",
    "rigid_fit",
    "rotation_angle",
    "rotation_from_quaternion_wxyz",
    "skew",
    "snap_to_rotation",
    "so3_exp",
]


#: Largest ``max|R R^T - I|`` accepted for a rotation matrix (and ``|det R - 1|``).
ORTHONORMAL_TOLERANCE = 1e-6


#: Largest ``| |q| - 1 |`` accepted for a unit quaternion.
QUATERNION_NORM_TOLERANCE = 1e-6


#: The same two tolerances for numbers read from a document (a map file, a request's
#: odometry): JSON writers round, so looser; the value is re-normalised / snapped after the check.
DOCUMENT_ROTATION_TOLERANCE = 1e-4


#: A 3x3 matrix this close to a rotation (``max|R R^T - I|``) is already one for
#: :func:`snap_to_rotation`, which then returns it unchanged instead of running an SVD.
ROTATION_EXACT_TOLERANCE = 1e-12


_I3 = np.eye(3)


def finite_float(owner: str, name: str, value: object) -> float:
    try:
        f = float(cast("SupportsFloat", value))  # or TypeError / ValueError
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"{owner}.{name} must be a number, got {value!r}") from exc
    if not math.isfinite(f):
        raise GeometryError(f"{owner}.{name} must be finite, got {f}")
    return f


def finite_array(owner: str, name: str, value: object, shape: tuple[int, ...]) -> FloatArray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"{owner}.{name} must be numeric with shape {shape}") from exc
    if arr.shape != shape:
        raise GeometryError(f"{owner}.{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise GeometryError(f"{owner}.{name} must be finite, got {arr.tolist()}")
    arr.setflags(write=False)
    return arr


def check_rotation(owner: str, name: str, value: object) -> FloatArray:
    """Validate a 3x3 rotation matrix (orthonormal within ``ORTHONORMAL_TOLERANCE``, det +1)."""
    R = finite_array(owner, name, value, (3, 3))
    err = float(np.max(np.abs(R @ R.T - np.eye(3))))
    if err > ORTHONORMAL_TOLERANCE:
        raise GeometryError(
            f"{owner}.{name} is not orthonormal: max|R R^T - I| = {err:.3g} "
            f"> tolerance {ORTHONORMAL_TOLERANCE:g}"
        )
    det = float(np.linalg.det(R))
    if abs(det - 1.0) > ORTHONORMAL_TOLERANCE:
        raise GeometryError(f"{owner}.{name} must be a proper rotation (det +1), det = {det:.6g}")
    return R


def check_pose(T: object, name: str = "world_from_camera",
               tolerance: float = ORTHONORMAL_TOLERANCE) -> FloatArray:
    """THE rule for a 4x4 rigid transform: finite, last row [0, 0, 0, 1] (within 1e-9),
    rotation block orthonormal within ``tolerance`` (:data:`ORTHONORMAL_TOLERANCE` in process,
    :data:`DOCUMENT_ROTATION_TOLERANCE` for numbers read from a document), det > 0. Raises
    :class:`GeometryError` with ``field=name``; returns the matrix as float (4, 4)."""
    try:
        M = np.array(T, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GeometryError("must be a numeric 4x4 matrix", field=name) from exc
    if M.shape != (4, 4) or not np.isfinite(M).all():
        raise GeometryError(f"must be a finite 4x4 matrix, got shape {M.shape}", field=name)
    rows = M.tolist()  # scalar checks in plain floats: this runs on every refine() call
    x, y, z, w = rows[3]
    if max(abs(x), abs(y), abs(z), abs(w - 1.0)) > 1e-9:
        raise GeometryError(f"last row must be [0, 0, 0, 1], got {rows[3]}", field=name)
    R = M[:3, :3]
    err = float(np.abs(R @ R.T - _I3).max())
    (a, b, c, _), (d, e, f, _), (g, h, i, _) = rows[:3]
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if err > tolerance or det < 0:
        raise GeometryError(
            f"rotation block is not a proper rotation (max|R R^T - I| = {err:.3g}, "
            f"det = {det:.6g})", field=name)
    return M


def exact_norm(values: FloatArray | Sequence[float]) -> float:
    """Euclidean norm of a short vector, the same bits on every machine: squares summed with
    ``math.fsum`` (correctly rounded), unlike ``np.linalg.norm`` whose BLAS dot product may
    round differently on another CPU. Used where the result is hashed (map content hashes)."""
    return math.sqrt(math.fsum(float(v) * float(v) for v in values))


def _is_rotation(rows: list[list[float]], tol: float) -> bool:
    """``max|R R^T - I| <= tol`` and ``det R > 0``, in plain float arithmetic (no BLAS; each
    entry of ``R R^T`` a correctly rounded ``math.fsum``, the symmetric ones computed once: the
    same decision as all nine, ~2 us instead of ~14 us: it runs on every refine() call)."""
    (a, b, c), (d, e, f), (g, h, k) = rows
    err = max(abs(math.fsum((a * a, b * b, c * c)) - 1.0),
              abs(math.fsum((d * d, e * e, f * f)) - 1.0),
              abs(math.fsum((g * g, h * h, k * k)) - 1.0),
              abs(math.fsum((a * d, b * e, c * f))),
              abs(math.fsum((a * g, b * h, c * k))),
              abs(math.fsum((d * g, e * h, f * k))))
    det = a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g)
    return err <= tol and det > 0  # False for NaN


def skew(w: FloatArray) -> FloatArray:
    """Cross-product matrices ``[w]x`` (..., 3, 3) of vectors ``w`` (..., 3):
    ``[w]x @ u = w x u``."""
    w = np.asarray(w, dtype=float)
    # one gather from [0, w, -w]: exactly the entries 0, w_k and -w_k
    padded = np.concatenate([np.zeros((*w.shape[:-1], 1)), w, -w], axis=-1)
    return padded[..., _SKEW_GATHER].reshape(*w.shape[:-1], 3, 3)


#: Index into ``[0, w0, w1, w2, -w0, -w1, -w2]`` of each entry of ``[w]x`` (row-major).
_SKEW_GATHER = np.array([0, 6, 2, 3, 0, 4, 5, 1, 0])


def so3_exp(omega: FloatArray) -> FloatArray:
    """Rotation matrices (..., 3, 3) of rotation vectors ``omega`` (..., 3) rad:
    ``exp([omega]x) = I + (sin th / th) W + ((1 - cos th) / th^2) W^2`` (Rodrigues, ``W =
    [omega]x``, ``th = |omega|``; the second-order series below 1e-8 rad)."""
    w = np.asarray(omega, dtype=float)
    W = skew(w)
    th = np.sqrt(np.sum(w * w, axis=-1))
    small = th < 1e-8
    t = np.where(small, 1.0, th)
    a = np.where(small, 1.0, np.sin(t) / t)[..., None, None]
    b = np.where(small, 0.5, (1.0 - np.cos(t)) / t**2)[..., None, None]
    return np.eye(3) + a * W + b * (W @ W)


def snap_to_rotation(matrix: FloatArray) -> FloatArray:
    """Nearest rotation matrix (Frobenius norm) to a 3x3 ``matrix``, via SVD, det forced to +1.

    A matrix that is already a rotation to :data:`ROTATION_EXACT_TOLERANCE` (1e-12) is returned
    unchanged (as a new float array): the SVD would only move its last bits, and differently
    with another LAPACK build, which must not change what is stored or hashed (maps imported
    from rotation matrices get the same quaternion, and content hash, on every machine).
    """
    M = np.asarray(matrix, dtype=float)
    if M.shape == (3, 3) and _is_rotation(M.tolist(), ROTATION_EXACT_TOLERANCE):
        return M.copy()
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R: FloatArray = U @ D @ Vt
    return R


def rotation_from_quaternion_wxyz(quaternion_wxyz: FloatArray | Sequence[float]) -> FloatArray:
    """3x3 rotation from a unit quaternion ``(w, x, y, z)``.

    The norm must be 1 within ``QUATERNION_NORM_TOLERANCE``; the quaternion is renormalised.
    """
    q = finite_array("quaternion", "quaternion_wxyz", quaternion_wxyz, (4,))
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise GeometryError(f"quaternion_wxyz must have unit norm, |q| = {n:.9g}")
    w, x, y, z = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_wxyz_from_rotation(rotation: FloatArray) -> FloatArray:
    """Unit quaternion ``(w, x, y, z)`` with ``w >= 0`` of a 3x3 rotation matrix.

    Sign convention: ``w > 0``; for half-turns (``|w| <= 1e-12``, returned as exactly 0) the
    first non-zero of ``x, y, z`` is positive, so the result is unique.
    """
    R = np.asarray(rotation, dtype=float)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s])
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s,
                      (R[0, 2] + R[2, 0]) / s])
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = np.array([(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s,
                      (R[1, 2] + R[2, 1]) / s])
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = np.array([(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s,
                      (R[1, 2] + R[2, 1]) / s, 0.25 * s])
    q /= exact_norm(q)  # no BLAS: the same bits on every machine (map hashes)
    return canonical_quaternion_wxyz(q)


def canonical_quaternion_wxyz(q: FloatArray) -> FloatArray:
    """The canonical sign of a unit ``(w, x, y, z)`` quaternion (``q`` and ``-q`` are the same
    rotation): ``w > 0``; for a half-turn (``|w| <= 1e-12``, then set to exactly 0) the first
    non-zero (``> 1e-12``) of ``x, y, z`` is positive. Returns a new array."""
    q = np.array(q, dtype=float)
    if abs(q[0]) <= 1e-12:
        q[0] = 0.0
    nonzero = np.flatnonzero(np.abs(q) > 1e-12)
    if nonzero.size and q[nonzero[0]] < 0:
        q = -q
    return q + 0.0  # -0.0 -> 0.0: equal rotations give equal text (hashes)


def pose_matrix(rotation: FloatArray, translation: FloatArray | Sequence[float]) -> FloatArray:
    """4x4 homogeneous matrix ``[[rotation, translation], [0, 1]]`` (direction kept by caller)."""
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = translation
    return T


def rigid_fit(src: FloatArray, dst: FloatArray) -> FloatArray:
    """The rigid 4x4 ``dst_from_src`` minimising ``sum |T src_i - dst_i|^2`` (points (n, 3) in
    metres, n >= 3; Kabsch: a proper rotation, det +1)."""
    src = np.asarray(src, dtype=float)
    dst = np.asarray(dst, dtype=float)
    cs, cd = src.mean(0), dst.mean(0)
    U, _, Vt = np.linalg.svd((src - cs).T @ (dst - cd))
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(Vt.T @ U.T)))])
    R = Vt.T @ D @ U.T
    return pose_matrix(R, cd - R @ cs)


def invert_pose(a_from_b: FloatArray) -> FloatArray:
    """Inverse of rigid 4x4 transforms: ``b_from_a`` from ``a_from_b``, batched (..., 4, 4)."""
    T = np.asarray(a_from_b, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros(T.shape)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def rotation_angle(rotation_a: FloatArray, rotation_b: FloatArray) -> FloatArray:
    """THE rotation error: the angle (radians, in [0, pi]) of the rotation between
    ``rotation_a`` and ``rotation_b`` (3x3 rotations, batched over leading axes: (..., 3, 3)),
    i.e. ``|Log(R_a^T R_b)|``. Computed from ``|R_a - R_b|_F = 2 sqrt(2) sin(angle / 2)``: exact
    to rounding for small angles, where the arccos of the trace loses half the digits (precision
    degrades only near pi). Returns an array of the leading shape (a 0-d array for one pair;
    ``float()`` it)."""
    d = np.asarray(rotation_a, dtype=float) - np.asarray(rotation_b, dtype=float)
    half_chord = np.sqrt(np.sum(d * d, axis=(-2, -1))) / (2.0 * math.sqrt(2.0))
    angle: FloatArray = 2.0 * np.arcsin(np.minimum(half_chord, 1.0))
    return angle
