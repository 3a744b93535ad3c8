"""Ellipses, ellipsoids, the pinhole camera and the projection ``C* = P Q* P^T``.

Conventions (used everywhere in QuadLoc)
----------------------------------------
* Image coordinates are pixels, origin at the top-left pixel corner, +x right, +y down.
* An ellipse is ``(cx, cy, a, b, angle)``: centre in pixels, **semi**-axes ``a`` (along the
  direction ``angle``) and ``b`` in pixels, ``angle`` in **radians** measured from +x towards +y.
* Shape matrix ``A = R(angle) diag(a^-2, b^-2) R(angle)^T``; level function
  ``Phi(x) = (x - c)^T A (x - c)`` (the contour is the level 1).
* Primal conic ``C = [[A, -A c], [-(A c)^T, c^T A c - 1]]``; the dual conic is ``C^-1``,
  normalised so that ``C*[2, 2] = -1``: ``C* = [[A^-1 - c c^T, -c], [-c^T, -1]]``.
* 2D Gaussian of an ellipse: ``mu = c``, ``Sigma = R diag(a^2, b^2) R^T = A^-1``.
* An ellipsoid is ``(center, axes, rotation)``: ``center`` in world metres, ``axes`` the three
  **semi**-axes in metres along the columns of ``rotation`` (ellipsoid frame -> world frame).
  Dual quadric ``Q* = T diag(a^2, b^2, c^2, -1) T^T`` with ``T = [[rotation, center], [0, 1]]``.
* Poses are named by direction. ``camera_from_world`` is a 4x4 homogeneous matrix mapping world
  points into the camera frame (OpenCV's ``[R | t]``); ``world_from_camera`` is its inverse.
* Camera axes are OpenCV's: +X right, +Y down, +Z forward.
* Quaternions are ``quaternion_wxyz`` (scalar first), unit norm, canonical sign ``w >= 0``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from quadloc.factors.jit import jit
from quadloc.factors.names import FieldError

#: Largest ``max|R R^T - I|`` accepted for a rotation matrix (and ``|det R - 1|``).
ORTHONORMAL_TOLERANCE = 1e-6
#: Largest ``| |q| - 1 |`` accepted for a unit quaternion.
QUATERNION_NORM_TOLERANCE = 1e-6
#: The same two tolerances for numbers read from a document (a map file, a request's
#: odometry): JSON writers round, so looser; the value is re-normalised / snapped after the check.
DOCUMENT_ROTATION_TOLERANCE = 1e-4
_I3 = np.eye(3)
#: Smallest depth (metres, camera Z) a point of an ellipsoid may have for a valid projection.
MIN_DEPTH = 1e-6

__all__ = [
    "DOCUMENT_ROTATION_TOLERANCE",
    "MIN_DEPTH",
    "ORTHONORMAL_TOLERANCE",
    "QUATERNION_NORM_TOLERANCE",
    "ROTATION_EXACT_TOLERANCE",
    "Camera",
    "DegenerateProjectionError",
    "Ellipse",
    "Ellipsoid",
    "FieldError",
    "GeometryError",
    "canonical_quaternion_wxyz",
    "check_pose",
    "dual_conics_from_params",
    "ellipse_params",
    "ellipse_params_and_validity",
    "ellipsoid_depth_margins",
    "exact_norm",
    "gaussians_from_dual_conics",
    "invert_pose",
    "level_values",
    "params_from_dual_conics",
    "params_from_gaussians",
    "pose_matrix",
    "project_ellipsoid",
    "project_ellipsoids_dual",
    "projected_gaussians",
    "quaternion_wxyz_from_rotation",
    "rotation_angle",
    "rotation_from_quaternion_wxyz",
    "sigma_entries",
    "skew",
    "snap_to_rotation",
    "so3_exp",
]


class GeometryError(FieldError):
    """Invalid geometric input (a :class:`FieldError`)."""


class DegenerateProjectionError(ValueError):
    """The image of an ellipsoid is not an ellipse.

    Raised when the ellipsoid crosses the camera's principal plane (part of it is behind the
    camera or the camera is inside it) or the projected conic is degenerate. ``reason`` is a
    short machine-readable code: ``"behind_camera"``, ``"crosses_image_plane"``,
    ``"camera_inside"`` or ``"degenerate_conic"``.
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


# --------------------------------------------------------------------------- validation helpers


