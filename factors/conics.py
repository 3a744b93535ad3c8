"""Ellipses (conics of the image): parameters, shape matrices, dual conics, 2D Gaussians.

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
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.names import GeometryError
from quadloc.factors.rotations import finite_array, finite_float

__all__ = [
    "DegenerateProjectionError",
    "Ellipse",
    "dual_conics_from_params",
    "ellipse_params",
    "ellipse_params_and_validity",
    "gaussian_derivatives_from_dual_conics",
    "gaussians_from_dual_conics",
    "level_values",
    "params_from_dual_conics",
    "params_from_gaussians",
    "sigma_entries",
]

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


#: floats or float arrays, the same for all the arguments of a call
_Real = TypeVar("_Real", float, FloatArray)


def sigma_entries(a: _Real, b: _Real, angle: _Real) -> tuple[_Real, _Real, _Real]:
    """``Sigma = R(angle) diag(a^2, b^2) R(angle)^T`` of an ellipse as ``(s00, s01, s11)``;
    with ``(1 / a, 1 / b)`` the entries of its implicit form ``A = Sigma^-1``.

    Floats (``math``, cheap per ellipse: the metrics) or arrays (elementwise: the batched
    paths). ``Sigma`` is the ellipse's covariance-like shape (:meth:`Ellipse.gaussian`).
    """
    if isinstance(angle, float | int):
        c, s = math.cos(angle), math.sin(angle)
    else:
        c, s = np.cos(angle), np.sin(angle)
    a2, b2 = a * a, b * b
    return a2 * c * c + b2 * s * s, (a2 - b2) * c * s, a2 * s * s + b2 * c * c


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
            object.__setattr__(self, name, finite_float("Ellipse", name, getattr(self, name)))
        for name in ("a", "b"):
            if getattr(self, name) <= 0.0:
                raise GeometryError(
                    f"Ellipse.{name} (semi-axis) must be > 0, got {getattr(self, name)}"
                )

    # -- basic properties
    @property
    def center(self) -> FloatArray:
        """Centre ``(cx, cy)`` in pixels, shape (2,)."""
        return np.array([self.cx, self.cy])

    @property
    def rotation(self) -> FloatArray:
        """2x2 rotation by ``angle`` (from +x towards +y): its first column is the direction of
        semi-axis ``a``."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([[c, -s], [s, c]])

    @property
    def area(self) -> float:
        """Area in px^2: ``pi a b``."""
        return math.pi * self.a * self.b

    def shape_matrix(self) -> FloatArray:
        """``A = R diag(a^-2, b^-2) R^T`` (2x2, px^-2)."""
        R = self.rotation
        return R @ np.diag([self.a**-2, self.b**-2]) @ R.T

    def params(self) -> FloatArray:
        """``[cx, cy, a, b, angle]`` as a float array of shape (5,)."""
        return np.array([self.cx, self.cy, self.a, self.b, self.angle])

    # -- conics
    def dual_conic(self) -> FloatArray:
        """Dual conic ``C* = C^-1`` normalised so that ``C*[2, 2] = -1`` (3x3, px^2)."""
        conic: FloatArray = dual_conics_from_params(self.params()[None])[0]
        return conic

    @classmethod
    def from_dual_conic(cls, dual_conic: FloatArray) -> Ellipse:
        """Ellipse of a dual conic of any scale; raises ``DegenerateProjectionError`` if none."""
        return cls(*params_from_dual_conics(np.asarray(dual_conic, dtype=float)[None])[0])

    # -- Gaussian
    def gaussian(self) -> tuple[FloatArray, FloatArray]:
        """``(mu, Sigma)``: ``mu = c`` (2,), ``Sigma = R diag(a^2, b^2) R^T`` (2x2)."""
        s00, s01, s11 = sigma_entries(self.a, self.b, self.angle)
        return self.center, np.array([[s00, s01], [s01, s11]])

    @classmethod
    def from_gaussian(cls, mu: Sequence[float], sigma: FloatArray) -> Ellipse:
        """Inverse of :meth:`gaussian` (``sigma`` symmetric positive definite)."""
        m = finite_array("Ellipse.from_gaussian", "mu", mu, (2,))
        S = finite_array("Ellipse.from_gaussian", "sigma", sigma, (2, 2))
        return cls(*params_from_gaussians(m[None], S[None])[0])

    # -- boxes, levels, contour
    def bbox(self) -> FloatArray:
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

    def contour_points(self, n: int = 64) -> FloatArray:
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


