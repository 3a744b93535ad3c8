"""Exact ellipse areas for the IoU / GIoU metrics, vectorised over N pairs of ellipses.

Decided (issue 10): the batched :func:`quadrant_areas_batch` is the ONLY implementation; the
single-pair :func:`intersection_area`, :func:`hull_area` and :func:`quadrant_areas` are views of
it with N = 1. The former scalar construction is kept verbatim as the tests' independent oracle
(``tests/oracles/overlap_reference.py``; equal to ~1e-9 relative, ``tests/test_overlap_batch.py``).

Ellipses are params ``(cx, cy, a, b, angle)`` (px, rad); areas px^2. Intersection: arcs of each
contour inside the other, between the contours' crossings (roots of a trigonometric quadratic,
bracketed on ``GRID`` angles, refined by safeguarded Newton). Convex hull: arcs joined by common
tangents (switches of the support functions on ``n_directions`` normals). Areas are closed-form
Green integrals ``1/2 ∮ x × dx``; their gradients w.r.t. the second ellipse's Gaussian
parameters ``g2 = (mu_x, mu_y, s00, s01, s11)`` (px, px^2) are exact boundary integrals. The
construction, its limits and the derivation: ``docs/design/factors.md`` ("Exact ellipse areas").
"""

from __future__ import annotations

import functools
import math

import numpy as np

from factors.geometry import sigma_entries

#: Number of parametric angles used to bracket the contour intersections.
GRID = 128
#: Default number of normal directions used to bracket the hull's common tangents.
HULL_DIRECTIONS = 128

_T_GRID = np.linspace(0.0, 2.0 * np.pi, GRID, endpoint=False)
#: (5, GRID): rows 1, cos t, sin t, cos 2t, sin 2t (the contour function on the grid is one
#: matmul with its coefficients), and the cyclic next index on the grid
_GRID_BASIS = np.stack([np.ones(GRID), np.cos(_T_GRID), np.sin(_T_GRID), np.cos(2 * _T_GRID),
                        np.sin(2 * _T_GRID)])
_GRID_NEXT = np.roll(np.arange(GRID), -1)
_TWO_PI = 2.0 * math.pi


def _quad(A: tuple[float, float, float], x: float, y: float) -> float:
    """The quadratic form of the symmetric ``A = (a, b, c)`` (``[[a, b], [b, c]]``) at
    ``(x, y)``; floats or arrays (elementwise) alike."""
    return A[0] * x * x + 2.0 * A[1] * x * y + A[2] * y * y


def _bilinear(A: tuple[float, float, float], x: float, y: float, u: float, v: float) -> float:
    """The bilinear form of the symmetric ``A = (a, b, c)`` at ``(x, y), (u, v)``."""
    return A[0] * x * u + A[1] * (x * v + y * u) + A[2] * y * v


def _crossing_coefficients(A2: tuple, P1: tuple, Q1: tuple, dx: float,
                           dy: float) -> tuple[float, float, float, float, float]:
    """``(k0, k1, k2, k3, k4)`` of ``f(t) = Phi_2(x_1(t)) - 1 = k0 + k1 cos t + k2 sin t +
    k3 cos 2t + k4 sin 2t``: ellipse 1's boundary ``c1 + P1 cos t + Q1 sin t`` in ellipse 2's
    implicit form (``A2``: its shape matrix, ``(dx, dy) = c1 - c2``); floats or arrays."""
    (P1x, P1y), (Q1x, Q1y) = P1, Q1
    pap, qaq = _quad(A2, P1x, P1y), _quad(A2, Q1x, Q1y)
    return (_quad(A2, dx, dy) + 0.5 * (pap + qaq) - 1.0,
            2.0 * _bilinear(A2, dx, dy, P1x, P1y), 2.0 * _bilinear(A2, dx, dy, Q1x, Q1y),
            0.5 * (pap - qaq), _bilinear(A2, P1x, P1y, Q1x, Q1y))


