"""The scalar forms of the smooth metrics (one pair of ellipses at a time): the tests' oracle
for the batched :func:`quadloc.factors.metrics.conic_residuals` (the only production implementation
of ``bbox``, ``algebraic``, ``frobenius``, ``wasserstein``, ``bhattacharyya``).

Moved verbatim from ``factors/metrics.py`` (issue 10); the formulas are documented in
:mod:`quadloc.factors.metrics` and ``docs/design/factors.md``.
"""

from __future__ import annotations

import math

import numpy as np

from quadloc.factors import metrics
from quadloc.factors.conics import Ellipse, sigma_entries

_SQRT2 = math.sqrt(2.0)
_INV_SQRT8 = 1.0 / math.sqrt(8.0)


def _sigma(e: Ellipse) -> tuple[float, float, float]:
    """``Sigma = R diag(a^2, b^2) R^T`` as ``(s00, s01, s11)``."""
    return sigma_entries(e.a, e.b, e.angle)


def _dual_vec(e: Ellipse) -> tuple[float, float, float, float, float]:
    """Upper elements ``[C00, C01, C02, C11, C12]`` of the normalised dual conic."""
    s00, s01, s11 = _sigma(e)
    cx, cy = e.cx, e.cy
    return s00 - cx * cx, s01 - cx * cy, -cx, s11 - cy * cy, -cy


def _h(u: float) -> float:
    """``sign(u) sqrt(ln cosh(u / 2) / 2)``: odd, analytic, ``~ u / (2 sqrt 2)`` near 0."""
    x = abs(0.5 * u)
    if x < 1e-2:  # series of ln cosh, relative error < 1e-14
        x2 = x * x
        lc = x2 * (0.5 + x2 * (-1.0 / 12.0 + x2 * (1.0 / 45.0)))
    else:  # ln cosh x = x + ln(1 + e^-2x) - ln 2, no overflow
        lc = x + math.log1p(math.exp(-2.0 * x)) - math.log(2.0)
    return math.copysign(math.sqrt(0.5 * lc), u)


def _canonical_axes(e: Ellipse) -> tuple[float, float, float]:
    """``(a, b, angle)`` with ``a >= b`` (angle shifted by pi/2 when the axes are swapped).

    Unlike :meth:`Ellipse.canonical` the angle is NOT wrapped to ``[-pi/2, pi/2)``: the
    level-set layout rotates with ``angle``, and a wrap by pi would reflect it through the
    centre (a different sample order); ``PoseResidualModel`` uses this same rule."""
    if e.b > e.a:
        return e.b, e.a, e.angle + 0.5 * math.pi
    return e.a, e.b, e.angle


def _bbox_residual(det: Ellipse, proj: Ellipse) -> np.ndarray:
    return det.bbox() - proj.bbox()


def _algebraic_residual(det: Ellipse, proj: Ellipse) -> np.ndarray:
    return np.subtract(_dual_vec(det), _dual_vec(proj))


def _frobenius_residual(det: Ellipse, proj: Ellipse) -> np.ndarray:
    d = np.subtract(_dual_vec(det), _dual_vec(proj))
    d[[1, 2, 4]] *= _SQRT2
    return d


def _wasserstein_residual(det: Ellipse, proj: Ellipse) -> np.ndarray:
    a1, b1, t1 = _canonical_axes(det)
    a2, b2, t2 = _canonical_axes(proj)
    # Angle between the major axes, reduced to [-pi/2, pi/2) (ellipses are pi-symmetric).
    delta = (t1 - t2 + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    s = math.sin(delta)
    P = (a1 * a1 - b1 * b1) * (a2 * a2 - b2 * b2)  # >= 0 with a >= b
    Q = a1 * a2 + b1 * b2
    k = math.sqrt(2.0 * P / (Q + math.sqrt(max(Q * Q - P * s * s, 0.0))))
    return np.array([det.cx - proj.cx, det.cy - proj.cy, a1 - a2, b1 - b2, k * s])


def _bhattacharyya_residual(det: Ellipse, proj: Ellipse) -> np.ndarray:
    d00, d01, d11 = _sigma(det)
    q00, q01, q11 = _sigma(proj)
    # Mahalanobis part with the Cholesky factor of S = (S_D + S_P) / 2.
    s00, s01, s11 = 0.5 * (d00 + q00), 0.5 * (d01 + q01), 0.5 * (d11 + q11)
    l00 = math.sqrt(s00)
    l10 = s01 / l00
    l11 = math.sqrt(max(s11 - l10 * l10, 0.0))
    dx, dy = det.cx - proj.cx, det.cy - proj.cy
    y0 = dx / l00
    y1 = (dy - l10 * y0) / l11
    # N = S_D^-1/2 S_P S_D^-1/2 computed in the detection's frame: D^-1 R^T S_P R D^-1.
    c, s = math.cos(det.angle), math.sin(det.angle)
    t00 = c * (q00 * c + q01 * s) + s * (q01 * c + q11 * s)
    t01 = c * (-q00 * s + q01 * c) + s * (-q01 * s + q11 * c)
    t11 = -s * (-q00 * s + q01 * c) + c * (-q01 * s + q11 * c)
    n00, n01, n11 = t00 / (det.a * det.a), t01 / (det.a * det.b), t11 / (det.b * det.b)
    half_tr, half_diff = 0.5 * (n00 + n11), 0.5 * (n00 - n11)
    rad = math.hypot(half_diff, n01)
    h0 = _h(math.log(half_tr + rad))
    h1 = _h(math.log(max(half_tr - rad, 1e-300)))
    # G = V diag(h) V^T in N's frame (back in the detection frame; rotation-free norm).
    mean, half = 0.5 * (h0 + h1), 0.5 * (h0 - h1)
    if rad > 0.0:
        cos2, sin2 = half_diff / rad, n01 / rad
    else:
        cos2, sin2 = 1.0, 0.0
    g00, g11, g01 = mean + half * cos2, mean - half * cos2, half * sin2
    return np.array([_INV_SQRT8 * y0, _INV_SQRT8 * y1, g00, g11, _SQRT2 * g01])


_RESIDUALS = {
    "bbox": _bbox_residual,
    "algebraic": _algebraic_residual,
    "frobenius": _frobenius_residual,
    "wasserstein": _wasserstein_residual,
    "bhattacharyya": _bhattacharyya_residual,
}


def residual(name: str, detection: Ellipse, projection: Ellipse, **options: object) -> np.ndarray:
    """The oracle's residual of the smooth metrics; the others (iou, giou, qbbox, level_set:
    no second implementation) are :func:`quadloc.factors.metrics.residual`."""
    if name in _RESIDUALS:
        return _RESIDUALS[name](detection, projection)
    return metrics.residual(name, detection, projection, **options)