def ellipse_params(ellipses: Sequence[Ellipse]) -> FloatArray:
    """Stack ellipses into an array of shape (N, 5): ``[cx, cy, a, b, angle]`` per row."""
    return np.array([(e.cx, e.cy, e.a, e.b, e.angle) for e in ellipses], dtype=float).reshape(-1, 5)


def dual_conics_from_params(params: FloatArray) -> FloatArray:
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


def ellipse_params_and_validity(center: FloatArray, sigma: FloatArray
                                ) -> tuple[FloatArray, BoolArray]:
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


def params_from_gaussians(center: FloatArray, sigma: FloatArray) -> FloatArray:
    """:func:`ellipse_params_and_validity`'s params; raises ``DegenerateProjectionError`` if a
    ``Sigma`` is not positive definite."""
    params, ok = ellipse_params_and_validity(center, sigma)
    if not ok.all():
        raise DegenerateProjectionError(
            "degenerate_conic",
            f"conic {int(np.argmin(ok))} is not an ellipse (shape not positive definite)")
    return params


def gaussians_from_dual_conics(Cn: FloatArray) -> tuple[FloatArray, FloatArray]:
    """THE centre and Sigma of NORMALISED dual conics ``Cn`` (..., 3, 3), ``Cn[2, 2] = -1``:
    ``mu = -Cn[:2, 2]`` (..., 2) px and ``Sigma = Cn[:2, :2] + mu mu^T`` (..., 2, 2) px^2
    (``Sigma = R diag(a^2, b^2) R^T`` for an ellipse; not positive definite otherwise)."""
    mu = -Cn[..., :2, 2]
    return mu, Cn[..., :2, :2] + mu[..., :, None] * mu[..., None, :]


def gaussian_derivatives_from_dual_conics(mu: FloatArray, dCn: FloatArray
                                          ) -> tuple[FloatArray, FloatArray]:
    """Derivatives of :func:`gaussians_from_dual_conics` along K directions: given the centres
    ``mu`` (N, 2) px and the derivatives ``dCn`` (N, K, 3, 3) of the normalised dual conics
    (e.g. K = 6 pose tangent directions), return ``dmu`` (N, K, 2) px and ``dSigma``
    (N, K, 2, 2) px^2 (``dSigma = dCn[:2, :2] + dmu mu^T + mu dmu^T``)."""
    dmu = -dCn[..., :2, 2]
    m = mu[:, None, :]
    dsigma = (dCn[..., :2, :2] + dmu[..., :, None] * m[..., None, :]
              + m[..., :, None] * dmu[..., None, :])
    return dmu, dsigma


def params_from_dual_conics(dual_conics: FloatArray) -> FloatArray:
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


def level_values(params: FloatArray, points: FloatArray) -> FloatArray:
    """``Phi_j(x)`` for ellipses (N, 5) at points (N, M, 2); returns (N, M)."""
    p = np.asarray(params, dtype=float)
    d = np.asarray(points, dtype=float) - p[:, None, :2]
    c, s = np.cos(p[:, 4])[:, None], np.sin(p[:, 4])[:, None]
    u = d[..., 0] * c + d[..., 1] * s
    v = -d[..., 0] * s + d[..., 1] * c
    values: FloatArray = (u / p[:, 2, None]) ** 2 + (v / p[:, 3, None]) ** 2
    return values
