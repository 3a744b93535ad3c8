"""The scalar exact-area construction (one pair of ellipses at a time): the tests' oracle for
the batched :func:`quadloc.factors.overlap.quadrant_areas_batch` (the only production
implementation).

Moved verbatim from ``factors/overlap.py`` (issue 10); the algorithm is described in
``docs/design/factors.md`` ("Exact ellipse areas").
"""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np

from quadloc.factors.conics import sigma_entries

#: Number of parametric angles used to bracket the contour intersections.
GRID = 128
#: Default number of normal directions used to bracket the hull's common tangents.
HULL_DIRECTIONS = 128

_T_GRID = np.linspace(0.0, 2.0 * np.pi, GRID, endpoint=False)
_COS_GRID, _SIN_GRID = np.cos(_T_GRID), np.sin(_T_GRID)
_COS2_GRID, _SIN2_GRID = np.cos(2 * _T_GRID), np.sin(2 * _T_GRID)
#: (5, GRID): rows 1, cos t, sin t, cos 2t, sin 2t (the contour function on the grid is one
#: matmul with its coefficients), and the cyclic next index on the grid
_GRID_BASIS = np.stack([np.ones(GRID), _COS_GRID, _SIN_GRID, _COS2_GRID, _SIN2_GRID])
_GRID_NEXT = np.roll(np.arange(GRID), -1)
_TWO_PI = 2.0 * math.pi


def _sign_changes(positive: np.ndarray) -> list[int]:
    """Indices ``i`` where ``positive[i] != positive[(i + 1) % n]`` (cyclic)."""
    idx = np.flatnonzero(positive[:-1] != positive[1:]).tolist()
    if positive[-1] != positive[0]:
        idx.append(positive.size - 1)
    return idx


def _ellipse_terms(p: np.ndarray) -> tuple[float, ...]:
    """``(Px, Py, Qx, Qy, A00, A01, A11)``: axis vectors ``P = a u``, ``Q = b v`` and ``A``."""
    a, b, angle = float(p[2]), float(p[3]), float(p[4])
    c, s = math.cos(angle), math.sin(angle)
    return (a * c, a * s, -b * s, b * c, *sigma_entries(1.0 / a, 1.0 / b, angle))


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


def _bracketed_root(fn, lo: float, hi: float, f0: float, f1: float, neg_lo: bool) -> float:
    """The root in ``[lo, hi]`` of a smooth ``fn(t) -> (f, df/dt)`` that changes sign there,
    negative at ``lo`` iff ``neg_lo`` (a rounding-level ``f0`` counts as its grid class).

    Newton steps from the secant guess ``f0``/``f1``, safeguarded by bisection: the bracket
    shrinks around the root at every step, so a step never leaves it (a plain clamped Newton
    can stall on the bracket's end and report it as the root).
    """
    t = lo + (hi - lo) * f0 / (f0 - f1) if f0 != f1 else 0.5 * (lo + hi)
    t = min(max(t, lo), hi)
    for _ in range(100):
        f, df = fn(t)
        if f == 0.0:
            return t
        if (f < 0.0) == neg_lo:
            lo = t
        else:
            hi = t
        t_new = t - f / df if df != 0.0 else lo - 1.0
        if not lo < t_new < hi:
            t_new = 0.5 * (lo + hi)
        if abs(t_new - t) < 1e-15 or hi - lo < 1e-15:
            return t_new
        t = t_new
    return t


