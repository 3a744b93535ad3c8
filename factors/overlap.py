"""Exact ellipse areas for the IoU / GIoU metrics, for N pairs of ellipses (compiled kernel).

Decided (issue 10): :func:`quadrant_areas_batch` is the ONLY implementation; the single-pair
:func:`intersection_area`, :func:`hull_area` and :func:`quadrant_areas` are views of it with
N = 1. The former scalar construction is kept verbatim as the tests' independent oracle
(``tests/support/oracles/overlap_reference.py``; equal to ~1e-9 relative,
``tests/factors/test_overlap_batch.py``). Decided (issue 14): the construction is compiled
(:func:`quadloc.factors.jit.jit`, one loop over the pairs, scalar code per pair): the pose factors
evaluate ~7 pairs per LM trial, where numpy's per-call overhead, not arithmetic, was the cost
(docs/design/factors.md, "Exact ellipse areas").

Ellipses are params ``(cx, cy, a, b, angle)`` (px, rad); areas px^2. Everything is computed in
the first ellipse's normalised frame (the unit circle there; areas scale by ``a1 b1``), with a
fixed number of pieces per pair. Intersection: arcs of each contour inside the other, between
the contours' crossings. Convex hull: arcs joined by the outer common tangents. Both sets of
angles are the roots of a trigonometric quadratic (bracketed on ``GRID`` angles, polished by
Newton steps; the hull's also where an ellipse pokes out between two grid angles). Areas are
closed-form Green integrals ``1/2 ∮ x × dx``; their gradients w.r.t. the second ellipse's
Gaussian parameters ``g2 = (mu_x, mu_y, s00, s01, s11)`` (px, px^2) are exact boundary
integrals. The construction, its limits and the derivation: ``docs/design/factors.md`` ("Exact
ellipse areas").
"""

from __future__ import annotations

import math

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.jit import jit

#: Number of parametric angles used to bracket the contour intersections and common tangents.
GRID = 128
#: Accepted for compatibility (option ``hull_directions`` of the metrics); unused: the common
#: tangents are roots of a trigonometric quadratic, bracketed on :data:`GRID` angles.
HULL_DIRECTIONS = 128

_T_GRID = np.linspace(0.0, 2.0 * np.pi, GRID, endpoint=False)
#: (5, GRID): rows 1, cos t, sin t, cos 2t, sin 2t (a trigonometric quadratic on the grid)
_GRID_BASIS = np.stack([np.ones(GRID), np.cos(_T_GRID), np.sin(_T_GRID), np.cos(2 * _T_GRID),
                        np.sin(2 * _T_GRID)])
#: (5, GRID): their derivatives 0, -sin t, cos t, -2 sin 2t, 2 cos 2t
_GRID_DBASIS = np.stack([np.zeros(GRID), -np.sin(_T_GRID), np.cos(_T_GRID),
                         -2.0 * np.sin(2 * _T_GRID), 2.0 * np.cos(2 * _T_GRID)])
#: A grid value above this is outside (rounding-level values, i.e. tangency, count as inside;
#: as the oracle).
_THRESHOLD = 1e-12
_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
_H = _TWO_PI / GRID
#: Newton steps polishing every root from the secant of its grid bracket (~1e-4 rad off a
#: simple root; the hull's tangent functions curve more): at rounding level after 4.
_NEWTON_STEPS = 4
#: Iteration cap of the safeguarded Newton finishing the roots that the plain steps did not
#: (bisection halves the bracket of 0.05 rad at least every other iteration).
_SAFEGUARDED_MAX_ITER = 100
#: Sub-grid points per level (and levels) locating the extremum of a tangent function inside
#: a grid cell (:func:`_add_pokes`): each level keeps 2 of 32 sub-intervals, so the extremum is
#: located to ~3e-9 rad (an ellipse 300 times longer than wide squeezes the normals where the
#: other one pokes out to ~1e-5 rad in its normalised frame).
_POKE_SUBGRID, _POKE_LEVELS = 32, 6
#: Region indices of the kernel's output: all of the second ellipse, the intersection, the hull.
_REGIONS = ("second", "intersection", "hull")
_SECOND, _INTER, _HULL = 0, 1, 2
#: Slots of the per-pair frame vector (:func:`_frame`).
(_CX, _CY, _PX, _PY, _QX, _QY, _DET, _S00, _S01, _S11, _AB1, _AB2, _A1, _B1, _COS1, _SIN1,
 _M00, _M01, _M10, _M11, _CUTS) = range(21)


