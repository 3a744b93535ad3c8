"""Exact ellipse areas for the IoU / GIoU metrics (private helper of :mod:`factors.metrics`).

Intersection area (exact up to root finding, float64)
-----------------------------------------------------
The boundary of ``E1 ∩ E2`` is made of the arcs of ``∂E1`` inside ``E2`` and the arcs of ``∂E2``
inside ``E1``, all traversed counter-clockwise (increasing parametric angle). By Green's theorem
the area is ``1/2 ∮ x × dx`` over those arcs, and for an ellipse arc
``x(t) = c + a cos(t) u + b sin(t) v`` (``u, v`` the unit axes, ``u × v = 1``) the integral has the
closed form ``1/2 [a b (t1 - t0) + c × (a (cos t1 - cos t0) u + b (sin t1 - sin t0) v)]``.
The arc end points are the intersection points of the two contours: the roots of the
trigonometric quadratic ``f(t) = Phi_2(x_1(t)) - 1`` (bracketed on a grid of ``GRID`` parametric
angles, then refined by Newton steps to machine precision). The same intersection points are
mapped to ``E2``'s parametric angle, so both boundaries use one consistent set of end points.
Only two roots closer together than one grid step (a lens thinner than ~1e-3 of the ellipse)
can be missed; the area then loses that lens.

Convex hull area (for GIoU, exact up to root finding)
-----------------------------------------------------
The hull boundary is made of arcs of the two ellipses joined by their common tangent segments.
The support functions ``h_i(theta) = n . c_i + sqrt(n^T Sigma_i n)`` are compared on
``n_directions`` normal directions (default 128) to find where the supporting ellipse switches
(a common tangent), each switch is refined by Newton steps, then the area is the sum of the
closed-form Green integrals of the supporting arcs plus ``1/2 p × q`` for each tangent segment.
Two switches closer than one direction step (an ellipse that pokes out of the other over a narrow
range of normals) leave no sign change on the grid; they are found from the derivative of
``h_1 - h_2``: on an interval where the grid winner does not change but the difference has an
interior extremum towards zero (its derivative changes sign), the extremum is located by bisection
on the derivative and, if the winner changes there, the two switches are bracketed on either side.
The result no longer depends on how the direction grid happens to fall (rigid-motion invariant).

Derivatives (exact, for the pose factors)
-----------------------------------------
Both areas are differentiated with respect to the second ellipse's Gaussian parameters
``g2 = (mu_x, mu_y, s00, s01, s11)`` (``Sigma = A^-1``, px^2) by the first-order area change of
a region whose boundary moves by ``dx``: ``dA = ∮ dx × dx/dt dt`` over the boundary traversed
counter-clockwise. Only the second ellipse's boundary moves (``_Boundary``), so
``dI = ∫ over its arcs inside E1``, in closed form per arc (``∫ u``, ``∫ u u^T`` of
``u = (cos t, sin t)``), and ``dH`` = the same over its arcs on the hull plus
``1/2 dx(q) × (end - start)`` for each common tangent segment touching it at ``q`` (the
contact points slide along the segment, and the first ellipse's end does not move). The end
points of the arcs need no derivative (the integrand is continuous across them). Gradients are
checked against central differences in the tests.
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
_COS_GRID, _SIN_GRID = np.cos(_T_GRID), np.sin(_T_GRID)
_COS2_GRID, _SIN2_GRID = np.cos(2 * _T_GRID), np.sin(2 * _T_GRID)
_TWO_PI = 2.0 * math.pi


def _sign_changes(positive: np.ndarray) -> list[int]:
    """Indices ``i`` where ``positive[i] != positive[(i + 1) % n]`` (cyclic)."""
    idx = np.flatnonzero(positive[:-1] != positive[1:]).tolist()
    if positive[-1] != positive[0]:
        idx.append(positive.size - 1)
    return idx


def _ellipse_terms(p: np.ndarray) -> tuple[float, ...]:
    """``(Px, Py, Qx, Qy, A00, A01, A11)``: axis vectors ``P = a u``, ``Q = b v`` and ``A``."""
    a, b = float(p[2]), float(p[3])
    c, s = math.cos(p[4]), math.sin(p[4])
    ia, ib = 1.0 / (a * a), 1.0 / (b * b)
    return (a * c, a * s, -b * s, b * c,
            ia * c * c + ib * s * s, (ia - ib) * c * s, ia * s * s + ib * c * c)


def _quad(A: tuple[float, float, float], x: float, y: float) -> float:
    return A[0] * x * x + 2.0 * A[1] * x * y + A[2] * y * y


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


def intersection_area(p1: np.ndarray, p2: np.ndarray) -> float:
    """Area (px^2) of the intersection of two filled ellipses given as params (5,)."""
    return _intersection(p1, p2, False)[0]


def intersection_area_and_gradient(p1: np.ndarray, p2: np.ndarray) -> tuple[float, np.ndarray]:
    """Intersection area (px^2) and its gradient (5,) with respect to the second ellipse's
    Gaussian parameters ``g2 = (mu_x, mu_y, s00, s01, s11)`` (module docstring, "Derivatives")."""
    area, grad = _intersection(p1, p2, True)
    return area, np.asarray(grad)


def _intersection(p1: np.ndarray, p2: np.ndarray, grad: bool) -> tuple[float, list[float]]:
    """Intersection area and, if ``grad``, its gradient w.r.t. ``g2`` (else zeros)."""
    zero = [0.0] * 5
    P1x, P1y, Q1x, Q1y, *A1l = _ellipse_terms(p1)
    P2x, P2y, Q2x, Q2y, *A2l = _ellipse_terms(p2)
    A1, A2 = tuple(A1l), tuple(A2l)
    ab1, ab2 = float(p1[2] * p1[3]), float(p2[2] * p2[3])
    # Origin of the integration at c1; d = c1 - c2.
    dx, dy = float(p1[0] - p2[0]), float(p1[1] - p2[1])

    def bil(A: tuple[float, float, float], x: float, y: float, u: float, v: float) -> float:
        return A[0] * x * u + A[1] * (x * v + y * u) + A[2] * y * v

    pap, qaq = _quad(A2, P1x, P1y), _quad(A2, Q1x, Q1y)
    paq = bil(A2, P1x, P1y, Q1x, Q1y)
    k0 = _quad(A2, dx, dy) + 0.5 * (pap + qaq) - 1.0
    k1, k2 = 2.0 * bil(A2, dx, dy, P1x, P1y), 2.0 * bil(A2, dx, dy, Q1x, Q1y)
    k3, k4 = 0.5 * (pap - qaq), paq
    # f is dimensionless; identical contours give f = 0 up to rounding amplified by the
    # eccentricity, so anything below 1e-9 is treated as the same ellipse (area error <= 1e-9).
    if abs(k0) + abs(k1) + abs(k2) + abs(k3) + abs(k4) <= 1e-9:
        # the same ellipse: the area is not differentiable (a kink of min(A1, A2)); half of
        # dA2 is the average of its one-sided derivatives for a change of size
        return math.pi * ab1, ([0.5 * g for g in _Boundary(p2).area()] if grad else zero)
    f = k0 + k1 * _COS_GRID + k2 * _SIN_GRID + k3 * _COS2_GRID + k4 * _SIN2_GRID
    sign = f > 1e-12  # rounding-level values (tangency) count as inside
    idx = _sign_changes(sign)
    if not idx:
        # No crossing: E1 inside E2 (f <= 0, decided where |f| is largest, so internal
        # tangency does not matter), else E2 inside E1 iff its centre is in E1, else disjoint.
        if f[int(np.argmax(np.abs(f)))] < 0.0:
            return math.pi * ab1, zero
        if _quad(A1, -dx, -dy) < 1.0:
            return math.pi * ab2, (_Boundary(p2).area() if grad else zero)
        return 0.0, zero

    def f_and_df(t: float) -> tuple[float, float]:
        ct, st = math.cos(t), math.sin(t)
        c2t, s2t = ct * ct - st * st, 2.0 * st * ct
        return (k0 + k1 * ct + k2 * st + k3 * c2t + k4 * s2t,
                -k1 * st + k2 * ct - 2.0 * k3 * s2t + 2.0 * k4 * c2t)

    h = _TWO_PI / GRID
    fl = f.tolist()
    roots1 = []
    for i in idx:
        lo = i * h
        roots1.append(_bracketed_root(f_and_df, lo, lo + h, fl[i], fl[(i + 1) % GRID],
                                      not sign[i]) % _TWO_PI)
    roots1.sort()
    # The same intersection points on E2: x - c2 = cos t P2 + sin t Q2.
    roots2 = []
    ia2, ib2 = 1.0 / float(p2[2]) ** 2, 1.0 / float(p2[3]) ** 2
    for t in roots1:
        rx = math.cos(t) * P1x + math.sin(t) * Q1x + dx
        ry = math.cos(t) * P1y + math.sin(t) * Q1y + dy
        roots2.append(math.atan2((rx * Q2x + ry * Q2y) * ib2, (rx * P2x + ry * P2y) * ia2)
                      % _TWO_PI)
    roots2.sort()
    arcs2: list[tuple[float, float]] | None = [] if grad else None
    area = _inside_arcs_area(roots1, (P1x, P1y, Q1x, Q1y), ab1, dx, dy, A2, 0.0, 0.0)
    area += _inside_arcs_area(roots2, (P2x, P2y, Q2x, Q2y), ab2, -dx, -dy, A1, -dx, -dy,
                              arcs2)
    clamped = min(max(area, 0.0), math.pi * min(ab1, ab2))
    if not grad:
        return clamped, zero
    if clamped != area:  # rounding put it outside [0, min(A1, A2)]: the bound's derivative
        return clamped, (_Boundary(p2).area() if clamped > 0.0 and ab2 <= ab1 else zero)
    # Only E2's arcs move: dI = sum over E2's arcs inside E1 of  ∫ dx × x'(t) dt.
    bnd = _Boundary(p2)
    g = zero[:]
    for t0, t1 in arcs2:  # type: ignore[union-attr]
        for k, v in enumerate(bnd.arc(t0, t1)):
            g[k] += v
    return clamped, g


def _inside_arcs_area(t: list[float], PQ: tuple[float, float, float, float], ab: float,
                      ox: float, oy: float, A_other: tuple[float, float, float],
                      cx: float, cy: float,
                      arcs: list[tuple[float, float]] | None = None) -> float:
    """Green's integral ``1/2 ∫ x × dx`` over the arcs of one ellipse (between consecutive
    sorted angles ``t``) lying inside the other one (``Phi_other < 1`` at the arc's middle).
    ``(ox, oy)`` is this ellipse's centre minus the other's; ``(cx, cy)`` is this centre
    relative to the integration origin. Closed form per arc (see the module docstring).
    The kept arcs ``(t0, t1)`` are appended to ``arcs`` when given.
    """
    Px, Py, Qx, Qy = PQ
    n = len(t)
    area = 0.0
    for i in range(n):
        t0 = t[i]
        t1 = t[i + 1] if i + 1 < n else t[0] + _TWO_PI
        if not t1 > t0:
            continue
        tm = 0.5 * (t0 + t1)
        cm, sm = math.cos(tm), math.sin(tm)
        if _quad(A_other, cm * Px + sm * Qx + ox, cm * Py + sm * Qy + oy) >= 1.0:
            continue
        dc, ds = math.cos(t1) - math.cos(t0), math.sin(t1) - math.sin(t0)
        area += 0.5 * (ab * (t1 - t0) + cx * (dc * Py + ds * Qy) - cy * (dc * Px + ds * Qx))
        if arcs is not None:
            arcs.append((t0, t1))
    return area


@functools.lru_cache(maxsize=8)
def _directions(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    th = np.linspace(0.0, _TWO_PI, n, endpoint=False)
    return th, np.cos(th), np.sin(th)


def _sigma_terms(p: np.ndarray) -> tuple[float, float, float]:
    """``(s00, s01, s11)`` of ``Sigma`` for params ``p = (cx, cy, a, b, angle)``."""
    return sigma_entries(float(p[2]), float(p[3]), float(p[4]))


def hull_area(p1: np.ndarray, p2: np.ndarray, n_directions: int = HULL_DIRECTIONS) -> float:
    """Area (px^2) of the convex hull of two ellipses, exact (see the module docstring)."""
    return _hull(p1, p2, n_directions, False)[0]


def hull_area_and_gradient(p1: np.ndarray, p2: np.ndarray,
                           n_directions: int = HULL_DIRECTIONS) -> tuple[float, np.ndarray]:
    """Hull area (px^2) and its gradient (5,) w.r.t. the second ellipse's Gaussian parameters
    ``g2 = (mu_x, mu_y, s00, s01, s11)`` (module docstring, "Derivatives")."""
    area, grad = _hull(p1, p2, n_directions, True)
    return area, np.asarray(grad)


def _hull(p1: np.ndarray, p2: np.ndarray, n_directions: int,
          grad: bool) -> tuple[float, list[float]]:
    """Hull area and, if ``grad``, its gradient w.r.t. ``g2`` (else zeros).

    The support functions ``h_i(theta) = n . c_i + sqrt(n^T Sigma_i n)`` are compared on
    ``n_directions`` normal directions to find where the supporting ellipse switches; each
    switch direction (a common tangent) is refined by Newton steps on ``h_1 - h_2``. The hull
    boundary is then the supporting arcs (closed-form Green integrals) joined by the common
    tangent segments (``1/2 p × q`` each).
    """
    th, nx, ny = _directions(int(n_directions))
    S1, S2 = _sigma_terms(p1), _sigma_terms(p2)
    # Origin at c1.
    c2x, c2y = float(p2[0] - p1[0]), float(p2[1] - p1[1])
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
    zero = [0.0] * 5
    if not switches:  # one ellipse supports every direction: it contains the other
        if first[0]:
            return math.pi * float(p1[2] * p1[3]), zero
        return math.pi * float(p2[2] * p2[3]), (_Boundary(p2).area() if grad else zero)
    switches.sort()
    ells = ((p1, 0.0, 0.0), (p2, c2x, c2y))

    def contact(k: int, t: float) -> tuple[float, float, float]:
        """Contact point (origin c1) and parametric angle of ellipse ``k`` for normal ``t``."""
        p, cx, cy = ells[k]
        a, b, ang = float(p[2]), float(p[3]), float(p[4])
        ca, sa = math.cos(ang), math.sin(ang)
        nu, nv = math.cos(t - ang), math.sin(t - ang)  # normal in the ellipse frame
        par = math.atan2(b * nv, a * nu)
        x_loc, y_loc = a * math.cos(par), b * math.sin(par)
        return cx + ca * x_loc - sa * y_loc, cy + sa * x_loc + ca * y_loc, par

    area = 0.0
    g = zero[:]
    bnd = _Boundary(p2) if grad else None
    n_sw = len(switches)
    for j in range(n_sw):
        t_start, k = switches[j]
        t_end, k_next = switches[(j + 1) % n_sw]
        if j + 1 == n_sw:
            t_end += _TWO_PI
        p, cx, cy = ells[k]
        a, b, ang = float(p[2]), float(p[3]), float(p[4])
        _, _, par0 = contact(k, t_start)
        x1, y1, par1 = contact(k, t_end)
        # The normal -> parametric angle map is monotone and maps half-turns to half-turns, so
        # the parametric span is on the same side of pi as the normal sweep; fix the 2 pi
        # wrap-around that rounding can cause for sweeps near 0 or 2 pi.
        sweep = t_end - t_start
        span = (par1 - par0) % _TWO_PI
        if sweep > 1.5 * math.pi and span < 0.5 * math.pi:
            span += _TWO_PI
        elif sweep < 0.5 * math.pi and span > 1.5 * math.pi:
            span -= _TWO_PI
        par1 = par0 + span
        ca, sa = math.cos(ang), math.sin(ang)
        dc, ds = math.cos(par1) - math.cos(par0), math.sin(par1) - math.sin(par0)
        wx = a * dc * ca - b * ds * sa
        wy = a * dc * sa + b * ds * ca
        area += 0.5 * (a * b * span + cx * wy - cy * wx)
        # Common tangent segment from this arc's end to the next arc's start.
        xn, yn, par_next = contact(k_next, t_end)
        area += 0.5 * (x1 * yn - y1 * xn)
        if bnd is not None:
            # dH = ∫ over E2's hull arcs of dx × x' dt, plus 1/2 dx(q) × (end - start) for
            # each tangent segment touching E2 at q (the contact points slide along the
            # segment, and E1's end does not move).
            parts = [bnd.point(par1 if k == 1 else par_next, xn - x1, yn - y1)]
            if k == 1:
                parts.append(bnd.arc(par0, par1))
            for part, w in zip(parts, (0.5, 1.0), strict=False):
                for i, v in enumerate(part):
                    g[i] += w * v
    return area, g