def _finite_float(owner: str, name: str, value: object) -> float:
    try:
        f = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"{owner}.{name} must be a number, got {value!r}") from exc
    if not math.isfinite(f):
        raise GeometryError(f"{owner}.{name} must be finite, got {f}")
    return f


def _finite_array(owner: str, name: str, value: object, shape: tuple[int, ...]) -> np.ndarray:
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


def check_rotation(owner: str, name: str, value: object) -> np.ndarray:
    """Validate a 3x3 rotation matrix (orthonormal within ``ORTHONORMAL_TOLERANCE``, det +1)."""
    R = _finite_array(owner, name, value, (3, 3))
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
               tolerance: float = ORTHONORMAL_TOLERANCE) -> np.ndarray:
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



# --------------------------------------------------------------------------- rotations and poses


def sigma_entries(a: float | np.ndarray, b: float | np.ndarray, angle: float | np.ndarray
                  ) -> tuple[float, float, float] | tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``Sigma = R(angle) diag(a^2, b^2) R(angle)^T`` of an ellipse as ``(s00, s01, s11)``;
    with ``(1 / a, 1 / b)`` the entries of its implicit form ``A = Sigma^-1``.

    Floats (``math``, cheap per ellipse: the metrics) or arrays (elementwise: the batched
    paths). ``Sigma`` is the ellipse's covariance-like shape (:meth:`Ellipse.gaussian`).
    """
    trig = (math.cos, math.sin) if isinstance(angle, float | int) else (np.cos, np.sin)
    c, s = trig[0](angle), trig[1](angle)
    a2, b2 = a * a, b * b
    return a2 * c * c + b2 * s * s, (a2 - b2) * c * s, a2 * s * s + b2 * c * c


#: A 3x3 matrix this close to a rotation (``max|R R^T - I|``) is already one for
#: :func:`snap_to_rotation`, which then returns it unchanged instead of running an SVD.
ROTATION_EXACT_TOLERANCE = 1e-12


def exact_norm(values: Sequence[float]) -> float:
    """Euclidean norm of a short vector, the same bits on every machine: squares summed with
    ``math.fsum`` (correctly rounded), unlike ``np.linalg.norm`` whose BLAS dot product may
    round differently on another CPU. Used where the result is hashed (map content hashes)."""
    return math.sqrt(math.fsum(float(v) * float(v) for v in values))


def _is_rotation(rows: list[list[float]], tol: float) -> bool:
    """``max|R R^T - I| <= tol`` and ``det R > 0``, in plain float arithmetic (no BLAS)."""
    err = max(abs(math.fsum(a * b for a, b in zip(rows[i], rows[j], strict=True))
                  - (1.0 if i == j else 0.0)) for i in range(3) for j in range(3))
    (a, b, c), (d, e, f), (g, h, k) = rows
    det = a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g)
    return err <= tol and det > 0  # False for NaN


def skew(w: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``[w]x`` (..., 3, 3) of vectors ``w`` (..., 3):
    ``[w]x @ u = w x u``."""
    w = np.asarray(w, dtype=float)
    # one gather from [0, w, -w]: exactly the entries 0, w_k and -w_k
    padded = np.concatenate([np.zeros((*w.shape[:-1], 1)), w, -w], axis=-1)
    return padded[..., _SKEW_GATHER].reshape(*w.shape[:-1], 3, 3)


#: Index into ``[0, w0, w1, w2, -w0, -w1, -w2]`` of each entry of ``[w]x`` (row-major).
_SKEW_GATHER = np.array([0, 6, 2, 3, 0, 4, 5, 1, 0])


def so3_exp(omega: np.ndarray) -> np.ndarray:
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


def snap_to_rotation(matrix: np.ndarray) -> np.ndarray:
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
    return U @ D @ Vt


def rotation_from_quaternion_wxyz(quaternion_wxyz: Sequence[float]) -> np.ndarray:
    """3x3 rotation from a unit quaternion ``(w, x, y, z)``.

    The norm must be 1 within ``QUATERNION_NORM_TOLERANCE``; the quaternion is renormalised.
    """
    q = _finite_array("quaternion", "quaternion_wxyz", quaternion_wxyz, (4,))
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


def quaternion_wxyz_from_rotation(rotation: np.ndarray) -> np.ndarray:
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


def canonical_quaternion_wxyz(q: np.ndarray) -> np.ndarray:
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