@jit
def _frame(p1: FloatArray, p2: FloatArray) -> FloatArray:
    """The second ellipse in the first one's normalised frame ``x' = D1^-1 R1^T (x - c1)`` (the
    first is the unit circle there), as a vector indexed by the ``_CX``.. slots: centre ``c``,
    axis vectors ``P = D1^-1 R1^T a2 u2``, ``Q`` (its boundary ``c + P cos s + Q sin s``, ``s``
    its own parametric angle), ``det = P × Q = a2 b2 / (a1 b1)``, ``Sigma' = P P^T + Q Q^T``;
    ``a1 b1``, ``a2 b2``, ``a1``, ``b1``, the first one's ``cos``/``sin`` of its angle, the
    world quantity of the gradients ``M = L2^-T`` (row-major), and from ``_CUTS`` on the 4
    angles ``s`` where the second ellipse crosses the axes (``cos s P + sin s Q = -c`` per
    coordinate; a line that it does not cut gives an extra split point, harmless: the pieces'
    sums are additive)."""
    fr = np.empty(_CUTS + 4)
    a1, b1 = p1[2], p1[3]
    c1, s1 = math.cos(p1[4]), math.sin(p1[4])
    dx, dy = p2[0] - p1[0], p2[1] - p1[1]
    fr[_CX], fr[_CY] = (c1 * dx + s1 * dy) / a1, (c1 * dy - s1 * dx) / b1
    a2, b2 = p2[2], p2[3]
    cd, sd = math.cos(p2[4] - p1[4]), math.sin(p2[4] - p1[4])
    Px, Py, Qx, Qy = a2 * cd / a1, a2 * sd / b1, -b2 * sd / a1, b2 * cd / b1
    fr[_PX], fr[_PY], fr[_QX], fr[_QY] = Px, Py, Qx, Qy
    fr[_DET] = Px * Qy - Py * Qx
    fr[_S00], fr[_S01], fr[_S11] = Px * Px + Qx * Qx, Px * Py + Qx * Qy, Py * Py + Qy * Qy
    fr[_AB1], fr[_AB2], fr[_A1], fr[_B1], fr[_COS1], fr[_SIN1] = a1 * b1, a2 * b2, a1, b1, c1, s1
    c2, s2 = math.cos(p2[4]), math.sin(p2[4])
    fr[_M00], fr[_M01], fr[_M10], fr[_M11] = c2 / a2, -s2 / b2, s2 / a2, c2 / b2
    for m, al, be, ga in ((0, Px, Qx, fr[_CX]), (1, Py, Qy, fr[_CY])):
        phi = math.atan2(be, al)
        dphi = math.acos(min(max(-ga / math.hypot(al, be), -1.0), 1.0))
        fr[_CUTS + m], fr[_CUTS + 2 + m] = phi + dphi, phi - dphi
    return fr


@jit
def _crossing_coefficients(fr: FloatArray) -> FloatArray:
    """(5,) ``k`` of ``f(t) = Phi_2(u(t)) - 1 = k0 + k1 cos t + k2 sin t + k3 cos 2t + k4 sin
    2t`` on the unit circle ``u(t)`` (< 0 inside the second ellipse; oracle:
    ``_crossing_coefficients``), with ``A' = Sigma'^-1 = adj(Sigma') / det^2``."""
    d2 = fr[_DET] * fr[_DET]
    A00, A01, A11 = fr[_S11] / d2, -fr[_S01] / d2, fr[_S00] / d2
    cx, cy = fr[_CX], fr[_CY]
    Acx, Acy = A00 * cx + A01 * cy, A01 * cx + A11 * cy
    k = np.empty(5)
    k[0], k[1], k[2] = 0.5 * (A00 + A11) + cx * Acx + cy * Acy - 1.0, -2.0 * Acx, -2.0 * Acy
    k[3], k[4] = 0.5 * (A00 - A11), A01
    return k