class _Boundary:
    """First-order motion of an ellipse's boundary with its Gaussian parameters.

    The boundary is ``x(t) = mu + L u(t)``, ``u = (cos t, sin t)``, ``L = R(angle) diag(a, b)``
    (the parametric angle used throughout this module). A change ``(d mu, d Sigma)`` of
    ``g = (mu_x, mu_y, s00, s01, s11)`` (``s01`` both off-diagonal entries) moves it by
    ``dx(t) = d mu + 1/2 d Sigma L^-T u(t)`` (one choice of ``dL`` with ``L dL^T + dL L^T =
    d Sigma``; other choices differ by a tangential motion, which changes no area). Each method
    returns a gradient over ``g`` (list of 5 floats).
    """

    __slots__ = ("ab", "m00", "m01", "m10", "m11")

    def __init__(self, p: np.ndarray) -> None:
        a, b = float(p[2]), float(p[3])
        c, s = math.cos(float(p[4])), math.sin(float(p[4]))
        self.m00, self.m01, self.m10, self.m11 = c / a, -s / b, s / a, c / b  # M = L^-T
        self.ab = a * b

    def arc(self, t0: float, t1: float) -> list[float]:
        """Gradient of ``∫_t0^t1 dx × x'(t) dt`` (the area swept by the arc, CCW outward).

        ``dx × x' = det(L) [(L^-1 d mu) . u + 1/2 u^T L^-1 d Sigma L^-T u]`` (``J^T L J =
        det(L) L^-T`` for 2x2), integrated in closed form: ``∫u``, ``∫u u^T``."""
        s0, c0, s1, c1 = math.sin(t0), math.cos(t0), math.sin(t1), math.cos(t1)
        iu0, iu1 = s1 - s0, c0 - c1
        half = 0.5 * (t1 - t0)
        q = 0.25 * (math.sin(2.0 * t1) - math.sin(2.0 * t0))
        cc, ss, cs = half + q, half - q, 0.5 * (s1 * s1 - s0 * s0)
        m00, m01, m10, m11 = self.m00, self.m01, self.m10, self.m11
        ab = self.ab
        # M Iuu (rows), then G = 1/2 ab M Iuu M^T
        r00, r01 = m00 * cc + m01 * cs, m00 * cs + m01 * ss
        r10, r11 = m10 * cc + m11 * cs, m10 * cs + m11 * ss
        g00 = 0.5 * ab * (r00 * m00 + r01 * m01)
        g01 = 0.5 * ab * (r00 * m10 + r01 * m11)
        g11 = 0.5 * ab * (r10 * m10 + r11 * m11)
        return [ab * (m00 * iu0 + m01 * iu1), ab * (m10 * iu0 + m11 * iu1),
                g00, 2.0 * g01, g11]

    def point(self, t: float, wx: float, wy: float) -> list[float]:
        """Gradient of ``dx(t) × w`` for a fixed vector ``w``."""
        p0, p1 = wy, -wx  # a × w = a . (w_y, -w_x)
        u0, u1 = math.cos(t), math.sin(t)
        v0, v1 = self.m00 * u0 + self.m01 * u1, self.m10 * u0 + self.m11 * u1  # L^-T u
        return [p0, p1, 0.5 * v0 * p0, 0.5 * (v1 * p0 + v0 * p1), 0.5 * v1 * p1]

    def area(self) -> list[float]:
        """Gradient of the ellipse's own area ``pi sqrt(det Sigma)``: ``pi ab / 2 Sigma^-1``."""
        m00, m01, m10, m11 = self.m00, self.m01, self.m10, self.m11
        k = 0.5 * math.pi * self.ab
        # Sigma^-1 = L^-T L^-1 = M M^T
        return [0.0, 0.0, k * (m00 * m00 + m01 * m01), 2.0 * k * (m00 * m10 + m01 * m11),
                k * (m10 * m10 + m11 * m11)]