@functools.lru_cache(maxsize=8)
def _direction_basis(n: int) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """Bases over the n hull directions ``t`` for :func:`_hull_batch`: (3, 2n) rows ``[1,
    cos 2t, sin 2t]`` then ``[0, -sin 2t, cos 2t]`` (``n^T Sigma n`` and half its derivative
    from the coefficients of ``_Batch.support``), (2, 2n) rows ``[cos t, sin t]`` then ``[-sin
    t, cos t]`` (``n . c`` and its derivative); and the cyclic next index (n,)."""
    th = np.linspace(0.0, _TWO_PI, n, endpoint=False)
    c, s, c2, s2 = np.cos(th), np.sin(th), np.cos(2 * th), np.sin(2 * th)
    quad_rows = np.stack([np.concatenate([np.ones(n), np.zeros(n)]),
                          np.concatenate([c2, -s2]), np.concatenate([s2, c2])])
    centre_rows = np.stack([np.concatenate([c, -s]), np.concatenate([s, c])])
    return (quad_rows, centre_rows), np.roll(np.arange(n), -1)



# Every step mirrors a function of the scalar oracle (tests/oracles/overlap_reference.py, named
# in each docstring as "oracle: ..."). Pieces are kept as flat arrays with their pair index; the
# ragged root / switch counts are padded (``inf``) and masked.

#: Iteration cap of the vectorised safeguarded Newton (it converges in ~5 steps from the grid).
_NEWTON_MAX_ITER = 100
#: Newton step (radians) below which the vectorised Newton stops, after taking it: with
#: quadratic convergence the error is then at rounding level.
_NEWTON_STEP_TOL = 1e-11
#: Sub-grid points per level (and levels) used to locate an interior extremum of ``h1 - h2``
#: between two hull directions (the oracle bisects on the derivative): 128^2 ~ 1.6e4
#: sub-intervals, i.e. ~3e-6 rad: the extremum value is then off by ~|f''| 1e-11 (~1e-9 px),
#: well below the sign test's ``tol`` (1e-10 of the ellipses' size and distance, ~1e-7 px).
_EXTREMUM_SUBGRID, _EXTREMUM_LEVELS = 128, 2