def pose_matrix(rotation: np.ndarray, translation: Sequence[float]) -> np.ndarray:
    """4x4 homogeneous matrix ``[[rotation, translation], [0, 1]]`` (direction kept by caller)."""
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = translation
    return T


def invert_pose(a_from_b: np.ndarray) -> np.ndarray:
    """Inverse of rigid 4x4 transforms: ``b_from_a`` from ``a_from_b``, batched (..., 4, 4)."""
    T = np.asarray(a_from_b, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros(T.shape)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def rotation_angle(rotation_a: np.ndarray, rotation_b: np.ndarray) -> np.ndarray:
    """THE rotation error: the angle (radians, in [0, pi]) of the rotation between
    ``rotation_a`` and ``rotation_b`` (3x3 rotations, batched over leading axes: (..., 3, 3)),
    i.e. ``|Log(R_a^T R_b)|``. Computed from ``|R_a - R_b|_F = 2 sqrt(2) sin(angle / 2)``: exact
    to rounding for small angles, where the arccos of the trace loses half the digits (precision
    degrades only near pi). Returns an array of the leading shape (a 0-d array for one pair;
    ``float()`` it)."""
    d = np.asarray(rotation_a, dtype=float) - np.asarray(rotation_b, dtype=float)
    half_chord = np.sqrt(np.sum(d * d, axis=(-2, -1))) / (2.0 * math.sqrt(2.0))
    return 2.0 * np.arcsin(np.minimum(half_chord, 1.0))


# --------------------------------------------------------------------------- ellipse


@dataclass(frozen=True)
class Ellipse:
    """An image ellipse: centre ``(cx, cy)`` px, semi-axes ``a, b`` px, ``angle`` radians.

    ``a`` lies along the unit vector ``(cos angle, sin angle)``. Instances are validated:
    finite numbers, strictly positive semi-axes.
    """

    cx: float
    cy: float
    a: float
    b: float
    angle: float

    def __post_init__(self) -> None:
        for name in ("cx", "cy", "a", "b", "angle"):
            object.__setattr__(self, name, _finite_float("Ellipse", name, getattr(self, name)))
        for name in ("a", "b"):
            if getattr(self, name) <= 0.0:
                raise GeometryError(
                    f"Ellipse.{name} (semi-axis) must be > 0, got {getattr(self, name)}"
                )

    # -- basic properties
    @property
    def center(self) -> np.ndarray:
        """Centre ``(cx, cy)`` in pixels, shape (2,)."""
        return np.array([self.cx, self.cy])

    @property
    def rotation(self) -> np.ndarray:
        """2x2 rotation by ``angle`` (from +x towards +y): its first column is the direction of
        semi-axis ``a``."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([[c, -s], [s, c]])

    @property
    def area(self) -> float:
        """Area in px^2: ``pi a b``."""
        return math.pi * self.a * self.b

    def shape_matrix(self) -> np.ndarray:
        """``A = R diag(a^-2, b^-2) R^T`` (2x2, px^-2)."""
        R = self.rotation
        return R @ np.diag([self.a**-2, self.b**-2]) @ R.T

    def params(self) -> np.ndarray:
        """``[cx, cy, a, b, angle]`` as a float array of shape (5,)."""
        return np.array([self.cx, self.cy, self.a, self.b, self.angle])

    # -- conics
    def dual_conic(self) -> np.ndarray:
        """Dual conic ``C* = C^-1`` normalised so that ``C*[2, 2] = -1`` (3x3, px^2)."""
        return dual_conics_from_params(self.params()[None])[0]

    @classmethod
    def from_dual_conic(cls, dual_conic: np.ndarray) -> Ellipse:
        """Ellipse of a dual conic of any scale; raises ``DegenerateProjectionError`` if none."""
        return cls(*params_from_dual_conics(np.asarray(dual_conic, dtype=float)[None])[0])

    # -- Gaussian
    def gaussian(self) -> tuple[np.ndarray, np.ndarray]:
        """``(mu, Sigma)``: ``mu = c`` (2,), ``Sigma = R diag(a^2, b^2) R^T`` (2x2)."""
        s00, s01, s11 = sigma_entries(self.a, self.b, self.angle)
        return self.center, np.array([[s00, s01], [s01, s11]])

    @classmethod
    def from_gaussian(cls, mu: Sequence[float], sigma: np.ndarray) -> Ellipse:
        """Inverse of :meth:`gaussian` (``sigma`` symmetric positive definite)."""
        mu = _finite_array("Ellipse.from_gaussian", "mu", mu, (2,))
        S = _finite_array("Ellipse.from_gaussian", "sigma", sigma, (2, 2))
        return cls(*params_from_gaussians(mu[None], S[None])[0])

    # -- boxes, levels, contour
    def bbox(self) -> np.ndarray:
        """Axis-aligned bounding box ``[xmin, ymin, xmax, ymax]`` in pixels."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        hx = math.hypot(self.a * c, self.b * s)
        hy = math.hypot(self.a * s, self.b * c)
        return np.array([self.cx - hx, self.cy - hy, self.cx + hx, self.cy + hy])

    @classmethod
    def from_bbox(cls, xmin: float, ymin: float, xmax: float, ymax: float) -> Ellipse:
        """Axis-aligned ellipse inscribed in a box (the usual box -> ellipse of detectors)."""
        if not xmax > xmin or not ymax > ymin:
            raise GeometryError(
                f"box must have xmax > xmin and ymax > ymin, got {[xmin, ymin, xmax, ymax]}"
            )
        return cls((xmin + xmax) / 2, (ymin + ymax) / 2, (xmax - xmin) / 2, (ymax - ymin) / 2, 0.0)

    def contour_points(self, n: int = 64) -> np.ndarray:
        """``n`` points on the contour at equal parametric angles, shape (n, 2) px."""
        t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        local = np.stack([self.a * np.cos(t), self.b * np.sin(t)], axis=-1)
        return local @ self.rotation.T + self.center

    def canonical(self) -> Ellipse:
        """Same set of points with ``a >= b`` and ``angle`` in ``[-pi/2, pi/2)``."""
        a, b, ang = self.a, self.b, self.angle
        if b > a:
            a, b, ang = b, a, ang + math.pi / 2
        ang = (ang + math.pi / 2) % math.pi - math.pi / 2
        return Ellipse(self.cx, self.cy, a, b, ang)


# --------------------------------------------------------------------------- batched ellipses


def ellipse_params(ellipses: Sequence[Ellipse]) -> np.ndarray:
    """Stack ellipses into an array of shape (N, 5): ``[cx, cy, a, b, angle]`` per row."""
    return np.array([(e.cx, e.cy, e.a, e.b, e.angle) for e in ellipses], dtype=float).reshape(-1, 5)


def dual_conics_from_params(params: np.ndarray) -> np.ndarray:
    """Normalised dual conics (N, 3, 3), ``C*[2, 2] = -1``, from ellipse params (N, 5)."""
    p = np.asarray(params, dtype=float)
    s00, s01, s11 = sigma_entries(p[:, 2], p[:, 3], p[:, 4])
    cx, cy = p[:, 0], p[:, 1]
    out = np.empty((p.shape[0], 3, 3))
    out[:, 0, 0] = s00 - cx * cx
    out[:, 1, 1] = s11 - cy * cy
    out[:, 0, 1] = out[:, 1, 0] = s01 - cx * cy
    out[:, 0, 2] = out[:, 2, 0] = -cx
    out[:, 1, 2] = out[:, 2, 1] = -cy
    out[:, 2, 2] = -1.0
    return out


def ellipse_params_and_validity(center: np.ndarray, sigma: np.ndarray
                                ) -> tuple[np.ndarray, np.ndarray]:
    """(N, 5) canonical params (a >= b, angle in [-pi/2, pi/2)) from centres (N, 2) px and
    ``Sigma = A^-1`` (N, 2, 2) px^2, and (N,) bool: ``Sigma`` positive definite (its smaller
    eigenvalue > 0; the rows where it is not are NaN or meaningless)."""
    sxx, syy, sxy = sigma[:, 0, 0], sigma[:, 1, 1], 0.5 * (sigma[:, 0, 1] + sigma[:, 1, 0])
    half_tr = 0.5 * (sxx + syy)
    disc = np.sqrt(np.maximum((0.5 * (sxx - syy)) ** 2 + sxy**2, 0.0))
    lam_major, lam_minor = half_tr + disc, half_tr - disc
    ok = lam_minor > 0.0
    angle = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    angle = (angle + np.pi / 2) % np.pi - np.pi / 2
    params = np.column_stack([center[:, 0], center[:, 1], np.sqrt(np.maximum(lam_major, 0.0)),
                              np.sqrt(np.maximum(lam_minor, 0.0)), angle])
    return params, ok


def params_from_gaussians(center: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """:func:`ellipse_params_and_validity`'s params; raises ``DegenerateProjectionError`` if a
    ``Sigma`` is not positive definite."""
    params, ok = ellipse_params_and_validity(center, sigma)
    if not ok.all():
        raise DegenerateProjectionError(
            "degenerate_conic",
            f"conic {int(np.argmin(ok))} is not an ellipse (shape not positive definite)")
    return params


def gaussians_from_dual_conics(Cn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """THE centre and Sigma of NORMALISED dual conics ``Cn`` (..., 3, 3), ``Cn[2, 2] = -1``:
    ``mu = -Cn[:2, 2]`` (..., 2) px and ``Sigma = Cn[:2, :2] + mu mu^T`` (..., 2, 2) px^2
    (``Sigma = R diag(a^2, b^2) R^T`` for an ellipse; not positive definite otherwise)."""
    mu = -Cn[..., :2, 2]
    return mu, Cn[..., :2, :2] + mu[..., :, None] * mu[..., None, :]


def gaussian_derivatives_from_dual_conics(mu: np.ndarray, dCn: np.ndarray
                                          ) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives of :func:`gaussians_from_dual_conics` along K directions: given the centres
    ``mu`` (N, 2) px and the derivatives ``dCn`` (N, K, 3, 3) of the normalised dual conics
    (e.g. K = 6 pose tangent directions), return ``dmu`` (N, K, 2) px and ``dSigma``
    (N, K, 2, 2) px^2 (``dSigma = dCn[:2, :2] + dmu mu^T + mu dmu^T``)."""
    dmu = -dCn[..., :2, 2]
    m = mu[:, None, :]
    dsigma = (dCn[..., :2, :2] + dmu[..., :, None] * m[..., None, :]
              + m[..., :, None] * dmu[..., None, :])
    return dmu, dsigma


def params_from_dual_conics(dual_conics: np.ndarray) -> np.ndarray:
    """Ellipse params (N, 5) from dual conics (N, 3, 3) of any scale.

    Raises ``DegenerateProjectionError`` if a conic is not a real ellipse. Output is canonical:
    ``a >= b`` and ``angle`` in ``[-pi/2, pi/2)``.
    """
    C = np.asarray(dual_conics, dtype=float)
    if C.ndim != 3 or C.shape[1:] != (3, 3) or not np.all(np.isfinite(C)):
        raise GeometryError("dual conics must be a finite array of shape (N, 3, 3)")
    w = C[:, 2, 2]
    if np.any(~(np.abs(w) > 0.0)):
        raise DegenerateProjectionError("degenerate_conic", "dual conic with C*[2, 2] = 0 "
                                        "(a parabola or a conic through infinity)")
    return params_from_gaussians(*gaussians_from_dual_conics(C / (-w)[:, None, None]))


def level_values(params: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``Phi_j(x)`` for ellipses (N, 5) at points (N, M, 2); returns (N, M)."""
    p = np.asarray(params, dtype=float)
    d = np.asarray(points, dtype=float) - p[:, None, :2]
    c, s = np.cos(p[:, 4])[:, None], np.sin(p[:, 4])[:, None]
    u = d[..., 0] * c + d[..., 1] * s
    v = -d[..., 0] * s + d[..., 1] * c
    return (u / p[:, 2, None]) ** 2 + (v / p[:, 3, None]) ** 2


# --------------------------------------------------------------------------- ellipsoid


@dataclass(frozen=True)
class Ellipsoid:
    """An ellipsoid in the world: ``center`` (3,) m, semi-``axes`` (3,) m, ``rotation`` (3, 3).

    ``rotation`` maps ellipsoid coordinates to world coordinates; its columns are the directions
    of the semi-axes. Points ``X`` inside satisfy
    ``(X - center)^T rotation diag(axes^-2) rotation^T (X - center) <= 1``.
    """

    center: np.ndarray
    axes: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _finite_array("Ellipsoid", "center", self.center, (3,)))
        axes = _finite_array("Ellipsoid", "axes", self.axes, (3,))
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
    def quaternion_wxyz(self) -> np.ndarray:
        """Orientation as a unit quaternion ``(w, x, y, z)``, ``w >= 0``."""
        return quaternion_wxyz_from_rotation(self.rotation)

    def dual_quadric(self) -> np.ndarray:
        """``Q* = T diag(a^2, b^2, c^2, -1) T^T`` (4x4), ``T = [[rotation, center], [0, 1]]``."""
        T = pose_matrix(self.rotation, self.center)
        return T @ np.diag([*(self.axes**2), -1.0]) @ T.T

    def shape_matrix(self) -> np.ndarray:
        """``M = rotation diag(axes^2) rotation^T`` (3x3, m^2): the quadric's inverse shape."""
        return self.rotation @ np.diag(self.axes**2) @ self.rotation.T


# --------------------------------------------------------------------------- camera


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
            object.__setattr__(self, name, _finite_float("Camera", name, getattr(self, name)))
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
    def from_matrix(cls, K: np.ndarray, width: int, height: int) -> Camera:
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
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def projection_matrix(self, camera_from_world: np.ndarray) -> np.ndarray:
        """``P = K [R | t]`` (3x4) from the 4x4 ``camera_from_world`` transform."""
        return self.K @ np.asarray(camera_from_world, dtype=float)[:3, :]

    def project_points(self, camera_from_world: np.ndarray, points_world: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of world points (N, 3); points must be in front of the camera."""
        T = np.asarray(camera_from_world, dtype=float)
        pc = np.asarray(points_world, dtype=float) @ T[:3, :3].T + T[:3, 3]
        uv = pc @ self.K.T
        return uv[:, :2] / uv[:, 2:3]


# --------------------------------------------------------------------------- projection


def depth_margin(center_depth: np.ndarray, axis_variance: np.ndarray) -> np.ndarray:
    """Smallest camera-frame depth (m) of an ellipsoid: ``z_c - sqrt(d^T S d)``, from its
    centre's depth ``z_c`` (m) and ``d^T S d`` (m^2), its shape matrix ``S = R diag(axes^2)
    R^T`` along the camera's optical axis ``d`` (``S_c[2, 2]`` in the camera frame); any
    matching shapes. The one place of this formula (the pose factors, the map-building
    factors and :func:`ellipsoid_depth_margins` call it)."""
    return center_depth - np.sqrt(np.maximum(axis_variance, 0.0))


def ellipsoid_depth_margins(
    camera_from_world: np.ndarray, centers: np.ndarray, shape_matrices: np.ndarray
) -> np.ndarray:
    """Smallest camera-frame depth (m) of each ellipsoid: ``z_c - sqrt(n^T M n)``, shape
    (..., N) for poses (..., 4, 4) (or ``[R | t]`` (..., 3, 4)).

    The projection is an ellipse exactly when this is positive (the whole ellipsoid is in front
    of the camera's principal plane, which also puts the camera outside it).
    ``centers`` (N, 3) world metres; ``shape_matrices`` (N, 3, 3) = ``R diag(axes^2) R^T``.
    """
    T = np.asarray(camera_from_world, dtype=float)
    r3 = T[..., 2, :3]
    zc = r3 @ np.asarray(centers).T + T[..., 2, 3, None]
    return depth_margin(zc, np.einsum("...i,nij,...j->...n", r3, shape_matrices, r3))


@jit
def _projected_gaussians_kernel(
    P: np.ndarray, T: np.ndarray, centers: np.ndarray, shape_matrices: np.ndarray,
    dual_quadrics: np.ndarray,
) -> tuple[np.ndarray, ...]:
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
    camera: Camera, camera_from_world: np.ndarray, centers: np.ndarray,
    shape_matrices: np.ndarray, dual_quadrics: np.ndarray, min_depth: float = MIN_DEPTH,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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
    camera: Camera, camera_from_world: np.ndarray, dual_quadrics: np.ndarray
) -> np.ndarray:
    """Projected dual conics ``C* = P Q* P^T`` (N, 3, 3), unnormalised, for (N, 4, 4) quadrics.

    No validity check: use :func:`ellipsoid_depth_margins` (or :func:`project_ellipsoid`).
    """
    P = camera.projection_matrix(camera_from_world)
    return np.einsum("ij,njk,lk->nil", P, np.asarray(dual_quadrics, dtype=float), P)


def project_ellipsoid(
    camera: Camera, camera_from_world: np.ndarray, ellipsoid: Ellipsoid,
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