class _Ell:
    """One ellipse of a pair, relative to the integration origin ``c1`` (the first ellipse's
    centre): ``x(t) = c + cos t P + sin t Q`` with ``P = a u``, ``Q = b v``."""

    __slots__ = ("A", "P", "Q", "ab", "bnd", "c")

    def __init__(self, p: np.ndarray, origin: np.ndarray, moving: bool) -> None:
        Px, Py, Qx, Qy, *A = _ellipse_terms(p)
        self.P, self.Q, self.A = (Px, Py), (Qx, Qy), tuple(A)
        self.ab = float(p[2] * p[3])
        self.c = (float(p[0] - origin[0]), float(p[1] - origin[1]))
        self.bnd = _Boundary(p) if moving else None

    def point(self, t: float) -> tuple[float, float]:
        ct, st = math.cos(t), math.sin(t)
        return (self.c[0] + ct * self.P[0] + st * self.Q[0],
                self.c[1] + ct * self.P[1] + st * self.Q[1])

    def arc_area(self, t0: float, t1: float) -> float:
        """``1/2 ∫_t0^t1 x × dx`` (origin ``c1``), closed form (module docstring)."""
        dc, ds = math.cos(t1) - math.cos(t0), math.sin(t1) - math.sin(t0)
        (Px, Py), (Qx, Qy), (cx, cy) = self.P, self.Q, self.c
        return 0.5 * (self.ab * (t1 - t0) + cx * (dc * Py + ds * Qy) - cy * (dc * Px + ds * Qx))

    def inside(self, x: float, y: float) -> bool:
        """Is the point (origin ``c1``) strictly inside this ellipse?"""
        return _quad(self.A, x - self.c[0], y - self.c[1]) < 1.0

    def line_crossings(self, nx: float, ny: float) -> list[float]:
        """Parametric angles where the boundary meets the line ``n . x = 0`` through ``c1``."""
        alpha = nx * self.P[0] + ny * self.P[1]
        beta = nx * self.Q[0] + ny * self.Q[1]
        gamma = nx * self.c[0] + ny * self.c[1]
        rad = math.hypot(alpha, beta)
        if rad == 0.0 or abs(gamma) > rad:
            return []
        phi, dphi = math.atan2(beta, alpha), math.acos(max(-1.0, min(1.0, -gamma / rad)))
        return [(phi + dphi) % _TWO_PI, (phi - dphi) % _TWO_PI]


# A closed boundary as pieces, traversed counter-clockwise, origin c1:
#   ("arc", k, t0, t1): ellipse k (0: the first, fixed; 1: the second, moving) from t0 to t1;
#   ("seg", x0, y0, x1, y1, end, par): a common tangent segment; ``end`` is 0 if its start, 1 if
#   its end lies on the moving ellipse (at parametric angle ``par``), the other end on the
#   fixed one.
_Piece = tuple


def _crossing_roots(e1: _Ell, e2: _Ell) -> tuple[str, list[float], list[float]]:
    """Where the two contours cross: ``("same" | "first_inside" | "second_inside" |
    "disjoint" | "crossing", roots on e1, roots on e2)`` (parametric angles, sorted).

    ``f(t) = Phi_2(x_1(t)) - 1`` is a trigonometric quadratic; its roots are bracketed on a
    grid of ``GRID`` angles and refined by :func:`_bracketed_root`, then mapped to e2's angle.
    """
    k0, k1, k2, k3, k4 = _crossing_coefficients(e2.A, e1.P, e1.Q, e1.c[0] - e2.c[0],
                                                 e1.c[1] - e2.c[1])
    # f is dimensionless; identical contours give f = 0 up to rounding amplified by the
    # eccentricity, so anything below 1e-9 is treated as the same ellipse (area error <= 1e-9).
    if abs(k0) + abs(k1) + abs(k2) + abs(k3) + abs(k4) <= 1e-9:
        return "same", [], []
    f = k0 + k1 * _COS_GRID + k2 * _SIN_GRID + k3 * _COS2_GRID + k4 * _SIN2_GRID
    sign = f > 1e-12  # rounding-level values (tangency) count as inside
    idx = _sign_changes(sign)
    if not idx:
        # No crossing: E1 inside E2 (f <= 0, decided where |f| is largest, so internal
        # tangency does not matter), else E2 inside E1 iff its centre is in E1, else disjoint.
        if f[int(np.argmax(np.abs(f)))] < 0.0:
            return "first_inside", [], []
        return ("second_inside" if e1.inside(*e2.c) else "disjoint"), [], []

    def f_and_df(t: float) -> tuple[float, float]:
        ct, st = math.cos(t), math.sin(t)
        c2t, s2t = ct * ct - st * st, 2.0 * st * ct
        return (k0 + k1 * ct + k2 * st + k3 * c2t + k4 * s2t,
                -k1 * st + k2 * ct - 2.0 * k3 * s2t + 2.0 * k4 * c2t)

    h = _TWO_PI / GRID
    fl = f.tolist()
    roots1 = sorted(_bracketed_root(f_and_df, i * h, (i + 1) * h, fl[i], fl[(i + 1) % GRID],
                                    not sign[i]) % _TWO_PI for i in idx)
    # The same points on E2: x - c2 = cos t P2 + sin t Q2.
    (P2x, P2y), (Q2x, Q2y) = e2.P, e2.Q
    ia2, ib2 = 1.0 / _quad((1.0, 0.0, 1.0), P2x, P2y), 1.0 / _quad((1.0, 0.0, 1.0), Q2x, Q2y)
    roots2 = []
    for t in roots1:
        x, y = e1.point(t)
        rx, ry = x - e2.c[0], y - e2.c[1]
        roots2.append(math.atan2((rx * Q2x + ry * Q2y) * ib2, (rx * P2x + ry * P2y) * ia2)
                      % _TWO_PI)
    return "crossing", roots1, sorted(roots2)