class _Batch:
    """Per-pair arrays of both ellipses relative to the first one's centre (oracle: ``_Ell``):
    axis vectors ``P_k = a u``, ``Q_k = b v``, centre ``c_k`` (``c_0 = 0``), ``A_k`` entries,
    ``ab_k``, and ``M = L^-T`` of the second (moving) ellipse (oracle: ``_Boundary``)."""

    def __init__(self, p1: np.ndarray, p2: np.ndarray) -> None:
        self.n = p1.shape[0]
        self.P, self.Q, self.A, self.ab, self.S = [], [], [], [], []
        for p in (p1, p2):
            a, b, c, s = p[:, 2], p[:, 3], np.cos(p[:, 4]), np.sin(p[:, 4])
            self.P.append((a * c, a * s))
            self.Q.append((-b * s, b * c))
            self.A.append(sigma_entries(1.0 / a, 1.0 / b, p[:, 4]))
            self.ab.append(a * b)
            self.S.append(sigma_entries(a, b, p[:, 4]))
        zero = np.zeros(self.n)
        self.c = [(zero, zero), (p2[:, 0] - p1[:, 0], p2[:, 1] - p1[:, 1])]
        a, b, c, s = p2[:, 2], p2[:, 3], np.cos(p2[:, 4]), np.sin(p2[:, 4])
        self.M = (c / a, -s / b, s / a, c / b)
        self.axes = (np.cos(p1[:, 4]), np.sin(p1[:, 4]))
        # n^T Sigma n = (s00 + s11) / 2 + (s00 - s11) / 2 cos 2t + s01 sin 2t, both ellipses
        self.support = np.stack([x for S in self.S
                                 for x in (0.5 * (S[0] + S[2]), 0.5 * (S[0] - S[2]), S[1])])
        # packed (2, n, 7): cx, cy, Px, Py, Qx, Qy, ab of each ellipse (one gather per use)
        self.E = np.stack([np.stack([*self.c[k], *self.P[k], *self.Q[k], self.ab[k]], axis=1)
                           for k in (0, 1)])

    def geometry(self, k: np.ndarray, pair: np.ndarray) -> np.ndarray:
        """Columns ``cx, cy, Px, Py, Qx, Qy, ab`` (7, m) of ellipse ``k`` (0/1) of ``pair``."""
        return self.E[k, pair].T

    def point(self, k: np.ndarray, pair: np.ndarray, t: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """Boundary points of ellipse ``k`` (0/1 per element) of pairs ``pair`` at angles ``t``."""
        cx, cy, Px, Py, Qx, Qy, _ = self.geometry(k, pair)
        ct, st = np.cos(t), np.sin(t)
        return cx + ct * Px + st * Qx, cy + ct * Py + st * Qy


def _newton_bracketed(fn, lo: np.ndarray, hi: np.ndarray, f0: np.ndarray, f1: np.ndarray,
                      neg_lo: np.ndarray, f_tol: np.ndarray) -> np.ndarray:
    """Roots of ``fn(t) -> (f, df)`` (elementwise) in brackets ``[lo, hi]``, safeguarded Newton
    from the secant guess (oracle: ``_bracketed_root``). An element stops when ``|f| <=
    f_tol``, after a Newton step below :data:`_NEWTON_STEP_TOL`, or when its bracket is that
    small (why this suffices: ``docs/design/factors.md``)."""
    lo, hi = lo.copy(), hi.copy()
    den = f0 - f1
    safe = np.where(den != 0.0, den, 1.0)
    t = np.where(den != 0.0, lo + (hi - lo) * f0 / safe, 0.5 * (lo + hi))
    t = np.minimum(np.maximum(t, lo), hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(_NEWTON_MAX_ITER):
            f, df = fn(t)
            left = (f < 0.0) == neg_lo
            lo = np.where(left, t, lo)
            hi = np.where(left, hi, t)
            t_new = t - f / df  # df == 0: inf / nan, not inside the bracket -> bisection
            newton = (lo < t_new) & (t_new < hi)
            t_new = np.where(newton, t_new, 0.5 * (lo + hi))
            at_root = np.abs(f) <= f_tol  # (f == 0 included) keep t, as the oracle
            t_new = np.where(at_root, t, t_new)
            if np.all(at_root | (newton & (np.abs(t_new - t) < _NEWTON_STEP_TOL))
                      | (hi - lo < 4e-15)):
                return t_new
            t = t_new
    return t


def _padded(pair: np.ndarray, values: list[np.ndarray], n: int, sort_key: np.ndarray
            ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Group flat per-element ``values`` by ``pair`` (sorted by ``sort_key`` within a pair) into
    (n, K) arrays, K the largest group; returns the counts (n,) and the padded arrays (``inf``
    where a pair has fewer)."""
    counts = np.bincount(pair, minlength=n)
    k_max = int(counts.max()) if counts.size else 0
    order = np.lexsort((sort_key, pair))
    pair_s = pair[order]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    col = np.arange(pair.size) - starts[pair_s]
    out = []
    for v in values:
        a = np.full((n, max(k_max, 1)), np.inf)
        a[pair_s, col] = v[order]
        out.append(a)
    return counts, out


def _crossing_roots_batch(b: _Batch) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Contour crossings (oracle: ``_crossing_roots``): ``kind`` (n,) (0 same, 1 first_inside, 2
    second_inside, 3 disjoint, 4 crossing), the counts (n,) and the sorted roots on e1 and on e2
    (n, K), ``inf``-padded."""
    k0, k1, k2, k3, k4 = _crossing_coefficients(b.A[1], b.P[0], b.Q[0], -b.c[1][0],
                                                 -b.c[1][1])
    ksum = np.abs(k0) + np.abs(k1) + np.abs(k2) + np.abs(k3) + np.abs(k4)
    same = ksum <= 1e-9
    f = np.stack([k0, k1, k2, k3, k4], axis=1) @ _GRID_BASIS  # (n, GRID)
    sign = f > 1e-12
    change = sign != sign[:, _GRID_NEXT]
    change[same] = False
    crossing = change.any(axis=1)
    f_max = f[np.arange(b.n), np.argmax(np.abs(f), axis=1)]
    second_in = _quad(b.A[0], b.c[1][0], b.c[1][1]) < 1.0
    kind = np.where(same, 0, np.where(crossing, 4, np.where(
        f_max < 0.0, 1, np.where(second_in, 2, 3))))
    pair, i = np.nonzero(change)
    h = _TWO_PI / GRID
    kk = [k[pair] for k in (k0, k1, k2, k3, k4)]

    def f_and_df(t):
        ct, st = np.cos(t), np.sin(t)
        c2t, s2t = ct * ct - st * st, 2.0 * st * ct
        return (kk[0] + kk[1] * ct + kk[2] * st + kk[3] * c2t + kk[4] * s2t,
                -kk[1] * st + kk[2] * ct - 2.0 * kk[3] * s2t + 2.0 * kk[4] * c2t)

    roots1 = _newton_bracketed(f_and_df, i * h, (i + 1) * h, f[pair, i],
                               f[pair, (i + 1) % GRID], ~sign[pair, i],
                               1e-15 * ksum[pair]) % _TWO_PI
    x, y = b.point(np.zeros_like(pair), pair, roots1)
    (P2x, P2y), (Q2x, Q2y) = (v[pair] for v in b.P[1]), (v[pair] for v in b.Q[1])
    rx, ry = x - b.c[1][0][pair], y - b.c[1][1][pair]
    roots2 = np.arctan2((rx * Q2x + ry * Q2y) / (Q2x * Q2x + Q2y * Q2y),
                        (rx * P2x + ry * P2y) / (P2x * P2x + P2y * P2y)) % _TWO_PI
    counts, (r1,) = _padded(pair, [roots1], b.n, roots1)
    _, (r2,) = _padded(pair, [roots2], b.n, roots2)
    return kind, counts, r1, r2


def _inside_arcs_batch(b: _Batch, k: int, counts: np.ndarray, roots: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Oracle: ``_inside_arcs``; (pair, t0, t1) of the arcs of ellipse ``k`` between
    consecutive roots that lie inside the other ellipse (tested at the arc's middle)."""
    kmax = roots.shape[1]
    col = np.arange(kmax)[None, :]
    has = col < counts[:, None]
    last = col + 1 >= counts[:, None]
    nxt = np.where(last, 0, col + 1)
    t0 = roots
    t1 = np.take_along_axis(roots, nxt, axis=1) + np.where(last, _TWO_PI, 0.0)
    pair, j = np.nonzero(has)
    t0, t1 = t0[pair, j], t1[pair, j]
    mx, my = b.point(np.full(pair.size, k), pair, 0.5 * (t0 + t1))
    o = 1 - k
    rx, ry = mx - b.c[o][0][pair], my - b.c[o][1][pair]
    inside = _quad([a[pair] for a in b.A[o]], rx, ry) < 1.0
    keep = (t1 > t0) & inside
    return pair[keep], t0[keep], t1[keep]


def _intersection_arcs_batch(b: _Batch) -> tuple[np.ndarray, ...]:
    """The intersection's boundary as flat arcs (pair, k, t0, t1) (oracle:
    ``_intersection_pieces``)."""
    kind, counts, r1, r2 = _crossing_roots_batch(b)
    whole = np.flatnonzero(kind <= 2)
    pieces = [(whole, np.where(kind[whole] == 1, 0, 1), np.zeros(whole.size),
               np.full(whole.size, _TWO_PI))]
    cross = kind == 4
    if cross.any():
        for k, r in ((0, r1), (1, r2)):
            c = np.where(cross, counts, 0)
            pair, t0, t1 = _inside_arcs_batch(b, k, c, r)
            pieces.append((pair, np.full(pair.size, k), t0, t1))
    return tuple(np.concatenate(x) for x in zip(*pieces, strict=True))


def _hdiff_batch(coef: np.ndarray, c2x: np.ndarray, c2y: np.ndarray, t: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised ``h1 - h2`` and its derivative in the normal angle ``t`` (oracle: ``hdiff`` in
    ``_hull_pieces``): ``h_k = n . c_k + sqrt(n^T Sigma_k n)``, ``c_1 = 0``; ``coef`` from
    ``b.support[:, pair]``: per pair (6, m) ``alpha_k, beta_k, gamma_k`` of ``n^T Sigma_k n
    = alpha + beta cos 2t + gamma sin 2t`` (broadcast against ``t``)."""
    c, s = np.cos(t), np.sin(t)
    c2, s2 = c * c - s * s, 2.0 * c * s
    q1 = coef[0] + coef[1] * c2 + coef[2] * s2
    q2 = coef[3] + coef[4] * c2 + coef[5] * s2
    r1, r2 = np.sqrt(q1), np.sqrt(q2)
    dq1 = coef[2] * c2 - coef[1] * s2  # (d q / dt) / 2
    dq2 = coef[5] * c2 - coef[4] * s2
    return (r1 - r2 - (c * c2x + s * c2y),
            dq1 / r1 - dq2 / r2 - (c * c2y - s * c2x))


def _hull_batch(b: _Batch, p1: np.ndarray, p2: np.ndarray, n_directions: int
                ) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """The hulls' boundaries (oracle: ``_hull_pieces``): arcs (pair, k, t0, t1) and common
    tangent segments (pair, x0, y0, x1, y1, end, par)."""
    n = b.n
    n_dir = int(n_directions)
    basis, nxt = _direction_basis(n_dir)
    c2x, c2y = b.c[1]
    # per direction: n^T Sigma_k n and half its derivative (n, 2, 2 n_dir), n . c2 and its
    # derivative (n, 2 n_dir): two matmuls with the cached bases
    quad_rows, centre_rows = basis
    v = b.support.T.reshape(n, 2, 3) @ quad_rows
    vc = np.stack([c2x, c2y], axis=1) @ centre_rows
    sq = np.sqrt(v[:, :, :n_dir])
    dsq = v[:, :, n_dir:] / sq
    diff = sq[:, 0] - sq[:, 1] - vc[:, :n_dir]
    ddiff = dsq[:, 0] - dsq[:, 1] - vc[:, n_dir:]
    tol = 1e-10 * (p1[:, 2] + p2[:, 2] + np.abs(c2x) + np.abs(c2y))
    dominant_first = diff.sum(axis=1) >= 0.0
    first = np.where(np.abs(diff) <= tol[:, None], dominant_first[:, None], diff > 0.0)
    h = _TWO_PI / n_dir
    first_n, ddiff_n, diff_n = first[:, nxt], ddiff[:, nxt], diff[:, nxt]
    sgn = np.where(first, 1.0, -1.0)
    change = first != first_n
    turn = ~change & (sgn * ddiff < 0.0) & (sgn * ddiff_n > 0.0)

    def sub(pair):
        return b.support[:, pair], c2x[pair], c2y[pair]

    sw_pair, sw_t, sw_k = [], [], []
    pair, i = np.nonzero(change)
    if pair.size:
        co, ax, ay = sub(pair)
        t = _newton_bracketed(lambda t: _hdiff_batch(co, ax, ay, t), i * h, (i + 1) * h,
                              diff[pair, i], diff_n[pair, i], ~first[pair, i], 1e-5 * tol[pair])
        sw_pair.append(pair)
        sw_t.append(t)
        sw_k.append(np.where(first_n[pair, i], 0, 1))
    pair, i = np.nonzero(turn)
    if pair.size:
        co, ax, ay = sub(pair)
        sign = np.where(first[pair, i], 1.0, -1.0)
        lo, width = i * h, np.full(pair.size, h)
        frac = np.linspace(0.0, 1.0, _EXTREMUM_SUBGRID + 1)
        co_col, ax_col, ay_col = co[:, :, None], ax[:, None], ay[:, None]
        for _ in range(_EXTREMUM_LEVELS):
            ts = lo[:, None] + width[:, None] * frac[None, :]
            d = sign[:, None] * _hdiff_batch(co_col, ax_col, ay_col, ts)[1]
            # the sub-interval where the derivative turns from towards zero to away from it
            j = np.clip(np.argmax(d >= 0.0, axis=1) - 1, 0, _EXTREMUM_SUBGRID - 1)
            width = width / _EXTREMUM_SUBGRID
            lo = lo + j * width
        t_min = lo + 0.5 * width
        f_min = _hdiff_batch(co, ax, ay, t_min)[0]
        pokes = sign * f_min < -tol[pair]
        if pokes.any():
            pair, i, t_min, f_min = pair[pokes], i[pokes], t_min[pokes], f_min[pokes]
            co, ax, ay = sub(pair)
            fi = first[pair, i]
            loser = np.where(fi, 1, 0)
            fn = lambda t: _hdiff_batch(co, ax, ay, t)  # noqa: E731
            t_a = _newton_bracketed(fn, i * h, t_min, diff[pair, i], f_min, ~fi, 1e-5 * tol[pair])
            t_b = _newton_bracketed(fn, t_min, (i + 1) * h, f_min, diff_n[pair, i], fi,
                                    1e-5 * tol[pair])
            sw_pair += [pair, pair]
            sw_t += [t_a, t_b]
            sw_k += [loser, 1 - loser]
    if sw_pair:
        sp, st, sk = (np.concatenate(x) for x in (sw_pair, sw_t, sw_k))
    else:
        sp = np.zeros(0, dtype=int)
        st, sk = np.zeros(0), np.zeros(0, dtype=int)
    counts, (T, K) = _padded(sp, [st, sk.astype(float)], n, st)
    # one ellipse supports every direction: it contains the other
    whole = np.flatnonzero(counts == 0)
    arcs = [(whole, np.where(first[whole, 0], 0, 1), np.zeros(whole.size),
             np.full(whole.size, _TWO_PI))]
    kmax = T.shape[1]
    colj = np.arange(kmax)[None, :]
    last = colj + 1 >= counts[:, None]
    nxt = np.where(last, 0, colj + 1)
    pair, j = np.nonzero(colj < counts[:, None])
    t_start, k = T[pair, j], K[pair, j].astype(int)
    t_end = np.take_along_axis(T, nxt, axis=1)[pair, j] + np.where(last[pair, j], _TWO_PI, 0.0)
    k_next = np.take_along_axis(K, nxt, axis=1)[pair, j].astype(int)

    def contact(kk, t):
        _, _, Px, Py, Qx, Qy, _ = b.geometry(kk, pair)
        n0, n1 = np.cos(t), np.sin(t)
        return np.arctan2(n0 * Qx + n1 * Qy, n0 * Px + n1 * Py)

    par0, par1 = contact(k, t_start), contact(k, t_end)
    sweep = t_end - t_start
    span = (par1 - par0) % _TWO_PI
    span = np.where((sweep > 1.5 * math.pi) & (span < 0.5 * math.pi), span + _TWO_PI,
                    np.where((sweep < 0.5 * math.pi) & (span > 1.5 * math.pi),
                             span - _TWO_PI, span))
    arcs.append((pair, k, par0, par0 + span))
    par_next = contact(k_next, t_end)
    x0, y0 = b.point(k, pair, par0 + span)
    x1, y1 = b.point(k_next, pair, par_next)
    segs = (pair, x0, y0, x1, y1, np.where(k == 1, 0, 1), np.where(k == 1, par0 + span, par_next))
    return tuple(np.concatenate(x) for x in zip(*arcs, strict=True)), segs


def _quadrant_sums_batch(b: _Batch, region: np.ndarray, arcs: tuple[np.ndarray, ...],
                         segs: tuple[np.ndarray, ...] | None, n_regions: int, grad: bool
                         ) -> tuple[np.ndarray, np.ndarray | None]:
    """Oracle: ``_piece_sums`` with ``axes``; the areas (n_regions, n, 4) of the regions
    bounded by the arcs (pair, k, t0, t1) and segments, split into the four quadrants of the
    first ellipse's frame, and their gradients (n_regions, n, 4, 5) w.r.t. the second
    ellipse's ``g2``. ``region`` is (arc regions, segment regions)."""
    n = b.n
    ca, sa = b.axes
    arc_region, seg_region = region
    a_pair, a_k, t0, t1 = arcs
    cx, cy, Px, Py, Qx, Qy, ab = b.geometry(a_k, a_pair)
    cal, sal = ca[a_pair], sa[a_pair]
    # cuts of each arc's ellipse by the two axis lines through c1 (oracle: _Ell.line_crossings),
    # both lines at once: normals (-sin, cos) and (cos, sin) of the first ellipse's angle
    nx_, ny_ = np.stack([-sal, cal]), np.stack([cal, sal])  # (2, m)
    alpha, beta, gamma = nx_ * Px + ny_ * Py, nx_ * Qx + ny_ * Qy, nx_ * cx + ny_ * cy
    rad = np.hypot(alpha, beta)
    ok = (rad != 0.0) & (np.abs(gamma) <= rad)
    phi = np.arctan2(beta, alpha)
    dphi = np.arccos(np.clip(-gamma / np.where(rad != 0.0, rad, 1.0), -1.0, 1.0))
    c = np.concatenate([phi + dphi, phi - dphi])  # (4, m)
    cs = t0 + (c - t0) % _TWO_PI
    ok4 = np.concatenate([ok, ok])
    cuts = np.where(ok4 & (t0 < cs) & (cs < t1), cs, t1)
    bounds = np.sort(np.concatenate([t0[None], cuts, t1[None]]), axis=0)  # (6, m)
    cb, sb = np.cos(bounds), np.sin(bounds)
    lo, hi = bounds[:-1], bounds[1:]
    cl, sl, ch, sh = cb[:-1], sb[:-1], cb[1:], sb[1:]
    mid = 0.5 * (lo + hi)
    cm, sm = np.cos(mid), np.sin(mid)
    X = cx + cm * Px + sm * Qx
    Y = cy + cm * Py + sm * Qy
    quad = _quadrant_index(cal * X + sal * Y, cal * Y - sal * X)
    dc, ds = ch - cl, sh - sl
    vals = [0.5 * (ab * (hi - lo) + cx * (dc * Py + ds * Qy) - cy * (dc * Px + ds * Qx))]
    if grad:  # only the second ellipse's arcs move (oracle: _Boundary.arc)
        w = (a_k == 1) * ab
        m00, m01, m10, m11 = (x[a_pair] for x in b.M)
        iu0, iu1 = sh - sl, cl - ch
        half = 0.5 * (hi - lo)
        q = 0.5 * (sh * ch - sl * cl)  # 1/4 (sin 2 t1 - sin 2 t0)
        cc, ss, cs_ = half + q, half - q, 0.5 * (sh * sh - sl * sl)
        r00, r01 = m00 * cc + m01 * cs_, m00 * cs_ + m01 * ss
        r10, r11 = m10 * cc + m11 * cs_, m10 * cs_ + m11 * ss
        vals += [w * (m00 * iu0 + m01 * iu1), w * (m10 * iu0 + m11 * iu1),
                 0.5 * w * (r00 * m00 + r01 * m01), w * (r00 * m10 + r01 * m11),
                 0.5 * w * (r10 * m10 + r11 * m11)]
    size = n_regions * n * 4
    width = len(vals)
    acc = np.zeros((size, width))
    index = (arc_region * n + a_pair) * 4 + quad  # (5, m)
    np.add.at(acc, index.ravel(), np.stack(vals, axis=-1).reshape(-1, width))
    if segs is not None and segs[0].size:
        s_pair, x0, y0, x1, y1, end, par = segs
        wx, wy = x1 - x0, y1 - y0
        cal, sal = ca[s_pair], sa[s_pair]
        nx_, ny_ = np.stack([-sal, cal]), np.stack([cal, sal])
        den = nx_ * wx + ny_ * wy
        with np.errstate(over="ignore"):  # a tiny den: a cut far outside (0, 1), dropped
            sv = -(nx_ * x0 + ny_ * y0) / np.where(den != 0.0, den, 1.0)
        inner = np.where((den != 0.0) & (sv > 0.0) & (sv < 1.0), sv, 1.0)
        sb = np.sort(np.concatenate([np.zeros((1, s_pair.size)), inner,
                                     np.ones((1, s_pair.size))]), axis=0)  # (4, m)
        s0, s1 = sb[:-1], sb[1:]
        xa, ya, xb, yb = x0 + s0 * wx, y0 + s0 * wy, x0 + s1 * wx, y0 + s1 * wy
        mx, my = 0.5 * (xa + xb), 0.5 * (ya + yb)
        quad = _quadrant_index(cal * mx + sal * my, cal * my - sal * mx)
        vals = [0.5 * (xa * yb - ya * xb)]
        if grad:  # 1/2 dx(q) x (end - start) shared along the segment (oracle: _piece_sums)
            share = 0.5 * np.where(end == 1, s1 * s1 - s0 * s0, (1 - s0) ** 2 - (1 - s1) ** 2)
            m00, m01, m10, m11 = (x[s_pair] for x in b.M)
            u0, u1 = np.cos(par), np.sin(par)
            v0, v1 = m00 * u0 + m01 * u1, m10 * u0 + m11 * u1
            p0, p1 = wy, -wx
            vals += [share * p0, share * p1, share * (0.5 * v0 * p0),
                     share * (0.5 * (v1 * p0 + v0 * p1)), share * (0.5 * v1 * p1)]
        index = (seg_region * n + s_pair) * 4 + quad
        np.add.at(acc, index.ravel(), np.stack(vals, axis=-1).reshape(-1, width))
    areas = acc[:, 0].reshape(n_regions, n, 4)
    return areas, acc[:, 1:].reshape(n_regions, n, 4, 5) if grad else None


def _quadrant_index(xl: np.ndarray, yl: np.ndarray) -> np.ndarray:
    """Quadrant 0..3 (counter-clockwise from ``+u, +v``) of local coordinates, as the oracle's
    ``quadrant`` of ``_piece_sums`` (boundaries: ``yl >= 0`` upper, ``xl >= 0`` right)."""
    return np.where(yl >= 0.0, np.where(xl >= 0.0, 0, 1), np.where(xl < 0.0, 2, 3))


def quadrant_areas_batch(
    p1: np.ndarray, p2: np.ndarray, hull: bool, n_directions: int = HULL_DIRECTIONS,
    gradient: bool = False,
) -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    """Areas in the four quadrants of the first ellipse's frame (centred on it, along its
    axes, counter-clockwise from ``+u, +v``; the first ellipse has ``A1 / 4`` in each) of the
    second ellipse, of the intersection and, if ``hull``, of the convex hull, for N pairs:
    params ``p1``, ``p2`` (N, 5) (px, rad). Returns ``{"second", "intersection"[, "hull"]}`` ->
    ``(areas (N, 4) px^2, gradients (N, 4, 5) or None)``, gradients w.r.t. each second
    ellipse's ``g2 = (mu_x, mu_y, s00, s01, s11)``. ``n_directions`` (>= 8): hull normals."""
    p1 = np.asarray(p1, dtype=float).reshape(-1, 5)
    p2 = np.asarray(p2, dtype=float).reshape(-1, 5)
    if p1.shape != p2.shape:
        raise ValueError(f"p1 and p2 must have the same shape (N, 5), got {p1.shape}, {p2.shape}")
    b = _Batch(p1, p2)
    n = b.n
    full = (np.arange(n), np.ones(n, dtype=int), np.zeros(n), np.full(n, _TWO_PI))
    inter = _intersection_arcs_batch(b)
    arcs = [full, inter]
    segs = None
    names = ["second", "intersection"]
    if hull:
        h_arcs, segs = _hull_batch(b, p1, p2, n_directions)
        arcs.append(h_arcs)
        names.append("hull")
    arc_region = np.concatenate([np.full(a[0].size, r) for r, a in enumerate(arcs)])
    all_arcs = tuple(np.concatenate(x) for x in zip(*arcs, strict=True))
    seg_region = np.full(0 if segs is None else segs[0].size, 2)
    areas, grads = _quadrant_sums_batch(b, (arc_region, seg_region), all_arcs, segs,
                                        len(names), gradient)
    return {name: (areas[r], None if grads is None else grads[r])
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
