"""Scoring candidate poses against detections: the IoU estimate, one-to-one matches, the scorer.

A pose (``camera_from_world``, 4x4 OpenCV ``[R | t]``) is scored by the IoU of each detection
with the projections of its label-compatible map objects (:meth:`MatchScorer.pair_iou`,
estimated by :func:`iou_estimates` from points filling the detections); a pair is an inlier
when its IoU reaches a threshold, and a pose's matches are the one-to-one greedy assignment of
its inliers (:func:`greedy_assignment`). Memory and time are bounded: pairs, points and
projections are processed in blocks (:data:`PAIR_BLOCK`, :data:`POINT_BLOCK`,
:data:`PROJECT_BLOCK`) with a deadline check between blocks (:class:`ScoringTimeoutError`).
The search that uses the scorer: :mod:`quadloc.service.localization.search`; the stages and
bounds in detail: ``docs/design/localization.md``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from quadloc.factors import camera as _camera
from quadloc.factors.arrays import BoolArray, FloatArray, Int32Array, IntArray
from quadloc.factors.budget import Deadline, deadline_passed, earliest
from quadloc.factors.camera import MIN_DEPTH, Camera, projected_gaussians
from quadloc.factors.conics import Ellipse, ellipse_params
from quadloc.factors.jit import jit
from quadloc.maps.compiled import CompiledMap

__all__ = [
    "HARD_STOP_FACTOR",
    "PAIR_BLOCK",
    "POINT_BLOCK",
    "PROJECT_BLOCK",
    "LabelGroup",
    "Match",
    "MatchScorer",
    "ScoringTimeoutError",
    "blocks",
    "ellipse_points",
    "greedy_assignment",
    "iou_estimates",
    "sunflower_disk",
]

#: Most (detection, object) pairs per block of the cheap per-pair tests (pruning).
PAIR_BLOCK = 1 << 16
#: Stage 1 (:meth:`MatchScorer.centre_hits`): a detection is hit when a compatible object's
#: projected centre has at most this level value of its ellipse (``Phi <= 4``: within twice
#: the ellipse).
CENTRE_HIT_LEVEL = 4.0
#: Most pair x point evaluations per block of the IoU estimate (stage 2): ~16 MB of temporaries.
POINT_BLOCK = 1 << 17
#: Most pose x object projections per block (each holds a few 3x3 / 4x4 float arrays).
PROJECT_BLOCK = 1 << 13
#: The scorer's hard stop (``MatchScorer.deadline`` in ``localize``), as a multiple of the time
#: budget on both clocks of a :class:`quadloc.factors.budget.Deadline`: the search stops at the
#: budget itself, this bounds the scoring after it (final matches, re-association).
HARD_STOP_FACTOR = 1.05

#: Usable detection rows of one label and the indices of the map objects compatible with them
#: (:attr:`MatchScorer.label_groups`).
LabelGroup = tuple[list[int], IntArray]


class ScoringTimeoutError(RuntimeError):
    """The scorer's deadline passed in the middle of scoring (see :class:`MatchScorer`)."""


def _check(stop_at: Deadline | None) -> None:
    if deadline_passed(stop_at):
        raise ScoringTimeoutError("time budget exceeded while scoring poses")


def blocks(n: int, size: int) -> Iterator[slice]:
    """Consecutive slices of at most ``size`` (at least 1) items covering ``range(n)``."""
    for start in range(0, n, max(1, size)):
        yield slice(start, min(n, start + max(1, size)))


@functools.lru_cache(maxsize=8)
def sunflower_disk(n: int) -> FloatArray:
    """``n`` points spread uniformly over the unit disk (Vogel's sunflower), shape (n, 2),
    read-only (computed once per ``n``)."""
    i = np.arange(n) + 0.5
    r = np.sqrt(i / n)
    th = i * (math.pi * (3.0 - math.sqrt(5.0)))
    out = np.column_stack([r * np.cos(th), r * np.sin(th)])
    out.setflags(write=False)
    return out