def _inside_arcs(e: _Ell, k: int, roots: list[float], other: _Ell) -> list[_Piece]:
    """Arcs of ellipse ``e`` (index ``k``) between consecutive ``roots`` lying inside
    ``other`` (tested at the arc's middle)."""
    out = []
    n = len(roots)
    for i in range(n):
        t0 = roots[i]
        t1 = roots[i + 1] if i + 1 < n else roots[0] + _TWO_PI
        if t1 > t0 and other.inside(*e.point(0.5 * (t0 + t1))):
            out.append(("arc", k, t0, t1))
    return out


def _intersection_pieces(e1: _Ell, e2: _Ell) -> list[_Piece]:
    """The boundary of ``E1 ∩ E2``: E1's arcs inside E2 and E2's arcs inside E1."""
    kind, roots1, roots2 = _crossing_roots(e1, e2)
    if kind == "disjoint":
        return []
    if kind in ("same", "second_inside"):
        return [("arc", 1, 0.0, _TWO_PI)]
    if kind == "first_inside":
        return [("arc", 0, 0.0, _TWO_PI)]
    return _inside_arcs(e1, 0, roots1, e2) + _inside_arcs(e2, 1, roots2, e1)


def _hull_pieces(p1: np.ndarray, p2: np.ndarray, e1: _Ell, e2: _Ell,
                 n_directions: int) -> list[_Piece]:
    """The boundary of the convex hull of the two ellipses.

    The support functions ``h_i(theta) = n . c_i + sqrt(n^T Sigma_i n)`` are compared on
    ``n_directions`` normal directions to find where the supporting ellipse switches (module
    docstring); each switch (a common tangent) is refined by :func:`_bracketed_root`. The hull
    boundary is then the supporting arcs joined by the common tangent segments.
    """
    th, nx, ny = _directions(int(n_directions))
    S1, S2 = _sigma_terms(p1), _sigma_terms(p2)
    c2x, c2y = e2.c
    q1 = S1[0] * nx * nx + 2.0 * S1[1] * nx * ny + S1[2] * ny * ny
    q2 = S2[0] * nx * nx + 2.0 * S2[1] * nx * ny + S2[2] * ny * ny
    sq1, sq2 = np.sqrt(q1), np.sqrt(q2)
    diff = sq1 - (nx * c2x + ny * c2y) - sq2  # h1 - h2
    # d(h1 - h2)/dtheta with dn = (-sin, cos): dn^T S n / sqrt(n^T S n) - dn . c2.
    ddiff = ((-ny * (S1[0] * nx + S1[1] * ny) + nx * (S1[1] * nx + S1[2] * ny)) / sq1
             - (-ny * c2x + nx * c2y)
             - (-ny * (S2[0] * nx + S2[1] * ny) + nx * (S2[1] * nx + S2[2] * ny)) / sq2)
    # Ties (|h1 - h2| at rounding level: identical ellipses, internal tangency) go to the
    # ellipse that dominates overall, so they never create spurious switches.
    tol = 1e-10 * (float(p1[2]) + float(p2[2]) + abs(c2x) + abs(c2y))
    dominant_first = float(np.sum(diff)) >= 0.0
    first = np.where(np.abs(diff) <= tol, dominant_first, diff > 0.0)

    def hdiff(t: float) -> tuple[float, float]:
        c, s = math.cos(t), math.sin(t)
        out, dout = 0.0, 0.0
        for S, cx, cy, sg in ((S1, 0.0, 0.0, 1.0), (S2, c2x, c2y, -1.0)):
            sn_x, sn_y = S[0] * c + S[1] * s, S[1] * c + S[2] * s
            q = math.sqrt(c * sn_x + s * sn_y)
            out += sg * (c * cx + s * cy + q)
            dout += sg * (-s * cx + c * cy + (-s * sn_x + c * sn_y) / q)
        return out, dout

    n_dir = len(th)
    h = _TWO_PI / n_dir
    dl = diff.tolist()
    # Intervals to look at: a change of winner, or the same winner with the difference turning
    # back towards zero inside (derivative from towards-zero to away-from-zero).
    nxt = np.roll(np.arange(n_dir), -1)
    sgn = np.where(first, 1.0, -1.0)
    candidates = np.flatnonzero((first != first[nxt])
                                | ((sgn * ddiff < 0.0) & (sgn * ddiff[nxt] > 0.0)))
    switches = []  # (normal angle, index of the supporting ellipse after the switch)
    for i in candidates.tolist():
        j = (i + 1) % n_dir
        lo, hi = i * h, (i + 1) * h
        if first[i] != first[j]:
            t = _bracketed_root(hdiff, lo, hi, dl[i], dl[j], not first[i])
            switches.append((t, 0 if first[j] else 1))
            continue
        # Same winner at both ends: look for an interior extremum towards zero (the loser
        # poking out between two grid directions).
        sign = 1.0 if first[i] else -1.0
        a_, b_ = lo, hi
        for _ in range(60):  # bisection on the derivative
            m = 0.5 * (a_ + b_)
            if sign * hdiff(m)[1] < 0.0:
                a_ = m
            else:
                b_ = m
            if b_ - a_ < 1e-15:
                break
        t_min = 0.5 * (a_ + b_)
        f_min = hdiff(t_min)[0]
        if sign * f_min >= -tol:
            continue
        loser = 1 if first[i] else 0
        up, down = not first[i], bool(first[i])
        switches.append((_bracketed_root(hdiff, lo, t_min, dl[i], f_min, up), loser))
        switches.append((_bracketed_root(hdiff, t_min, hi, f_min, dl[j], down), 1 - loser))
    if not switches:  # one ellipse supports every direction: it contains the other
        return [("arc", 0 if first[0] else 1, 0.0, _TWO_PI)]
    switches.sort()
    ells = (e1, e2)

    def contact(k: int, t: float) -> float:
        """Parametric angle of the contact point of ellipse ``k`` for the normal angle ``t``."""
        e = ells[k]
        # normal n in the ellipse frame (u, v): (n.u, n.v); contact at atan2(b n.v, a n.u)
        n0, n1 = math.cos(t), math.sin(t)
        return math.atan2(n0 * e.Q[0] + n1 * e.Q[1], n0 * e.P[0] + n1 * e.P[1])

    pieces: list[_Piece] = []
    n_sw = len(switches)
    for j in range(n_sw):
        t_start, k = switches[j]
        t_end, k_next = switches[(j + 1) % n_sw]
        if j + 1 == n_sw:
            t_end += _TWO_PI
        par0, par1 = contact(k, t_start), contact(k, t_end)
        # The normal -> parametric angle map is monotone and maps half-turns to half-turns, so
        # the parametric span is on the same side of pi as the normal sweep; fix the 2 pi
        # wrap-around that rounding can cause for sweeps near 0 or 2 pi.
        sweep = t_end - t_start
        span = (par1 - par0) % _TWO_PI
        if sweep > 1.5 * math.pi and span < 0.5 * math.pi:
            span += _TWO_PI
        elif sweep < 0.5 * math.pi and span > 1.5 * math.pi:
            span -= _TWO_PI
        pieces.append(("arc", k, par0, par0 + span))
        # Common tangent segment from this arc's end to the next arc's start.
        par_next = contact(k_next, t_end)
        x0, y0 = ells[k].point(par0 + span)
        x1, y1 = ells[k_next].point(par_next)
        pieces.append(("seg", x0, y0, x1, y1, 0 if k == 1 else 1,
                       par0 + span if k == 1 else par_next))
    return pieces