@jit
def _tangent_coefficients(fr: FloatArray) -> FloatArray:
    """(5,) ``k`` of ``g(phi) = (1 - c . n)^2 - n^T Sigma' n``, ``n = (cos phi, sin phi)``,
    scaled to ``sum |k| = 1``: zero where the line of normal ``n`` touching the unit circle
    touches the second ellipse too (common tangents; the outer ones, where the support ``c . n
    + sqrt(n^T Sigma' n)`` of the second ellipse is 1, are the hull's)."""
    cx, cy = fr[_CX], fr[_CY]
    k = np.empty(5)
    k[0] = 1.0 + 0.5 * (cx * cx + cy * cy - fr[_S00] - fr[_S11])
    k[1], k[2] = -2.0 * cx, -2.0 * cy
    k[3], k[4] = 0.5 * (cx * cx - cy * cy - fr[_S00] + fr[_S11]), cx * cy - fr[_S01]
    scale = max(abs(k[0]) + abs(k[1]) + abs(k[2]) + abs(k[3]) + abs(k[4]), 1e-300)
    for m in range(5):
        k[m] /= scale
    return k


@jit
def _trig(k: FloatArray, t: float) -> tuple[float, float]:
    """The trigonometric quadratic ``k`` (5,) and its derivative at ``t``."""
    c, s = math.cos(t), math.sin(t)
    cs = c * s
    c2, s2 = c * c - s * s, cs + cs
    return (k[0] + k[1] * c + k[2] * s + k[3] * c2 + k[4] * s2,
            k[2] * c - k[1] * s + 2.0 * (k[4] * c2 - k[3] * s2))


@jit
def _sort(a: FloatArray) -> None:
    """Sort a short array in place (insertion sort: numba's np.sort costs seconds to compile)."""
    for i in range(1, a.size):
        v = a[i]
        j = i - 1
        while j >= 0 and a[j] > v:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v


@jit
def _grid_values(k: FloatArray, basis: FloatArray) -> FloatArray:
    """The trigonometric quadratic ``k`` (5,) at the :data:`GRID` angles (GRID,), ``basis``
    :data:`_GRID_BASIS` (the grids are arguments: numba does not cache a function that reads a
    global array)."""
    f = np.empty(GRID)
    for i in range(GRID):
        f[i] = (k[0] + k[1] * basis[1, i] + k[2] * basis[2, i] + k[3] * basis[3, i]
                + k[4] * basis[4, i])
    return f


@jit
def _clamp01(x: float) -> float:
    """``fmin(fmax(x, 0), 1)``: nan -> 0 (as numpy's fmax), +-inf -> 1 / 0."""
    if not x > 0.0:
        return 0.0
    return 1.0 if x > 1.0 else x


@jit
def _brackets(f: FloatArray, br: FloatArray) -> None:
    """Grid brackets of the roots of a trigonometric quadratic whose grid values are ``f``
    (GRID,): the first 4 cells where the sign (``f > _THRESHOLD``) changes, written to ``br``
    (5, 4): rows has (0/1), lower end, upper end, value at each end. A trigonometric quadratic
    changes sign at most 4 times."""
    for j in range(4):
        br[0, j], br[1, j], br[2, j], br[3, j], br[4, j] = 0.0, 0.0, _H, f[0], f[1]
    n = 0
    for i in range(GRID):
        i1 = i + 1 if i + 1 < GRID else 0
        if (f[i] > _THRESHOLD) != (f[i1] > _THRESHOLD) and n < 4:
            br[0, n], br[1, n], br[2, n], br[3, n], br[4, n] = 1.0, i * _H, i * _H + _H, f[i], \
                f[i1]
            n += 1