def ellipse_points(params: FloatArray, unit: FloatArray, axis: int = -1) -> FloatArray:
    """Points (D, M, 2) px filling ellipses ``params`` (D, 5) ``(cx, cy, a, b, angle)`` (px,
    rad) from unit-disk points ``unit`` (M, 2) (e.g. :func:`sunflower_disk`); with ``axis=1``,
    (D, 2, M) (x and y rows contiguous)."""
    c, s = np.cos(params[:, 4]), np.sin(params[:, 4])
    u = unit[None, :, 0] * params[:, 2, None]
    v = unit[None, :, 1] * params[:, 3, None]
    x = params[:, 0, None] + c[:, None] * u - s[:, None] * v
    y = params[:, 1, None] + s[:, None] * u + c[:, None] * v
    return np.stack([x, y], axis=axis)


def iou_estimates(
    det_points: FloatArray, det_areas: FloatArray, proj_centres: FloatArray,
    proj_inv_shape: FloatArray,
) -> FloatArray:
    """IoU of detections and projected ellipses, estimated from points inside the detections.

    Args:
        det_points: (..., M, 2) points uniformly filling each detection (sunflower pattern).
        det_areas: (...,) detection areas px^2.
        proj_centres: (..., 2), proj_inv_shape: (..., 2, 2) the projected ellipses
            (``A^-1``, symmetric: its upper entries are read).

    Returns:
        (...,) IoU in [0, 1]: ``I / (area_det + area_proj - I)`` with
        ``I = area_det * fraction of the points inside the projection`` (:func:`_point_iou`);
        0 where ``det(A^-1) <= 0``.
    """
    S = np.asarray(proj_inv_shape, dtype=float)
    pts = np.asarray(det_points, dtype=float)
    shape = np.broadcast_shapes(pts.shape[:-2], np.shape(det_areas), np.shape(proj_centres)[:-1],
                                S.shape[:-2])
    n_pts = pts.shape[-2]
    # one row per estimate: (K, 2, M) points (x and y rows), (K,) area, (K, 2) centre and
    # (K, 2, 2) A^-1, as fresh C-ordered float64 copies (the kernel's one argument type)
    xy = np.array(np.moveaxis(np.broadcast_to(pts, (*shape, n_pts, 2)), -1, -2),
                  dtype=float, order="C").reshape(-1, 2, n_pts)
    areas = np.array(np.broadcast_to(det_areas, shape), dtype=float, order="C").reshape(-1)
    centres = np.array(np.broadcast_to(proj_centres, (*shape, 2)), dtype=float,
                       order="C").reshape(-1, 2)
    s = np.array(np.broadcast_to(S, (*shape, 2, 2)), dtype=float, order="C").reshape(-1, 2, 2)
    out: FloatArray = _iou_rows_kernel(xy, areas, centres, s).reshape(shape)
    return out


@jit
def _ellipse_entries(s00: float, s01: float, s11: float) -> tuple[float, float, float, float]:
    """THE inverse and area of a projected ellipse from the entries of its ``A^-1`` (px^2):
    ``(A00, A01, A11, area)`` with ``A = (A^-1)^-1`` (garbage where ``det(A^-1) <= 0``) and the
    area ``pi sqrt(det(A^-1)) = pi a b`` px^2 (0 where the determinant is <= 0)."""
    det = s00 * s11 - s01 * s01
    safe = det if det > 0.0 else 1.0
    return s11 / safe, -s01 / safe, s00 / safe, math.pi * math.sqrt(max(det, 0.0))


@jit
def _point_iou(xy: FloatArray, det_area: float, cx: float, cy: float, a00: float, a01: float,
               a11: float, area_proj: float) -> float:
    """THE IoU estimate of one (detection, projection) pair: the points ``xy`` (2, M) px
    filling the detection (area ``det_area`` px^2), the fraction inside the projected ellipse
    ``(x - c)^T A (x - c) <= 1`` (centre ``cx, cy``, entries of ``A``, area ``area_proj``)
    times the detection area as the intersection; in [0, 1]."""
    n_pts = xy.shape[1]
    inside = 0
    for m in range(n_pts):
        dx = xy[0, m] - cx
        dy = xy[1, m] - cy
        if a00 * dx ** 2 + 2 * a01 * dx * dy + a11 * dy ** 2 <= 1.0:
            inside += 1
    inter = inside / n_pts * det_area
    iou: float = min(inter / max(det_area + area_proj - inter, 1e-300), 1.0)
    return iou


