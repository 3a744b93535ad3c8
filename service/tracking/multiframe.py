"""Multi-frame RANSAC: initialize (or relocalize) a session from several frames' detections.

Detections of the buffered frames become virtual image points of the newest (reference) frame
through the odometry; P3P on three of them gives ``camera_r_from_world`` hypotheses, scored on
every frame with :class:`quadloc.service.localization.scoring.MatchScorer`. Accepted with at least
:data:`MIN_DISTINCT_OBJECTS` objects and :data:`MIN_TOTAL_INLIERS` inliers and no distinct rival
within :data:`AMBIGUITY_RATIO`. Poses are ``camera_from_world`` unless named otherwise. The
method: docs/design/service.md#multi-frame-ransac.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from quadloc.factors.arrays import FloatArray, IntArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera
from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import invert_pose
from quadloc.maps.compiled import CompiledMap
from quadloc.service.localization.hypotheses import p3p_hypotheses_batch, size_depths
from quadloc.service.localization.scoring import (
    Match,
    MatchScorer,
    ScoringTimeoutError,
    greedy_assignment,
)

__all__ = ["AMBIGUITY_RATIO", "MIN_DISTINCT_OBJECTS", "MIN_TOTAL_INLIERS", "InitFrame",
           "MultiFrameOutcome", "multi_frame_ransac"]

MIN_DISTINCT_OBJECTS = 3
MIN_TOTAL_INLIERS = 4
AMBIGUITY_RATIO = 0.85
AMBIGUITY_DISTANCE_M = 0.3
STAGE2 = 24


@dataclass(frozen=True)
class InitFrame:
    """One buffered frame: its usable detections and the odometry pose.

    Attributes:
        odom_from_camera: 4x4 (OpenCV camera axes).
        ellipses: (D, 5) ``(cx, cy, a, b, angle)`` of the usable detections.
        labels: their D labels; detection_indices: their indices in the frame's request.
    """

    odom_from_camera: FloatArray
    ellipses: FloatArray
    labels: tuple[str, ...]
    detection_indices: tuple[int, ...]


@dataclass(frozen=True)
class MultiFrameOutcome:
    """``camera_from_world`` of every input frame (or None) and each frame's inlier matches."""

    camera_from_world: list[FloatArray] | None
    matches: list[list[Match]]
    n_objects: int
    n_inliers: int
    hypotheses: int
    reason: str | None


def _draw_unused(objects: IntArray, used: set[int], rng: np.random.Generator) -> int | None:
    """One of ``objects`` (indices) not in ``used``, uniformly (one ``rng.integers`` call;
    None, without a call, when every one is used): the j-th of them in their order, found by
    skipping the positions of the used ones (at most two per sample) rather than by listing the
    free ones (a label of a building map has hundreds of objects)."""
    skip = np.flatnonzero(np.logical_or.reduce([objects == u for u in used])) if used else ()
    if len(objects) == len(skip):
        return None
    j = int(rng.integers(len(objects) - len(skip)))
    for q in skip:  # ascending positions
        j += int(j >= q)
    return int(objects[j])


def _virtual_points(frames: Sequence[InitFrame], ref_from_k: list[FloatArray],
                    camera: Camera, sample: list[tuple[int, int, int]],
                    compiled: CompiledMap, Kinv: FloatArray) -> FloatArray | None:
    """The sample's detections seen from the reference frame (3, 2) px: each ellipse centre
    at the depth its size gives (``Kinv``: the camera's inverse intrinsics), carried by the
    odometry; None when one falls behind the reference camera."""
    pts = []
    for k, d, o in sample:
        e = frames[k].ellipses[d]
        r_obj = float(np.prod(compiled.axes[o]) ** (1.0 / 3.0))
        z = float(size_depths(camera, e[2:4], r_obj))
        p = ref_from_k[k][:3, :3] @ (z * (Kinv @ np.array([e[0], e[1], 1.0]))) \
            + ref_from_k[k][:3, 3]
        if p[2] <= 0.05:
            return None
        uv = camera.K @ (p / p[2])
        pts.append(uv[:2])
    return np.array(pts)