@jit
def _add_pokes(k: FloatArray, f: FloatArray, br: FloatArray, dbasis: FloatArray) -> None:
    """Add to ``br`` (:func:`_brackets`) the root pairs of ``k`` that lie between two grid
    angles (no sign change on the grid; oracle: the extremum search of ``_hull_pieces``). With
    ``|f''| <= M = |k1| + |k2| + 4 (|k3| + |k4|)``, ``f`` keeps its sign over a cell if it does
    over the Taylor lower bound ``sigma f_i + sigma f'_i tau - M tau^2 / 2`` from either end
    (concave: checked at the other end); in the remaining cells the extremum is located on a
    sub-grid, and a sign change there brackets both roots. ``dbasis``:
    :data:`_GRID_DBASIS`."""
    bound = (0.5 * _H * _H) * (abs(k[1]) + abs(k[2]) + 4.0 * (abs(k[3]) + abs(k[4])))
    for i in range(GRID):
        i1 = i + 1 if i + 1 < GRID else 0
        g, g1 = f[i] - _THRESHOLD, f[i1] - _THRESHOLD
        dg = dg1 = 0.0
        for m in range(5):
            dg += k[m] * dbasis[m, i]
            dg1 += k[m] * dbasis[m, i1]
        sigma = 1.0 if g > 0.0 else -1.0
        if not (sigma * (g + _H * dg) <= bound and sigma * (g1 - _H * dg1) <= bound
                and sigma * g1 > 0.0):
            continue
        sign = 1.0 if f[i] > 0.0 else -1.0
        lo, width = i * _H, _H
        for _ in range(_POKE_LEVELS):
            best, jbest = np.inf, 0
            for j in range(_POKE_SUBGRID + 1):
                v = sign * _trig(k, lo + width * (j / _POKE_SUBGRID))[0]
                if v < best:
                    best, jbest = v, j
            j = min(max(jbest - 1, 0), _POKE_SUBGRID - 2)
            lo = lo + j * width / _POKE_SUBGRID
            width = 2.0 * width / _POKE_SUBGRID
        t_min = lo + 0.5 * width
        f_min = _trig(k, t_min)[0]
        a = b = -1
        for j in range(4):
            if br[0, j] == 0.0:
                if a < 0:
                    a = j
                elif b < 0:
                    b = j
        if sign * f_min >= 0.0 or b < 0:
            continue
        br[0, a], br[1, a], br[2, a], br[3, a], br[4, a] = 1.0, i * _H, t_min, f[i], f_min
        br[0, b], br[1, b], br[2, b], br[3, b], br[4, b] = 1.0, t_min, (i + 1) * _H, f_min, f[i1]


@jit
def _safeguarded(k: FloatArray, t: float, lo: float, hi: float, f_lo: float) -> float:
    """The root of ``k`` in the bracket ``[lo, hi]`` (value ``f_lo`` at ``lo``), from ``t``:
    Newton steps that stay in the bracket, else bisection, the bracket shrinking at every
    iterate (oracle: ``_bracketed_root``); up to :data:`_SAFEGUARDED_MAX_ITER` iterations, until
    a step or the bracket is below 1e-12 rad, or ``f`` is 0."""
    neg_lo = not f_lo > _THRESHOLD
    for _ in range(_SAFEGUARDED_MAX_ITER):
        f, df = _trig(k, t)
        if f == 0.0:
            break
        if (f < 0.0) == neg_lo:  # the root is right of t
            lo = t
        else:
            hi = t
        t_new = t - f / df
        newton = lo < t_new < hi
        if not newton:
            t_new = 0.5 * (lo + hi)
        done = (newton and abs(t_new - t) < 1e-12) or hi - lo < 1e-12
        t = t_new
        if done:
            break
    return t


@jit
def _roots(k: FloatArray, br: FloatArray) -> FloatArray:
    """The roots (4,) of ``k`` in the brackets ``br`` (:func:`_brackets`), sorted in ``[0, 2
    pi)``: from the secant, :data:`_NEWTON_STEPS` Newton steps kept in the bracket; the roots
    whose last step was not at rounding level (a function that curves a lot within its
    bracket) are finished by :func:`_safeguarded`. Empty slots repeat the largest root (0 if
    none: extra split points, harmless)."""
    t = np.zeros(4)
    first = -np.inf
    for j in range(4):
        if br[0, j] == 0.0:
            continue
        lo, hi, f0, f1 = br[1, j], br[2, j], br[3, j], br[4, j]
        tj = lo + (hi - lo) * _clamp01(f0 / (f0 - f1))
        f = step = moved = 0.0
        for _ in range(_NEWTON_STEPS):
            f, df = _trig(k, tj)
            step = f / df
            # a zero derivative: +-inf -> a bracket end, nan -> lo
            t_new = tj - step
            t_new = min(t_new, hi) if t_new >= lo else lo
            moved = t_new - tj
            tj = t_new
        # converged: at a root, or the last (unclamped) step below 1e-9 rad
        if not (f == 0.0 or (abs(moved) < 1e-9 and abs(step) < 1e-9)):
            tj = _safeguarded(k, tj, lo, hi, f0)
        t[j] = tj
        first = max(first, tj)
    for j in range(4):
        if br[0, j] == 0.0:
            t[j] = first if first > -np.inf else 0.0
        t[j] = t[j] % _TWO_PI
    _sort(t)
    return t