@jit
def _iou_rows_kernel(xy: FloatArray, det_areas: FloatArray, centres: FloatArray,
                     inv_shape: FloatArray) -> FloatArray:
    """:func:`iou_estimates` of K rows: points (K, 2, M), areas (K,), projected centres (K, 2)
    and ``A^-1`` (K, 2, 2); (K,), 0 where ``det(A^-1) <= 0``."""
    n = xy.shape[0]
    out = np.zeros(n)
    for k in range(n):
        s00, s01, s11 = inv_shape[k, 0, 0], inv_shape[k, 0, 1], inv_shape[k, 1, 1]
        if s00 * s11 - s01 * s01 > 0.0:
            a00, a01, a11, area = _ellipse_entries(s00, s01, s11)
            out[k] = _point_iou(xy[k], det_areas[k], centres[k, 0], centres[k, 1], a00, a01,
                                a11, area)
    return out


@jit
def _centre_hit_counts_kernel(T: FloatArray, P: FloatArray, centers: FloatArray,
                              shape_matrices: FloatArray, pair_d: Int32Array,
                              pair_s: Int32Array, params: FloatArray, cos: FloatArray,
                              sin: FloatArray, hit_level: float, min_depth: float
                              ) -> FloatArray:
    """:meth:`MatchScorer.centre_hits` of H poses ``T`` (H, 4, 4) ``camera_from_world`` (``P``
    (H, 3, 4): ``K [R | t]``): per pose, the number of detections (rows of ``params`` (D, 5);
    ``cos``, ``sin`` (D,) of their angles) with a compatible pair (``pair_d``, ``pair_s``:
    detection row, object slot of ``centers`` (S, 3) and ``shape_matrices`` (S, 3, 3), world
    m) whose object lies entirely at depth > ``min_depth``
    (:func:`quadloc.factors.camera.depth_margin`; its projection is then an ellipse) and whose
    projected centre (:func:`quadloc.service.localization.hypotheses.point_centres`) has level
    value ``<= hit_level`` in the detection's ellipse
    (:func:`quadloc.factors.conics.level_values`). Each object is projected once per pose
    (not per pair, nor its dual quadric: stage 1 needs neither). Returns (H,)."""
    n_h, n_s, n_det = P.shape[0], centers.shape[0], params.shape[0]
    out = np.zeros(n_h)
    hit = np.zeros(n_det, dtype=np.bool_)
    u = np.empty(n_s)
    v = np.empty(n_s)
    front = np.empty(n_s, dtype=np.bool_)
    for h in range(n_h):
        for s in range(n_s):
            X = centers[s]
            z = T[h, 2, 0] * X[0] + T[h, 2, 1] * X[1] + T[h, 2, 2] * X[2] + T[h, 2, 3]
            r0, r1, r2, M = T[h, 2, 0], T[h, 2, 1], T[h, 2, 2], shape_matrices[s]
            var = (r0 * (M[0, 0] * r0 + M[0, 1] * r1 + M[0, 2] * r2)
                   + r1 * (M[1, 0] * r0 + M[1, 1] * r1 + M[1, 2] * r2)
                   + r2 * (M[2, 0] * r0 + M[2, 1] * r1 + M[2, 2] * r2))
            front[s] = _camera.depth_margin_kernel(z, var) > min_depth
            x = P[h, 0, 0] * X[0] + P[h, 0, 1] * X[1] + P[h, 0, 2] * X[2] + P[h, 0, 3]
            y = P[h, 1, 0] * X[0] + P[h, 1, 1] * X[1] + P[h, 1, 2] * X[2] + P[h, 1, 3]
            w = P[h, 2, 0] * X[0] + P[h, 2, 1] * X[1] + P[h, 2, 2] * X[2] + P[h, 2, 3]
            if not abs(w) > 1e-12:
                w = 1e-12
            u[s], v[s] = x / w, y / w
        hit[:] = False
        count = 0
        for p in range(len(pair_d)):
            d, s = pair_d[p], pair_s[p]
            if hit[d] or not front[s]:
                continue
            dx, dy = u[s] - params[d, 0], v[s] - params[d, 1]
            a = (dx * cos[d] + dy * sin[d]) / params[d, 2]
            b = (-dx * sin[d] + dy * cos[d]) / params[d, 3]
            if a * a + b * b <= hit_level:
                hit[d] = True
                count += 1
        out[h] = count
    return out


