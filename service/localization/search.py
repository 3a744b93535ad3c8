"""Label-constrained RANSAC over detection/object correspondences (paper section V-B).

Candidate poses come from :mod:`quadloc.service.localization.hypotheses` (P3P on centres with
>= 3 usable detections, P2E with 2, P2E as a fallback of at most :data:`P2E_FALLBACK_BUDGET`
samples) on the minimal samples of :mod:`quadloc.service.localization.sampling`, in its order.
A pose is scored by :class:`quadloc.service.localization.scoring.MatchScorer` (a pair is an
inlier when IoU >= ``inlier_iou``; a pose's score is the sum of its one-to-one inliers' IoUs);
the search keeps the best :data:`KEEP_DISTINCT` mutually distinct qualified hypotheses
(:func:`distinct_poses`). Early exit once a pose explains every usable detection (after the
competitor sweep); a search neither exhaustive nor stopped early ends with the competitor sweep
of its best hypothesis' detections (:meth:`_Search.sweep_best`: the copies of a room); time
bounded by deadline checks before every batch and inside the scoring
of a batch. All poses here are ``camera_from_world`` (4x4, OpenCV ``[R | t]``). Stages,
ordering and bounds in detail: ``docs/design/localization.md``.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera
from quadloc.factors.conics import Ellipse
from quadloc.service.localization.hypotheses import p2e_hypotheses, p3p_checked_batch
from quadloc.service.localization.sampling import (
    Sample,
    count_samples,
    sample_order,
    sweep_samples,
)
from quadloc.service.localization.scoring import (
    PAIR_BLOCK,
    Match,
    MatchScorer,
    ScoringTimeoutError,
    blocks,
    compile_scoring_kernels,
)

__all__ = [
    "DISTINCT_ANGLE_DEG",
    "DISTINCT_POSITION_M",
    "EARLY_EXIT_MEAN_IOU",
    "KEEP_DISTINCT",
    "P2E_FALLBACK_BUDGET",
    "STAGE2_CANDIDATES",
    "Hypothesis",
    "RansacOutcome",
    "competitor_sweep",
    "compile_search_kernels",
    "distinct_poses",
    "ransac",
]

#: Stop sampling once a pose explains every usable detection with this mean IoU.
EARLY_EXIT_MEAN_IOU = 0.5
#: Early exit only with at least this many usable detections: with 2-3 the search is small and
#: must go on to find competing hypotheses (ambiguity check).
EARLY_EXIT_MIN_DETECTIONS = 4
#: Candidates per batch whose IoUs are computed (the best by the stage-1 centre test).
STAGE2_CANDIDATES = 24
#: Stage 1 (the centre test keeping :data:`STAGE2_CANDIDATES` poses of a batch) only when a
#: batch has more (pose, pair) tests than this: below, every pose is scored (vectorised).
STAGE1_MIN_WORK = 1 << 14
#: Minimal samples of the first P3P batch (a frame explained by it stops the search early).
FIRST_BATCH = 8
#: Minimal samples per P3P batch (P3P calls between score / budget checks), and per P2E batch.
BATCH = 32
P2E_BATCH = 4
#: At most this many P2E samples when P2E is the fallback of a frame with >= 3 detections
#: (one P2E solve costs ~10-30 ms in Python, a P3P solve ~0.05 ms).
P2E_FALLBACK_BUDGET = 24
#: Number of distinct hypotheses kept (:attr:`RansacOutcome.alternatives`), and what
#: "distinct" means: camera centres further apart than this (m) or orientations differing by
#: more than this (deg). Used by the ambiguity check of
#: ``quadloc.service.localization.confidence``.
KEEP_DISTINCT = 4
DISTINCT_POSITION_M = 0.5
DISTINCT_ANGLE_DEG = 20.0

#: What :func:`distinct_poses` compares (:func:`_pose_key`).
_PoseKey = tuple[list[float], list[float]]


@dataclass(frozen=True)
class Hypothesis:
    """A qualified pose (``camera_from_world`` 4x4), its one-to-one matches and score (sum of
    the matches' IoUs)."""

    camera_from_world: FloatArray
    matches: tuple[Match, ...]
    score: float

    @functools.cached_property
    def pose_key(self) -> _PoseKey:
        """:func:`_pose_key` of the pose, computed once (the search compares it often)."""
        return _pose_key(self.camera_from_world)


@dataclass(frozen=True)
class RansacOutcome:
    """Best pose found. ``camera_from_world`` is None when nothing qualified; then ``reason`` is
    ``"no_label_match"``, ``"no_hypothesis_above_inlier_threshold"`` or
    ``"time_budget_exceeded"``. ``alternatives``: up to ``keep`` (:data:`KEEP_DISTINCT`) qualified,
    mutually distinct hypotheses (:func:`distinct_poses`), best first (the first is the
    returned pose, with the 96-point matches it was accepted with)."""

    camera_from_world: FloatArray | None
    matches: tuple[Match, ...]
    score: float
    hypotheses_evaluated: int
    samples_tried: int
    exhaustive: bool
    timed_out: bool
    reason: str | None
    alternatives: tuple[Hypothesis, ...] = ()


def ransac(
    scorer: MatchScorer,
    up_world: FloatArray,
    *,
    inlier_iou: float,
    min_inliers: int,
    max_hypotheses: int,
    rng: np.random.Generator,
    deadline: Deadline | None = None,
    seeds: FloatArray | None = None,
    sample: bool = True,
    keep: int = KEEP_DISTINCT,
) -> RansacOutcome:
    """Search poses from minimal samples (see the module docstring).

    Args:
        scorer: detections + map + camera.
        up_world: the map's up axis (3,) (P2E starts its searches at camera rolls around it).
        inlier_iou, min_inliers: acceptance of a pose.
        max_hypotheses: budget of minimal samples per solver (P3P, then P2E).
        rng: sampler (only used when not exhaustive: exhaustive runs do not depend on it).
        deadline: when the search stops (e.g. CPU time of this thread with a wall-clock hard
            limit, :meth:`quadloc.factors.budget.Deadline.cpu_budget`; None: never), checked
            before every batch and inside the scoring of a batch.
        seeds: candidate poses (S, 4, 4) ``camera_from_world`` scored before any sample (the
            constellation search of large maps,
            :mod:`quadloc.service.localization.constellations`); None: none.
        sample: whether minimal samples are solved at all (False: the seeds only).
        keep: distinct hypotheses kept (default :data:`KEEP_DISTINCT`; more for the candidate
            places of a large map).
    """
    need = scorer.n_det
    if need < 2:
        return RansacOutcome(None, (), 0.0, 0, 0, True, False, "no_label_match")
    search = _Search(scorer, up_world, inlier_iou, min_inliers, rng, deadline, keep)
    has3 = need >= 3 and count_samples(scorer, 3) > 0
    has2 = count_samples(scorer, 2) > 0
    stop = not sample
    if seeds is not None and len(seeds):
        try:
            stop = search.consider(np.asarray(seeds, dtype=float)) or stop
        except ScoringTimeoutError:
            search.timed_out = stop = True
    if has3 and not stop:
        stop = search.run(3, max_hypotheses)
    if not search.kept and not stop and has2:  # P2E: alone, or the fallback of P3P
        search.run(2, max_hypotheses if need < 3 else min(max_hypotheses, P2E_FALLBACK_BUDGET))
    if has3 and sample and not search.exhaustive and not search.timed_out:
        search.sweep_best()
    if not search.kept:
        reason = ("time_budget_exceeded" if search.timed_out else "no_label_match"
                  if not (has3 or has2) else "no_hypothesis_above_inlier_threshold")
        return RansacOutcome(None, (), 0.0, search.evaluated, search.tried, search.exhaustive,
                             search.timed_out, reason)
    best = search.kept[0]
    try:
        matches = tuple(scorer.matches(best.camera_from_world, inlier_iou))
    except ScoringTimeoutError:  # past the scorer's hard stop: keep the accepted assignment
        matches = ()
    if len(matches) < min_inliers:
        # the finer IoU estimate (256 points) lost an inlier at the threshold: keep the
        # assignment the pose was accepted with (96 points)
        matches = best.matches
    return RansacOutcome(best.camera_from_world, matches, best.score, search.evaluated,
                         search.tried, search.exhaustive, search.timed_out, None,
                         tuple(search.kept))


class _Search:
    """The state of one :func:`ransac` call and its steps.

    Attributes:
        kept: distinct qualified hypotheses, best first (:func:`_keep_distinct`); ``kept[0]``
            only ever changes to a better one, so it is the best pose found.
        evaluated: candidate poses scored; tried: minimal samples solved.
        exhaustive: every run so far tried every label-compatible sample.
        timed_out: the deadline stopped the search.
    """

    def __init__(self, scorer: MatchScorer, up_world: FloatArray, inlier_iou: float,
                 min_inliers: int, rng: np.random.Generator, deadline: Deadline | None,
                 keep: int = KEEP_DISTINCT) -> None:
        self.scorer = scorer
        self.keep = keep
        self.up_world = up_world
        self.inlier_iou = inlier_iou
        self.min_inliers = min_inliers
        self.rng = rng
        self.deadline = deadline
        self.n_pairs = len(scorer.pair_d)
        self.kept: list[Hypothesis] = []
        self.evaluated = 0
        self.tried = 0
        self.exhaustive = True
        self.timed_out = False
        #: detection triples (scorer rows) whose every assignment was tried (competitor sweeps)
        self.swept: set[tuple[int, ...]] = set()

    def run(self, size: int, budget: int) -> bool:
        """Solve and score the samples of ``size`` (3: P3P, 2: P2E) in
        :func:`quadloc.service.localization.sampling.sample_order`, batch by batch, up to
        ``budget`` samples; True when the search must stop (the frame is explained, after the
        competitor sweep; or the deadline passed)."""
        order = sample_order(self.scorer, size, budget, self.rng)
        if not order.exhaustive:
            self.exhaustive = False
        self.swept.update(s[0] for s in order.sweep_first)
        batch = FIRST_BATCH if size == 3 else P2E_BATCH
        start = self.tried
        while True:
            if deadline_passed(self.deadline):
                self.timed_out = True
                return True
            chunk = list(itertools.islice(order.samples, batch))
            if not chunk:
                return False
            self.tried += len(chunk)
            batch = BATCH if size == 3 else P2E_BATCH
            try:
                if self.consider(self.solve(chunk, size)):
                    # the frame is explained: before stopping, look for the competitors the
                    # ambiguity check needs (every other explanation of one detection triple;
                    # those not tried yet when the sweep came first)
                    sweep = order.competitor_sweep(self.tried - start)
                    self.tried += len(sweep)
                    self.swept.update(s[0] for s in sweep)
                    if sweep:
                        self.consider(self.solve(sweep, size))
                    return True
            except ScoringTimeoutError:
                self.timed_out = True
                return True

    def sweep_best(self) -> None:
        """The competitor sweep of the best hypothesis' own detections
        (:func:`quadloc.service.localization.sampling.sweep_samples` over the rows it
        matches), unless that triple was swept already or the deadline passed. A search that
        was not exhaustive and did not exit early may have found one explanation only: a
        distinct pose explaining the same detections (a copy of the room elsewhere in the map,
        the other of two same-label objects) assigns this triple to other objects, so P3P on
        its assignments finds it."""
        if self.kept:
            self.sweep([m.detection_index for m in self.kept[0].matches])

    def sweep(self, detection_indices: Sequence[int]) -> None:
        """Score every assignment of the sweep triple of these detections (original indices,
        :func:`quadloc.service.localization.sampling.sweep_samples` over their rows), unless
        that triple was swept already or the deadline passed."""
        if deadline_passed(self.deadline):
            return
        row = {d: r for r, d in enumerate(self.scorer.detection_indices)}
        rows = np.array(sorted(row[d] for d in detection_indices), dtype=np.intp)
        sweep = sweep_samples(self.scorer, rows) if len(rows) >= 3 else []
        if not sweep or sweep[0][0] in self.swept:
            return
        self.swept.add(sweep[0][0])
        self.tried += len(sweep)
        try:
            self.consider(self.solve(sweep, 3))
        except ScoringTimeoutError:
            self.timed_out = True

    def solve(self, chunk: list[Sample], size: int) -> FloatArray:
        """Candidate poses (M, 4, 4) ``camera_from_world`` of minimal samples: one P3P call
        (:func:`quadloc.service.localization.hypotheses.p3p_checked_batch`: the poses of
        ``cv2.solveP3P`` from one compiled kernel for the batch), or P2E."""
        scorer, cm = self.scorer, self.scorer.compiled
        if size == 3:
            poses, _ = p3p_checked_batch(scorer.params[np.array([c[0] for c in chunk]), :2],
                                         cm.centers[np.array([c[1] for c in chunk])],
                                         scorer.camera)
            return poses
        found: list[FloatArray] = []
        for dets, objs in chunk:
            ells = [Ellipse(*scorer.params[d]) for d in dets]
            found.extend(p2e_hypotheses(ells, [cm.ellipsoids[o] for o in objs], scorer.camera,
                                        self.up_world))
        return np.array(found).reshape(-1, 4, 4)

    def consider(self, poses: FloatArray) -> bool:
        """Score candidate poses (vectorised over poses and pairs, memory bounded); keeps the
        best distinct hypotheses; returns True to stop early (:meth:`explained`)."""
        if len(poses) == 0:
            return False
        scorer, inlier_iou = self.scorer, self.inlier_iou
        self.evaluated += len(poses)
        if len(poses) > STAGE2_CANDIDATES and len(poses) * self.n_pairs > STAGE1_MIN_WORK:
            # large problems only: the cheap centre test picks the candidates worth an IoU
            hits = scorer.centre_hits(poses, stop_at=self.deadline)
            keep = np.argsort(-hits, kind="stable")[:STAGE2_CANDIDATES]
            poses = poses[keep]
        for blk in blocks(len(poses), max(1, PAIR_BLOCK // max(1, self.n_pairs))):
            iou = scorer.pair_iou(poses[blk], floor=inlier_iou, stop_at=self.deadline)
            # per-detection best object: an upper bound of the one-to-one score and count
            bound, count = scorer.pair_scores(iou, inlier_iou)
            block = poses[blk]
            bounds: list[float] = bound.tolist()
            counts: list[int] = count.tolist()
            # best bound first: the bar rises early and fewer assignments are needed
            for h in np.argsort(-bound, kind="stable").tolist():
                bar = self.kept[-1].score if len(self.kept) >= self.keep else -1.0
                if bounds[h] <= bar or counts[h] < self.min_inliers:
                    continue
                # one-to-one (greedy) assignment, as in the final matches
                m = scorer.pair_assignment(iou[h], inlier_iou)
                score = float(sum(x.iou for x in m))
                if len(m) >= self.min_inliers and score > bar:
                    self.kept = _keep_distinct(self.kept, Hypothesis(block[h], tuple(m), score),
                                               self.keep)
        return self.explained()

    def explained(self) -> bool:
        """Whether the best pose explains every usable detection (at least
        :data:`EARLY_EXIT_MIN_DETECTIONS`) with mean IoU >= :data:`EARLY_EXIT_MEAN_IOU`."""
        need = self.scorer.n_det
        return (need >= EARLY_EXIT_MIN_DETECTIONS and bool(self.kept)
                and len(self.kept[0].matches) >= need
                and self.kept[0].score >= EARLY_EXIT_MEAN_IOU * need)


def competitor_sweep(scorer: MatchScorer, up_world: FloatArray,
                     detection_indices: Sequence[int], *, inlier_iou: float, min_inliers: int,
                     deadline: Deadline | None = None, keep: int = KEEP_DISTINCT
                     ) -> tuple[tuple[Hypothesis, ...], int]:
    """The competitor sweep of these detections (original indices; :meth:`_Search.sweep`):
    every explanation of their sweep triple, e.g. the copies of a room whose objects explain
    them, for a pose that refinement grew beyond what the search found (its inliers were never
    swept). Returns (the qualified, mutually distinct hypotheses, best first, at most ``keep``;
    the number of poses scored)."""
    search = _Search(scorer, up_world, inlier_iou, min_inliers, np.random.default_rng(0),
                     deadline, keep)
    search.sweep(detection_indices)
    return tuple(search.kept), search.evaluated


def compile_search_kernels() -> None:
    """Compile (or load from numba's cache) the search's kernels (the scorer's,
    :func:`quadloc.service.localization.scoring.compile_scoring_kernels`, and the P3P of
    :func:`quadloc.service.localization.hypotheses.p3p_checked_batch`), so that no request
    pays for it: the service calls it at start-up with
    :func:`quadloc.factors.pose_residuals.compile_kernels`."""
    compile_scoring_kernels()
    camera = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)
    p3p_checked_batch(np.array([[[300.0, 200.0], [350.0, 260.0], [280.0, 250.0]]]),
                      np.array([[[0.0, 0.0, 3.0], [0.3, 0.2, 3.1], [-0.1, 0.3, 2.9]]]), camera)


def _keep_distinct(kept: list[Hypothesis], new: Hypothesis, keep: int = KEEP_DISTINCT
                   ) -> list[Hypothesis]:
    """``kept`` (best first, mutually distinct) with ``new`` inserted: it replaces the kept
    hypotheses it is not distinct from if it scores better than all of them, is dropped if one
    of them scores at least as well; at most ``keep`` are kept."""
    close = [h for h in kept if not _distinct_keys(h.pose_key, new.pose_key)]
    if any(h.score >= new.score for h in close):
        return kept
    out = [h for h in kept if all(h is not c for c in close)] + [new]
    out.sort(key=lambda h: -h.score)
    return out[:keep]


def distinct_poses(camera_from_world_a: FloatArray, camera_from_world_b: FloatArray) -> bool:
    """Whether two poses differ by more than :data:`DISTINCT_POSITION_M` (camera centres) or
    :data:`DISTINCT_ANGLE_DEG` (rotation angle)."""
    return _distinct_keys(_pose_key(camera_from_world_a), _pose_key(camera_from_world_b))


def _pose_key(camera_from_world: FloatArray) -> _PoseKey:
    """What :func:`distinct_poses` compares: ``R^T t`` (3,) (minus the camera centre) and the
    row-major entries of ``R`` (9,), as Python floats."""
    R = camera_from_world[:3, :3]
    return (R.T @ camera_from_world[:3, 3]).tolist(), R.ravel().tolist()


def _distinct_keys(a: _PoseKey, b: _PoseKey) -> bool:
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