@jit
def _quadrant(x: float, y: float) -> int:
    """Quadrant 0..3 of a point of the normalised frame, counter-clockwise from ``+u, +v`` (as
    the oracle's ``quadrant``: ``y >= 0`` upper, ``x >= 0`` right)."""
    if y >= 0.0:
        return 0 if x >= 0.0 else 1
    return 2 if x < 0.0 else 3


@jit
def _circle_arc(fr: FloatArray, t0: float, t1: float, out: FloatArray) -> None:
    """Add the area ``1/2 ∫ x × dx`` of the arc ``[t0, t1]`` (``0 <= t0 < 2 pi``, ``t1 <= t0 +
    2 pi``) of the unit circle (the first ellipse, which does not move: no gradient) to a
    region's sums ``out`` (4 quadrants, area + 5 gradient) ``[quadrant, 0]``: half the length
    of its part in each quadrant, times ``a1 b1``."""
    for q in range(4):
        length = 0.0
        for turn in range(2):
            q_lo = q * _HALF_PI + turn * _TWO_PI
            ov = min(t1, q_lo + _HALF_PI) - max(t0, q_lo)
            if ov > 0.0:
                length += ov
        out[q, 0] += 0.5 * fr[_AB1] * length


@jit
def _ellipse_arc(fr: FloatArray, t0: float, t1: float, grad: bool, b: FloatArray,
                 out: FloatArray) -> None:
    """Add the arc ``[t0, t1]`` of the second ellipse to a region's sums ``out`` (4, 6) (oracle:
    ``_piece_sums`` with ``axes``): split where the ellipse crosses the axes (the pieces then
    lie in one quadrant each), areas ``1/2 ∫ x × dx`` (times ``a1 b1``) in column 0, gradients
    w.r.t. ``g2`` in world units in columns 1..5 (oracle: ``_Boundary.arc``). ``b``: scratch
    (6,)."""
    cx, cy, Px, Py, Qx, Qy = fr[_CX], fr[_CY], fr[_PX], fr[_PY], fr[_QX], fr[_QY]
    b[0], b[5] = t0, t1
    for m in range(4):
        b[1 + m] = min(t0 + (fr[_CUTS + m] - t0) % _TWO_PI, t1)
    _sort(b[1:5])
    h_ab1 = 0.5 * fr[_AB1]
    w = fr[_AB2]
    m00, m01, m10, m11 = fr[_M00], fr[_M01], fr[_M10], fr[_M11]
    for p in range(5):
        lo, hi = b[p], b[p + 1]
        if not hi > lo:  # an empty piece (a cut outside the arc) adds nothing
            continue
        cl, sl, ch, sh = math.cos(lo), math.sin(lo), math.cos(hi), math.sin(hi)
        mid = 0.5 * (lo + hi)
        cm, sm = math.cos(mid), math.sin(mid)
        q = _quadrant(cx + cm * Px + sm * Qx, cy + cm * Py + sm * Qy)
        dc, ds = ch - cl, sh - sl
        o = out[q]
        o[0] += h_ab1 * (fr[_DET] * (hi - lo) + cx * (dc * Py + ds * Qy)
                         - cy * (dc * Px + ds * Qx))
        if grad:
            half = 0.5 * (hi - lo)
            qq = 0.5 * (sh * ch - sl * cl)  # 1/4 (sin 2 t1 - sin 2 t0)
            cc, ss, cs_ = half + qq, half - qq, 0.5 * (sh * sh - sl * sl)
            r00, r01 = m00 * cc + m01 * cs_, m00 * cs_ + m01 * ss
            r10, r11 = m10 * cc + m11 * cs_, m10 * cs_ + m11 * ss
            o[1] += w * (m00 * ds - m01 * dc)
            o[2] += w * (m10 * ds - m11 * dc)
            o[3] += (0.5 * w) * (r00 * m00 + r01 * m01)
            o[4] += w * (r00 * m10 + r01 * m11)
            o[5] += (0.5 * w) * (r10 * m10 + r11 * m11)