def _piece_sums(pieces: list[_Piece], ells: tuple[_Ell, _Ell], grad: bool,
                axes: tuple[float, float] | None = None) -> tuple[list[float], list[list[float]]]:
    """Area ``1/2 ∮ x × dx`` of the region bounded by ``pieces`` and, if ``grad``, its
    gradient w.r.t. the moving ellipse's ``g2`` (module docstring, "Derivatives").

    With ``axes = (cos, sin)`` of the first ellipse's angle, the region is split into the four
    quadrants of the first ellipse's frame (centred on it, along its axes; counter-clockwise
    from ``+u, +v``): ``1/2 ∫ x × dx`` vanishes along rays from the origin, so each quadrant's
    area is the sum over the pieces' parts inside it. Returns lists of 1 or 4 areas and
    gradients.
    """
    n_out = 1 if axes is None else 4
    areas = [0.0] * n_out
    grads = [[0.0] * 5 for _ in range(n_out)]
    if axes is not None:
        ca, sa = axes
        lines = ((-sa, ca), (ca, sa))  # normals of the +u axis line and of the +v axis line
        cuts_by_ellipse: list[list[float] | None] = [None, None]

    def quadrant(x: float, y: float) -> int:
        xl, yl = ca * x + sa * y, -sa * x + ca * y
        if yl >= 0.0:
            return 0 if xl >= 0.0 else 1
        return 2 if xl < 0.0 else 3

    def add(q: int, area: float, g: list[float] | None, w: float = 1.0) -> None:
        areas[q] += area
        if g is not None:
            row = grads[q]
            for i in range(5):
                row[i] += w * g[i]

    for piece in pieces:
        if piece[0] == "arc":
            _, k, t0, t1 = piece
            e = ells[k]
            if axes is None:
                add(0, e.arc_area(t0, t1), e.bnd.arc(t0, t1) if grad and k == 1 else None)
                continue
            if cuts_by_ellipse[k] is None:
                cuts_by_ellipse[k] = sorted(c for n in lines for c in e.line_crossings(*n))
            base = math.floor(t0 / _TWO_PI) * _TWO_PI
            inner = sorted(c + base + m * _TWO_PI for c in cuts_by_ellipse[k]  # type: ignore[union-attr]
                           for m in (0, 1, 2) if t0 < c + base + m * _TWO_PI < t1)
            bounds = [t0, *inner, t1]
            for a_, b_ in itertools.pairwise(bounds):
                q = quadrant(*e.point(0.5 * (a_ + b_)))
                add(q, e.arc_area(a_, b_), e.bnd.arc(a_, b_) if grad and k == 1 else None)
            continue
        _, x0, y0, x1, y1, end, par = piece
        wx, wy = x1 - x0, y1 - y0
        g_full = None
        if grad:  # 1/2 dx(q) × (end - start), q on the moving ellipse
            g_full = ells[1].bnd.point(par, wx, wy)
        if axes is None:
            add(0, 0.5 * (x0 * y1 - y0 * x1), g_full, 0.5)
            continue
        inner = []
        for nx_, ny_ in lines:
            den = nx_ * wx + ny_ * wy
            if den != 0.0:
                s = -(nx_ * x0 + ny_ * y0) / den
                if 0.0 < s < 1.0:
                    inner.append(s)
        bounds = [0.0, *sorted(inner), 1.0]
        for s0, s1 in itertools.pairwise(bounds):
            xa, ya, xb, yb = x0 + s0 * wx, y0 + s0 * wy, x0 + s1 * wx, y0 + s1 * wy
            q = quadrant(0.5 * (xa + xb), 0.5 * (ya + yb))
            # the normal motion is linear along the segment, 0 at its fixed end: this part
            # carries (sigma1^2 - sigma0^2) of it, sigma the fraction from the fixed end
            share = s1 * s1 - s0 * s0 if end == 1 else (1 - s0) ** 2 - (1 - s1) ** 2
            add(q, 0.5 * (xa * yb - ya * xb), g_full, 0.5 * share)
    return areas, grads


