"""Label-constrained RANSAC over detection/object correspondences (paper section V-B).

Candidate poses come from :mod:`quadloc.service.localization.hypotheses` (P3P on centres with >= 3
usable detections, P2E with 2, P2E as a fallback of at most :data:`P2E_FALLBACK_BUDGET`
samples). A pose is scored by the IoU of each detection with the projections of its
label-compatible objects (:meth:`MatchScorer.pair_iou`, estimated by :func:`iou_estimates`); a
pair is an inlier when IoU >= ``inlier_iou``, a pose's score is the sum of its one-to-one
(:func:`greedy_assignment`) inliers' IoUs. Exhaustive over the label-compatible minimal
samples when there are at most ``max_hypotheses`` (the seed plays no part), else seeded random
ones after the competitor sweep (:func:`_sweep_samples`); early exit once a pose explains every
usable detection; memory and time bounded by blocks with deadline checks
(:class:`ScoringTimeoutError`). All poses here are ``camera_from_world`` (4x4, OpenCV
``[R | t]``). Stages, ordering and bounds in detail: ``docs/design/localization.md``.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from quadloc.factors.budget import Deadline, deadline_passed, earliest
from quadloc.factors.camera import Camera, projected_gaussians
from quadloc.factors.conics import Ellipse, ellipse_params, level_values
from quadloc.maps.compiled import CompiledMap
from quadloc.service.localization.hypotheses import (
    p2e_hypotheses,
    p3p_hypotheses_batch,
    point_centres,
    project_objects,
)

__all__ = [
    "EARLY_EXIT_MEAN_IOU",
    "P2E_FALLBACK_BUDGET",
    "STAGE2_CANDIDATES",
    "Hypothesis",
    "Match",
    "MatchScorer",
    "RansacOutcome",
    "ScoringTimeoutError",
    "distinct_poses",
    "greedy_assignment",
    "iou_estimates",
    "project_objects",
    "ransac",
    "sunflower_disk",
]

#: Stop sampling once a pose explains every usable detection with this mean IoU.
EARLY_EXIT_MEAN_IOU = 0.5
#: Candidates per batch whose IoUs are computed (the best by the stage-1 centre test).
STAGE2_CANDIDATES = 24
#: Stage 1 (the centre test keeping :data:`STAGE2_CANDIDATES` poses of a batch) only when a
#: batch has more (pose, pair) tests than this: below, every pose is scored (vectorised).
STAGE1_MIN_WORK = 1 << 14
#: Exhaustive P3P searches with at most this many samples try them most promising first
#: (:func:`_most_promising_first`; larger ones keep the lazy fixed order: bounded memory).
ORDER_CAP = 4096
#: Minimal samples of the first P3P batch (a frame explained by it stops the search early).
FIRST_BATCH = 8
#: Competitor sweep after an early exit (:func:`_sweep_samples`): detections considered and
#: most samples.
SWEEP_CANDIDATES = 8
SWEEP_MAX_SAMPLES = 24
#: Minimal samples per batch (P3P calls between score / budget checks).
BATCH = 32
#: Number of distinct hypotheses kept (:attr:`RansacOutcome.alternatives`), and what
#: "distinct" means: camera centres further apart than this (m) or orientations differing by
#: more than this (deg). Used by the ambiguity check of ``quadloc.service.localization.confidence``.
KEEP_DISTINCT = 4
DISTINCT_POSITION_M = 0.5
DISTINCT_ANGLE_DEG = 20.0
#: Early exit (see the module docstring) only with at least this many usable detections: with
#: 2-3 the search is small and must go on to find competing hypotheses (ambiguity check).
EARLY_EXIT_MIN_DETECTIONS = 4
#: At most this many P2E samples when P2E is the fallback of a frame with >= 3 detections
#: (one P2E solve costs ~10-30 ms in Python, a P3P solve ~0.05 ms).
P2E_FALLBACK_BUDGET = 24
#: Most (detection, object) pairs per block of the cheap per-pair tests (stage 1, pruning).
PAIR_BLOCK = 1 << 16
#: Most pair x point evaluations per block of the IoU estimate (stage 2): ~16 MB of temporaries.
POINT_BLOCK = 1 << 17
#: Most pose x object projections per block (each holds a few 3x3 / 4x4 float arrays).
PROJECT_BLOCK = 1 << 13
#: The scorer's hard stop (``MatchScorer.deadline`` in ``localize``), as a multiple of the time
#: budget on both clocks of a :class:`quadloc.factors.budget.Deadline`: the search stops at the
#: budget itself, this bounds the scoring after it (final matches, re-association).
HARD_STOP_FACTOR = 1.05


class ScoringTimeoutError(RuntimeError):
    """The scorer's deadline passed in the middle of scoring (see :class:`MatchScorer`)."""


def _check(stop_at: Deadline | None) -> None:
    if deadline_passed(stop_at):
        raise ScoringTimeoutError("time budget exceeded while scoring poses")


def _blocks(n: int, size: int) -> Iterator[slice]:
    for start in range(0, n, max(1, size)):
        yield slice(start, min(n, start + max(1, size)))


@functools.lru_cache(maxsize=8)
def sunflower_disk(n: int) -> np.ndarray:
    """``n`` points spread uniformly over the unit disk (Vogel's sunflower), shape (n, 2),
    read-only (computed once per ``n``)."""
    i = np.arange(n) + 0.5
    r = np.sqrt(i / n)
    th = i * (math.pi * (3.0 - math.sqrt(5.0)))
    out = np.column_stack([r * np.cos(th), r * np.sin(th)])
    out.setflags(write=False)
    return out