@jit
def _segment(fr: FloatArray, x0: float, y0: float, x1: float, y1: float, end2: bool,
             par: float, grad: bool, out: FloatArray) -> None:
    """Add a tangent segment of the hull (start ``(x0, y0)``, end ``(x1, y1)`` in the
    normalised frame; ``end2``: it ends on the second ellipse, at its angle ``par``, else
    starts there) to the hull's sums ``out`` (4, 6) (oracle: ``_piece_sums``), split where it
    crosses the axes.
    The gradient: ``1/2 dx(q) × (end - start)``, shared along the segment."""
    wx, wy = x1 - x0, y1 - y0
    sb = np.empty(4)
    sb[0], sb[1], sb[2], sb[3] = 0.0, _clamp01(-x0 / wx), _clamp01(-y0 / wy), 1.0
    if sb[1] > sb[2]:
        sb[1], sb[2] = sb[2], sb[1]
    ax, by = fr[_A1] * wx, fr[_B1] * wy
    Wx, Wy = fr[_COS1] * ax - fr[_SIN1] * by, fr[_SIN1] * ax + fr[_COS1] * by
    u0, u1 = math.cos(par), math.sin(par)
    v0, v1 = fr[_M00] * u0 + fr[_M01] * u1, fr[_M10] * u0 + fr[_M11] * u1
    for p in range(3):
        s0, s1 = sb[p], sb[p + 1]
        xa, ya, xb, yb = x0 + s0 * wx, y0 + s0 * wy, x0 + s1 * wx, y0 + s1 * wy
        o = out[_quadrant(0.5 * (xa + xb), 0.5 * (ya + yb))]
        o[0] += 0.5 * fr[_AB1] * (xa * yb - ya * xb)
        if grad:
            share = 0.5 * (s1 * s1 - s0 * s0 if end2 else (1 - s0) ** 2 - (1 - s1) ** 2)
            o[1] += share * Wy
            o[2] += -share * Wx
            o[3] += share * (0.5 * v0 * Wy)
            o[4] += share * (0.5 * (v1 * Wy - v0 * Wx))
            o[5] += -share * (0.5 * v1 * Wx)


@jit
def _point(fr: FloatArray, s: float) -> tuple[float, float]:
    """The second ellipse's point at its angle ``s``, normalised frame."""
    cs, ss = math.cos(s), math.sin(s)
    return fr[_CX] + cs * fr[_PX] + ss * fr[_QX], fr[_CY] + cs * fr[_PY] + ss * fr[_QY]


@jit
def _hull(fr: FloatArray, phi: FloatArray, grad: bool, b: FloatArray, out: FloatArray
          ) -> None:
    """Add the hull's boundary to its sums ``out`` (4, 6) (oracle: ``_hull_pieces``): over the four
    intervals of normal angles between the sorted common tangents ``phi`` (4,), the unit
    circle's arc ``[phi_j, phi_j+1]`` (its contact angle is the normal angle) or the second
    ellipse's ``[s_j, s_j + span_j]``, whichever supports the interval, and the tangent segment
    at each ``phi_j+1`` where the support switches. ``b``: scratch (6,)."""
    p1 = np.empty(4)
    p1[:3], p1[3] = phi[1:], phi[0] + _TWO_PI
    # the second ellipse's support at the middle normal: > 1 where it is on the hull
    win2 = np.empty(4, dtype=np.bool_)
    for j in range(4):
        mid = 0.5 * (phi[j] + p1[j])
        cm, sm = math.cos(mid), math.sin(mid)
        quad = fr[_S00] * cm * cm + 2.0 * fr[_S01] * cm * sm + fr[_S11] * sm * sm
        win2[j] = fr[_CX] * cm + fr[_CY] * sm + math.sqrt(quad) > 1.0
    # one ellipse supports every normal (it contains the other): whole arcs from 0
    whole = True
    for j in range(4):
        if win2[j] != win2[(j + 1) % 4]:
            whole = False
    if whole:
        phi = np.zeros(4)
        p1[:3], p1[3] = 0.0, _TWO_PI
    # contact angle of the second ellipse at normal phi: maximises n . (P cos s + Q sin s)
    s = np.empty(4)
    for j in range(4):
        cp, sp = math.cos(phi[j]), math.sin(phi[j])
        s[j] = math.atan2(cp * fr[_QX] + sp * fr[_QY], cp * fr[_PX] + sp * fr[_PY])
    for j in range(4):
        jn = (j + 1) % 4
        s_next = s[jn]
        # [phi0, phi1] narrower than pi sweeps less than pi of the second ellipse's angle, a
        # wider one more (a linear image of the circle): the turn of s1 - s0 follows
        span = (s_next - s[j]) % _TWO_PI
        if p1[j] - phi[j] <= math.pi:
            if span > 1.5 * math.pi:
                span -= _TWO_PI
        elif span < 0.5 * math.pi:
            span += _TWO_PI
        if win2[j]:
            _ellipse_arc(fr, s[j], s[j] + span, grad, b, out)
        else:
            _circle_arc(fr, phi[j], p1[j], out)
        if win2[j] != win2[jn]:
            ux, uy = math.cos(p1[j]), math.sin(p1[j])
            xs, ys = _point(fr, s_next)
            x0, y0 = (xs, ys) if win2[j] else (ux, uy)
            x1, y1 = (xs, ys) if win2[jn] else (ux, uy)
            _segment(fr, x0, y0, x1, y1, win2[jn], s_next, grad, out)