def multi_frame_ransac(
    frames: Sequence[InitFrame], compiled: CompiledMap, camera: Camera, *,
    inlier_iou: float = 0.2, max_samples: int = 300, rng: np.random.Generator | None = None,
    deadline: Deadline | None = None, extra_hypotheses: Sequence[FloatArray] = (),
) -> MultiFrameOutcome:
    """Search a pose of the newest frame explaining the detections of all ``frames``.

    Args:
        frames: buffered frames, the last one is the reference (its pose is the hypothesis).
        extra_hypotheses: ``camera_from_world`` poses of the reference frame to score as well
            (e.g. a client prior).
        max_samples: minimal samples drawn (uniform over frames' detections and compatible
            objects, seeded by ``rng``): always all of them, so that the answer depends on the
            inputs and the seed only, never on the machine's speed.
        deadline: checked between samples and inside the scoring (None: no limit); once it
            has passed the search gives up: reason ``time_budget_exceeded``, no pose.
    """
    rng = rng or np.random.default_rng(0)
    ref = frames[-1].odom_from_camera
    ref_inv = invert_pose(ref)
    ref_from_k = [ref_inv @ f.odom_from_camera for f in frames]
    k_from_ref = [invert_pose(T) for T in ref_from_k]
    scorers = [MatchScorer(compiled, camera, [Ellipse(*map(float, e)) for e in f.ellipses],
                           list(f.labels), list(f.detection_indices)) if len(f.labels) else None
               for f in frames]
    pool = [(k, d, compiled.indices_for(lab)) for k, f in enumerate(frames)
            for d, lab in enumerate(f.labels) if len(compiled.indices_for(lab))]
    hyps: list[FloatArray] = [np.asarray(h, float) for h in extra_hypotheses]
    if len(pool) >= 3:
        K_inv = np.array(np.linalg.inv(camera.K), dtype=np.float64)
        image_points: list[FloatArray] = []
        world_points: list[FloatArray] = []
        for _ in range(max_samples):
            if deadline_passed(deadline):  # gives up (no pose), never answers from fewer
                return MultiFrameOutcome(None, [], 0, 0, len(hyps), "time_budget_exceeded")
            idx = rng.choice(len(pool), 3, replace=False)
            sample: list[tuple[int, int, int]] = []
            used: set[int] = set()
            for i in idx:
                k, d, objs = pool[int(i)]
                o = _draw_unused(objs, used, rng)
                if o is None:
                    break
                used.add(o)
                sample.append((k, d, o))
            if len(sample) < 3:
                continue
            vp = _virtual_points(frames, ref_from_k, camera, sample, compiled, K_inv)
            if vp is None:
                continue
            image_points.append(vp)
            world_points.append(compiled.centers[[s[2] for s in sample]])
        if image_points:  # every sample's P3P at once, in sample order
            hyps.extend(p3p_hypotheses_batch(np.array(image_points), np.array(world_points),
                                             camera)[0])
    if not hyps:
        return MultiFrameOutcome(None, [], 0, 0, 0, "too_few_objects")
    H = np.array(hyps).reshape(-1, 4, 4)
    # stage 1: centre hits summed over frames; stage 2: IoU scores on the best STAGE2
    try:
        return _score(frames, scorers, k_from_ref, H, len(hyps), inlier_iou, deadline)
    except ScoringTimeoutError:  # the scorers check the deadline inside their blocks
        return MultiFrameOutcome(None, [], 0, 0, len(hyps), "time_budget_exceeded")


def _score(frames: Sequence[InitFrame], scorers: Sequence[MatchScorer | None],
           k_from_ref: list[FloatArray], H: FloatArray, n_hyps: int, inlier_iou: float,
           deadline: Deadline | None) -> MultiFrameOutcome:
    """The two scoring stages of :func:`multi_frame_ransac` over the hypotheses ``H`` (h, 4, 4)
    of the reference frame; raises ``ScoringTimeoutError`` once ``deadline`` has passed."""
    hits = np.zeros(len(H))
    for k, sc in enumerate(scorers):
        if sc is not None:
            hits += sc.centre_hits(np.einsum("ij,hjk->hik", k_from_ref[k], H), deadline)
    keep = np.argsort(-hits, kind="stable")[:STAGE2]
    H = H[keep]
    score = np.zeros(len(H))
    per_frame: list[list[list[Match]]] = [[[] for _ in frames] for _ in range(len(H))]
    for k, sc in enumerate(scorers):
        if sc is None:
            continue
        dense = sc.dense_iou(np.einsum("ij,hjk->hik", k_from_ref[k], H), stop_at=deadline)
        for h in range(len(H)):
            m = greedy_assignment(dense[h], sc.detection_indices, inlier_iou)
            per_frame[h][k] = m
            score[h] += sum(x.iou for x in m)
    order = np.argsort(-score, kind="stable")
    best = int(order[0])
    matched = {m.object_index for ms in per_frame[best] for m in ms}
    n_inl = sum(len(ms) for ms in per_frame[best])
    if len(matched) < MIN_DISTINCT_OBJECTS or n_inl < MIN_TOTAL_INLIERS:
        return MultiFrameOutcome(None, [], len(matched), n_inl, n_hyps, "too_few_objects")
    c_best = invert_pose(H[best])[:3, 3]
    for h in order[1:]:
        if score[h] < AMBIGUITY_RATIO * score[best]:
            break
        if np.linalg.norm(invert_pose(H[h])[:3, 3] - c_best) > AMBIGUITY_DISTANCE_M:
            return MultiFrameOutcome(None, [], len(matched), n_inl, n_hyps, "ambiguous")
    poses = [k_from_ref[k] @ H[best] for k in range(len(frames))]
    return MultiFrameOutcome(poses, per_frame[best], len(matched), n_inl, n_hyps, None)