@jit
def _pair_iou_kernel(mx: FloatArray, my: FloatArray, s00: FloatArray, s01: FloatArray,
                     s11: FloatArray, valid: BoolArray, pair_d: Int32Array, pair_s: Int32Array,
                     pair_cx: FloatArray, pair_cy: FloatArray, pair_radii: FloatArray,
                     pair_areas: FloatArray, xy: FloatArray, floor: float, out: FloatArray,
                     row0: int, h0: int, max_points: int) -> int:
    """:meth:`MatchScorer.pair_iou` of the poses ``h0, h0 + 1, ...`` of a projected block
    (``mx .. s11``, ``valid``: (H, S) per compatible object, :func:`projected_gaussians`), into
    ``out[row0 + h]`` (P per row, left as they are where a pair is pruned: callers pass zeros);
    pairs (``pair_d``, ``pair_s``: detection row, position in the compatible objects; the
    detection's centre, bounding radius, area per pair), filling points ``xy`` (D, 2, M).
    Per (pose, pair): the bounding-circle test (disjoint: IoU exactly 0), the area bound
    ``area_det >= floor * area_proj`` when ``floor > 0`` (the estimate is at most their ratio),
    then :func:`_point_iou`. Stops after the pose at which more than ``max_points`` point
    evaluations were made (the caller checks its deadline between calls); returns the next
    pose to do (H when done)."""
    n_h, n_pairs = mx.shape[0], pair_d.shape[0]
    n_pts = xy.shape[2]
    # per compatible object of a pose: the inverse's entries, area, largest semi-axis
    n_s = mx.shape[1]
    a00 = np.empty(n_s)
    a01 = np.empty(n_s)
    a11 = np.empty(n_s)
    area = np.empty(n_s)
    r_proj = np.empty(n_s)
    done = 0
    h = h0
    while h < n_h:
        for s in range(n_s):
            a00[s], a01[s], a11[s], area[s] = _ellipse_entries(s00[h, s], s01[h, s], s11[h, s])
            if valid[h, s]:
                # sqrt of the largest eigenvalue of A^-1
                det = s00[h, s] * s11[h, s] - s01[h, s] * s01[h, s]
                half_tr = 0.5 * (s00[h, s] + s11[h, s])
                r_proj[s] = math.sqrt(max(
                    half_tr + math.sqrt(max(half_tr ** 2 - det, 0.0)), 0.0))
            else:  # an invalid projection's bounding circle meets nothing
                r_proj[s] = -np.inf
        for p in range(n_pairs):
            s = pair_s[p]
            gap = math.hypot(mx[h, s] - pair_cx[p], my[h, s] - pair_cy[p])
            if not gap <= (pair_radii[p] + r_proj[s]) * (1 + 1e-9) + 1e-9:
                continue  # disjoint bounding circles: no point inside
            if floor > 0 and not pair_areas[p] >= floor * area[s]:
                continue
            out[row0 + h, p] = _point_iou(xy[pair_d[p]], pair_areas[p], mx[h, s], my[h, s],
                                          a00[s], a01[s], a11[s], area[s])
            done += n_pts
        h += 1
        if done > max_points:
            break
    return h