@jit
def _pair(p1: FloatArray, p2: FloatArray, hull: bool, grad: bool, basis: FloatArray,
          dbasis: FloatArray, out: FloatArray) -> None:
    """One pair's quadrant sums into ``out`` (3 regions, 4 quadrants, area + 5 gradient)."""
    fr = _frame(p1, p2)
    k = _crossing_coefficients(fr)
    # contours this close count as identical (oracle: f below 1e-9, area error <= 1e-9)
    same = abs(k[0]) + abs(k[1]) + abs(k[2]) + abs(k[3]) + abs(k[4]) <= 1e-9
    f = _grid_values(k, basis)
    br = np.empty((5, 4))
    # rounding-level values (tangency) count as inside (oracle)
    _brackets(f, br)
    if same:
        br[0] = 0.0
    t0 = _roots(k, br)
    cross = br[0, 0] + br[0, 1] + br[0, 2] + br[0, 3] > 0.0
    # intersection: the unit circle's arcs between crossings inside the second ellipse (at
    # their middle), the second ellipse's inside the unit circle; without a crossing, the first
    # inside the second iff f < 0 where |f| is largest (tangency does not matter), else the
    # second inside the first iff its centre is, else disjoint; the same ellipse: the second
    i_max = 0
    for i in range(GRID):
        if abs(f[i]) > abs(f[i_max]):
            i_max = i
    first_in = f[i_max] < 0.0
    second_in = same or (not first_in and fr[_CX] ** 2 + fr[_CY] ** 2 < 1.0)
    s = np.zeros(4)
    b = np.empty(6)
    arc = np.empty((4, 6))
    for j in range(4):
        t1 = t0[j + 1] if j < 3 else t0[0] + _TWO_PI
        inside = _trig(k, 0.5 * (t0[j] + t1))[0] < 0.0 if cross else first_in and not same
        if inside:
            _circle_arc(fr, t0[j], t1, out[_INTER])
        if cross:
            # the same point on the second ellipse: (cos s, sin s) ∝ [P Q]^-1 (u - c)
            ux, uy = math.cos(t0[j]) - fr[_CX], math.sin(t0[j]) - fr[_CY]
            s[j] = math.atan2(fr[_PX] * uy - fr[_PY] * ux, fr[_QY] * ux - fr[_QX] * uy) \
                % _TWO_PI
    _sort(s)
    for j in range(4):
        s1 = s[j + 1] if j < 3 else s[0] + _TWO_PI
        arc[:] = 0.0
        _ellipse_arc(fr, s[j], s1, grad, b, arc)
        out[_SECOND] += arc
        if cross:
            mx, my = _point(fr, 0.5 * (s[j] + s1))
            inside = mx * mx + my * my < 1.0
        else:
            inside = second_in
        if inside:
            out[_INTER] += arc
    if hull:
        kg = _tangent_coefficients(fr)
        fg = _grid_values(kg, basis)
        _brackets(fg, br)
        _add_pokes(kg, fg, br, dbasis)
        _hull(fr, _roots(kg, br), grad, b, out[_HULL])