def _pair(p1: np.ndarray, p2: np.ndarray, grad: bool) -> tuple[_Ell, _Ell]:
    origin = np.asarray(p1[:2], dtype=float)
    return _Ell(p1, origin, False), _Ell(p2, origin, grad)


def intersection_area(p1: np.ndarray, p2: np.ndarray) -> float:
    """Area (px^2) of the intersection of two filled ellipses given as params (5,)."""
    e1, e2 = _pair(p1, p2, False)
    area = _piece_sums(_intersection_pieces(e1, e2), (e1, e2), False)[0][0]
    return min(max(area, 0.0), math.pi * min(e1.ab, e2.ab))


def hull_area(p1: np.ndarray, p2: np.ndarray, n_directions: int = HULL_DIRECTIONS) -> float:
    """Area (px^2) of the convex hull of two ellipses, exact (see the module docstring)."""
    e1, e2 = _pair(p1, p2, False)
    return _piece_sums(_hull_pieces(p1, p2, e1, e2, n_directions), (e1, e2), False)[0][0]


def quadrant_areas(
    p1: np.ndarray, p2: np.ndarray, hull: bool, n_directions: int = HULL_DIRECTIONS,
    gradient: bool = False,
) -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    """Areas (px^2) in the four quadrants of the first ellipse's frame (module docstring,
    "Quadrants") of the second ellipse (``"second"``), of the intersection (``"intersection"``)
    and, if ``hull``, of the convex hull (``"hull"``): each ``(areas (4,), gradients (4, 5) or
    None)``, gradients w.r.t. the second ellipse's ``g2``. The first ellipse has ``A1 / 4`` in
    each quadrant."""
    e1, e2 = _pair(p1, p2, gradient)
    ells = (e1, e2)
    axes = (math.cos(float(p1[4])), math.sin(float(p1[4])))
    regions = {"second": [("arc", 1, 0.0, _TWO_PI)], "intersection": _intersection_pieces(e1, e2)}
    if hull:
        regions["hull"] = _hull_pieces(p1, p2, e1, e2, n_directions)
    out = {}
    for name, pieces in regions.items():
        areas, grads = _piece_sums(pieces, ells, gradient, axes)
        out[name] = (np.asarray(areas), np.asarray(grads) if gradient else None)
    return out