def _ellipse_points(params: np.ndarray, unit: np.ndarray, axis: int = -1) -> np.ndarray:
    """Points (D, M, 2) filling ellipses (D, 5) from unit-disk points (M, 2); with
    ``axis=1``, (D, 2, M) (x and y rows contiguous)."""
    c, s = np.cos(params[:, 4]), np.sin(params[:, 4])
    u = unit[None, :, 0] * params[:, 2, None]
    v = unit[None, :, 1] * params[:, 3, None]
    x = params[:, 0, None] + c[:, None] * u - s[:, None] * v
    y = params[:, 1, None] + s[:, None] * u + c[:, None] * v
    return np.stack([x, y], axis=axis)


def iou_estimates(
    det_points: np.ndarray, det_areas: np.ndarray, proj_centres: np.ndarray,
    proj_inv_shape: np.ndarray,
) -> np.ndarray:
    """IoU of detections and projected ellipses, estimated from points inside the detections.

    Args:
        det_points: (..., M, 2) points uniformly filling each detection (sunflower pattern).
        det_areas: (...,) detection areas px^2.
        proj_centres: (..., 2), proj_inv_shape: (..., 2, 2) the projected ellipses
            (``A^-1``, must be positive definite where the result is used).

    Returns:
        (...,) IoU in [0, 1]: ``I / (area_det + area_proj - I)`` with
        ``I = area_det * fraction of the points inside the projection`` (:func:`_point_iou`).
    """
    S = proj_inv_shape
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    a00, a01, a11 = _inverse_entries(S[..., 0, 0], S[..., 0, 1], S[..., 1, 1], det)
    iou = _point_iou(det_points[..., 0], det_points[..., 1], det_areas, proj_centres[..., 0],
                     proj_centres[..., 1], a00, a01, a11, _ellipse_area(det))
    return np.where(det > 0, iou, 0.0)


