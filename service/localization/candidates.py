"""Verified candidate poses of ``localize()`` and how they compare: support, distinctness,
ambiguity.

A :class:`Candidate` is a pose that passed verification (refined, or not with
``metric="none"``, and still explaining >= ``min_inliers`` detections at that pose), from the
RANSAC search or from the client's prior. Candidates are ranked by support (inliers, then the
sum of their IoUs, :func:`sort_by_support`), reduced to mutually distinct ones
(:func:`distinct_ranking`), and the best is ambiguous when a distinct runner-up competes with
it (:func:`competes`, the rules of
:func:`quadloc.service.localization.confidence.is_ambiguous`) and the objects it predicts in
view but were not detected do not rule it out
(:func:`quadloc.service.localization.negative_evidence.weigh_misses`). Poses are
``world_from_camera`` (4x4, OpenCV camera axes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from quadloc.factors.arrays import FloatArray
from quadloc.factors.rotations import invert_pose
from quadloc.service.localization.confidence import is_ambiguous
from quadloc.service.localization.refine import RefinementResult
from quadloc.service.localization.search import distinct_poses
from quadloc.service.localization.types import InlierMatch

__all__ = [
    "Candidate",
    "competes",
    "distinct_ranking",
    "iou_competitor",
    "sort_by_support",
]


@dataclass(eq=False)
class Candidate:
    """A verified pose.

    Attributes:
        world_from_camera: 4x4 camera pose in the map (OpenCV camera axes).
        raw_covariance: the refinement's 6x6 ``[omega, v]`` covariance (rad, m; body frame;
            before calibration), None without refinement or when singular.
        inliers: the one-to-one inliers at ``world_from_camera``.
        refinement: the last refinement (None with ``metric="none"``); status: its
            ``LocalizationResult.refinement_status``.
        source: ``"ransac"`` or ``"prior"`` (set by the prior stage).
        capped: an alternative whose refinement stopped at its iteration cap (refined in full
            if it competes).
        copy_but_one: the view of a better candidate's supporting objects but its weakest in
            an exact copy of them (``pipeline._copy_competitors``): one match fewer is no
            evidence between exact copies (a spurious detection can land on an object beyond
            the copied ones), so it competes with one inlier fewer (:func:`competes`).
    """

    world_from_camera: FloatArray
    raw_covariance: FloatArray | None
    inliers: list[InlierMatch]
    refinement: RefinementResult | None
    status: str | None
    source: str = "ransac"
    capped: bool = False
    copy_but_one: bool = False

    @property
    def score(self) -> float:
        """Sum of the inliers' IoUs (the RANSAC score, at the verified pose)."""
        return float(sum(m.iou for m in self.inliers))

    @property
    def chi2(self) -> float:
        """The refinement's chi2 of everything measured: the detections' plus the gravity's
        (NaN without refinement)."""
        res = self.refinement
        return math.nan if res is None else float(res.chi2 + res.gravity_chi2)

    @property
    def n_refined(self) -> int:
        """Number of detections the refinement's chi2 sums over (0 without refinement)."""
        return 0 if self.refinement is None else len(self.refinement.per_detection_cost)

    def chi2_against(self, best: Candidate) -> float:
        """This candidate's chi2 where it compares with ``best``'s (refined over as many
        detections, the same metric); NaN otherwise (the chi2 rules then do not apply)."""
        return self.chi2 if self.n_refined == best.n_refined else math.nan

    def support(self) -> tuple[int, float]:
        """(inlier count, score): the order in which candidates are compared."""
        return len(self.inliers), self.score


def sort_by_support(candidates: list[Candidate]) -> None:
    """Sort in place, best-supported first (inliers, then the sum of their IoUs; the prior's
    candidate wins ties)."""
    candidates.sort(key=lambda a: (*a.support(), a.source == "prior"), reverse=True)


def distinct_ranking(candidates: Sequence[Candidate]) -> list[Candidate]:
    """The candidates (best first) distinct from every better one
    (:func:`quadloc.service.localization.search.distinct_poses`): the ambiguity candidates."""
    ranked: list[Candidate] = []
    for a in candidates:
        if all(distinct_poses(invert_pose(a.world_from_camera), invert_pose(b.world_from_camera))
               for b in ranked):
            ranked.append(a)
    return ranked


def competes(best: Candidate, other: Candidate, chi2_ratio: float | None = None) -> bool:
    """Whether ``other`` (a distinct runner-up) competes with ``best``
    (:func:`quadloc.service.localization.confidence.is_ambiguous`: by refined chi2 when they
    compare, within ``chi2_ratio``, default ``AMBIGUITY_CHI2_RATIO``, else by IoU sum, told
    whether it matches the same map objects), or is an exact copy's view short of one of its
    inliers (``Candidate.copy_but_one``)."""
    if other.copy_but_one and len(other.inliers) + 1 >= len(best.inliers):
        return True
    return is_ambiguous(len(best.inliers), best.score, len(other.inliers), other.score,
                        same_objects={m.object_id for m in other.inliers}
                        == {m.object_id for m in best.inliers},
                        best_chi2=best.chi2, runner_up_chi2=other.chi2_against(best),
                        chi2_ratio=chi2_ratio)


def iou_competitor(a: Candidate, others: Sequence[Candidate]) -> bool:
    """Whether a runner-up whose chi2 does not compare with ``a``'s competes by its IoU sum
    (the part of :func:`competes` that does not depend on the chi2 ratio: with it and
    ``chi2_competitor`` the bench re-decides the ambiguity for another ratio)."""
    return any(competes(a, b) for b in others if b is not a
               and not (math.isfinite(a.chi2) and math.isfinite(b.chi2_against(a))))