def compile_scoring_kernels() -> None:
    """Compile (or load from numba's cache) the scorer's kernels (:meth:`MatchScorer.pair_iou`,
    :func:`iou_estimates`, the greedy assignment) with the argument types of the search's
    calls, so that no request pays for it (called by
    :func:`quadloc.service.localization.search.compile_search_kernels` at start-up)."""
    one = np.ones((1, 1))
    xy = np.zeros((1, 2, 4))
    _pair_iou_kernel(one, one, one, 0 * one, one, np.ones((1, 1), dtype=bool),
                     np.zeros(1, dtype=np.int32), np.zeros(1, dtype=np.int32), np.zeros(1),
                     np.zeros(1), np.ones(1), np.ones(1), xy, 0.0, np.zeros((1, 1)), 0, 0, 1)
    iou_estimates(np.zeros((4, 2)), np.ones(()), np.zeros(2), np.eye(2))
    _centre_hit_counts_kernel(np.eye(4)[None], np.zeros((1, 3, 4)), np.zeros((1, 3)),
                              np.zeros((1, 3, 3)), np.zeros(1, dtype=np.int32),
                              np.zeros(1, dtype=np.int32), np.ones((1, 5)), np.ones(1),
                              np.zeros(1), CENTRE_HIT_LEVEL, MIN_DEPTH)
    _greedy(np.zeros(1, dtype=np.int32), np.zeros(1, dtype=np.int32), np.ones(1), 0.5, [0])
    _greedy(np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), np.ones(1), 0.5, [0])


@dataclass(frozen=True)
class Match:
    """A detection (index into the usable detections' original indices) -> map object index."""

    detection_index: int
    object_index: int
    iou: float


def greedy_assignment(
    iou: FloatArray, detection_indices: Sequence[int], threshold: float
) -> list[Match]:
    """One-to-one matches from a dense IoU matrix (D, N), greedily by decreasing IoU, keeping
    pairs with IoU >= ``threshold``. ``detection_indices[d]`` is row d's original index."""
    # only the entries at or above the threshold are listed (the matrix may be large)
    flat_iou = np.ravel(iou)
    cand = np.flatnonzero(flat_iou >= threshold)
    pair_d, pair_o = np.divmod(cand, iou.shape[1])
    return _greedy(pair_d, pair_o, flat_iou[cand], threshold, detection_indices)


def _greedy(pair_d: IntArray | Int32Array, pair_o: IntArray | Int32Array, iou: FloatArray,
            threshold: float, detection_indices: Sequence[int]) -> list[Match]:
    """THE greedy one-to-one assignment of pairs (``pair_d[p]``, ``pair_o[p]``) with
    ``iou[p] >= threshold``, by decreasing IoU (ties: the later pair first), sorted by
    detection index (the walk: :func:`_greedy_kernel`)."""
    # int32 (a scorer's pairs) or int64 (a dense matrix's) indices: one specialisation each
    picked = _greedy_kernel(pair_d, pair_o, np.ascontiguousarray(iou, dtype=float), threshold)
    vals: list[float] = iou[picked].tolist()
    ds: list[int] = pair_d[picked].tolist()
    os_: list[int] = pair_o[picked].tolist()
    out = [Match(int(detection_indices[d]), o, v) for d, o, v in zip(ds, os_, vals, strict=True)]
    return sorted(out, key=lambda m: m.detection_index)


@jit
def _greedy_kernel(pair_d: IntArray | Int32Array, pair_o: IntArray | Int32Array, iou: FloatArray,
                   threshold: float) -> IntArray:
    """The pairs :func:`_greedy` keeps, in the order it takes them: the pairs with
    ``iou >= threshold`` in a stable ascending sort of their IoUs, walked backwards, each kept
    when neither its detection nor its object is taken yet. Returns their indices (K,)."""
    n = iou.shape[0]
    cand = np.empty(n, dtype=np.int64)
    n_cand = 0
    n_d, n_o = 0, 0
    for p in range(n):
        if iou[p] >= threshold:
            cand[n_cand] = p
            n_cand += 1
            n_d = max(n_d, pair_d[p] + 1)
            n_o = max(n_o, pair_o[p] + 1)
    cand = cand[:n_cand]
    order = np.argsort(iou[cand], kind="mergesort")  # stable
    used_d = np.zeros(n_d, dtype=np.bool_)
    used_o = np.zeros(n_o, dtype=np.bool_)
    picked = np.empty(n_cand, dtype=np.int64)
    n_picked = 0
    for k in range(n_cand - 1, -1, -1):
        p = cand[order[k]]
        if not used_d[pair_d[p]] and not used_o[pair_o[p]]:
            used_d[pair_d[p]] = True
            used_o[pair_o[p]] = True
            picked[n_picked] = p
            n_picked += 1
    return picked[:n_picked]


