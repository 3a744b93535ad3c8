"""The nine ellipse-ellipse metrics of the paper, as costs and least-squares residuals.

Public entry points
-------------------
* ``cost(name, detection, projection, **options) -> float``
* ``residual(name, detection, projection, **options) -> FloatArray`` (1-D, fixed length per
  metric and options) with ``cost == ||residual||^2`` (to rounding, ~1e-12 relative), except
  iou / giou: ``cost == sum(residual)`` (non-negative rows, see below).
* ``residual_size(name, **options) -> int``.
* ``level_set_sample_points(...)`` / ``level_set_sampling_scale(...)``: the level-set sampling
  layout, shared with the GTSAM factors.
* ``conic_residuals`` / ``overlap_residual``: the batched (N pairs) implementations.

One implementation per metric (decided, issue 10): the smooth metrics (bbox, algebraic,
frobenius, wasserstein, bhattacharyya) are :func:`conic_residuals`, iou / giou are
:func:`overlap_residual` (exact areas of :mod:`quadloc.factors.overlap`), both batched; ``residual``
and ``cost`` are their N = 1 views and :mod:`quadloc.factors.pose_conic_metrics` /
:mod:`quadloc.factors.pose_overlap_metrics` chain them to the pose. The former scalar forms are the
tests' oracle (``tests/support/oracles/metrics_reference.py``). ``qbbox`` and ``level_set`` exist
here one pair at a time (the pose factors' level set is its own evaluation in the camera rays,
:mod:`quadloc.factors.pose_level_set`, tested equal to :func:`residual`).

Argument order: the **detection** (fixed, measured) comes first, the **projection** (the
moving, predicted ellipse) second. Every residual is "detection minus projection". All lengths
are pixels, angles radians (see :mod:`quadloc.factors.conics` for the ellipse conventions). Design
rationale: ``docs/design/factors.md`` ("Metrics").

Metrics, costs and residuals (``r``, length in brackets)
--------------------------------------------------------
``iou`` [4]
    Jaccard distance ``Delta = 1 - |D ∩ P| / |D ∪ P|`` in ``[0, 1]`` (the cost); flat (== 1)
    for disjoint ellipses. ``r_k = |(D △ P) ∩ Q_k| / |D ∪ P| >= 0`` over the four quadrants
    ``Q_k`` of the detection's frame (centred on it, along its axes), ``sum_k r_k = Delta``.
    With ``disjoint_hull`` (the pose factors) a DISJOINT pair gets the giou rows instead;
    ``residual("iou")`` and ``cost("iou")`` are the metric itself.
``giou`` [4]
    ``Delta = 1 - GIoU``, ``GIoU = IoU - |C \\ (D ∪ P)| / |C|``, ``C`` the convex hull of the
    two ellipses; in ``[0, 2]`` (the cost), flat when one ellipse contains the other. Option
    ``hull_directions`` (default 128, >= 8): accepted, no longer used (exact tangents).
    ``r_k = |(D △ P) ∩ Q_k| / |D ∪ P| + |(C \\ (D ∪ P)) ∩ Q_k| / |C|``, ``sum_k r_k = Delta``.
``bbox`` [4]
    ``r = B_D - B_P``, ``B = [xmin, ymin, xmax, ymax]`` the axis-aligned boxes; cost the
    squared norm (not rotation invariant).
``qbbox`` [4]
    ``r = B_D^trunc - B_P^trunc``, ``B^trunc`` the exact box of the part of an ellipse inside
    the image ``[0, W] x [0, H]`` (:func:`clipped_bbox`); requires ``image_size=(W, H)`` px. An
    ellipse that misses the image uses its full box clamped to the image. Equal to ``bbox``
    when both ellipses are inside the image.
``algebraic`` [5]
    ``r = vec(Cn_D) - vec(Cn_P)``, ``vec`` = the 5 upper elements ``[C00, C01, C02, C11, C12]``
    of the normalised dual conics (``C*[2,2] = -1``); units px^2 (C00, C01, C11) and px.
``frobenius`` [5]
    cost = ``Delta_fro^2`` (the paper's ``Delta_fro = ||Cn_D - Cn_P||_F`` squared),
    ``r = [d00, sqrt2 d01, sqrt2 d02, d11, sqrt2 d12]``, ``d = Cn_D - Cn_P``.
``wasserstein`` [5]
    Squared 2-Wasserstein distance of the Gaussians ``N(c, Sigma = R diag(a^2, b^2) R^T)``;
    ``r = [mu_D - mu_P, a_D - a_P, b_D - b_P, k sin(delta)]`` with canonical semi-axes
    ``a >= b``, ``delta`` the angle between the major axes reduced to ``[-pi/2, pi/2)``,
    ``k = sqrt(2 P / (Q + sqrt(Q^2 - P sin^2 delta)))``, ``P = (a_D^2 - b_D^2)(a_P^2 - b_P^2)``,
    ``Q = a_D a_P + b_D b_P`` (``r[4]`` flips sign only at perpendicular axes).
``bhattacharyya`` [5]
    ``1/8 dmu^T S^-1 dmu + 1/2 ln(det S / sqrt(det S_D det S_P))``, ``S = (S_D + S_P) / 2``;
    ``r = [L^-1 dmu / sqrt(8), G00, G11, sqrt2 G01]``, ``S = L L^T`` (Cholesky), ``G = h(log N)``
    with ``h(u) = sign(u) sqrt(ln cosh(u / 2) / 2)`` and ``N = S_D^-1/2 S_P S_D^-1/2``.
``level_set`` [n_azimuths * n_levels]
    ``r_i = Phi_D(x_i) - Phi_P(x_i)`` at the sample points of :func:`level_set_sample_points`
    (on the level curves of the DETECTION); cost ``sum r_i^2``. Options ``n_azimuths`` (6),
    ``n_levels`` (4), ``scale`` (2.0), ``adaptive`` (True).

Invariances: iou, giou, wasserstein, bhattacharyya and level_set are invariant to a common
rigid motion of both ellipses (level_set needs an even ``n_azimuths``); bbox/qbbox change with
rotations; algebraic/frobenius change with rotations and translations.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import SupportsFloat, TypedDict, cast

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.conics import (
    Ellipse,
    dual_conics_from_params,
    gaussian_derivatives_from_dual_conics,
    gaussians_from_dual_conics,
    level_values,
    sigma_entries,
)
from quadloc.factors.jit import jit
from quadloc.factors.names import METRIC_NAMES
from quadloc.factors.overlap import (
    HULL_DIRECTIONS,
    hull_area,
    intersection_area,
    quadrant_areas,
    quadrant_sums,
)

__all__ = [
    "CONIC_METRICS",
    "DEFAULT_LEVEL_SET_SCALE",
    "LEVEL_SET_ADAPTIVE_GAIN",
    "METRIC_NAMES",
    "LevelSetOptions",
    "canonical_axes",
    "clipped_bbox",
    "conic_detection_terms",
    "conic_residuals",
    "convex_hull_area",
    "cost",
    "ellipse_intersection_area",
    "level_set_sample_points",
    "level_set_sampling_scale",
    "overlap_residual",
    "residual",
    "residual_size",
]


#: Default outermost sampled level "radius" ``s_max`` (the curve ``Phi_D = s_max^2``).
DEFAULT_LEVEL_SET_SCALE = 2.0
#: Adaptive sampling: ``s_max = max(scale, LEVEL_SET_ADAPTIVE_GAIN * d)`` (see sampling doc).
LEVEL_SET_ADAPTIVE_GAIN = 1.0

_SQRT2 = math.sqrt(2.0)
_INV_SQRT8 = 1.0 / math.sqrt(8.0)
#: The metrics that are smooth functions of the projection's dual conic (:func:`conic_residuals`).
CONIC_METRICS = ("algebraic", "frobenius", "wasserstein", "bhattacharyya", "bbox")
_VEC5 = np.array([0, 1, 2, 4, 5])  # upper elements [C00, C01, C02, C11, C12], flat indices
_FRO_W = np.array([1.0, _SQRT2, _SQRT2, 1.0, _SQRT2])


class LevelSetOptions(TypedDict, total=False):
    """The ``level_set`` metric's options, as keywords of :func:`level_set_sample_points`
    (defaults there; validated at run time like every metric option)."""

    n_azimuths: int
    n_levels: int
    scale: float
    adaptive: bool


#: Per metric: its options and its residual length (level_set: ``n_azimuths * n_levels``).
_OPTIONS: dict[str, tuple[tuple[str, ...], int]] = {
    "iou": ((), 4),
    "giou": (("hull_directions",), 4),
    "bbox": ((), 4),
    "qbbox": (("image_size",), 4),
    "algebraic": ((), 5),
    "frobenius": ((), 5),
    "wasserstein": ((), 5),
    "bhattacharyya": ((), 5),
    "level_set": (("n_azimuths", "n_levels", "scale", "adaptive"), 0),
}


# --------------------------------------------------------------------------- validation


def _check_options(name: str, options: Mapping[str, object]) -> None:
    """Known metric ``name`` (``ValueError``), known ``options`` (``TypeError``)."""
    if name not in _OPTIONS:
        raise ValueError(f"unknown metric {name!r}; valid names: {', '.join(METRIC_NAMES)}")
    allowed = _OPTIONS[name][0]
    for key in options:
        if key not in allowed:
            valid = ", ".join(allowed) if allowed else "none"
            raise TypeError(f"metric {name!r} got an unknown option {key!r} (valid: {valid})")


def _check_ellipse(arg: str, value: object) -> Ellipse:
    if not isinstance(value, Ellipse):
        raise TypeError(f"{arg} must be a quadloc.factors.conics.Ellipse, "
                        f"got {type(value).__name__}")
    return value


def _positive_int(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"option {name} must be a positive integer, got {value!r}")
    return int(value)


def _positive_float(name: str, value: object) -> float:
    if isinstance(value, str | bytes | bool):  # float("2") and float(True) would pass
        raise ValueError(f"option {name} must be a number, got {value!r}")
    try:
        f = float(cast("SupportsFloat", value))  # or TypeError / ValueError
    except (TypeError, ValueError) as exc:
        raise ValueError(f"option {name} must be a number, got {value!r}") from exc
    if not (math.isfinite(f) and f > 0.0):
        raise ValueError(f"option {name} must be finite and > 0, got {value!r}")
    return f


def _image_size(value: object) -> tuple[float, float]:
    if value is None:
        raise ValueError("metric 'qbbox' needs the option image_size=(width, height) in pixels")
    try:
        w, h = cast("tuple[object, object]", value)  # unpacked or TypeError / ValueError
    except (TypeError, ValueError) as exc:
        raise ValueError(f"option image_size must be (width, height), got {value!r}") from exc
    return _positive_float("image_size[0] (width)", w), _positive_float("image_size[1] (height)", h)


# --------------------------------------------------------------------------- boxes


def clipped_bbox(ellipse: Ellipse, image_size: Sequence[float]) -> FloatArray | None:
    """Exact box ``[xmin, ymin, xmax, ymax]`` of ``ellipse ∩ [0, W] x [0, H]`` (pixels).

    The extremes of the (convex) intersection are attained among: the ellipse's own axis
    extreme points that lie in the image, the intersections of the contour with the four image
    border lines that lie on the border segments, and the image corners inside the ellipse.
    Returns ``None`` when the ellipse does not meet the image.
    """
    W, H = _image_size(image_size)
    s00, s01, s11 = sigma_entries(ellipse.a, ellipse.b, ellipse.angle)
    cx, cy = ellipse.cx, ellipse.cy
    # Inverse shape matrix A = Sigma^-1.
    det = s00 * s11 - s01 * s01
    a00, a01, a11 = s11 / det, -s01 / det, s00 / det
    xs: list[float] = []
    ys: list[float] = []
    eps = 1e-9 * max(W, H)

    def keep(x: float, y: float) -> None:
        if -eps <= x <= W + eps and -eps <= y <= H + eps:
            xs.append(min(max(x, 0.0), W))
            ys.append(min(max(y, 0.0), H))

    # Axis extreme points: c ± Sigma e_x / sqrt(s00), c ± Sigma e_y / sqrt(s11).
    rx, ry = math.sqrt(s00), math.sqrt(s11)
    for sg in (-1.0, 1.0):
        keep(cx + sg * rx, cy + sg * s01 / rx)
        keep(cx + sg * s01 / ry, cy + sg * ry)
    # Contour ∩ border lines x = x0 (k = 0) and y = y0 (k = 1), in the offsets d across and
    # e along the border: a_dd d^2 + 2 a01 d e + a_ee e^2 = 1.
    for k, (a_dd, a_ee, c_d, c_e, ends) in enumerate(((a00, a11, cx, cy, (0.0, W)),
                                                       (a11, a00, cy, cx, (0.0, H)))):
        for b0 in ends:
            d = b0 - c_d
            disc = (a01 * d) ** 2 - a_ee * (a_dd * d * d - 1.0)
            if disc >= 0.0:
                r = math.sqrt(disc)
                for e in ((-a01 * d - r) / a_ee, (-a01 * d + r) / a_ee):
                    keep(*((b0, c_e + e) if k == 0 else (c_e + e, b0)))
    for x0 in (0.0, W):
        for y0 in (0.0, H):
            dx, dy = x0 - cx, y0 - cy
            if a00 * dx * dx + 2.0 * a01 * dx * dy + a11 * dy * dy <= 1.0:
                keep(x0, y0)
    if not xs:
        return None
    return np.array([min(xs), min(ys), max(xs), max(ys)])


# --------------------------------------------------------------------------- areas


def ellipse_intersection_area(e1: Ellipse, e2: Ellipse) -> float:
    """Exact area (px^2) of ``e1 ∩ e2`` (see :mod:`quadloc.factors.overlap`)."""
    return intersection_area(e1.params(), e2.params())


def convex_hull_area(e1: Ellipse, e2: Ellipse, hull_directions: int = HULL_DIRECTIONS) -> float:
    """Area (px^2) of the convex hull of the two ellipses (exact, see
    :mod:`quadloc.factors.overlap`)."""
    inter = ellipse_intersection_area(e1, e2)
    union = e1.area + e2.area - inter
    return max(hull_area(e1.params(), e2.params(), hull_directions), union)


# --------------------------------------------------------------------------- level-set sampling


@functools.lru_cache(maxsize=64)
def _level_template(n_azimuths: int, n_levels: int) -> tuple[FloatArray, FloatArray]:
    """Unit-scale layout ``(radius, phi)`` arrays of length ``n_levels * n_azimuths``.

    Level-major order: index ``i = l * n_azimuths + k`` is azimuth ``k`` of level ``l``.
    ``radius = (l + 1) / n_levels``; ``phi = 2 pi k / n_azimuths + l pi / n_azimuths``
    (staggered by half a step per level).
    """
    lv = np.repeat(np.arange(n_levels), n_azimuths)
    k = np.tile(np.arange(n_azimuths), n_levels)
    radius = (lv + 1.0) / n_levels
    phi = 2.0 * np.pi * k / n_azimuths + np.pi * lv / n_azimuths
    u = radius * np.cos(phi)
    v = radius * np.sin(phi)
    uv = np.stack([u, v], axis=-1)
    uv.setflags(write=False)
    r2 = radius**2
    r2.setflags(write=False)
    return uv, r2


def _adaptive_scale(det: Ellipse, proj: Ellipse | None, scale: float, adaptive: bool) -> float:
    if not adaptive or proj is None:
        return scale
    phi = float(level_values(det.params()[None], proj.center[None, None])[0, 0])  # Phi_D(c_P)
    return max(scale, LEVEL_SET_ADAPTIVE_GAIN * math.sqrt(phi))


def level_set_sampling_scale(
    detection: Ellipse, projection: Ellipse | None = None, *,
    scale: float = DEFAULT_LEVEL_SET_SCALE, adaptive: bool = True,
) -> float:
    """Outermost sampled level radius ``s_max`` (unitless, in detection radii).

    ``s_max = scale`` unless ``adaptive`` and a ``projection`` is given, in which case
    ``s_max = max(scale, LEVEL_SET_ADAPTIVE_GAIN * d)`` with ``d = sqrt(Phi_D(c_P))`` the
    projection centre's distance from the detection centre in the detection's own normalised
    metric (d = 1 on the detection contour). So when the ellipses are far apart the sampled
    region grows to reach the projection. ``d`` is invariant to a common rigid motion.
    For iterative refinement compute it once at the initial estimate (the paper: "depending
    on the original distance") and pass ``scale=s_max, adaptive=False`` afterwards.
    """
    _check_ellipse("detection", detection)
    if projection is not None:
        _check_ellipse("projection", projection)
    return _adaptive_scale(detection, projection, _positive_float("scale", scale), adaptive)


def _sample_points(det: Ellipse, s_max: float, n_azimuths: int, n_levels: int) -> FloatArray:
    uv, _ = _level_template(n_azimuths, n_levels)
    a, b, ang = canonical_axes(det.params()[None])[0]
    c, s = math.cos(ang), math.sin(ang)
    # x = c_D + uv @ (s_max R diag(a, b))^T
    Mt = np.array([[a * c * s_max, a * s * s_max], [-b * s * s_max, b * c * s_max]])
    points: FloatArray = uv @ Mt + (det.cx, det.cy)
    return points


def level_set_sample_points(
    detection: Ellipse, projection: Ellipse | None = None, *, n_azimuths: int = 6,
    n_levels: int = 4, scale: float = DEFAULT_LEVEL_SET_SCALE, adaptive: bool = True,
) -> FloatArray:
    """Sample points (M, 2) px, ``M = n_levels * n_azimuths``, on the detection's level curves.

    Layout (level-major, index ``i = l * n_azimuths + k``, ``l < n_levels``, ``k < n_azimuths``)::

        s_l   = s_max * (l + 1) / n_levels                  # level radius, Phi_D(x_i) = s_l^2
        phi   = 2 pi k / n_azimuths + pi l / n_azimuths      # parametric angle, staggered
        x_i   = c_D + R(angle_D) [a_D s_l cos(phi), b_D s_l sin(phi)]

    with ``s_max`` from :func:`level_set_sampling_scale` (``scale`` = 2 by default: the levels
    of radius 0.5, 1, 1.5, 2, i.e. ``Phi_D`` = 0.25, 1, 2.25, 4 including the contour).
    The detection is first put in canonical form (``a >= b``), so the layout depends only on
    the ellipse, not on how its axes are labelled. The points are attached to the detection's
    frame, hence move with it under any rigid motion (rotation equivariance; with an even
    ``n_azimuths`` the set is also unchanged by the ellipse's 180-degree symmetry, so the
    metric is exactly invariant to common rigid motions). A circle (``a == b``) has no
    orientation; its azimuths then start at its ``angle`` as given.
    """
    s_max = level_set_sampling_scale(detection, projection, scale=scale, adaptive=adaptive)
    return _sample_points(detection, s_max, _positive_int("n_azimuths", n_azimuths),
                          _positive_int("n_levels", n_levels))


def _level_set_residual(det: Ellipse, proj: Ellipse, n_azimuths: int = 6, n_levels: int = 4,
                        scale: float = DEFAULT_LEVEL_SET_SCALE,
                        adaptive: bool = True) -> FloatArray:
    n_azimuths = _positive_int("n_azimuths", n_azimuths)  # always: 6.0 == 6 but is no int
    n_levels = _positive_int("n_levels", n_levels)
    scale = _positive_float("scale", scale)
    s_max = _adaptive_scale(det, proj, scale, adaptive)
    pts = _sample_points(det, s_max, n_azimuths, n_levels)
    _, r2 = _level_template(n_azimuths, n_levels)
    phi_det = r2 * (s_max * s_max)  # exact Phi_D on the sampled level curves
    r: FloatArray = phi_det - level_values(proj.params()[None], pts[None])[0]
    return r


# --------------------------------------------------------------------------- smooth metrics


def canonical_axes(P: FloatArray) -> FloatArray:
    """``(a, b, angle)`` (N, 3) with ``a >= b`` of ellipse params ``P`` (N, 5), the angle
    shifted by pi/2 where the axes are swapped. Unlike :meth:`Ellipse.canonical` it is NOT
    wrapped to ``[-pi/2, pi/2)``: the level-set layout rotates with ``angle``, and a wrap by pi
    would reflect it through the centre (a different sample order)."""
    out = np.empty((len(P), 3))
    np.maximum(P[:, 2], P[:, 3], out=out[:, 0])
    np.minimum(P[:, 2], P[:, 3], out=out[:, 1])
    np.add(P[:, 4], (P[:, 3] > P[:, 2]) * (0.5 * np.pi), out=out[:, 2])
    return out


def conic_detection_terms(name: str, detections: FloatArray) -> tuple[FloatArray, ...]:
    """What the smooth metric ``name`` needs of detections given as params ``detections``
    (N, 5) (px, rad); they are fixed during a refinement, so the pose factors compute this once
    and pass it to every :func:`conic_residuals` call (the solver's inner loop)."""
    P = np.asarray(detections, dtype=float)
    if name in ("algebraic", "frobenius"):
        return (dual_conics_from_params(P).reshape(len(P), 9)[:, _VEC5],)
    if name == "bbox":  # the axis-aligned box [cx - hx, cy - hy, cx + hx, cy + hy]
        c, s = np.cos(P[:, 4]), np.sin(P[:, 4])
        hd = np.stack([np.hypot(P[:, 2] * c, P[:, 3] * s), np.hypot(P[:, 2] * s, P[:, 3] * c)], 1)
        return (np.concatenate((P[:, :2] - hd, P[:, :2] + hd), axis=1),)
    if name == "wasserstein":  # centre, canonical semi-axes (a >= b) and angle
        return (P[:, :2], *canonical_axes(P).T)
    # bhattacharyya: params, Sigma_D entries, cos / sin of the angle
    return (P, *sigma_entries(P[:, 2], P[:, 3], P[:, 4]), np.cos(P[:, 4]), np.sin(P[:, 4]))


def conic_residuals(
    name: str, detections: FloatArray, Cn: FloatArray, dCn: FloatArray | None = None,
    gaussians: tuple[FloatArray, FloatArray] | None = None,
    detection_terms: tuple[FloatArray, ...] | None = None,
) -> tuple[FloatArray, FloatArray | None]:
    """Residual rows (N, dim) of the smooth metric ``name`` (one of :data:`CONIC_METRICS`)
    between detections given as params ``detections`` (N, 5) (px, rad) and projections given
    as normalised dual conics ``Cn`` (N, 3, 3) (``Cn[2, 2] = -1``); with ``dCn`` (N, K, 3, 3),
    derivatives of ``Cn`` along K directions (e.g. the 6 pose tangents), also ``dr`` (N, dim,
    K) along them, else None. ``gaussians``: the projections' ``(mu (N, 2), Sigma (N, 2, 2))``
    if known more precisely than from ``Cn`` (whose entries carry ~eps |mu|^2 of rounding).
    ``detection_terms``: :func:`conic_detection_terms` of ``detections`` if already computed.

    The one implementation of these metrics: :func:`residual` is its N = 1 view and
    :class:`quadloc.factors.pose_residuals.PoseResidualModel` chains it to the pose (the scalar
    forms are the tests' oracle, ``tests/support/oracles/metrics_reference.py``).
    """
    n = Cn.shape[0]
    terms = conic_detection_terms(name, detections) if detection_terms is None \
        else detection_terms
    if name in ("algebraic", "frobenius"):
        r = terms[0] - Cn.reshape(n, 9)[:, _VEC5]
        J = None if dCn is None else -dCn.reshape(n, -1, 9)[:, :, _VEC5].transpose(0, 2, 1)
        if name == "frobenius":
            r = r * _FRO_W
            J = None if J is None else J * _FRO_W[None, :, None]
        return r, J
    mu, S = gaussians_from_dual_conics(Cn) if gaussians is None else gaussians
    d = None if dCn is None else gaussian_derivatives_from_dual_conics(mu, dCn)
    rows = {"bbox": _bbox_rows, "wasserstein": _wasserstein_rows,
            "bhattacharyya": _bhattacharyya_rows}[name]
    return rows(terms, mu, S, d)


def _conic_residual(name: str, det: Ellipse, proj: Ellipse) -> FloatArray:
    mu, S = proj.gaussian()
    r: FloatArray = conic_residuals(name, det.params()[None], proj.dual_conic()[None],
                                    gaussians=(mu[None], S[None]))[0][0]
    return r


def _bbox_rows(terms: tuple[FloatArray, ...], mu: FloatArray, S: FloatArray,
               d: tuple[FloatArray, FloatArray] | None) -> tuple[FloatArray, FloatArray | None]:
    """``r = B_D - B_P``, ``B = [cx - hx, cy - hy, cx + hx, cy + hy]`` with the half-sizes
    ``hx = sqrt(Sigma00)``, ``hy = sqrt(Sigma11)`` of the axis-aligned box (arguments as
    passed by :func:`conic_residuals`)."""
    (box_d,) = terms
    h = np.sqrt(np.diagonal(S, axis1=1, axis2=2))  # (N, 2) half-sizes (hx, hy)
    r = box_d - np.concatenate((mu - h, mu + h), axis=1)
    if d is None:
        return r, None
    dmu, dsig = d  # (N, K, 2), (N, K, 2, 2)
    dh = np.diagonal(dsig, axis1=2, axis2=3) / (2.0 * h[:, None, :])  # (N, K, 2)
    return r, np.concatenate((dh - dmu, -dmu - dh), axis=2).transpose(0, 2, 1)


def _wasserstein_rows(terms: tuple[FloatArray, ...], mu: FloatArray, S: FloatArray,
                      d: tuple[FloatArray, FloatArray] | None
                      ) -> tuple[FloatArray, FloatArray | None]:
    """The W2 residual ``[mu_D - mu_P, a_D - a_P, b_D - b_P, k sin(delta)]``
    (canonical semi-axes ``a >= b``, ``delta`` the angle between the major axes mod pi,
    ``k = sqrt(2 P / (Q + sqrt(Q^2 - P sin^2 delta)))``, ``P = (a_D^2 - b_D^2)(a_P^2 -
    b_P^2)``, ``Q = a_D a_P + b_D b_P``) and its derivative through ``Sigma_P``.

    At a circular projection (the major-axis angle is undefined) or a circular detection
    (``k = 0``) the angle terms of the Jacobian are set to 0 (the metric is not
    differentiable there).
    """
    s00, s01, s11 = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
    h, m = 0.5 * (s00 - s11), 0.5 * (s00 + s11)
    rho = np.sqrt(h * h + s01 * s01)
    a2, b2 = np.sqrt(m + rho), np.sqrt(np.maximum(m - rho, 0.0))
    t2 = 0.5 * np.arctan2(s01, h)
    mu_d, a1, b1, t1 = terms
    delta = (t1 - t2 + 0.5 * np.pi) % np.pi - 0.5 * np.pi
    sn, cs = np.sin(delta), np.cos(delta)
    P = (a1 * a1 - b1 * b1) * (a2 * a2 - b2 * b2)
    Q = a1 * a2 + b1 * b2
    Rq = np.sqrt(np.maximum(Q * Q - P * sn * sn, 0.0))
    D = Q + Rq
    k = np.sqrt(2.0 * P / D)
    r = np.stack([mu_d[:, 0] - mu[:, 0], mu_d[:, 1] - mu[:, 1], a1 - a2, b1 - b2, k * sn],
                 axis=1)
    if d is None:
        return r, None
    col = (slice(None), None)  # (N,) -> (N, 1) against the K directions
    dmu, dsig = d
    ds00, ds01, ds11 = dsig[..., 0, 0], dsig[..., 0, 1], dsig[..., 1, 1]
    dh, dm = 0.5 * (ds00 - ds11), 0.5 * (ds00 + ds11)
    tiny = 1e-12 * m
    round_proj = rho <= tiny
    rho_s = np.where(round_proj, 1.0, rho)[col]
    drho = (h[col] * dh + s01[col] * ds01) / rho_s
    da2 = (dm + drho) / (2.0 * a2[col])
    db2 = (dm - drho) / (2.0 * np.maximum(b2, 1e-300)[col])
    dt2 = np.where(round_proj[col], 0.0, 0.5 * (h[col] * ds01 - s01[col] * dh) / rho_s**2)
    ddelta = -dt2
    dP = ((a1 * a1 - b1 * b1)[col]) * (2.0 * a2[col] * da2 - 2.0 * b2[col] * db2)
    dQ = a1[col] * da2 + b1[col] * db2
    Rs = np.where(Rq > 0, Rq, 1.0)[col]
    dR = (2.0 * Q[col] * dQ - dP * (sn * sn)[col] - 2.0 * (P * sn * cs)[col] * ddelta) / (
        2.0 * Rs)
    zero_k = k <= 1e-150
    ks = np.where(zero_k, 1.0, k)[col]
    dk = np.where(zero_k[col], 0.0,
                  (dP / D[col] - P[col] * (dQ + dR) / (D * D)[col]) / ks)
    dks = dk * sn[col] + (k * cs)[col] * ddelta
    J = np.stack([-dmu[..., 0], -dmu[..., 1], -da2, -db2, dks], axis=1)  # (N, 5, 6)
    return r, J


def _bhattacharyya_rows(terms: tuple[FloatArray, ...], mu: FloatArray, Q: FloatArray,
                        d: tuple[FloatArray, FloatArray] | None
                        ) -> tuple[FloatArray, FloatArray | None]:
    """The Bhattacharyya residual ``[L^-1 dmu / sqrt 8, G00, G11, sqrt2 G01]``
    (``S = (S_D + S_P) / 2 = L L^T``, ``G = h(log N)``, ``N = S_D^-1/2 S_P S_D^-1/2``,
    ``h(u) = sign(u) sqrt(ln cosh(u / 2) / 2)``) and its derivative. The spectral
    function's derivative is Daleckii-Krein's ``dG = V (F o (V^T dN V)) V^T`` (divided
    differences of ``h(log lambda)``, its derivative when the eigenvalues coincide).
    """
    q00, q01, q11 = Q[:, 0, 0], Q[:, 0, 1], Q[:, 1, 1]
    P, d00, d01, d11, c, s = terms
    s00, s01, s11 = 0.5 * (d00 + q00), 0.5 * (d01 + q01), 0.5 * (d11 + q11)
    l00 = np.sqrt(s00)
    l10 = s01 / l00
    l11 = np.sqrt(np.maximum(s11 - l10 * l10, 0.0))
    dx = P[:, 0] - mu[:, 0]
    dy = P[:, 1] - mu[:, 1]
    y0 = dx / l00
    y1 = (dy - l10 * y0) / l11
    a, b = P[:, 2], P[:, 3]

    def to_n(x00: FloatArray, x01: FloatArray, x11: FloatArray
             ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``D^-1 R^T X R D^-1`` (the detection frame), elementwise."""
        t00 = c * (x00 * c + x01 * s) + s * (x01 * c + x11 * s)
        t01 = c * (-x00 * s + x01 * c) + s * (-x01 * s + x11 * c)
        t11 = -s * (-x00 * s + x01 * c) + c * (-x01 * s + x11 * c)
        return t00 / (a * a), t01 / (a * b), t11 / (b * b)

    n00, n01, n11 = to_n(q00, q01, q11)
    half_tr, half_diff = 0.5 * (n00 + n11), 0.5 * (n00 - n11)
    rad = np.hypot(half_diff, n01)
    lam0 = half_tr + rad
    lam1 = np.maximum(half_tr - rad, 1e-300)
    u0, u1 = np.log(lam0), np.log(lam1)
    h0, h1 = _h(u0), _h(u1)
    theta = 0.5 * np.arctan2(n01, half_diff)  # N's first eigenvector angle
    cos2, sin2 = np.cos(2 * theta), np.sin(2 * theta)
    mean, half = 0.5 * (h0 + h1), 0.5 * (h0 - h1)
    g00, g11, g01 = mean + half * cos2, mean - half * cos2, half * sin2
    r = np.stack([_INV_SQRT8 * y0, _INV_SQRT8 * y1, g00, g11, _SQRT2 * g01], axis=1)
    if d is None:
        return r, None
    col = (slice(None), None)
    dmu, dsig = d
    dq00, dq01, dq11 = dsig[..., 0, 0], dsig[..., 0, 1], dsig[..., 1, 1]
    L00, L10, L11, Y0, Y1 = (v[col] for v in (l00, l10, l11, y0, y1))
    dl00 = 0.25 * dq00 / L00
    dl10 = (0.5 * dq01 - L10 * dl00) / L00
    dl11 = (0.5 * dq11 - 2.0 * L10 * dl10) / (2.0 * L11)
    dy0 = (-dmu[..., 0] - Y0 * dl00) / L00
    dy1 = (-dmu[..., 1] - dl10 * Y0 - L10 * dy0 - Y1 * dl11) / L11
    c, s, a, b = c[col], s[col], a[col], b[col]
    dn00, dn01, dn11 = to_n(dq00, dq01, dq11)
    ct, st = np.cos(theta)[col], np.sin(theta)[col]
    e00 = ct * ct * dn00 + 2 * ct * st * dn01 + st * st * dn11
    e11 = st * st * dn00 - 2 * ct * st * dn01 + ct * ct * dn11
    e01 = -ct * st * dn00 + (ct * ct - st * st) * dn01 + st * ct * dn11
    f0 = _dh_dlambda(u0, h0, lam0)
    f1 = _dh_dlambda(u1, h1, lam1)
    gap = lam0 - lam1
    close = gap <= 1e-7 * lam0
    f01 = np.where(close, 0.5 * (f0 + f1), (h0 - h1) / np.where(close, 1.0, gap))
    M00, M01, M11 = f0[col] * e00, f01[col] * e01, f1[col] * e11
    dg00 = ct * ct * M00 - 2 * ct * st * M01 + st * st * M11
    dg11 = st * st * M00 + 2 * ct * st * M01 + ct * ct * M11
    dg01 = ct * st * M00 + (ct * ct - st * st) * M01 - st * ct * M11
    J = np.stack([_INV_SQRT8 * dy0, _INV_SQRT8 * dy1, dg00, dg11, _SQRT2 * dg01], axis=1)
    return r, J


def _log_cosh(x: FloatArray) -> FloatArray:
    """``ln cosh(x)`` without overflow, accurate near 0 (series), elementwise."""
    ax = np.abs(x)
    x2 = ax * ax
    series = x2 * (0.5 + x2 * (-1.0 / 12.0 + x2 * (1.0 / 45.0)))
    big = ax + np.log1p(np.exp(-2.0 * ax)) - math.log(2.0)
    return np.where(ax < 1e-2, series, big)


def _h(u: FloatArray) -> FloatArray:
    """``sign(u) sqrt(ln cosh(u / 2) / 2)``: odd, analytic, ``~ u / (2 sqrt 2)`` near 0."""
    return np.sign(u) * np.sqrt(0.5 * _log_cosh(0.5 * u))


def _dh_dlambda(u: FloatArray, h: FloatArray, lam: FloatArray) -> FloatArray:
    """``d h(ln lambda) / d lambda`` for ``h(u) = sign(u) sqrt(ln cosh(u / 2) / 2)``:
    ``h'(u) = tanh(|u| / 2) / (8 |h|)`` (-> 1/4 as u -> 0), divided by ``lambda``."""
    ah = np.abs(h)
    small = np.abs(u) < 1e-4
    dh_du = np.where(small, 0.25,
                     np.tanh(0.5 * np.abs(u)) / (8.0 * np.where(small, 1.0, ah)))
    return dh_du / lam


# --------------------------------------------------------------------------- residuals


def _hull_directions(value: object) -> int:
    n = _positive_int("hull_directions", value)
    if n < 8:
        raise ValueError(f"option hull_directions must be >= 8, got {n}")
    return n


def overlap_delta(
    name: str, detection_params: FloatArray, projection_params: FloatArray,
    hull_directions: int = HULL_DIRECTIONS,
) -> float:
    """``Delta`` of ``iou`` (``1 - IoU``) or ``giou`` (``1 - GIoU``) between a detection and a
    projection given as params ``(cx, cy, a, b, angle)`` (px, rad): ``I``, ``U = A_D + A_P -
    I``, ``C = max(hull, U)``; ``Delta_iou = 1 - I/U`` in [0, 1], ``Delta_giou = 2 - I/U - U/C``
    in [0, 2] (clamped against rounding)."""
    det, proj = np.asarray(detection_params, float), np.asarray(projection_params, float)
    q = quadrant_areas(det, proj, name == "giou", hull_directions)
    a_det, a_proj = math.pi * float(det[2] * det[3]), math.pi * float(proj[2] * proj[3])
    inter = min(max(float(q["intersection"][0].sum()), 0.0), min(a_det, a_proj))
    union = a_det + a_proj - inter
    if name == "iou":
        return min(max(1.0 - inter / union, 0.0), 1.0)
    hull = max(float(q["hull"][0].sum()), union)
    return min(max(2.0 - inter / union - union / hull, 0.0), 2.0)


def overlap_residual(
    name: str, detection_params: FloatArray, projection_params: FloatArray,
    hull_directions: int = HULL_DIRECTIONS, gradient: bool = False,
    disjoint_hull: bool = False,
) -> tuple[FloatArray, FloatArray | None]:
    """The iou / giou residual: ``Delta`` split over the four quadrants ``Q_k`` of the
    detection's frame (module docstring), ``r_k >= 0``, ``sum_k r_k = Delta``; and, if
    ``gradient``, ``dr / dg`` w.r.t. the projection's Gaussian parameters ``g = (mu_x,
    mu_y, s00, s01, s11)`` (px, px^2), exact (:func:`quadloc.factors.overlap.quadrant_sums`).

    Params are one pair ``(5,)`` each (returns ``r`` (4,), ``dr/dg`` (4, 5)) or N pairs
    ``(N, 5)`` (returns (N, 4), (N, 4, 5); the pose factors evaluate all objects in one call).
    ``r_k = |(D △ P) ∩ Q_k| / U`` (iou) ``+ |(C \\ (D ∪ P)) ∩ Q_k| / C`` (giou), with
    ``|(D △ P) ∩ Q_k| = A_D / 4 + |P ∩ Q_k| - 2 |D ∩ P ∩ Q_k|``. The one place of these
    formulas: the scalar metric and the pose factors call it.

    ``disjoint_hull`` (iou only; the pose factors' refinement rows, module docstring "iou"):
    a pair whose ellipses do not intersect gets the giou rows instead (``sum_k r_k = 2 - U/C``
    instead of the flat 1), so the refinement is pulled towards the detection.
    """
    det = np.array(detection_params, dtype=float, order="C")  # a fresh copy (the kernels')
    single = det.ndim == 1
    det = det.reshape(-1, 5)
    proj = np.asarray(projection_params, dtype=float).reshape(-1, 5)
    sums = quadrant_sums(det, proj, name == "giou", gradient)
    r, d_r = _overlap_rows(det, sums, name == "giou")
    if name == "iou" and disjoint_hull:
        disjoint = sums[:, 1, :, 0].sum(axis=1) <= 0.0
        if disjoint.any():
            r[disjoint], d_r[disjoint] = _overlap_rows(
                det[disjoint], quadrant_sums(det[disjoint], proj[disjoint], True, gradient),
                True)
    if single:
        return r[0], d_r[0] if gradient else None
    return r, d_r if gradient else None


@jit
def _overlap_rows(det: FloatArray, sums: FloatArray, giou: bool
                  ) -> tuple[FloatArray, FloatArray]:
    """:func:`overlap_residual`'s rows (N, 4) and gradients (N, 4, 5) (zeros where ``sums``
    holds none) from the quadrant sums of :func:`quadloc.factors.overlap.quadrant_sums` (detections
    ``det`` (N, 5)); ``giou``: add the hull's gap term (``sums`` computed with the hull)."""
    n = det.shape[0]
    r = np.empty((n, 4))
    d_r = np.empty((n, 4, 5))
    inter = np.empty(4)
    d_inter = np.empty((4, 5))
    union_k = np.empty(4)
    d_union_k = np.empty((4, 5))
    d_union = np.empty(5)
    d_hull = np.empty(5)
    for i in range(n):
        quarter = 0.25 * math.pi * det[i, 2] * det[i, 3]  # |D ∩ Q_k|
        second, both, hull = sums[i, 0], sums[i, 1], sums[i, 2]
        # |D ∩ P ∩ Q_k| <= min(|D ∩ Q_k|, |P ∩ Q_k|): enforced against rounding and the "same
        # ellipse" shortcut of quadloc.factors.overlap (contours closer than 1e-9 count as
        # identical, the intersection as the whole second ellipse), so the rows stay >= 0
        union = 4.0 * quarter
        for k in range(4):
            cap = min(quarter, second[k, 0])
            if both[k, 0] > cap:
                inter[k] = cap
                for g in range(5):
                    d_inter[k, g] = second[k, 1 + g] if second[k, 0] < quarter else 0.0
            else:
                inter[k] = both[k, 0]
                for g in range(5):
                    d_inter[k, g] = both[k, 1 + g]
            union += second[k, 0] - inter[k]
        d_union[:] = 0.0
        for k in range(4):
            union_k[k] = quarter + second[k, 0] - inter[k]
            for g in range(5):
                d_union_k[k, g] = second[k, 1 + g] - d_inter[k, g]
                d_union[g] += d_union_k[k, g]
        for k in range(4):
            r[i, k] = (union_k[k] - inter[k]) / union
            for g in range(5):
                d_r[i, k, g] = ((d_union_k[k, g] - d_inter[k, g]) - r[i, k] * d_union[g]
                                ) / union
        if not giou:
            continue
        # rounding: a hull below the union means the hull IS the union (one ellipse contains
        # the other), whose gap term is zero
        c = hull[0, 0] + hull[1, 0] + hull[2, 0] + hull[3, 0]
        if not c >= union:
            continue
        for g in range(5):
            d_hull[g] = hull[0, 1 + g] + hull[1, 1 + g] + hull[2, 1 + g] + hull[3, 1 + g]
        for k in range(4):
            gap = (hull[k, 0] - union_k[k]) / c
            r[i, k] += gap
            for g in range(5):
                d_r[i, k, g] += ((hull[k, 1 + g] - d_union_k[k, g]) - gap * d_hull[g]) / c
    return r, d_r


def _overlap_rows_of_pair(name: str, det: Ellipse, proj: Ellipse,
                          hull_directions: int = HULL_DIRECTIONS) -> FloatArray:
    """iou / giou of one pair: the residual rows (4,)."""
    return overlap_residual(name, det.params(), proj.params(),
                            _hull_directions(hull_directions))[0]


def _overlap_cost(name: str, det: Ellipse, proj: Ellipse,
                  hull_directions: int = HULL_DIRECTIONS) -> float:
    """iou / giou of one pair: the cost ``Delta``."""
    return overlap_delta(name, det.params(), proj.params(), _hull_directions(hull_directions))


def _qbbox_residual(det: Ellipse, proj: Ellipse, image_size: object = None) -> FloatArray:
    W, H = _image_size(image_size)
    return _truncated_box(det, W, H) - _truncated_box(proj, W, H)


def _truncated_box(e: Ellipse, W: float, H: float) -> FloatArray:
    box = clipped_bbox(e, (W, H))
    return np.clip(e.bbox(), 0.0, [W, H, W, H]) if box is None else box


#: per metric, ``(detection, projection, **options) -> residual``; the options differ per
#: metric (checked by :func:`_check_options` first)
_RESIDUALS: dict[str, Callable[..., FloatArray]] = {
    **{m: functools.partial(_conic_residual, m) for m in CONIC_METRICS},
    "qbbox": _qbbox_residual,
    "level_set": _level_set_residual,
    **{m: functools.partial(_overlap_rows_of_pair, m) for m in ("iou", "giou")},
}
#: the metrics whose cost is not the residual's squared norm, same signature
_SCALAR_COSTS: dict[str, Callable[..., float]] = {
    m: functools.partial(_overlap_cost, m) for m in ("iou", "giou")}


def residual(name: str, detection: Ellipse, projection: Ellipse, **options: object) -> FloatArray:
    """Residual vector of metric ``name`` (1-D float array, length :func:`residual_size`).

    ``cost(name, ...) == ||residual(name, ...)||^2``, except iou / giou (``cost ==
    sum(residual)``). See the module docstring for each metric's residual, units and
    options. Unknown ``name`` -> ``ValueError`` listing the valid names; unknown option ->
    ``TypeError`` naming it; bad option value -> ``ValueError``.
    """
    _check_options(name, options)
    _check_ellipse("detection", detection)
    _check_ellipse("projection", projection)
    return _RESIDUALS[name](detection, projection, **options)


def cost(name: str, detection: Ellipse, projection: Ellipse, **options: object) -> float:
    """Cost of metric ``name`` between a detection and a projection (>= 0, 0 when identical).

    iou / giou return ``1 - IoU`` / ``1 - GIoU``; the others ``||residual||^2`` (frobenius is
    the *squared* Frobenius norm, wasserstein the *squared* W2 distance).
    """
    _check_options(name, options)
    _check_ellipse("detection", detection)
    _check_ellipse("projection", projection)
    if name in _SCALAR_COSTS:
        return float(_SCALAR_COSTS[name](detection, projection, **options))
    r = _RESIDUALS[name](detection, projection, **options)
    return float(r @ r)


def residual_size(name: str, **options: object) -> int:
    """Length of :func:`residual` for metric ``name`` with these options."""
    _check_options(name, options)
    if name == "level_set":
        return (_positive_int("n_azimuths", options.get("n_azimuths", 6))
                * _positive_int("n_levels", options.get("n_levels", 4)))
    return _OPTIONS[name][1]
