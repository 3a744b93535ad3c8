"""Label-constrained RANSAC over detection/object correspondences (paper section V-B).

Hypotheses come from :mod:`service.localization.hypotheses` (P3P on centres with >= 3 usable
detections, P2E with 2, and P2E as a fallback — at most :data:`P2E_FALLBACK_BUDGET` samples —
when no P3P pose qualifies). Each candidate pose is
scored by the overlap (IoU) between the detections and the projected ellipsoids of the
label-compatible map objects, each detection taking its best object:

* **stage 1** (all candidates, cheap): a detection is "hit" when the projection of a compatible
  object's centre lies within twice its ellipse (``Phi_det <= 4``) and that object's projection
  is valid (ellipsoid entirely in front of the camera);
* **stage 2** (the :data:`STAGE2_CANDIDATES` best of stage 1 in each batch): IoU of every
  compatible pair, estimated by :func:`iou_estimates` (a fixed sunflower pattern of points
  inside each detection; relative area error ~1/n_points, checked against
  ``factors.metrics`` in the tests). A pair is an inlier when IoU >= ``inlier_iou``; the
  score of a pose is the sum of its inliers' IoUs (so both the number of explained detections
  and how well they overlap count). The final assignment is one-to-one (greedy by IoU).

Exhaustive over the label-compatible minimal samples when there are at most
``max_hypotheses`` of them, else ``max_hypotheses`` random samples (seeded); early exit once a
pose explains every usable detection with mean IoU >= :data:`EARLY_EXIT_MEAN_IOU`, and when the
time budget runs out. All poses here are ``camera_from_world`` (4x4, OpenCV ``[R | t]``).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from factors.geometry import Camera, Ellipse, ellipse_params
from maps.compiled import CompiledMap
from service.localization.hypotheses import p2e_hypotheses, p3p_hypotheses

__all__ = [
    "EARLY_EXIT_MEAN_IOU",
    "P2E_FALLBACK_BUDGET",
    "STAGE2_CANDIDATES",
    "Match",
    "MatchScorer",
    "RansacOutcome",
    "estimate_iou",
    "greedy_assignment",
    "iou_estimates",
    "ransac",
]

#: Stop sampling once a pose explains every usable detection with this mean IoU.
EARLY_EXIT_MEAN_IOU = 0.5
#: Candidates per batch whose IoUs are computed (the best by the stage-1 centre test).
STAGE2_CANDIDATES = 24
#: Minimal samples per batch (P3P calls between score / budget checks).
BATCH = 32
#: At most this many P2E samples when P2E is the fallback of a frame with >= 3 detections
#: (one P2E solve costs ~10-30 ms in Python, a P3P solve ~0.05 ms).
P2E_FALLBACK_BUDGET = 24


def _sunflower(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    r = np.sqrt(i / n)
    th = i * (math.pi * (3.0 - math.sqrt(5.0)))
    return np.column_stack([r * np.cos(th), r * np.sin(th)])


def _ellipse_points(params: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """Points (D, M, 2) filling ellipses (D, 5) from unit-disk points (M, 2)."""
    c, s = np.cos(params[:, 4]), np.sin(params[:, 4])
    u = unit[None, :, 0] * params[:, 2, None]
    v = unit[None, :, 1] * params[:, 3, None]
    x = params[:, 0, None] + c[:, None] * u - s[:, None] * v
    y = params[:, 1, None] + s[:, None] * u + c[:, None] * v
    return np.stack([x, y], axis=-1)


def project_objects(
    camera: Camera, camera_from_world: np.ndarray, centers: np.ndarray,
    shape_matrices: np.ndarray, dual_quadrics: np.ndarray, min_depth: float = 1e-6,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Projections of S ellipsoids at H poses, vectorised.

    Args:
        camera_from_world: (H, 4, 4).
        centers, shape_matrices, dual_quadrics: (S, 3), (S, 3, 3), (S, 4, 4) world frame.

    Returns:
        ``centres`` (H, S, 2) px of the projected ellipses, ``inv_shape`` (H, S, 2, 2) their
        ``A^-1 = R diag(a^2, b^2) R^T`` (px^2), ``valid`` (H, S) bool (ellipsoid entirely at
        depth > ``min_depth`` and a real ellipse), ``point_centres`` (H, S, 2) px: projections
        of the ellipsoid centres (garbage where the centre is behind the camera).
    """
    T = np.asarray(camera_from_world, dtype=float)
    r3 = T[:, 2, :3]
    zc = r3 @ centers.T + T[:, 2, 3, None]
    extent = np.sqrt(np.maximum(np.einsum("hi,sij,hj->hs", r3, shape_matrices, r3), 0.0))
    valid = zc - extent > min_depth
    P = np.einsum("ij,hjk->hik", camera.K, T[:, :3, :])
    C = np.einsum("hij,sjk,hlk->hsil", P, dual_quadrics, P)
    w = -C[..., 2, 2]
    ok = np.abs(w) > 0
    w = np.where(ok, w, 1.0)
    Cn = C / w[..., None, None]
    cen = -Cn[..., :2, 2]
    inv_shape = Cn[..., :2, :2] + cen[..., :, None] * cen[..., None, :]
    det = inv_shape[..., 0, 0] * inv_shape[..., 1, 1] - inv_shape[..., 0, 1] ** 2
    valid &= ok & (det > 0) & (inv_shape[..., 0, 0] > 0)
    hom = np.einsum("hij,sj->hsi", P[:, :, :3], centers) + P[:, None, :, 3]
    zh = np.where(np.abs(hom[..., 2]) > 1e-12, hom[..., 2], 1e-12)
    return cen, inv_shape, valid, hom[..., :2] / zh[..., None]


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
        ``I = area_det * fraction of the points inside the projection``.
    """
    S = proj_inv_shape
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    safe = np.where(det > 0, det, 1.0)
    a00, a11, a01 = S[..., 1, 1] / safe, S[..., 0, 0] / safe, -S[..., 0, 1] / safe
    d = det_points - proj_centres[..., None, :]
    phi = (a00[..., None] * d[..., 0] ** 2 + 2 * a01[..., None] * d[..., 0] * d[..., 1]
           + a11[..., None] * d[..., 1] ** 2)
    frac = np.mean(phi <= 1.0, axis=-1)
    inter = frac * det_areas
    area_proj = math.pi * np.sqrt(np.maximum(det, 0.0))
    iou = inter / np.maximum(det_areas + area_proj - inter, 1e-300)
    return np.where(det > 0, np.clip(iou, 0.0, 1.0), 0.0)


def estimate_iou(detection: Ellipse, projection: Ellipse, n_points: int = 256) -> float:
    """Scalar :func:`iou_estimates` of two ellipses (for checks and reporting)."""
    p = detection.params()[None]
    pts = _ellipse_points(p, _sunflower(n_points))[0]
    _, S = projection.gaussian()
    return float(iou_estimates(pts, np.array(detection.area), projection.center, S))


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
    order = np.argsort(iou, axis=None)[::-1]
    used_d: set[int] = set()
    used_o: set[int] = set()
    out = []
    n = iou.shape[1]
    for flat in order:
        value = float(iou.flat[flat])
        if value < threshold:
            break
        d, o = divmod(int(flat), n)
        if d in used_d or o in used_o:
            continue
        used_d.add(d)
        used_o.add(o)
        out.append(Match(int(detection_indices[d]), o, value))
    return sorted(out, key=lambda m: m.detection_index)


class MatchScorer:
    """Scores candidate poses against a fixed set of detections and a compiled map.

    ``detection_indices`` are the original indices of the usable detections (labels in the
    map); ``ellipses`` / ``labels`` are theirs. Only label-compatible pairs are evaluated.
    """

    def __init__(
        self, compiled: CompiledMap, camera: Camera, ellipses: Sequence[Ellipse],
        labels: Sequence[str], detection_indices: Sequence[int], n_points: int = 96,
    ) -> None:
        self.compiled = compiled
        self.camera = camera
        self.detection_indices = list(detection_indices)
        self.params = ellipse_params(ellipses)
        self.n_det = len(ellipses)
        self.n_obj = len(compiled)
        compat = np.zeros((self.n_det, self.n_obj), dtype=bool)
        for d, label in enumerate(labels):
            compat[d, compiled.indices_for(label)] = True
        self.compat = compat
        self.pair_d, self.pair_o = np.nonzero(compat)
        self.objects = np.unique(self.pair_o)
        # Position of each pair's object within self.objects.
        self.pair_s = np.searchsorted(self.objects, self.pair_o)
        self.unit = _sunflower(n_points)
        self.points = _ellipse_points(self.params, self.unit)
        self.areas = math.pi * self.params[:, 2] * self.params[:, 3]
        c, s = np.cos(self.params[:, 4]), np.sin(self.params[:, 4])
        R = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
        self.shape = np.einsum("dij,dj,dkj->dik", R, self.params[:, 2:4] ** -2.0, R)

    def compatible_objects(self, d: int) -> np.ndarray:
        """Object indices compatible with usable detection row ``d``."""
        return np.flatnonzero(self.compat[d])

    def _project(self, camera_from_world: np.ndarray) -> tuple[np.ndarray, ...]:
        cm = self.compiled
        o = self.objects
        return project_objects(self.camera, camera_from_world, cm.centers[o],
                               cm.shape_matrices[o], cm.dual_quadrics[o])

    def centre_hits(self, camera_from_world: np.ndarray) -> np.ndarray:
        """Stage 1: number of detections hit by a compatible valid object's centre, (H,)."""
        _, _, valid, pc = self._project(camera_from_world)
        d = pc[:, self.pair_s, :] - self.params[self.pair_d, :2]
        A = self.shape[self.pair_d]
        phi = np.einsum("hpi,pij,hpj->hp", d, A, d)
        hit = (phi <= 4.0) & valid[:, self.pair_s]
        per_det = np.zeros((hit.shape[0], self.n_det))
        np.maximum.at(per_det.T, self.pair_d, hit.T.astype(float))
        return per_det.sum(axis=1)

    def dense_iou(self, camera_from_world: np.ndarray,
                  points: np.ndarray | None = None) -> np.ndarray:
        """IoU (H, D, N) of every usable detection with every map object (0 if incompatible or
        the projection is invalid)."""
        cen, inv_shape, valid, _ = self._project(camera_from_world)
        pts = self.points if points is None else points
        iou = iou_estimates(pts[self.pair_d][None], self.areas[self.pair_d][None],
                            cen[:, self.pair_s], inv_shape[:, self.pair_s])
        iou = np.where(valid[:, self.pair_s], iou, 0.0)
        out = np.zeros((iou.shape[0], self.n_det, self.n_obj))
        out[:, self.pair_d, self.pair_o] = iou
        return out

    def scores(self, dense: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
        """(score (H,), inlier count (H,)) with each detection taking its best object."""
        best = dense.max(axis=2)
        inl = best >= threshold
        return np.where(inl, best, 0.0).sum(axis=1), inl.sum(axis=1)

    def matches(self, camera_from_world: np.ndarray, threshold: float,
                n_points: int = 256) -> list[Match]:
        """One-to-one inlier matches at one pose (IoU with ``n_points`` per detection)."""
        pts = _ellipse_points(self.params, _sunflower(n_points))
        dense = self.dense_iou(np.asarray(camera_from_world)[None], pts)[0]
        return greedy_assignment(dense, self.detection_indices, threshold)


@dataclass(frozen=True)
class RansacOutcome:
    """Best pose found. ``camera_from_world`` is None when nothing qualified; then ``reason`` is
    ``"no_label_match"``, ``"no_hypothesis_above_inlier_threshold"`` or
    ``"time_budget_exceeded"``."""

    camera_from_world: np.ndarray | None
    matches: tuple[Match, ...]
    score: float
    hypotheses_evaluated: int
    samples_tried: int
    exhaustive: bool
    timed_out: bool
    reason: str | None


def _enumerate_samples(scorer: MatchScorer, size: int, cap: int) -> list[tuple] | None:
    """All label-compatible minimal samples ((d...), (o...)) with distinct objects, or None if
    there are more than ``cap``."""
    out: list[tuple] = []
    compat = [scorer.compatible_objects(d) for d in range(scorer.n_det)]
    for dets in itertools.combinations(range(scorer.n_det), size):
        for objs in itertools.product(*(compat[d] for d in dets)):
            if len(set(objs)) == size:
                out.append((dets, objs))
                if len(out) > cap:
                    return None
    return out


def _has_sample(scorer: MatchScorer, size: int) -> bool:
    """Whether at least one label-compatible minimal sample of ``size`` exists."""
    return _enumerate_samples(scorer, size, 0) is None


def _random_samples(scorer: MatchScorer, size: int, count: int,
                    rng: np.random.Generator) -> list[tuple]:
    compat = [scorer.compatible_objects(d) for d in range(scorer.n_det)]
    out: list[tuple] = []
    attempts = 0
    while len(out) < count and attempts < 20 * count:
        attempts += 1
        dets = tuple(sorted(rng.choice(scorer.n_det, size, replace=False).tolist()))
        objs = tuple(int(compat[d][rng.integers(len(compat[d]))]) for d in dets)
        if len(set(objs)) == size:
            out.append((dets, objs))
    return out


def ransac(
    scorer: MatchScorer,
    up_world: np.ndarray,
    *,
    inlier_iou: float,
    min_inliers: int,
    max_hypotheses: int,
    rng: np.random.Generator,
    deadline: float | None = None,
) -> RansacOutcome:
    """Search poses from minimal samples (see the module docstring).

    Args:
        scorer: detections + map + camera.
        up_world: the map's up axis (P2E's zero-roll assumption).
        inlier_iou, min_inliers: acceptance of a pose.
        max_hypotheses: budget of minimal samples per solver (P3P, then P2E).
        rng: sampler (only used when not exhaustive).
        deadline: ``time.perf_counter()`` value after which the search stops.
    """
    cm = scorer.compiled
    best_T: np.ndarray | None = None
    best_score, best_count = -1.0, 0
    evaluated = 0
    tried = 0
    timed_out = False
    exhaustive = True
    need = scorer.n_det

    def consider(poses: np.ndarray) -> bool:
        """Score candidate poses; returns True to stop early."""
        nonlocal best_T, best_score, best_count, evaluated
        if len(poses) == 0:
            return False
        evaluated += len(poses)
        if len(poses) > STAGE2_CANDIDATES:
            hits = scorer.centre_hits(poses)
            keep = np.argsort(-hits, kind="stable")[:STAGE2_CANDIDATES]
            poses = poses[keep]
        dense = scorer.dense_iou(poses)
        score, count = scorer.scores(dense, inlier_iou)
        i = int(np.argmax(score))
        if count[i] >= min_inliers and score[i] > best_score:
            best_T, best_score, best_count = poses[i], float(score[i]), int(count[i])
        return best_count >= need and best_score >= EARLY_EXIT_MEAN_IOU * need

    def run(size: int, budget: int) -> bool:
        nonlocal tried, timed_out, exhaustive
        samples = _enumerate_samples(scorer, size, budget)
        if samples is None:
            exhaustive = False
            samples = _random_samples(scorer, size, budget, rng)
        else:
            samples = [samples[i] for i in rng.permutation(len(samples))]
        batch = BATCH if size == 3 else 4
        for start in range(0, len(samples), batch):
            if deadline is not None and time.perf_counter() > deadline:
                timed_out = True
                return True
            poses = []
            for dets, objs in samples[start:start + batch]:
                tried += 1
                if size == 3:
                    sols = p3p_hypotheses(scorer.params[list(dets), :2],
                                          cm.centers[list(objs)], scorer.camera)
                else:
                    ells = [Ellipse(*scorer.params[d]) for d in dets]
                    sols = p2e_hypotheses(ells, [cm.ellipsoids[o] for o in objs],
                                          scorer.camera, up_world)
                poses.extend(sols)
            if consider(np.array(poses).reshape(-1, 4, 4)):
                return True
        return False

    if need < 2:
        return RansacOutcome(None, (), 0.0, 0, 0, True, False, "no_label_match")
    has_any = False
    if need >= 3:
        has_any = _has_sample(scorer, 3)
        stop = run(3, max_hypotheses) if has_any else False
        if best_T is None and not stop and _has_sample(scorer, 2):
            has_any = True
            run(2, min(max_hypotheses, P2E_FALLBACK_BUDGET))
    else:
        has_any = _has_sample(scorer, 2)
        if has_any:
            run(2, max_hypotheses)
    if best_T is None:
        if timed_out:
            reason = "time_budget_exceeded"
        elif not has_any:
            reason = "no_label_match"
        else:
            reason = "no_hypothesis_above_inlier_threshold"
        return RansacOutcome(None, (), 0.0, evaluated, tried, exhaustive, timed_out, reason)
    matches = tuple(scorer.matches(best_T, inlier_iou))
    return RansacOutcome(best_T, matches, best_score, evaluated, tried, exhaustive, timed_out,
                         None)