class MatchScorer:
    """Scores candidate poses against a fixed set of detections and a compiled map.

    ``detection_indices`` are the original indices of the usable detections (labels in the
    map); ``ellipses`` / ``labels`` are theirs. Only label-compatible pairs are evaluated, in
    bounded blocks (module docstring). ``deadline`` (a :class:`quadloc.factors.budget.Deadline`
    or None) is a hard stop for every scoring call: past it they raise
    :class:`ScoringTimeoutError` (a search passes its own, earlier, stop to the calls it makes).

    Attributes (read-only after construction): ``params`` (D, 5) the detections' ellipses
    ``(cx, cy, a, b, angle)`` px / rad; ``compat`` (D, N) bool, label compatibility with the N
    map objects; ``pair_d``, ``pair_o`` (P,) the compatible (detection row, object index)
    pairs in row-major order; ``pair_starts`` (D,) each detection's first pair; ``objects``
    the sorted indices of the objects with a compatible detection; ``points`` (D, M, 2) px
    filling the detections; ``areas``, ``radii`` (D,) px^2 / px.
    """

    def __init__(
        self, compiled: CompiledMap, camera: Camera, ellipses: Sequence[Ellipse],
        labels: Sequence[str], detection_indices: Sequence[int], n_points: int = 96,
        deadline: Deadline | None = None,
    ) -> None:
        self.compiled = compiled
        self.camera = camera
        self.deadline = deadline
        self.detection_indices = list(detection_indices)
        self.labels = list(labels)
        self.params: FloatArray = ellipse_params(ellipses)
        self.n_det = len(ellipses)
        self.n_obj = len(compiled)
        compat = np.zeros((self.n_det, self.n_obj), dtype=bool)
        for d, label in enumerate(labels):
            compat[d, compiled.indices_for(label)] = True
        self.compat: BoolArray = compat
        # int32 indices (maps hold <= QUADLOC_MAX_MAP_OBJECTS objects): 12 bytes per pair
        pair_d, pair_o = np.nonzero(compat)
        self.pair_d: Int32Array = pair_d.astype(np.int32)
        self.pair_o: Int32Array = pair_o.astype(np.int32)
        # sorted, like np.unique(pair_o)
        self.objects: IntArray = np.flatnonzero(compat.any(axis=0))
        # Position of each pair's object within self.objects (a gather: no sort of the pairs).
        position = np.zeros(self.n_obj, dtype=np.int32)
        position[self.objects] = np.arange(len(self.objects), dtype=np.int32)
        self.pair_s: Int32Array = position[self.pair_o]
        # the compatible objects' arrays, gathered once per call (not per projection)
        self._object_arrays: tuple[FloatArray, FloatArray, FloatArray] = (
            compiled.centers[self.objects], compiled.shape_matrices[self.objects],
            compiled.dual_quadrics[self.objects])
        # first pair of each detection (pairs are sorted by detection; every usable detection
        # has a compatible object): the segments of np.maximum.reduceat
        self.pair_starts: IntArray = np.searchsorted(
            self.pair_d, np.arange(self.n_det)).astype(np.intp)
        # filling points (D, 2, M) per number of points M (x and y contiguous)
        self._xy: dict[int, FloatArray] = {
            n_points: ellipse_points(self.params, sunflower_disk(n_points), axis=1)}
        self.points: FloatArray = self._xy[n_points].transpose(0, 2, 1)  # (D, M, 2)
        self.areas: FloatArray = math.pi * self.params[:, 2] * self.params[:, 3]
        # the detections' axis directions (stage 1's level values)
        self._cos: FloatArray = np.cos(self.params[:, 4])
        self._sin: FloatArray = np.sin(self.params[:, 4])
        self.radii: FloatArray = np.maximum(self.params[:, 2], self.params[:, 3])
        # per pair, once per call: the detection's centre, bounding radius and area
        pair_params = self.params[self.pair_d]
        self._pair_cx = np.ascontiguousarray(pair_params[:, 0])
        self._pair_cy = np.ascontiguousarray(pair_params[:, 1])
        self._pair_radii, self._pair_areas = self.radii[self.pair_d], self.areas[self.pair_d]
        # every detection has a pair (always in localize): pair_scores needs no mask
        self._has_pairs: BoolArray = np.bincount(self.pair_d, minlength=self.n_det) > 0

    def _points_xy(self, n_points: int) -> FloatArray:
        """The detections' filling points, (D, 2, n_points), computed once per scorer."""
        if n_points not in self._xy:
            self._xy[n_points] = ellipse_points(self.params, sunflower_disk(n_points), axis=1)
        return self._xy[n_points]

    def compatible_objects(self, d: int) -> IntArray:
        """Object indices compatible with usable detection row ``d``."""
        return np.flatnonzero(self.compat[d])

    @functools.cached_property
    def label_groups(self) -> list[LabelGroup]:
        """Usable detections grouped by their compatible objects (= by label, since a map
        object has one category): ``[(detection rows, compatible object indices), ...]`` in
        order of first detection. Groups of different labels have disjoint objects."""
        groups: dict[str, list[int]] = {}
        for d, label in enumerate(self.labels):
            groups.setdefault(label, []).append(d)
        return [(dets, self.compatible_objects(dets[0]).astype(np.intp))
                for dets in groups.values()]

    def _stop(self, stop_at: Deadline | None) -> Deadline | None:
        return earliest(stop_at, self.deadline)

    def _project(self, camera_from_world: FloatArray) -> tuple[
            FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, BoolArray, FloatArray]:
        """:func:`projected_gaussians` of the compatible objects (callers pass at most
        ``PROJECT_BLOCK // len(objects)`` poses)."""
        centers, shape_matrices, dual_quadrics = self._object_arrays
        return projected_gaussians(self.camera, camera_from_world, centers, shape_matrices,
                                   dual_quadrics)

    def centre_hits(self, camera_from_world: FloatArray,
                    stop_at: Deadline | None = None) -> FloatArray:
        """Stage 1: number of detections hit by a compatible valid object's centre (its
        projection at level value ``<= CENTRE_HIT_LEVEL`` of the detection's ellipse), (H,).
        One compiled kernel (:func:`_centre_hit_counts_kernel`) per block of
        :data:`PROJECT_BLOCK` projections."""
        stop_at = self._stop(stop_at)
        T = np.asarray(camera_from_world, dtype=float)
        out = np.zeros(len(T))
        step = max(1, PROJECT_BLOCK // max(1, len(self.objects)))
        for hb in blocks(len(T), step):
            _check(stop_at)
            Tb = np.array(T[hb], dtype=float, order="C")
            out[hb] = _centre_hit_counts_kernel(
                Tb, np.ascontiguousarray(self.camera.K @ Tb[:, :3, :]), self._object_arrays[0],
                self._object_arrays[1], self.pair_d, self.pair_s, self.params, self._cos,
                self._sin, CENTRE_HIT_LEVEL, MIN_DEPTH)
        return out

    def pair_iou(self, camera_from_world: FloatArray, points: FloatArray | None = None,
                 floor: float = 0.0, stop_at: Deadline | None = None) -> FloatArray:
        """IoU (H, P) of every label-compatible pair (``pair_d[p]``, ``pair_o[p]``) at H poses,
        vectorised over poses and pairs (0 where the projection is invalid, and 0 where the
        estimate cannot reach ``floor``: callers that only use IoUs >= a threshold get the same
        results). Cheap closed-form pre-filters run first on every (pose, pair): disjoint
        bounding circles (the IoU is exactly 0) and the area ratio (the estimate is at most
        ``area_det / area_proj``); only the survivors get the point test. One compiled kernel
        (:func:`_pair_iou_kernel`) per block of :data:`PROJECT_BLOCK` projections, returning
        to check the deadline after about :data:`POINT_BLOCK` point evaluations. Memory: the
        output plus the block's projections; keep ``H x P`` bounded (callers pass
        ``max(1, PAIR_BLOCK // P)`` poses at a time)."""
        xy = self._xy[self.points.shape[1]] if points is None else np.moveaxis(points, -1, -2)
        return self._pair_iou(camera_from_world, xy, floor, stop_at)

    def _pair_iou(self, camera_from_world: FloatArray, xy: FloatArray, floor: float,
                  stop_at: Deadline | None) -> FloatArray:
        """:meth:`pair_iou` with the filling points as (D, 2, M)."""
        stop_at = self._stop(stop_at)
        T = np.asarray(camera_from_world, dtype=float)
        n_pairs = len(self.pair_d)
        out = np.zeros((len(T), n_pairs))
        if n_pairs == 0:
            return out
        xy = np.ascontiguousarray(xy, dtype=float)
        for hb in blocks(len(T), max(1, PROJECT_BLOCK // max(1, len(self.objects)))):
            _check(stop_at)
            mx, my, s00, s01, s11, valid, _ = self._project(T[hb])
            h = 0
            while h < len(mx):  # the kernel returns after about POINT_BLOCK evaluations
                if h:
                    _check(stop_at)
                h = _pair_iou_kernel(mx, my, s00, s01, s11, valid, self.pair_d, self.pair_s,
                                     self._pair_cx, self._pair_cy, self._pair_radii,
                                     self._pair_areas, xy, floor, out, hb.start, h,
                                     POINT_BLOCK)
        return out

    def dense_iou(self, camera_from_world: FloatArray, points: FloatArray | None = None,
                  floor: float = 0.0, stop_at: Deadline | None = None) -> FloatArray:
        """IoU (H, D, N) of every usable detection with every map object: :meth:`pair_iou`
        scattered into the (detections x objects) matrix (0 if incompatible). Memory: the
        output plus bounded blocks; call it with few poses (H) on large maps."""
        T = np.asarray(camera_from_world, dtype=float)
        out = np.zeros((len(T), self.n_det, self.n_obj))
        for h in range(len(T)):
            out[h, self.pair_d, self.pair_o] = self.pair_iou(T[h:h + 1], points, floor,
                                                             stop_at)[0]
        return out

    def pair_scores(self, iou: FloatArray, threshold: float) -> tuple[FloatArray, IntArray]:
        """(score (H,), inlier count (H,)) from pair IoUs (H, P) (:meth:`pair_iou`), each
        detection taking its best compatible object (an upper bound of the one-to-one
        assignment's)."""
        if iou.shape[1] == 0:
            return np.zeros(len(iou)), np.zeros(len(iou), dtype=np.intp)
        if self._has_pairs.all():
            best = np.maximum.reduceat(iou, self.pair_starts, axis=1)
        else:  # detections without a compatible object (not in a localize() scorer) score 0
            has = self._has_pairs
            best = np.zeros((len(iou), len(self.pair_starts)))
            best[:, has] = np.maximum.reduceat(iou, self.pair_starts[has], axis=1)
        inl = best >= threshold
        return np.where(inl, best, 0.0).sum(axis=1), inl.sum(axis=1)

    def pair_assignment(self, iou: FloatArray, threshold: float) -> list[Match]:
        """:func:`greedy_assignment` of one pose's pair IoUs (P,) (:meth:`pair_iou`): the same
        matches as on the dense (detections x objects) matrix (pairs are in its row-major
        order, so ties break the same way)."""
        return _greedy(self.pair_d, self.pair_o, iou, threshold, self.detection_indices)

    def matches(self, camera_from_world: FloatArray, threshold: float,
                n_points: int = 256) -> list[Match]:
        """One-to-one inlier matches at one pose (IoU with ``n_points`` per detection).
        Raises :class:`ScoringTimeoutError` past ``self.deadline``."""
        iou = self._pair_iou(np.asarray(camera_from_world)[None], self._points_xy(n_points),
                             threshold, None)[0]
        return self.pair_assignment(iou, threshold)
