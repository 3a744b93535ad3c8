"""Exact ellipse areas for the IoU / GIoU metrics, vectorised over N pairs of ellipses.

Decided (issue 10): the batched :func:`quadrant_areas_batch` is the ONLY implementation; the
single-pair :func:`intersection_area`, :func:`hull_area` and :func:`quadrant_areas` are views of
it with N = 1. The former scalar construction is kept verbatim as the tests' independent oracle
(``tests/oracles/overlap_reference.py``; equal to ~1e-9 relative, ``tests/test_overlap_batch.py``).

Ellipses are params ``(cx, cy, a, b, angle)`` (px, rad); areas px^2. Everything is computed in
the first ellipse's normalised frame (the unit circle there; areas scale by ``a1 b1``), with a
fixed number of pieces per pair (no ragged arrays, a fixed number of numpy calls). Intersection:
arcs of each contour inside the other, between the contours' crossings. Convex hull: arcs joined
by the outer common tangents. Both sets of angles are the roots of a trigonometric quadratic
(bracketed on ``GRID`` angles, polished by Newton steps; the hull's also where an ellipse pokes
out between two grid angles). Areas are closed-form Green integrals ``1/2 ∮ x × dx``; their
gradients w.r.t. the second ellipse's Gaussian parameters ``g2 = (mu_x, mu_y, s00, s01, s11)``
(px, px^2) are exact boundary integrals. The construction, its limits and the derivation:
``docs/design/factors.md`` ("Exact ellipse areas").
"""

from __future__ import annotations

import math

import numpy as np

#: Number of parametric angles used to bracket the contour intersections and common tangents.
GRID = 128
#: Accepted for compatibility (option ``hull_directions`` of the metrics); unused: the common
#: tangents are roots of a trigonometric quadratic, bracketed on :data:`GRID` angles.
HULL_DIRECTIONS = 128

_T_GRID = np.linspace(0.0, 2.0 * np.pi, GRID, endpoint=False)
#: (5, GRID): rows 1, cos t, sin t, cos 2t, sin 2t (a trigonometric quadratic on the grid is
#: one matmul with its coefficients); the cyclic next index on the grid
_GRID_BASIS = np.stack([np.ones(GRID), np.cos(_T_GRID), np.sin(_T_GRID), np.cos(2 * _T_GRID),
                        np.sin(2 * _T_GRID)])
#: (5, GRID): their derivatives' rows 0, -sin t, cos t, -2 sin 2t, 2 cos 2t
_GRID_DBASIS = np.stack([np.zeros(GRID), -np.sin(_T_GRID), np.cos(_T_GRID),
                         -2.0 * np.sin(2 * _T_GRID), 2.0 * np.cos(2 * _T_GRID)])
_GRID_INDEX = np.arange(GRID)
_GRID_NEXT = (_GRID_INDEX + 1) % GRID
_NEXT4 = np.array([1, 2, 3, 0])
#: A grid value above this is outside (rounding-level values, i.e. tangency, count as inside;
#: as the oracle).
_THRESHOLD = 1e-12
_TWO_PI = 2.0 * math.pi
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
#: (4 quadrants, 2 turns) bounds of the quadrants' angle intervals on the unit circle
_QUADRANT_LO = (np.arange(4)[:, None] * 0.5 * np.pi + np.arange(2)[None, :] * _TWO_PI)
_QUADRANT_HI = _QUADRANT_LO + 0.5 * np.pi


