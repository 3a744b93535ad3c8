"""Negative evidence between candidate places: objects a pose predicts in view that were not
detected.

A candidate pose predicts the map objects of :func:`quadloc.maps.visibility.predicted_in_view`
with :data:`VIEW_RULE` (centre in front at 0.3-6 m, at most half of its projected disc cut off
by the image border, at least :data:`VIEW_RULE`'s ``min_area_px`` px^2, the zone of the nearest
one); those not among its inliers are its *misses* (:func:`missed_objects`). Each miss is an
event of probability :data:`MISS_RATE` if the candidate is right (the detector's misses,
occlusion included) and about 1 if it is not, so a candidate with ``k`` more misses than
another is ``(1 / MISS_RATE)^k`` times less likely on that evidence alone.

The place comparison (:func:`weigh_misses`): among the best candidate and the runners-up that
compete with it (:func:`quadloc.service.localization.candidates.competes`: as many inliers, a
comparable fit), a runner-up with at least :func:`miss_margin` more misses than the best no
longer competes (its place loses the tie); the competitor with the fewest misses becomes the
best when every other member of the tie has at least that margin more. Candidates that do not
compete are never promoted: the detections rule, misses only break ties between places that
explain them equally well (exact copies of a room predict the same misses and stay
``ambiguous``). Poses ``world_from_camera`` (4x4, OpenCV camera axes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from quadloc.factors.camera import Camera
from quadloc.factors.rotations import invert_pose
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.visibility import ViewRule, predicted_in_view
from quadloc.service.localization.candidates import Candidate, competes

__all__ = [
    "MISS_RATE",
    "NEGATIVE_EVIDENCE_RATIO",
    "VIEW_RULE",
    "miss_margin",
    "missed_objects",
    "weigh_misses",
]

#: Probability that the detector does not report an object predicted in view (occlusion
#: included). The simulator's detector misses 11-13 % of the objects :data:`VIEW_RULE` predicts
#: at the true pose (``bench.building`` frames, tuning seeds 5 and 7, 10 rooms, perturbed and
#: random); a third is assumed (as tracking sessions do: real detectors miss more), which
#: makes each miss weaker evidence than the simulator's would be.
MISS_RATE = 1.0 / 3.0
#: A runner-up loses a tie when the misses make it at least this many times less likely.
NEGATIVE_EVIDENCE_RATIO = 100.0
#: The single-frame rule of "predicted in view" (:func:`quadloc.maps.visibility.predicted_in_view`).
VIEW_RULE = ViewRule(min_depth_m=0.3, max_depth_m=6.0, inset_fraction=0.0, max_truncation=0.5,
                     min_area_px=400.0)


def miss_margin(miss_rate: float = MISS_RATE, ratio: float = NEGATIVE_EVIDENCE_RATIO) -> int:
    """The fewest extra misses that make a candidate ``ratio`` times less likely:
    ``ceil(log(ratio) / log(1 / miss_rate))`` (5 with the defaults)."""
    return math.ceil(math.log(ratio) / math.log(1.0 / miss_rate) - 1e-9)


def missed_objects(compiled: CompiledMap, camera: Camera, candidate: Candidate) -> int:
    """How many objects of ``compiled`` (the whole map) ``candidate`` predicts in view
    (:data:`VIEW_RULE`) that are not among its inliers."""
    seen = predicted_in_view(compiled, camera, invert_pose(candidate.world_from_camera),
                             VIEW_RULE)
    matched = {m.object_id for m in candidate.inliers}
    return sum(1 for i in seen.tolist() if compiled.object_ids[i] not in matched)


def weigh_misses(ranked: Sequence[Candidate], compiled: CompiledMap, camera: Camera,
                 margin: int | None = None, chi2_ratio: float | None = None
                 ) -> tuple[list[Candidate], bool, dict[int, int]]:
    """The place comparison with negative evidence (module docstring) of ``ranked`` (best
    first, mutually distinct). Returns the ranking (the best possibly replaced by a competitor
    with fewer misses, the others in their order), whether a runner-up still competes (the
    answer is ambiguous), and the misses of each candidate weighed (by ``id``). ``margin``:
    default :func:`miss_margin`; ``chi2_ratio``: of :func:`competes` (the best's,
    ``confidence.answer_chi2_ratio``; default ``AMBIGUITY_CHI2_RATIO``)."""
    k = miss_margin() if margin is None else margin
    out = list(ranked)
    if not out:
        return out, False, {}
    tie = [out[0]] + [b for b in out[1:] if competes(out[0], b, chi2_ratio)]
    misses = {id(a): missed_objects(compiled, camera, a) for a in tie}
    if len(tie) > 1:
        fewest = min(tie, key=lambda a: misses[id(a)])
        if fewest is not out[0] and all(misses[id(b)] - misses[id(fewest)] >= k
                                        for b in tie if b is not fewest):
            out = [fewest] + [b for b in out if b is not fewest]
    best = out[0]
    rivals = [b for b in out[1:] if competes(best, b, chi2_ratio)]
    for b in rivals:
        if id(b) not in misses:
            misses[id(b)] = missed_objects(compiled, camera, b)
    ambiguous = any(misses[id(b)] - misses[id(best)] < k for b in rivals)
    return out, ambiguous, misses