@jit
def _batch(p1: FloatArray, p2: FloatArray, hull: bool, grad: bool, basis: FloatArray,
           dbasis: FloatArray) -> FloatArray:
    """(N, 3, 4, 6): per pair, region (second, intersection, hull), quadrant, area + gradient."""
    out = np.zeros((p1.shape[0], 3, 4, 6))
    for i in range(p1.shape[0]):
        _pair(p1[i], p2[i], hull, grad, basis, dbasis, out[i])
    return out


def quadrant_sums(p1: FloatArray, p2: FloatArray, hull: bool, gradient: bool = False
                  ) -> FloatArray:
    """The kernel's output for N pairs of params ``p1``, ``p2`` (N, 5) (px, rad): (N, 3, 4, 6),
    per pair the regions (second ellipse, intersection, hull: zeros unless ``hull``), the four
    quadrants (:func:`quadrant_areas_batch`), and the area (px^2) followed by its gradient
    w.r.t. ``g2`` (zeros unless ``gradient``)."""
    # fresh C-ordered writable copies: the kernel is compiled for that one array type
    p1 = np.array(p1, dtype=float, order="C").reshape(-1, 5)
    p2 = np.array(p2, dtype=float, order="C").reshape(-1, 5)
    if p1.shape != p2.shape:
        raise ValueError(f"p1 and p2 must have the same shape (N, 5), got {p1.shape}, {p2.shape}")
    return _batch(p1, p2, bool(hull), bool(gradient), _GRID_BASIS, _GRID_DBASIS)


def quadrant_areas_batch(
    p1: FloatArray, p2: FloatArray, hull: bool, n_directions: int = HULL_DIRECTIONS,
    gradient: bool = False,
) -> dict[str, tuple[FloatArray, FloatArray | None]]:
    """Areas in the four quadrants of the first ellipse's frame (centred on it, along its
    axes, counter-clockwise from ``+u, +v``; the first ellipse has ``A1 / 4`` in each) of the
    second ellipse, of the intersection and, if ``hull``, of the convex hull, for N pairs:
    params ``p1``, ``p2`` (N, 5) (px, rad). Returns ``{"second", "intersection"[, "hull"]}`` ->
    ``(areas (N, 4) px^2, gradients (N, 4, 5) or None)``, gradients w.r.t. each second
    ellipse's ``g2 = (mu_x, mu_y, s00, s01, s11)``. ``n_directions``: unused (see
    :data:`HULL_DIRECTIONS`)."""
    out = quadrant_sums(p1, p2, hull, gradient)
    return {name: (out[:, r, :, 0], out[:, r, :, 1:] if gradient else None)
            for r, name in enumerate(_REGIONS[:3 if hull else 2])}


def quadrant_areas(
    p1: FloatArray, p2: FloatArray, hull: bool, n_directions: int = HULL_DIRECTIONS,
    gradient: bool = False,
) -> dict[str, tuple[FloatArray, FloatArray | None]]:
    """:func:`quadrant_areas_batch` of one pair (params (5,) each): areas (4,) px^2 and
    gradients (4, 5) or None per region."""
    q = quadrant_areas_batch(p1, p2, hull, n_directions, gradient)
    return {k: (a[0], None if g is None else g[0]) for k, (a, g) in q.items()}


def intersection_areas(p1: FloatArray, p2: FloatArray) -> FloatArray:
    """Areas (N,) px^2 of the intersections of N pairs of filled ellipses given as params
    (N, 5) each, clamped to ``[0, min(area1, area2)]`` against rounding."""
    p1, p2 = np.asarray(p1, dtype=float), np.asarray(p2, dtype=float)
    area = quadrant_areas_batch(p1, p2, False, HULL_DIRECTIONS, False)["intersection"][0].sum(
        axis=1)
    areas: FloatArray = np.clip(
        area, 0.0, math.pi * np.minimum(p1[:, 2] * p1[:, 3], p2[:, 2] * p2[:, 3]))
    return areas


def intersection_area(p1: FloatArray, p2: FloatArray) -> float:
    """Area (px^2) of the intersection of two filled ellipses given as params (5,)."""
    return float(intersection_areas(np.reshape(p1, (1, 5)), np.reshape(p2, (1, 5)))[0])


def hull_area(p1: FloatArray, p2: FloatArray, n_directions: int = HULL_DIRECTIONS) -> float:
    """Area (px^2) of the convex hull of two ellipses given as params (5,), exact."""
    return float(quadrant_areas(p1, p2, True, n_directions)["hull"][0].sum())