class _Frame:
    """Per-pair (N,) quantities of the second ellipse in the first one's normalised frame
    ``x' = D1^-1 R1^T (x - c1)`` (the first ellipse is the unit circle there): centre ``c``,
    axis vectors ``P = D1^-1 R1^T a2 u2``, ``Q`` (its boundary ``c + P cos s + Q sin s``, ``s``
    its own parametric angle), ``Sigma' = P P^T + Q Q^T`` and ``det = P × Q = a2 b2 / (a1
    b1)``; and the world quantities of the gradients (``a2 b2``, ``M = L2^-T``)."""

    def __init__(self, p1: np.ndarray, p2: np.ndarray) -> None:
        a1, b1 = p1[:, 2], p1[:, 3]
        self.a1, self.b1, self.ab1 = a1, b1, a1 * b1
        c1, s1 = np.cos(p1[:, 4]), np.sin(p1[:, 4])
        self.cos1, self.sin1 = c1, s1
        dx, dy = p2[:, 0] - p1[:, 0], p2[:, 1] - p1[:, 1]
        self.cx, self.cy = (c1 * dx + s1 * dy) / a1, (c1 * dy - s1 * dx) / b1
        a2, b2 = p2[:, 2], p2[:, 3]
        cd, sd = np.cos(p2[:, 4] - p1[:, 4]), np.sin(p2[:, 4] - p1[:, 4])
        self.Px, self.Py = a2 * cd / a1, a2 * sd / b1
        self.Qx, self.Qy = -b2 * sd / a1, b2 * cd / b1
        self.det = self.Px * self.Qy - self.Py * self.Qx
        self.s00 = self.Px * self.Px + self.Qx * self.Qx
        self.s01 = self.Px * self.Py + self.Qx * self.Qy
        self.s11 = self.Py * self.Py + self.Qy * self.Qy
        self.ab2 = a2 * b2
        c2, s2 = np.cos(p2[:, 4]), np.sin(p2[:, 4])
        self.M = (c2 / a2, -s2 / b2, s2 / a2, c2 / b2)

    def crossing_coefficients(self) -> np.ndarray:
        """(5, N) ``k`` of ``f(t) = Phi_2(u(t)) - 1 = k0 + k1 cos t + k2 sin t + k3 cos 2t + k4
        sin 2t`` on the unit circle ``u(t)`` (< 0 inside the second ellipse; oracle:
        ``_crossing_coefficients``), with ``A' = Sigma'^-1 = adj(Sigma') / det^2``."""
        d2 = self.det * self.det
        A00, A01, A11 = self.s11 / d2, -self.s01 / d2, self.s00 / d2
        cx, cy = self.cx, self.cy
        Acx, Acy = A00 * cx + A01 * cy, A01 * cx + A11 * cy
        return np.array([0.5 * (A00 + A11) + cx * Acx + cy * Acy - 1.0, -2.0 * Acx,
                         -2.0 * Acy, 0.5 * (A00 - A11), A01])

    def tangent_coefficients(self) -> np.ndarray:
        """(5, N) ``k`` of ``g(phi) = (1 - c . n)^2 - n^T Sigma' n``, ``n = (cos phi, sin
        phi)``: zero where the line of normal ``n`` touching the unit circle touches the second
        ellipse too (common tangents; the outer ones, where the support ``c . n + sqrt(n^T
        Sigma' n)`` of the second ellipse is 1, are the hull's)."""
        cx, cy = self.cx, self.cy
        return np.array([1.0 + 0.5 * (cx * cx + cy * cy - self.s00 - self.s11),
                         -2.0 * cx, -2.0 * cy,
                         0.5 * (cx * cx - cy * cy - self.s00 + self.s11), cx * cy - self.s01])

    def point(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points of the second ellipse at its angles ``s`` (N, m), normalised frame."""
        cs, ss = np.cos(s), np.sin(s)
        return (self.cx[:, None] + cs * self.Px[:, None] + ss * self.Qx[:, None],
                self.cy[:, None] + cs * self.Py[:, None] + ss * self.Qy[:, None])

    def to_world(self, wx: np.ndarray, wy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A vector (N, m) of the normalised frame in world axes, ``R1 D1 w``."""
        ax, by = self.a1[:, None] * wx, self.b1[:, None] * wy
        c, s = self.cos1[:, None], self.sin1[:, None]
        return c * ax - s * by, s * ax + c * by


def _trig(k: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The trigonometric quadratics ``k`` (5, M, 1) and their derivatives at ``t`` (M, m)."""
    c, s = np.cos(t), np.sin(t)
    cs = c * s
    c2, s2 = c * c - s * s, cs + cs
    return (k[0] + k[1] * c + k[2] * s + k[3] * c2 + k[4] * s2,
            k[2] * c - k[1] * s + 2.0 * (k[4] * c2 - k[3] * s2))


def _brackets(k: np.ndarray, threshold: np.ndarray, skip: np.ndarray
              ) -> tuple[np.ndarray, ...]:
    """Grid brackets of the roots of trigonometric quadratics ``k`` (5, M): the values on the
    grid (M, GRID), and up to 4 cells per row where the sign (``f > threshold``, (M, 1))
    changes (rows ``skip``: none): ``has`` (M, 4), their lower ends and values at both ends."""
    f = k.T @ _GRID_BASIS
    sign = f > threshold
    change = sign != sign[:, _GRID_NEXT]
    change[skip] = False
    # a trigonometric quadratic changes sign at most 4 times: those cells (in any order),
    # GRID where a row has fewer
    cell = np.partition(np.where(change, _GRID_INDEX, GRID), 3, axis=1)[:, :4]
    has = cell < GRID
    cell = np.where(has, cell, 0)
    rows = np.arange(f.shape[0])[:, None]
    lo = cell * _H
    return f, has, lo, lo + _H, f[rows, cell], f[rows, _GRID_NEXT[cell]]


def _add_pokes(k: np.ndarray, f: np.ndarray, brackets: list[np.ndarray], rows: np.ndarray,
               threshold: float) -> None:
    """Add to ``brackets`` (``has``, ``lo``, ``hi``, ``f0``, ``f1``; (M, 4), in place) the
    root pairs of rows ``rows`` that lie between two grid angles (no sign change on the grid;
    oracle: the extremum search of ``_hull_pieces``). With ``|f''| <= M = |k1| + |k2| + 4
    (|k3| + |k4|)``, ``f`` keeps its sign over a cell if it does over the Taylor lower bound
    ``sigma f_i + sigma f'_i tau - M tau^2 / 2`` from either end (concave: checked at the
    other end); in the remaining cells the extremum is located on a sub-grid, and a sign
    change there brackets both roots."""
    kr = k[:, rows]
    g = f[rows] - threshold
    dg = kr.T @ _GRID_DBASIS
    sigma = np.where(g > 0.0, 1.0, -1.0)
    bound = (0.5 * _H * _H) * (np.abs(kr[1]) + np.abs(kr[2])
                               + 4.0 * (np.abs(kr[3]) + np.abs(kr[4])))[:, None]
    g1, dg1 = g[:, _GRID_NEXT], dg[:, _GRID_NEXT]
    near = (sigma * (g + _H * dg) <= bound) & (sigma * (g1 - _H * dg1) <= bound) \
        & (sigma * g1 > 0.0)
    fr = f[rows]
    if not near.any():
        return
    r, i = np.nonzero(near)
    kk = k[:, rows[r]][:, :, None]
    sign = np.where(fr[r, i] > 0.0, 1.0, -1.0)
    lo, width = i * _H, np.full(r.size, _H)
    frac = np.linspace(0.0, 1.0, _POKE_SUBGRID + 1)
    for _ in range(_POKE_LEVELS):
        v = sign[:, None] * _trig(kk, lo[:, None] + width[:, None] * frac)[0]
        j = np.minimum(np.maximum(np.argmin(v, axis=1) - 1, 0), _POKE_SUBGRID - 2)
        lo = lo + j * width / _POKE_SUBGRID
        width = 2.0 * width / _POKE_SUBGRID
    t_min = lo + 0.5 * width
    f_min = _trig(kk, t_min[:, None])[0][:, 0]
    has, b_lo, b_hi, f0, f1 = brackets
    for rr, ii, tm, fm, sg in zip(rows[r], i, t_min, f_min, sign, strict=True):
        free = np.flatnonzero(~has[rr])
        if sg * fm >= 0.0 or free.size < 2:
            continue
        a, b = free[:2]
        has[rr, [a, b]] = True
        b_lo[rr, [a, b]] = ii * _H, tm
        b_hi[rr, [a, b]] = tm, (ii + 1) * _H
        f0[rr, [a, b]] = f[rr, ii], fm
        f1[rr, [a, b]] = fm, f[rr, _GRID_NEXT[ii]]


def _roots(k: np.ndarray, has: np.ndarray, lo: np.ndarray, hi: np.ndarray, f0: np.ndarray,
           f1: np.ndarray) -> np.ndarray:
    """Roots (M, 4) of ``k`` (5, M) in the brackets: from the secant, :data:`_NEWTON_STEPS`
    Newton steps kept in the bracket; the roots whose last step was not at rounding level
    (a function that curves a lot within its bracket) are finished by :func:`_safeguarded`. A
    row's empty slots repeat one of its roots (0 if none: extra split points, harmless)."""
    den = np.where(has, f0 - f1, 1.0)
    t = lo + (hi - lo) * np.fmin(np.fmax(np.where(has, f0 / den, 0.5), 0.0), 1.0)
    kk = k[:, :, None]
    for _ in range(_NEWTON_STEPS):
        f, df = _trig(kk, t)
        step = f / df
        # a zero derivative: +-inf -> a bracket end, nan -> lo (np.fmax ignores nan)
        t_new = np.fmin(np.fmax(t - step, lo), hi)
        t, moved = t_new, t_new - t
    # converged: at a root, or the last (unclamped) step below 1e-9 rad (now at rounding level)
    bad = has & ~((f == 0.0) | ((np.abs(moved) < 1e-9) & (np.abs(step) < 1e-9)))
    if bad.any():
        r, j = np.nonzero(bad)
        t[r, j] = _safeguarded(k[:, r], t[r, j], lo[r, j], hi[r, j], f0[r, j])
    first = np.max(np.where(has, t, -np.inf), axis=1, keepdims=True)  # -inf: none
    return np.where(has, t, np.where(first > -np.inf, first, 0.0)) % _TWO_PI


def _safeguarded(k: np.ndarray, t: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                 f_lo: np.ndarray) -> np.ndarray:
    """Roots (m,) of ``k`` (5, m) in brackets ``[lo, hi]`` (values ``f_lo`` at ``lo``), from
    ``t``: Newton steps that stay in the bracket, else bisection, the bracket shrinking at
    every iterate (oracle: ``_bracketed_root``); up to :data:`_SAFEGUARDED_MAX_ITER`
    iterations, until a step or the bracket is below 1e-12 rad, or ``f`` is 0."""
    neg_lo = ~(f_lo > _THRESHOLD)
    kk = k[:, :, None]
    for _ in range(_SAFEGUARDED_MAX_ITER):
        f, df = (v[:, 0] for v in _trig(kk, t[:, None]))
        left = (f < 0.0) == neg_lo  # the root is right of t
        lo, hi = np.where(left, t, lo), np.where(left, hi, t)
        t_new = t - f / df
        newton = (lo < t_new) & (t_new < hi)
        t_new = np.where(newton, t_new, 0.5 * (lo + hi))
        done = (newton & (np.abs(t_new - t) < 1e-12)) | (hi - lo < 1e-12) | (f == 0.0)
        t = np.where(f == 0.0, t, t_new)
        if done.all():
            break
    return t


def _cyclic(t: np.ndarray) -> np.ndarray:
    """The next of each sorted angle (N, m), the last one's wrapping to the first + 2 pi."""
    return np.concatenate([t[:, 1:], t[:, :1] + _TWO_PI], axis=1)


def _hull(fr: _Frame, phi: np.ndarray) -> tuple[np.ndarray, ...]:
    """The hull's boundary (oracle: ``_hull_pieces``) over the four intervals of normal angles
    between the sorted common tangents ``phi`` (N, 4): the unit circle's arcs ``[phi_j,
    phi_j+1]`` (its contact angle is the normal angle), the second ellipse's ``[s_j, s_j +
    span_j]``, which one supports each interval (``win2`` (N, 4) bool), and the tangent
    segments at each ``phi_j+1`` where the support switches (start / end points, end on the
    second ellipse, its angle there, switch)."""
    p1 = _cyclic(phi)
    # the second ellipse's support at the middle normal: > 1 where it is on the hull
    mid = 0.5 * (phi + p1)
    cm, sm = np.cos(mid), np.sin(mid)
    quad = (fr.s00[:, None] * cm * cm + 2.0 * fr.s01[:, None] * cm * sm
            + fr.s11[:, None] * sm * sm)
    win2 = fr.cx[:, None] * cm + fr.cy[:, None] * sm + np.sqrt(quad) > 1.0
    win2_next = win2[:, _NEXT4]
    switch = win2 != win2_next
    # one ellipse supports every normal (it contains the other): whole arcs from 0
    whole = ~switch.any(axis=1)[:, None]
    phi = np.where(whole, 0.0, phi)
    p1 = _cyclic(phi)
    # contact angle of the second ellipse at normal phi: maximises n . (P cos s + Q sin s)
    cp, sp = np.cos(phi), np.sin(phi)
    s = np.arctan2(cp * fr.Qx[:, None] + sp * fr.Qy[:, None],
                   cp * fr.Px[:, None] + sp * fr.Py[:, None])
    s_next = s[:, _NEXT4]
    # [phi0, phi1] narrower than pi sweeps less than pi of the second ellipse's angle, a wider
    # one more (a linear image of the circle): the turn of s1 - s0 follows
    span = (s_next - s) % _TWO_PI
    span = np.where(p1 - phi <= math.pi, np.where(span > 1.5 * math.pi, span - _TWO_PI, span),
                    np.where(span < 0.5 * math.pi, span + _TWO_PI, span))
    ux, uy = np.cos(p1), np.sin(p1)
    xs, ys = fr.point(s_next)
    segs = (np.where(win2, xs, ux), np.where(win2, ys, uy), np.where(win2_next, xs, ux),
            np.where(win2_next, ys, uy), win2_next, s_next, switch)
    return phi, p1, s, s + span, win2, segs


def _quadrants(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """One-hot (4, ...) float quadrant of points of the normalised frame (counter-clockwise
    from ``+u, +v``; as the oracle's ``quadrant``: ``y >= 0`` upper, ``x >= 0`` right)."""
    up, right = y >= 0.0, x >= 0.0
    return np.array([up & right, up & ~right, ~up & ~right, ~up & right], dtype=float)


def _circle_sums(fr: _Frame, t0: np.ndarray, t1: np.ndarray, weights: np.ndarray
                 ) -> np.ndarray:
    """Areas (N, 4, R) ``1/2 ∫ x × dx`` of arcs ``[t0, t1]`` (N, m) (``0 <= t0 < 2 pi``, ``t1
    <= t0 + 2 pi``) of the unit circle (the first ellipse, which does not move) per quadrant,
    weighted (N, m, R): half the length of each arc's part in the quadrant, times ``a1 b1``."""
    ov = np.minimum(t1[:, :, None, None], _QUADRANT_HI) - np.maximum(t0[:, :, None, None],
                                                                     _QUADRANT_LO)
    length = np.maximum(ov, 0.0).sum(axis=3)  # (N, m, 4)
    return (0.5 * fr.ab1)[:, None, None] * (length.transpose(0, 2, 1) @ weights)


def _ellipse_sums(fr: _Frame, t0: np.ndarray, t1: np.ndarray, weights: np.ndarray,
                  grad: bool) -> np.ndarray:
    """Quadrant sums (N, 4, R, 1 + 5 grad) of arcs ``[t0, t1]`` (N, m) of the second ellipse,
    weighted (N, m, R) (oracle: ``_piece_sums`` with ``axes``): each arc is split where the
    ellipse crosses the axes (pieces then lie in one quadrant each), areas ``1/2 ∫ x × dx``
    (times ``a1 b1``), gradients w.r.t. ``g2`` in world units (oracle: ``_Boundary.arc``)."""
    cx, cy, Px, Py, Qx, Qy = (v[:, None] for v in (fr.cx, fr.cy, fr.Px, fr.Py, fr.Qx, fr.Qy))
    # where x' = 0 and y' = 0 (cos s P + sin s Q = -c per coordinate): 4 angles; a line that
    # does not cut gives an extra split point, harmless (the pieces' sums are additive)
    alpha, beta, gamma = np.array([Px, Py]), np.array([Qx, Qy]), np.array([cx, cy])
    phi = np.arctan2(beta, alpha)
    dphi = np.arccos(np.fmin(np.fmax(-gamma / np.hypot(alpha, beta), -1.0), 1.0))
    cuts = t0 + (np.concatenate([phi + dphi, phi - dphi]) - t0) % _TWO_PI  # (4, N, m)
    bounds = np.sort(np.concatenate([t0[None], np.minimum(cuts, t1), t1[None]]), axis=0)
    cb, sb = np.cos(bounds), np.sin(bounds)
    lo, hi = bounds[:-1], bounds[1:]
    cl, sl, ch, sh = cb[:-1], sb[:-1], cb[1:], sb[1:]
    mid = 0.5 * (lo + hi)
    cm, sm = np.cos(mid), np.sin(mid)
    onehot = _quadrants(cx + cm * Px + sm * Qx, cy + cm * Py + sm * Qy)  # (4, 5, N, m)
    dc, ds = ch - cl, sh - sl
    vals = [(0.5 * fr.ab1)[:, None] * (fr.det[:, None] * (hi - lo) + cx * (dc * Py + ds * Qy)
                                       - cy * (dc * Px + ds * Qx))]
    if grad:
        w = fr.ab2[:, None]
        m00, m01, m10, m11 = (x[:, None] for x in fr.M)
        half = 0.5 * (hi - lo)
        q = 0.5 * (sh * ch - sl * cl)  # 1/4 (sin 2 t1 - sin 2 t0)
        cc, ss, cs_ = half + q, half - q, 0.5 * (sh * sh - sl * sl)
        r00, r01 = m00 * cc + m01 * cs_, m00 * cs_ + m01 * ss
        r10, r11 = m10 * cc + m11 * cs_, m10 * cs_ + m11 * ss
        vals += [w * (m00 * ds - m01 * dc), w * (m10 * ds - m11 * dc),
                 (0.5 * w) * (r00 * m00 + r01 * m01), w * (r00 * m10 + r01 * m11),
                 (0.5 * w) * (r10 * m10 + r11 * m11)]
    return _accumulate(onehot, np.array(vals), weights)


def _accumulate(onehot: np.ndarray, vals: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``sum_{p, j} onehot[q, p, n, j] weights[n, j, r] vals[v, p, n, j]`` -> (N, 4, R, V)
    for pieces ``p`` of items ``j``: onehot (4, P, N, m), vals (V, P, N, m), weights (N, m,
    R)."""
    V, _, n, m = vals.shape
    R = weights.shape[-1]
    # per item: (4, P) @ (P, V) -> (N, m, 4, V), then the weights over the items
    per_item = onehot.transpose(2, 3, 0, 1) @ vals.transpose(2, 3, 1, 0)
    out = weights.transpose(0, 2, 1) @ per_item.reshape(n, m, 4 * V)  # (N, R, 4 V)
    return out.reshape(n, R, 4, V).transpose(0, 2, 1, 3)


def _segment_sums(fr: _Frame, segs: tuple[np.ndarray, ...], grad: bool) -> np.ndarray:
    """Quadrant sums (N, 4, 1, 1 + 5 grad) of the hull's tangent segments (N, 4) (oracle:
    ``_piece_sums``), each split where it crosses the axes."""
    x0, y0, x1, y1, end2, par, switch = segs
    wx, wy = x1 - x0, y1 - y0
    # where x' = 0, y' = 0 along the segment (a division by 0: +-inf or nan -> an end)
    cut = np.fmin(np.fmax(np.array([-x0 / wx, -y0 / wy]), 0.0), 1.0)
    zero = np.zeros((1, *x0.shape))
    sb = np.sort(np.concatenate([zero, cut, zero + 1.0]), axis=0)
    s0, s1 = sb[:-1], sb[1:]
    xa, ya, xb, yb = x0 + s0 * wx, y0 + s0 * wy, x0 + s1 * wx, y0 + s1 * wy
    onehot = _quadrants(0.5 * (xa + xb), 0.5 * (ya + yb))
    vals = [(0.5 * fr.ab1)[:, None] * (xa * yb - ya * xb)]
    if grad:  # 1/2 dx(q) x (end - start) shared along the segment (oracle: _piece_sums)
        share = 0.5 * np.where(end2, s1 * s1 - s0 * s0, (1 - s0) ** 2 - (1 - s1) ** 2)
        Wx, Wy = fr.to_world(wx, wy)
        m00, m01, m10, m11 = (x[:, None] for x in fr.M)
        u0, u1 = np.cos(par), np.sin(par)
        v0, v1 = m00 * u0 + m01 * u1, m10 * u0 + m11 * u1
        vals += [share * Wy, -share * Wx, share * (0.5 * v0 * Wy),
                 share * (0.5 * (v1 * Wy - v0 * Wx)), -share * (0.5 * v1 * Wx)]
    return _accumulate(onehot, np.array(vals), switch[:, :, None].astype(float))


def quadrant_areas_batch(
    p1: np.ndarray, p2: np.ndarray, hull: bool, n_directions: int = HULL_DIRECTIONS,
    gradient: bool = False,
) -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    """Areas in the four quadrants of the first ellipse's frame (centred on it, along its
    axes, counter-clockwise from ``+u, +v``; the first ellipse has ``A1 / 4`` in each) of the
    second ellipse, of the intersection and, if ``hull``, of the convex hull, for N pairs:
    params ``p1``, ``p2`` (N, 5) (px, rad). Returns ``{"second", "intersection"[, "hull"]}`` ->
    ``(areas (N, 4) px^2, gradients (N, 4, 5) or None)``, gradients w.r.t. each second
    ellipse's ``g2 = (mu_x, mu_y, s00, s01, s11)``. ``n_directions``: unused (see
    :data:`HULL_DIRECTIONS`)."""
    p1 = np.asarray(p1, dtype=float).reshape(-1, 5)
    p2 = np.asarray(p2, dtype=float).reshape(-1, 5)
    if p1.shape != p2.shape:
        raise ValueError(f"p1 and p2 must have the same shape (N, 5), got {p1.shape}, {p2.shape}")
    names = ["second", "intersection", "hull"] if hull else ["second", "intersection"]
    if p1.shape[0] == 0:
        return {k: (np.zeros((0, 4)), np.zeros((0, 4, 5)) if gradient else None)
                for k in names}
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return _quadrant_areas(p1, p2, hull, gradient, names)


def _quadrant_areas(p1: np.ndarray, p2: np.ndarray, hull: bool, gradient: bool,
                    names: list[str]) -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    """:func:`quadrant_areas_batch` of N >= 1 pairs (divisions by zero allowed: a zero
    derivative or segment direction is handled where it occurs)."""
    n, R = p1.shape[0], len(names)
    fr = _Frame(p1, p2)
    k = fr.crossing_coefficients()
    # contours this close count as identical (oracle: f below 1e-9, area error <= 1e-9)
    same = np.abs(k).sum(axis=0) <= 1e-9
    skip = same
    if hull:  # both root problems at once: rows n.. are the common tangents' (normalised)
        kg = fr.tangent_coefficients()
        kg = kg / np.maximum(np.abs(kg).sum(axis=0), 1e-300)
        k = np.concatenate([k, kg], axis=1)
        skip = np.concatenate([same, np.zeros(n, dtype=bool)])
    # rounding-level values (tangency) count as inside (oracle)
    f, *brackets = _brackets(k, _THRESHOLD, skip)
    if hull:
        _add_pokes(k, f, brackets, np.arange(n, 2 * n), _THRESHOLD)
    roots = _roots(k, *brackets)
    has = brackets[0][:n].any(axis=1)
    # intersection: the unit circle's arcs between crossings inside the second ellipse (at
    # their middle), the second ellipse's inside the unit circle; without a crossing, the first
    # inside the second iff f < 0 where |f| is largest (tangency does not matter), else the
    # second inside the first iff its centre is, else disjoint; the same ellipse: the second
    t0 = np.sort(roots[:n], axis=1)
    t1 = _cyclic(t0)
    f_mid = _trig(k[:, :n, None], 0.5 * (t0 + t1))[0]
    fn = f[:n]
    first_in = fn[np.arange(n), np.argmax(np.abs(fn), axis=1)] < 0.0
    second_in = same | (~first_in & (fr.cx * fr.cx + fr.cy * fr.cy < 1.0))
    cross = has[:, None]
    w1 = np.zeros((n, 4, R))
    w1[:, :, 1] = np.where(cross, f_mid < 0.0, (first_in & ~same)[:, None])
    # the same points on the second ellipse: (cos s, sin s) ∝ [P Q]^-1 (u - c) (det > 0)
    ux, uy = np.cos(t0) - fr.cx[:, None], np.sin(t0) - fr.cy[:, None]
    s = np.arctan2(fr.Px[:, None] * uy - fr.Py[:, None] * ux,
                   fr.Qy[:, None] * ux - fr.Qx[:, None] * uy)
    s0 = np.sort(np.where(cross, s % _TWO_PI, 0.0), axis=1)
    s1 = _cyclic(s0)
    mx, my = fr.point(0.5 * (s0 + s1))
    w2 = np.zeros((n, 4, R))
    w2[:, :, 0] = 1.0  # all of the second ellipse
    w2[:, :, 1] = np.where(cross, mx * mx + my * my < 1.0, second_in[:, None])
    c0, c1, e0, e1, ew, cw = [t0], [t1], [s0], [s1], [w2], [w1]
    if hull:
        h0, h1, hs0, hs1, win2, segs = _hull(fr, np.sort(roots[n:], axis=1))
        wh = np.zeros((n, 4, R))
        wh[:, :, 2] = ~win2
        c0.append(h0)
        c1.append(h1)
        cw.append(wh)
        wh = np.zeros((n, 4, R))
        wh[:, :, 2] = win2
        e0.append(hs0)
        e1.append(hs1)
        ew.append(wh)
    if hull:
        c0, c1, cw = (np.concatenate(x, axis=1) for x in (c0, c1, cw))
        e0, e1, ew = (np.concatenate(x, axis=1) for x in (e0, e1, ew))
    else:
        c0, c1, cw, e0, e1, ew = c0[0], c1[0], cw[0], e0[0], e1[0], ew[0]
    acc = _ellipse_sums(fr, e0, e1, ew, gradient)  # (N, 4, R, V)
    acc[:, :, :, 0] += _circle_sums(fr, c0, c1, cw)
    if hull:
        acc[:, :, 2:] += _segment_sums(fr, segs, gradient)
    return {name: (acc[:, :, r, 0], acc[:, :, r, 1:] if gradient else None)
            for r, name in enumerate(names)}


def quadrant_areas(
    p1: np.ndarray, p2: np.ndarray, hull: bool, n_directions: int = HULL_DIRECTIONS,
    gradient: bool = False,
) -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    """:func:`quadrant_areas_batch` of one pair (params (5,) each): areas (4,) px^2 and
    gradients (4, 5) or None per region."""
    q = quadrant_areas_batch(p1, p2, hull, n_directions, gradient)
    return {k: (a[0], None if g is None else g[0]) for k, (a, g) in q.items()}


def intersection_areas(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """Areas (N,) px^2 of the intersections of N pairs of filled ellipses given as params
    (N, 5) each, clamped to ``[0, min(area1, area2)]`` against rounding."""
    p1, p2 = np.asarray(p1, dtype=float), np.asarray(p2, dtype=float)
    area = quadrant_areas_batch(p1, p2, False, HULL_DIRECTIONS, False)["intersection"][0].sum(
        axis=1)
    return np.clip(area, 0.0, math.pi * np.minimum(p1[:, 2] * p1[:, 3], p2[:, 2] * p2[:, 3]))


def intersection_area(p1: np.ndarray, p2: np.ndarray) -> float:
    """Area (px^2) of the intersection of two filled ellipses given as params (5,)."""
    return float(intersection_areas(np.reshape(p1, (1, 5)), np.reshape(p2, (1, 5)))[0])


def hull_area(p1: np.ndarray, p2: np.ndarray, n_directions: int = HULL_DIRECTIONS) -> float:
    """Area (px^2) of the convex hull of two ellipses given as params (5,), exact."""
    return float(quadrant_areas(p1, p2, True, n_directions)["hull"][0].sum())