@functools.lru_cache(maxsize=8)
def _direction_basis(n: int) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """Bases over the n hull directions ``t`` for :func:`_hull_batch`: (3, 2n) rows ``[1,
    cos 2t, sin 2t]`` then ``[0, -sin 2t, cos 2t]`` (``n^T Sigma n`` and half its derivative
    from the coefficients of ``_Batch.support``), (2, 2n) rows ``[cos t, sin t]`` then ``[-sin
    t, cos t]`` (``n . c`` and its derivative); and the cyclic next index (n,)."""
    th, c, s = _directions(n)
    c2, s2 = np.cos(2 * th), np.sin(2 * th)
    quad_rows = np.stack([np.concatenate([np.ones(n), np.zeros(n)]),
                          np.concatenate([c2, -s2]), np.concatenate([s2, c2])])
    centre_rows = np.stack([np.concatenate([c, -s]), np.concatenate([s, c])])
    return (quad_rows, centre_rows), np.roll(np.arange(n), -1)


@functools.lru_cache(maxsize=8)
def _directions(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    th = np.linspace(0.0, _TWO_PI, n, endpoint=False)
    return th, np.cos(th), np.sin(th)


def _sigma_terms(p: np.ndarray) -> tuple[float, float, float]:
    """``(s00, s01, s11)`` of ``Sigma`` for params ``p = (cx, cy, a, b, angle)``."""
    return sigma_entries(float(p[2]), float(p[3]), float(p[4]))