def _inverse_entries(s00: np.ndarray, s01: np.ndarray, s11: np.ndarray, det: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Entries ``(A00, A01, A11)`` of ``A = (A^-1)^-1`` from those of ``A^-1`` and its
    determinant (any shapes; garbage where ``det <= 0``)."""
    safe = np.where(det > 0, det, 1.0)
    return s11 / safe, -s01 / safe, s00 / safe


def _ellipse_area(det: np.ndarray) -> np.ndarray:
    """Area (px^2) of ellipses from ``det(A^-1) = a^2 b^2``."""
    return math.pi * np.sqrt(np.maximum(det, 0.0))


def _point_iou(px: np.ndarray, py: np.ndarray, det_areas: np.ndarray, cx: np.ndarray,
               cy: np.ndarray, a00: np.ndarray, a01: np.ndarray, a11: np.ndarray,
               area_proj: np.ndarray) -> np.ndarray:
    """THE IoU estimate: points ``(px, py)`` (..., M) filling the detections (areas (...,)),
    the fraction inside the projected ellipses ``(x - c)^T A (x - c) <= 1`` (centres ``cx, cy``,
    entries of ``A``, areas ``area_proj``, each (...,)) times the detection area as the
    intersection; (...,) in [0, 1]."""
    dx = px - cx[..., None]
    dy = py - cy[..., None]
    phi = a00[..., None] * dx ** 2 + 2 * a01[..., None] * dx * dy + a11[..., None] * dy ** 2
    inter = np.count_nonzero(phi <= 1.0, axis=-1) / px.shape[-1] * det_areas
    return np.minimum(inter / np.maximum(det_areas + area_proj - inter, 1e-300), 1.0)


@dataclass(frozen=True)
class Match:
    """A detection (index into the usable detections' original indices) -> map object index."""

    detection_index: int
    object_index: int
    iou: float


def greedy_assignment(
    iou: np.ndarray, detection_indices: Sequence[int], threshold: float
) -> list[Match]:
    """One-to-one matches from a dense IoU matrix (D, N), greedily by decreasing IoU, keeping
    pairs with IoU >= ``threshold``. ``detection_indices[d]`` is row d's original index."""
    # only the entries at or above the threshold are listed (the matrix may be large)
    flat_iou = np.ravel(iou)
    cand = np.flatnonzero(flat_iou >= threshold)
    return _greedy(*np.divmod(cand, iou.shape[1]), flat_iou[cand], threshold, detection_indices)


def _greedy(pair_d: np.ndarray, pair_o: np.ndarray, iou: np.ndarray, threshold: float,
            detection_indices: Sequence[int]) -> list[Match]:
    """THE greedy one-to-one assignment of pairs (``pair_d[p]``, ``pair_o[p]``) with
    ``iou[p] >= threshold``, by decreasing IoU (ties: the later pair first), sorted by
    detection index."""
    cand = np.flatnonzero(iou >= threshold)
    vals, ds, os_ = iou[cand].tolist(), pair_d[cand].tolist(), pair_o[cand].tolist()
    used_d: set[int] = set()
    used_o: set[int] = set()
    out = []
    # a stable ascending sort, walked backwards
    for k in reversed(sorted(range(len(vals)), key=vals.__getitem__)):
        d, o = ds[k], os_[k]
        if d not in used_d and o not in used_o:
            used_d.add(d)
            used_o.add(o)
            out.append(Match(int(detection_indices[d]), o, vals[k]))
    return sorted(out, key=lambda m: m.detection_index)


class MatchScorer:
    """Scores candidate poses against a fixed set of detections and a compiled map.

    ``detection_indices`` are the original indices of the usable detections (labels in the
    map); ``ellipses`` / ``labels`` are theirs. Only label-compatible pairs are evaluated, in
    bounded blocks (module docstring). ``deadline`` (a :class:`quadloc.factors.budget.Deadline`
    or None) is a hard stop for every scoring call: past it they raise
    :class:`ScoringTimeoutError` (a search passes its own, earlier, stop to the calls it makes).
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
        self.params = ellipse_params(ellipses)
        self.n_det = len(ellipses)
        self.n_obj = len(compiled)
        compat = np.zeros((self.n_det, self.n_obj), dtype=bool)
        for d, label in enumerate(labels):
            compat[d, compiled.indices_for(label)] = True
        self.compat = compat
        # int32 indices (maps hold <= QUADLOC_MAX_MAP_OBJECTS objects): 12 bytes per pair
        self.pair_d, self.pair_o = (i.astype(np.int32) for i in np.nonzero(compat))
        self.objects = np.flatnonzero(compat.any(axis=0))  # sorted, like np.unique(pair_o)
        # Position of each pair's object within self.objects (a gather: no sort of the pairs).
        position = np.zeros(self.n_obj, dtype=np.int32)
        position[self.objects] = np.arange(len(self.objects), dtype=np.int32)
        self.pair_s = position[self.pair_o]
        # the compatible objects' arrays, gathered once per call (not per projection)
        self._object_arrays = tuple(a[self.objects] for a in (
            compiled.centers, compiled.shape_matrices, compiled.dual_quadrics))
        self._sample_counts: dict[int, int] = {}  # count_samples, once per size
        # first pair of each detection (pairs are sorted by detection; every usable detection
        # has a compatible object): the segments of np.maximum.reduceat
        self.pair_starts = np.searchsorted(self.pair_d, np.arange(self.n_det)).astype(np.intp)
        # filling points (D, 2, M) per number of points M (x and y contiguous)
        self._xy = {n_points: _ellipse_points(self.params, sunflower_disk(n_points), axis=1)}
        self.points = self._xy[n_points].transpose(0, 2, 1)  # (D, M, 2)
        self.areas = math.pi * self.params[:, 2] * self.params[:, 3]
        self.radii = np.maximum(self.params[:, 2], self.params[:, 3])
        # per pair, once per call: the detection's centre, bounding radius and area
        pair_params = self.params[self.pair_d]
        self._pair_cx, self._pair_cy = pair_params[:, 0], pair_params[:, 1]
        self._pair_radii, self._pair_areas = self.radii[self.pair_d], self.areas[self.pair_d]
        # every detection has a pair (always in localize): pair_scores needs no mask
        self._has_pairs = np.bincount(self.pair_d, minlength=self.n_det) > 0

    def _points_xy(self, n_points: int) -> np.ndarray:
        """The detections' filling points, (D, 2, n_points), computed once per scorer."""
        if n_points not in self._xy:
            self._xy[n_points] = _ellipse_points(self.params, sunflower_disk(n_points), axis=1)
        return self._xy[n_points]

    def compatible_objects(self, d: int) -> np.ndarray:
        """Object indices compatible with usable detection row ``d``."""
        return np.flatnonzero(self.compat[d])

    @functools.cached_property
    def label_groups(self) -> list[tuple[list[int], np.ndarray]]:
        """Usable detections grouped by their compatible objects (= by label, since a map
        object has one category): ``[(detection rows, compatible object indices), ...]`` in
        order of first detection. Groups of different labels have disjoint objects."""
        groups: dict[str, list[int]] = {}
        for d, label in enumerate(self.labels):
            groups.setdefault(label, []).append(d)
        return [(dets, self.compatible_objects(dets[0]).astype(int)) for dets in groups.values()]

    def _stop(self, stop_at: Deadline | None) -> Deadline | None:
        return earliest(stop_at, self.deadline)

    def _project(self, camera_from_world: np.ndarray) -> tuple[np.ndarray, ...]:
        """:func:`projected_gaussians` of the compatible objects (callers pass at most
        ``PROJECT_BLOCK // len(objects)`` poses)."""
        return projected_gaussians(self.camera, camera_from_world, *self._object_arrays)

    def centre_hits(self, camera_from_world: np.ndarray,
                    stop_at: Deadline | None = None) -> np.ndarray:
        """Stage 1: number of detections hit by a compatible valid object's centre, (H,)."""
        stop_at = self._stop(stop_at)
        T = np.asarray(camera_from_world, dtype=float)
        out = np.zeros(len(T))
        step = max(1, PROJECT_BLOCK // max(1, len(self.objects)))
        for hb in _blocks(len(T), step):
            _check(stop_at)
            *_, valid, P = self._project(T[hb])
            pc = point_centres(P, self._object_arrays[0])
            for h in range(len(pc)):
                per_det = np.zeros(self.n_det, dtype=bool)
                for blk in _blocks(len(self.pair_d), PAIR_BLOCK):
                    _check(stop_at)
                    pd, ps = self.pair_d[blk], self.pair_s[blk]
                    phi = level_values(self.params[pd], pc[h, ps][:, None])[:, 0]
                    per_det[pd[(phi <= 4.0) & valid[h, ps]]] = True
                out[hb.start + h] = per_det.sum()
        return out

    def pair_iou(self, camera_from_world: np.ndarray, points: np.ndarray | None = None,
                 floor: float = 0.0, stop_at: Deadline | None = None) -> np.ndarray:
        """IoU (H, P) of every label-compatible pair (``pair_d[p]``, ``pair_o[p]``) at H poses,
        vectorised over poses and pairs (0 where the projection is invalid, and 0 where the
        estimate cannot reach ``floor``: callers that only use IoUs >= a threshold get the same
        results). Cheap closed-form pre-filters run first on every (pose, pair): disjoint
        bounding circles (the IoU is exactly 0) and the area ratio (the estimate is at most
        ``area_det / area_proj``); only the survivors get the point test. Memory: the output
        plus blocks of at most :data:`PAIR_BLOCK` (pose, pair) tests and :data:`POINT_BLOCK`
        point evaluations; keep ``H x P`` bounded (callers pass
        ``max(1, PAIR_BLOCK // P)`` poses at a time)."""
        xy = self._xy[self.points.shape[1]] if points is None else np.moveaxis(points, -1, -2)
        return self._pair_iou(camera_from_world, xy, floor, stop_at)

    def _pair_iou(self, camera_from_world: np.ndarray, xy: np.ndarray, floor: float,
                  stop_at: Deadline | None) -> np.ndarray:
        """:meth:`pair_iou` with the filling points as (D, 2, M)."""
        stop_at = self._stop(stop_at)
        T = np.asarray(camera_from_world, dtype=float)
        n_pts = xy.shape[2]
        n_pairs = len(self.pair_d)
        out = np.zeros((len(T), n_pairs))
        if n_pairs == 0:
            return out
        step = max(1, min(PROJECT_BLOCK // max(1, len(self.objects)),
                          PAIR_BLOCK // n_pairs))
        for hb in _blocks(len(T), step):
            _check(stop_at)
            mx, my, s00, s01, s11, valid, _ = self._project(T[hb])
            n_h = len(mx)
            det = s00 * s11 - s01 * s01
            half_tr = 0.5 * (s00 + s11)
            # largest semi-axis of each projection: sqrt of the largest eigenvalue of A^-1;
            # -inf where the projection is invalid (its bounding circle meets nothing)
            r_proj = np.where(valid, np.sqrt(np.maximum(
                half_tr + np.sqrt(np.maximum(half_tr ** 2 - det, 0.0)), 0.0)), -np.inf)
            area_proj = _ellipse_area(det)
            # what the point test needs of each (pose, object), gathered per surviving pair
            grid = np.stack([mx, my, *_inverse_entries(s00, s01, s11, det), area_proj], axis=-1)
            for blk in _blocks(n_pairs, max(1, PAIR_BLOCK // n_h)):
                _check(stop_at)
                pd, ps = self.pair_d[blk], self.pair_s[blk]
                gap = np.hypot(mx[:, ps] - self._pair_cx[blk], my[:, ps] - self._pair_cy[blk])
                # disjoint bounding circles: no point inside
                keep = gap <= (self._pair_radii[blk] + r_proj[:, ps]) * (1 + 1e-9) + 1e-9
                if floor > 0:  # the estimate is <= area_d / area_p
                    keep &= self._pair_areas[blk] >= floor * area_proj[:, ps]
                kh, kp = np.nonzero(keep)
                for sub in _blocks(len(kh), POINT_BLOCK // n_pts):
                    _check(stop_at)
                    h, k = kh[sub], kp[sub]
                    g = grid[h, ps[k]]  # (K, 6)
                    pts = xy[pd[k]]  # (K, 2, M)
                    out[hb.start + h, blk.start + k] = _point_iou(
                        pts[:, 0], pts[:, 1], self._pair_areas[blk][k], g[:, 0], g[:, 1],
                        g[:, 2], g[:, 3], g[:, 4], g[:, 5])
        return out

    def dense_iou(self, camera_from_world: np.ndarray, points: np.ndarray | None = None,
                  floor: float = 0.0, stop_at: Deadline | None = None) -> np.ndarray:
        """IoU (H, D, N) of every usable detection with every map object: :meth:`pair_iou`
        scattered into the (detections x objects) matrix (0 if incompatible). Memory: the
        output plus bounded blocks; call it with few poses (H) on large maps."""
        T = np.asarray(camera_from_world, dtype=float)
        out = np.zeros((len(T), self.n_det, self.n_obj))
        for h in range(len(T)):
            out[h, self.pair_d, self.pair_o] = self.pair_iou(T[h:h + 1], points, floor,
                                                             stop_at)[0]
        return out

    def pair_scores(self, iou: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
        """(score (H,), inlier count (H,)) from pair IoUs (H, P) (:meth:`pair_iou`), each
        detection taking its best compatible object (an upper bound of the one-to-one
        assignment's)."""
        if iou.shape[1] == 0:
            return np.zeros(len(iou)), np.zeros(len(iou), dtype=int)
        if self._has_pairs.all():
            best = np.maximum.reduceat(iou, self.pair_starts, axis=1)
        else:  # detections without a compatible object (not in a localize() scorer) score 0
            has = self._has_pairs
            best = np.zeros((len(iou), len(self.pair_starts)))
            best[:, has] = np.maximum.reduceat(iou, self.pair_starts[has], axis=1)
        inl = best >= threshold
        return np.where(inl, best, 0.0).sum(axis=1), inl.sum(axis=1)

    def pair_assignment(self, iou: np.ndarray, threshold: float) -> list[Match]:
        """:func:`greedy_assignment` of one pose's pair IoUs (P,) (:meth:`pair_iou`): the same
        matches as on the dense (detections x objects) matrix (pairs are in its row-major
        order, so ties break the same way)."""
        return _greedy(self.pair_d, self.pair_o, iou, threshold, self.detection_indices)

    def matches(self, camera_from_world: np.ndarray, threshold: float,
                n_points: int = 256) -> list[Match]:
        """One-to-one inlier matches at one pose (IoU with ``n_points`` per detection).
        Raises :class:`ScoringTimeoutError` past ``self.deadline``."""
        iou = self._pair_iou(np.asarray(camera_from_world)[None], self._points_xy(n_points),
                             threshold, None)[0]
        return self.pair_assignment(iou, threshold)


@dataclass(frozen=True)
class Hypothesis:
    """A qualified pose (``camera_from_world`` 4x4), its one-to-one matches and score (sum of
    the matches' IoUs)."""

    camera_from_world: np.ndarray
    matches: tuple[Match, ...]
    score: float

    @functools.cached_property
    def pose_key(self) -> tuple[list[float], list[float]]:
        """:func:`_pose_key` of the pose, computed once (the search compares it often)."""
        return _pose_key(self.camera_from_world)


def distinct_poses(camera_from_world_a: np.ndarray, camera_from_world_b: np.ndarray) -> bool:
    """Whether two poses differ by more than :data:`DISTINCT_POSITION_M` (camera centres) or
    :data:`DISTINCT_ANGLE_DEG` (rotation angle)."""
    return _distinct_keys(_pose_key(camera_from_world_a), _pose_key(camera_from_world_b))


def _pose_key(camera_from_world: np.ndarray) -> tuple[list[float], list[float]]:
    """What :func:`distinct_poses` compares: ``R^T t`` (3,) (minus the camera centre) and the
    row-major entries of ``R`` (9,), as Python floats."""
    R = camera_from_world[:3, :3]
    return (R.T @ camera_from_world[:3, 3]).tolist(), R.ravel().tolist()


def _distinct_keys(a: tuple[list[float], list[float]], b: tuple[list[float], list[float]]
                   ) -> bool:
    """:func:`distinct_poses` of two :func:`_pose_key` (plain float arithmetic: 3- and 9-term
    sums cost less than a numpy call)."""
    (ca, ra), (cb, rb) = a, b
    dx, dy, dz = cb[0] - ca[0], cb[1] - ca[1], cb[2] - ca[2]
    if dx * dx + dy * dy + dz * dz > DISTINCT_POSITION_M ** 2:
        return True
    # cos of the relative angle from trace(Ra Rb^T) = sum(Ra * Rb)
    trace = (ra[0] * rb[0] + ra[1] * rb[1] + ra[2] * rb[2] + ra[3] * rb[3] + ra[4] * rb[4]
             + ra[5] * rb[5] + ra[6] * rb[6] + ra[7] * rb[7] + ra[8] * rb[8])
    return (trace - 1.0) / 2.0 < _COS_DISTINCT


_COS_DISTINCT = math.cos(math.radians(DISTINCT_ANGLE_DEG))


@dataclass(frozen=True)
class RansacOutcome:
    """Best pose found. ``camera_from_world`` is None when nothing qualified; then ``reason`` is
    ``"no_label_match"``, ``"no_hypothesis_above_inlier_threshold"`` or
    ``"time_budget_exceeded"``. ``alternatives``: up to :data:`KEEP_DISTINCT` qualified,
    mutually distinct hypotheses (:func:`distinct_poses`), best first (the first is the
    returned pose, with the 96-point matches it was accepted with)."""

    camera_from_world: np.ndarray | None
    matches: tuple[Match, ...]
    score: float
    hypotheses_evaluated: int
    samples_tried: int
    exhaustive: bool
    timed_out: bool
    reason: str | None
    alternatives: tuple[Hypothesis, ...] = ()


def _compositions(groups: list[tuple[list[int], np.ndarray]], size: int) -> list[tuple[int, ...]]:
    """Ways to split a sample of ``size`` among the groups: ``m_g`` detections (and as many
    distinct objects) from group g, ``m_g <= min(#detections, #objects)``."""
    caps = [min(len(d), len(o), size) for d, o in groups]
    out: list[tuple[int, ...]] = []

    def rec(g: int, left: int, acc: tuple[int, ...]) -> None:
        if g == len(groups):
            if left == 0:
                out.append(acc)
            return
        for m in range(min(caps[g], left) + 1):
            rec(g + 1, left - m, (*acc, m))

    rec(0, size, ())
    return out


def count_samples(scorer: MatchScorer, size: int) -> int:
    """Number of label-compatible minimal samples of ``size`` (distinct detections, distinct
    objects), from per-label counts: ``sum over splits of prod_g C(n_det_g, m_g) P(n_obj_g, m_g)``
    (no walk over detection tuples, so it costs nothing with hundreds of detections)."""
    if size not in scorer._sample_counts:  # once per scorer (= per call) and size
        # the coefficient of x^size in prod_g sum_m C(n_det_g, m) P(n_obj_g, m) x^m (exact
        # ints): the same sum as over the splits (_compositions), in O(groups x size)
        coeffs = [1] + [0] * size
        for d, o in scorer.label_groups:
            term = [math.comb(len(d), m) * math.perm(len(o), m) for m in range(size + 1)]
            coeffs = [sum(coeffs[i] * term[k - i] for i in range(k + 1))
                      for k in range(size + 1)]
        scorer._sample_counts[size] = coeffs[size]
    return scorer._sample_counts[size]


def _iter_samples(groups: list[tuple[list[int], np.ndarray]],
                  size: int) -> Iterator[tuple[tuple[int, ...], tuple[int, ...]]]:
    """Every label-compatible minimal sample ((d...), (o...)) (detections ascending), lazily,
    in a fixed order: split among the groups, then itertools' combinations of each group's
    detections and permutations of its objects. Materialised per split: each drawn group's
    (combination, permutation) list, none longer than the split's sample count (callers list
    at most ``cap`` samples, :func:`_enumerate_samples`)."""
    for comp in _compositions(groups, size):
        # per group the split draws from: its (detection, object) pair lists, combinations of
        # detections outer, permutations of objects inner; their product in group order
        per_group = [[list(zip(dets, objs, strict=True))
                      for dets in itertools.combinations(d, m)
                      for objs in itertools.permutations([int(x) for x in o], m)]
                     for (d, o), m in zip(groups, comp, strict=True) if m]
        for parts in itertools.product(*per_group):
            dets, objs = zip(*sorted(itertools.chain.from_iterable(parts)), strict=True)
            yield dets, objs


def _enumerate_samples(scorer: MatchScorer, size: int,
                       cap: int) -> Iterator[tuple[tuple[int, ...], tuple[int, ...]]] | None:
    """All label-compatible minimal samples (lazily, :func:`_iter_samples`' fixed order), or
    None if there are more than ``cap``. Only the samples themselves are generated (per label
    group), never all detection tuples."""
    if count_samples(scorer, size) > cap:
        return None
    return _iter_samples(scorer.label_groups, size)


def _random_samples(scorer: MatchScorer, size: int, count: int,
                    rng: np.random.Generator) -> Iterator[tuple[tuple[int, ...], tuple[int, ...]]]:
    """``count`` label-compatible samples drawn uniformly (with repetition) over all of them,
    lazily (one at a time): a split among the label groups with probability proportional to
    its number of samples, then distinct detections and distinct objects within each group."""
    groups = scorer.label_groups
    comps = _compositions(groups, size)
    weights = np.array([float(math.prod(math.comb(len(d), m) * math.perm(len(o), m)
                                        for (d, o), m in zip(groups, c, strict=True)))
                        for c in comps])
    if len(comps) == 0 or weights.sum() == 0:
        return
    p = weights / weights.sum()
    # rng.choice(len(comps), p=p) without its per-call checks: the same cdf search of one
    # rng.random() draw (the same stream; tests/service/localization/test_ransac.py)
    cdf = p.cumsum()
    cdf /= cdf[-1]
    for _ in range(count):
        k = int(cdf.searchsorted(rng.random(), side="right"))
        pairs = []
        for (d, o), m in zip(groups, comps[k], strict=True):
            if m == 0:
                continue
            dd = rng.choice(len(d), m, replace=False)
            oo = rng.choice(len(o), m, replace=False)
            pairs += [(d[int(i)], int(o[int(j)])) for i, j in zip(dd, oo, strict=True)]
        pairs.sort()
        yield tuple(q[0] for q in pairs), tuple(q[1] for q in pairs)


def _most_promising_first(scorer: MatchScorer) -> Iterator[tuple[tuple[int, ...], tuple[int, ...]]]:
    """Every label-compatible triple sample (an exhaustive search), ordered so that the ones
    most likely to give the right pose come first, which lets the early exit happen after the
    first batch: fewest label-compatible alternatives first (the product over the sample's
    detections of their numbers of compatible objects: a detection whose label has one object
    in the map can only be matched to it), then the largest image triangle of the detection
    centres (P3P's conditioning); ties in :func:`_iter_samples`' order. A stable order on fixed
    keys: independent of the seed.

    Both keys depend on the detection triple only, so the triples are sorted (not the samples)
    and each triple's object assignments are generated lazily, when the search reaches them:
    the samples after an early exit are never built. Triples with equal keys (duplicate
    detections) have their samples merged in :func:`_iter_samples`' order."""
    groups = scorer.label_groups
    comps = _compositions(groups, 3)
    # detection triples in order of first appearance in _iter_samples, with their position
    # key there: (split, then per drawn group the index of its detection combination)
    triples: list[tuple[int, ...]] = []
    where: list[tuple[int, tuple[int, ...]]] = []
    for ci, comp in enumerate(comps):
        drawn = [(d, m) for (d, _), m in zip(groups, comp, strict=True) if m]
        for combos in itertools.product(*(enumerate(itertools.combinations(d, m))
                                          for d, m in drawn)):
            triples.append(tuple(sorted(itertools.chain.from_iterable(c for _, c in combos))))
            where.append((ci, tuple(k for k, _ in combos)))
    if not triples:
        return
    n_compat = scorer.compat.sum(axis=1).astype(float)
    dets = np.array(triples)
    prod = np.prod(n_compat[dets], axis=1)
    area = _triangle_areas(scorer, dets)
    order = np.lexsort((-area, prod)).tolist()
    k = 0
    while k < len(order):
        run = [order[k]]
        while (k + len(run) < len(order) and prod[order[k + len(run)]] == prod[order[k]]
               and area[order[k + len(run)]] == area[order[k]]):
            run.append(order[k + len(run)])
        k += len(run)
        if len(run) == 1:
            yield from _triple_samples(groups, comps, triples[run[0]], where[run[0]])
        else:  # equal keys: every sample of the run, in _iter_samples' order
            merged = sorted(itertools.chain.from_iterable(
                _triple_samples(groups, comps, triples[t], where[t], keyed=True) for t in run))
            yield from (sm for _, sm in merged)


def _triple_samples(
    groups: list[tuple[list[int], np.ndarray]], comps: list[tuple[int, ...]],
    triple: tuple[int, ...], where: tuple[int, tuple[int, ...]], keyed: bool = False,
) -> Iterator:
    """The samples ``(dets, objs)`` of one detection triple (every assignment of distinct
    compatible objects), in :func:`_iter_samples`' order; with ``keyed``, each as ``(key,
    sample)``, ``key`` its position there. ``where``: the triple's split index and per drawn
    group its combination index (:func:`_most_promising_first`)."""
    ci, combo_index = where
    drawn = [(set(d), [int(x) for x in o], m)
             for (d, o), m in zip(groups, comps[ci], strict=True) if m]
    # per drawn group, the positions of its detections in the (ascending) triple
    slots = [[k for k, x in enumerate(triple) if x in dets] for dets, _, _ in drawn]
    perms = [list(itertools.permutations(o, m)) for _, o, m in drawn]
    for choice in itertools.product(*(range(len(p)) for p in perms)):
        objs = [0] * len(triple)
        for sl, p, j in zip(slots, perms, choice, strict=True):
            for k, o in zip(sl, p[j], strict=True):
                objs[k] = o
        if keyed:  # per group: combination index x permutations + permutation index
            yield (ci, *(c * len(p) + j for c, p, j in zip(combo_index, perms, choice,
                                                           strict=True))), (triple, tuple(objs))
        else:
            yield triple, tuple(objs)


def _triangle_areas(scorer: MatchScorer, dets: np.ndarray) -> np.ndarray:
    """Twice the image areas (S,) px^2 of the triangles of detection centres ``dets`` (S, 3)
    (P3P's conditioning)."""
    c = scorer.params[dets, :2]  # (S, 3, 2)
    return np.abs((c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1])
                  - (c[:, 2, 0] - c[:, 0, 0]) * (c[:, 1, 1] - c[:, 0, 1]))


def _sweep_samples(scorer: MatchScorer) -> list[tuple[tuple[int, ...], tuple[int, ...]]]:
    """The minimal samples of the competitor sweep: every label-compatible assignment
    (distinct objects) of ONE detection triple, the one with the largest image triangle among
    the :data:`SWEEP_CANDIDATES` detections with the fewest compatible objects and at most
    :data:`SWEEP_MAX_SAMPLES` assignments; empty if none qualifies (why:
    ``docs/design/localization.md``)."""
    groups = scorer.label_groups
    group_of = np.zeros(scorer.n_det, dtype=np.intp)
    for g, (dets, _) in enumerate(groups):
        group_of[dets] = g
    n_objects = np.array([len(o) for _, o in groups], dtype=np.int64)[group_of]  # per detection
    # the candidates: fewest compatible objects, then lowest index; their triples ascending
    cand = np.sort(np.lexsort((np.arange(scorer.n_det), n_objects))[:SWEEP_CANDIDATES])
    tris = cand[_triples(len(cand))]
    # assignments of distinct objects: n0 (n1 - [g1 = g0]) (n2 - [g2 = g0] - [g2 = g1])
    g, n = group_of[tris], n_objects[tris]
    counts = n[:, 0] * (n[:, 1] - (g[:, 1] == g[:, 0])) * (
        n[:, 2] - (g[:, 2] == g[:, 0]) - (g[:, 2] == g[:, 1]))
    ok = np.flatnonzero((counts > 0) & (counts <= SWEEP_MAX_SAMPLES))
    if len(ok) == 0:
        return []
    tri = tuple(tris[ok[np.argmax(_triangle_areas(scorer, tris[ok]))]].tolist())
    return [(tri, objs)
            for objs in itertools.product(*(groups[group_of[d]][1].tolist() for d in tri))
            if len(set(objs)) == 3]


@functools.lru_cache(maxsize=16)
def _triples(n: int) -> np.ndarray:
    """``itertools.combinations(range(n), 3)`` as an array (T, 3), read-only."""
    out = np.array(list(itertools.combinations(range(n), 3)), dtype=np.intp).reshape(-1, 3)
    out.setflags(write=False)
    return out


def ransac(
    scorer: MatchScorer,
    up_world: np.ndarray,
    *,
    inlier_iou: float,
    min_inliers: int,
    max_hypotheses: int,
    rng: np.random.Generator,
    deadline: Deadline | None = None,
) -> RansacOutcome:
    """Search poses from minimal samples (see the module docstring).

    Args:
        scorer: detections + map + camera.
        up_world: the map's up axis (P2E starts its searches at camera rolls around it).
        inlier_iou, min_inliers: acceptance of a pose.
        max_hypotheses: budget of minimal samples per solver (P3P, then P2E).
        rng: sampler (only used when not exhaustive: exhaustive runs do not depend on it).
        deadline: when the search stops (e.g. CPU time of this thread with a wall-clock hard
            limit, :meth:`quadloc.factors.budget.Deadline.cpu_budget`; None: never), checked
            before every batch and inside the scoring of a batch.
    """
    cm = scorer.compiled
    # distinct qualified hypotheses, best first: kept[0] only ever changes to a better one
    # (_keep_distinct), so it is the best pose found
    kept: list[Hypothesis] = []
    evaluated = tried = 0
    timed_out, exhaustive = False, True
    need = scorer.n_det
    n_pairs = len(scorer.pair_d)

    def consider(poses: np.ndarray) -> bool:
        """Score candidate poses (vectorised over poses and pairs, memory bounded); keeps the
        best distinct hypotheses; returns True to stop early."""
        nonlocal evaluated, kept
        if len(poses) == 0:
            return False
        evaluated += len(poses)
        if len(poses) > STAGE2_CANDIDATES and len(poses) * n_pairs > STAGE1_MIN_WORK:
            # large problems only: the cheap centre test picks the candidates worth an IoU
            hits = scorer.centre_hits(poses, stop_at=deadline)
            keep = np.argsort(-hits, kind="stable")[:STAGE2_CANDIDATES]
            poses = poses[keep]
        for blk in _blocks(len(poses), max(1, PAIR_BLOCK // max(1, n_pairs))):
            iou = scorer.pair_iou(poses[blk], floor=inlier_iou, stop_at=deadline)
            # per-detection best object: an upper bound of the one-to-one score and count
            bound, count = scorer.pair_scores(iou, inlier_iou)
            block, bounds, counts = poses[blk], bound.tolist(), count.tolist()
            # best bound first: the bar rises early and fewer assignments are needed
            for h in np.argsort(-bound, kind="stable").tolist():
                bar = kept[-1].score if len(kept) >= KEEP_DISTINCT else -1.0
                if bounds[h] <= bar or counts[h] < min_inliers:
                    continue
                # one-to-one (greedy) assignment, as in the final matches
                m = scorer.pair_assignment(iou[h], inlier_iou)
                score = float(sum(x.iou for x in m))
                if len(m) >= min_inliers and score > bar:
                    kept = _keep_distinct(kept, Hypothesis(block[h], tuple(m), score))
        return (need >= EARLY_EXIT_MIN_DETECTIONS and bool(kept)
                and len(kept[0].matches) >= need and kept[0].score >= EARLY_EXIT_MEAN_IOU * need)

    def solve(chunk: list[tuple[tuple[int, ...], tuple[int, ...]]], size: int) -> np.ndarray:
        """Candidate poses (M, 4, 4) of minimal samples: one vectorised P3P call, or P2E."""
        if size == 3:
            poses, _ = p3p_hypotheses_batch(scorer.params[np.array([c[0] for c in chunk]), :2],
                                            cm.centers[np.array([c[1] for c in chunk])],
                                            scorer.camera)
            return poses
        found = []
        for dets, objs in chunk:
            ells = [Ellipse(*scorer.params[d]) for d in dets]
            found.extend(p2e_hypotheses(ells, [cm.ellipsoids[o] for o in objs], scorer.camera,
                                        up_world))
        return np.array(found).reshape(-1, 4, 4)

    def run(size: int, budget: int) -> bool:
        nonlocal tried, timed_out, exhaustive
        samples = _enumerate_samples(scorer, size, budget)
        sweep_first: list[tuple[tuple[int, ...], tuple[int, ...]]] = []
        if samples is None:
            exhaustive = False
            # the competitor sweep's samples first (the most promising triple, found without
            # listing every sample), then random ones (seeded) up to the budget
            sweep_first = _sweep_samples(scorer)[:budget] if size == 3 else []
            samples = itertools.chain(sweep_first, _random_samples(
                scorer, size, budget - len(sweep_first), rng))
        elif size == 3 and count_samples(scorer, size) <= ORDER_CAP:
            samples = _most_promising_first(scorer)
        # exhaustive: every sample in a fixed order (the seed plays no part)
        batch = FIRST_BATCH if size == 3 else 4
        start = tried
        while True:
            if deadline_passed(deadline):
                timed_out = True
                return True
            chunk = list(itertools.islice(samples, batch))
            if not chunk:
                return False
            tried += len(chunk)
            batch = BATCH if size == 3 else 4
            try:
                if consider(solve(chunk, size)):
                    # the frame is explained: before stopping, look for the competitors the
                    # ambiguity check needs (every other explanation of one detection triple;
                    # those not tried yet when the sweep came first)
                    sweep = (sweep_first[tried - start:] if sweep_first
                             else _sweep_samples(scorer) if size == 3 else [])
                    tried += len(sweep)
                    if sweep:
                        consider(solve(sweep, size))
                    return True
            except ScoringTimeoutError:
                timed_out = True
                return True

    if need < 2:
        return RansacOutcome(None, (), 0.0, 0, 0, True, False, "no_label_match")
    has3 = need >= 3 and count_samples(scorer, 3) > 0
    has2 = count_samples(scorer, 2) > 0
    stop = run(3, max_hypotheses) if has3 else False
    if not kept and not stop and has2:  # P2E: alone, or the fallback of P3P
        run(2, max_hypotheses if need < 3 else min(max_hypotheses, P2E_FALLBACK_BUDGET))
    if not kept:
        reason = ("time_budget_exceeded" if timed_out else "no_label_match"
                  if not (has3 or has2) else "no_hypothesis_above_inlier_threshold")
        return RansacOutcome(None, (), 0.0, evaluated, tried, exhaustive, timed_out, reason)
    best = kept[0]
    try:
        matches = tuple(scorer.matches(best.camera_from_world, inlier_iou))
    except ScoringTimeoutError:  # past the scorer's hard stop: keep the accepted assignment
        matches = ()
    if len(matches) < min_inliers:
        # the finer IoU estimate (256 points) lost an inlier at the threshold: keep the
        # assignment the pose was accepted with (96 points)
        matches = best.matches
    return RansacOutcome(best.camera_from_world, matches, best.score, evaluated, tried,
                         exhaustive, timed_out, None, tuple(kept))


def _keep_distinct(kept: list[Hypothesis], new: Hypothesis) -> list[Hypothesis]:
    """``kept`` (best first, mutually distinct) with ``new`` inserted: it replaces the kept
    hypotheses it is not distinct from if it scores better than all of them, is dropped if one
    of them scores at least as well; at most :data:`KEEP_DISTINCT` are kept."""
    close = [h for h in kept if not _distinct_keys(h.pose_key, new.pose_key)]
    if any(h.score >= new.score for h in close):
        return kept
    out = [h for h in kept if all(h is not c for c in close)] + [new]
    out.sort(key=lambda h: -h.score)
    return out[:KEEP_DISTINCT]
