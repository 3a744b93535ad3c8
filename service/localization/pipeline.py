"""``localize()``: relocalization from scratch (paper section V-B) or from a client prior.

Stages (wall time of each in ``LocalizationResult.timings_ms``): ``validate`` (input, compiled
map, usable detections), ``prior`` (only with a :class:`PosePrior`: gated association and
refinement from it; an answer explaining every usable detection is returned at once),
``hypotheses`` (:func:`quadloc.service.localization.search.ransac`), ``refine``
(:func:`quadloc.service.localization.refine.refine` of the best hypothesis and up to
:data:`REFINED_ALTERNATIVES` distinct runners-up, with re-association) and ``assess``
(:mod:`quadloc.service.localization.confidence`: calibrated covariance, confidence, ambiguity).
The time budget (:class:`quadloc.factors.budget.Deadline`) bounds the whole call: no LM iteration
starts after it (``refinement_status == "time_budget"``). Each stage's rules in detail:
``docs/design/localization.md``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.gravity_factor import GravityMeasurement
from quadloc.factors.pose_residuals import expmap_pose3
from quadloc.factors.rotations import invert_pose
from quadloc.maps.compiled import CompiledMap, compile_map
from quadloc.maps.model import SceneMap
from quadloc.service.localization.calibration import MIN_CONFIDENCE, S2_FLOOR
from quadloc.service.localization.confidence import (
    calibrated_covariance,
    calibration_key,
    chi2_competitor,
    confidence_probability,
    covariance_scale,
    evidence_features,
    is_ambiguous,
    residual_variance,
)
from quadloc.service.localization.gravity import (
    answer_gate_deg,
    gravity_measurement,
    tilt_errors_deg,
)
from quadloc.service.localization.refine import RefinementResult, refine
from quadloc.service.localization.sampling import count_samples
from quadloc.service.localization.scoring import (
    HARD_STOP_FACTOR,
    Match,
    MatchScorer,
    ellipse_points,
    greedy_assignment,
    sunflower_disk,
)
from quadloc.service.localization.search import Hypothesis, distinct_poses, ransac
from quadloc.service.localization.types import (
    NO_REFINEMENT,
    Alternative,
    Detection,
    Gravity,
    InlierMatch,
    LocalizationInputError,
    LocalizationOptions,
    LocalizationResult,
    PosePrior,
    check_detections,
)

__all__ = ["localize", "prior_gate_poses", "refine_pose"]

def _validate(
    detections: Sequence[Detection], scene_map: SceneMap | CompiledMap, camera: Camera,
    options: LocalizationOptions, prior: PosePrior | None, gravity: Gravity | None = None,
) -> CompiledMap:
    check_detections(detections)
    for name, value, types, what in (
            ("scene_map", scene_map, (SceneMap, CompiledMap), "a SceneMap or CompiledMap"),
            ("camera", camera, Camera, "a Camera"),
            ("options", options, LocalizationOptions, "LocalizationOptions"),
            ("prior", prior, (PosePrior, type(None)), "a PosePrior or None"),
            ("gravity", gravity, (Gravity, type(None)), "a Gravity or None")):
        if not isinstance(value, types):
            raise LocalizationInputError(f"must be {what}, got {type(value).__name__}",
                                         field=name)
    compiled = compile_map(scene_map)
    if len(compiled) == 0:
        raise LocalizationInputError("the map has no objects", field="scene_map")
    if options.unknown_label_policy == "error":
        for i, d in enumerate(detections):
            if len(compiled.indices_for(d.label)) == 0:
                raise LocalizationInputError(
                    f"{d.label!r} is not a category of the map "
                    f"(unknown_label_policy 'error'; map categories: "
                    f"{', '.join(sorted(set(compiled.categories)))})",
                    field=f"detections[{i}].label")
    return compiled


def _not_localized(reason: str, metric: str, evaluated: int, timings: dict[str, float],
                   t0: float, refinement_status: str | None = None) -> LocalizationResult:
    timings["total"] = (time.perf_counter() - t0) * 1e3
    return LocalizationResult(False, reason, None, None, 0.0, (), metric, evaluated, False,
                              timings, refinement_status)


def refine_pose(
    detections: Sequence[Detection], ellipsoids: Sequence[Ellipsoid], camera: Camera,
    initial_world_from_camera: np.ndarray, options: LocalizationOptions,
    prior: PosePrior | None = None, deadline: Deadline | None = None,
    gravity: GravityMeasurement | None = None,
) -> RefinementResult:
    """:func:`quadloc.service.localization.refine.refine` with the options' metric, sigma, kernel,
    iteration cap and metric options (and the prior as a factor when it has a covariance, and
    the gravity factor); after ``deadline`` (None: no limit) no LM iteration starts."""
    return refine(
        detections, ellipsoids, camera, initial_world_from_camera, options.metric,
        use_sigma=options.use_sigma, robust=options.robust, robust_scale=options.robust_scale,
        prior_world_from_camera=None if prior is None or prior.covariance is None
        else prior.world_from_camera,
        prior_covariance=None if prior is None else prior.covariance, gravity=gravity,
        max_iterations=options.max_iterations,
        metric_options=dict(options.metric_options) if options.metric_options else None,
        deadline=deadline)


def _pairs(matches: Sequence[Match]) -> set[tuple[int, int]]:
    return {(m.detection_index, m.object_index) for m in matches}


def _refine_and_verify(
    matches: Sequence[Match], detections: Sequence[Detection], scorer: MatchScorer,
    world_from_camera: np.ndarray, options: LocalizationOptions, prior: PosePrior | None,
    deadline: Deadline | None, gravity: GravityMeasurement | None,
) -> tuple[_Answer | None, str | None]:
    """Refine on ``matches`` (with the scorer's map and camera), re-associate, refine again if
    the set changed (and the deadline has not passed). Returns (the answer, or None if the
    result fails the inlier check; the refinement status — see
    ``LocalizationResult.refinement_status`` — or None with ``metric="none"``)."""
    thr, compiled = options.inlier_iou, scorer.compiled
    if options.metric == NO_REFINEMENT:
        final = scorer.matches(invert_pose(world_from_camera), thr)
        if len(final) < options.min_inliers:
            return None, None
        return _Answer(world_from_camera, None, [
            InlierMatch(m.detection_index, compiled.object_ids[m.object_index], m.iou,
                        1.0 - m.iou) for m in final], None, None), None
    current = list(matches)
    T = world_from_camera
    for round_ in range(2):
        res = refine_pose([detections[m.detection_index] for m in current],
                          [compiled.ellipsoids[m.object_index] for m in current],
                          scorer.camera, T, options, prior, deadline, gravity)
        status = "time_budget" if res.resample_skipped else res.status
        if res.status in ("diverged", "invalid_projection") or not np.all(
                np.isfinite(res.world_from_camera)):
            return None, status
        T = res.world_from_camera
        new = scorer.matches(invert_pose(T), thr)
        if _pairs(new) == _pairs(current) or len(new) < options.min_inliers or round_ == 1:
            break
        if deadline_passed(deadline):
            status = "time_budget"  # the changed inlier set is not refined again
            break
        current = new
    cost = {(m.detection_index, m.object_index): float(c)
            for m, c in zip(current, res.per_detection_cost, strict=True)}
    inliers = [InlierMatch(m.detection_index, compiled.object_ids[m.object_index], m.iou,
                           cost[(m.detection_index, m.object_index)])
               for m in new if (m.detection_index, m.object_index) in cost]
    if len(inliers) < options.min_inliers:
        return None, status
    return _Answer(T, res.covariance, inliers, res, status), status


@dataclass(eq=False)
class _Answer:
    """A verified pose: ``world_from_camera``, raw covariance, inliers, the refinement (None
    with ``metric="none"``) and its status; ``source`` is set by ``localize``."""

    world_from_camera: np.ndarray
    raw_covariance: np.ndarray | None
    inliers: list[InlierMatch]
    refinement: RefinementResult | None
    status: str | None
    source: str = "ransac"
    capped: bool = False  # an alternative whose refinement stopped at its iteration cap

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

    def chi2_against(self, best: _Answer) -> float:
        """This answer's chi2 where it compares with ``best``'s (refined over as many
        detections, the same metric); NaN otherwise (the chi2 rules then do not apply)."""
        return self.chi2 if self.n_refined == best.n_refined else math.nan

    def support(self) -> tuple[int, float]:
        """(inlier count, score): the order in which answers are compared."""
        return len(self.inliers), self.score


def _competes(best: _Answer, other: _Answer) -> bool:
    """Whether ``other`` (a distinct runner-up) competes with ``best``
    (:func:`quadloc.service.localization.confidence.is_ambiguous`: by refined chi2 when they
    compare, else by IoU sum, told whether it matches the same map objects)."""
    return is_ambiguous(len(best.inliers), best.score, len(other.inliers), other.score,
                        same_objects={m.object_id for m in other.inliers}
                        == {m.object_id for m in best.inliers},
                        best_chi2=best.chi2, runner_up_chi2=other.chi2_against(best))


def _is_ambiguous_answer(ranked: Sequence[_Answer]) -> bool:
    """Whether some distinct runner-up of ``ranked`` (best first, mutually distinct) competes
    with the best (:func:`_competes`)."""
    return any(_competes(ranked[0], b) for b in ranked[1:])


def _iou_competitor(a: _Answer, others: Sequence[_Answer]) -> bool:
    """Whether a runner-up whose chi2 does not compare with ``a``'s competes by its IoU sum
    (the part of :func:`_competes` that does not depend on the chi2 ratio: with it and
    ``chi2_competitor`` the bench re-decides the ambiguity for another ratio)."""
    return any(_competes(a, b) for b in others if b is not a
               and not (math.isfinite(a.chi2) and math.isfinite(b.chi2_against(a))))


#: Alternatives (beyond the best) refined for the ambiguity check, and the RANSAC score ratio
#: below which an alternative is not worth refining (a refinement changes the sum of IoUs by
#: far less than this).
REFINED_ALTERNATIVES = 2
ALTERNATIVE_PREFILTER_RATIO = 0.5
#: LM iteration cap of an alternative's refinement (a capped alternative that competes is then
#: refined in full from where it stopped; measurements: ``docs/design/localization.md``).
ALTERNATIVE_MAX_ITERATIONS = 15
#: Prior gating: the association at the prior pose also tries the poses at +-
#: ``PRIOR_GATE_SIGMAS`` standard deviations along each principal axis of the prior's
#: covariance (a pair is kept at its best IoU over these poses).
PRIOR_GATE_SIGMAS = 2.0
#: An alternative whose matches are a subset of the best hypothesis' is not refined when the
#: best has at least this many matches (``_same_explanation``).
SAME_EXPLANATION_MIN_MATCHES = 4


def _same_explanation(alternative: Hypothesis, best: Hypothesis) -> bool:
    """Whether ``alternative`` only re-uses the best hypothesis' correspondences (its matches
    are a subset of the best's) while the best has >= :data:`SAME_EXPLANATION_MIN_MATCHES`
    (its refinement then converges to the best's pose: not distinct)."""
    if len(best.matches) < SAME_EXPLANATION_MIN_MATCHES:
        return False
    return _pairs(alternative.matches) <= _pairs(best.matches)


def prior_gate_poses(prior: PosePrior) -> np.ndarray:
    """``world_from_camera`` poses (H, 4, 4) at which the prior's associations are gated: the
    prior pose, and with a covariance the poses ``T Exp(+-g sqrt(lambda_k) e_k)`` along each
    principal axis (eigenvector ``e_k``, eigenvalue ``lambda_k``; tangent ``[omega, v]``, body
    frame, right perturbation) with ``g = PRIOR_GATE_SIGMAS``."""
    T = np.asarray(prior.world_from_camera, dtype=float)
    poses = [T]
    if prior.covariance is not None:
        lam, vec = np.linalg.eigh(np.asarray(prior.covariance, dtype=float))
        for k in range(6):
            step = PRIOR_GATE_SIGMAS * math.sqrt(max(float(lam[k]), 0.0)) * vec[:, k]
            poses += [T @ expmap_pose3(step), T @ expmap_pose3(-step)]
    return np.array(poses)


def _prior_matches(scorer: MatchScorer, prior: PosePrior, threshold: float) -> list[Match]:
    """One-to-one matches gated by the prior: each pair's best IoU over
    :func:`prior_gate_poses` (projected-ellipse gating under the prior's uncertainty)."""
    cw = np.array([invert_pose(T) for T in prior_gate_poses(prior)])
    pts = ellipse_points(scorer.params, sunflower_disk(256))
    dense = scorer.dense_iou(cw, pts).max(axis=0)
    return greedy_assignment(dense, scorer.detection_indices, threshold)


def localize(
    detections: Sequence[Detection],
    scene_map: SceneMap | CompiledMap,
    camera: Camera,
    options: LocalizationOptions = LocalizationOptions(),  # noqa: B008 (frozen, immutable)
    prior: PosePrior | None = None,
    gravity: Gravity | None = None,
) -> LocalizationResult:
    """Estimate the camera pose from object detections (see the module docstring).

    Args:
        detections: the image's detections (ellipses in px, labels, optional sigma / score).
        scene_map: the map (world frame, metres), or its :class:`CompiledMap`.
        camera: intrinsics and image size of the image.
        options: :class:`LocalizationOptions`.
        prior: optional client pose prior (``world_from_camera``, optional covariance).
        gravity: optional measured gravity direction (camera axes): a factor on the pose's
            tilt in every refinement; candidates whose tilt disagrees with it are dropped, and
            an answer that disagrees is not localized (reason ``gravity_mismatch``; a prior's
            answer that disagrees leaves the search from scratch to decide)
            (:mod:`quadloc.service.localization.gravity`).

    Returns:
        :class:`LocalizationResult`; ``localized=False`` with a ``reason`` is a normal answer.

    Raises:
        LocalizationInputError: (a ``ValueError``) bad input, the message names the field.
        ScoringTimeoutError: scoring ran past 1.05 x ``time_budget_ms`` (huge map x detections).
    """
    t0 = time.perf_counter()
    cpu0 = time.thread_time()  # the budget counts this thread's CPU time (quadloc.factors.budget)
    timings: dict[str, float] = {}
    compiled = _validate(detections, scene_map, camera, options, prior, gravity)
    metric = options.metric
    if options.use_sigma and any(d.sigma is None for d in detections):
        # sigma weights only when every detection has a sigma: mixed weights would have no
        # calibrated covariance or confidence (confidence.calibration_key)
        options = replace(options, use_sigma=False)
    key = calibration_key(metric, options.use_sigma)
    usable = [i for i, d in enumerate(detections) if len(compiled.indices_for(d.label)) > 0]
    t1 = time.perf_counter()
    timings["validate"] = (t1 - t0) * 1e3
    if len(detections) < 2:
        return _not_localized("too_few_detections", metric, 0, timings, t0)
    if len(usable) < 2:
        return _not_localized("no_label_match", metric, 0, timings, t0)
    # CPU time of this thread, with a wall-clock hard limit (quadloc.factors.budget); the scorer
    # raises ScoringTimeoutError past HARD_STOP_FACTOR x the budget
    deadline = Deadline.cpu_budget(options.time_budget_ms, cpu_start=cpu0, wall_start=t0)
    scorer = MatchScorer(compiled, camera, [detections[i].ellipse for i in usable],
                         [detections[i].label for i in usable], usable,
                         deadline=Deadline.cpu_budget(options.time_budget_ms, HARD_STOP_FACTOR,
                                                      cpu_start=cpu0, wall_start=t0))
    evaluated = 0
    n_samples = count_samples(scorer, 2)
    up_world = compiled.scene_map.up
    measured = None if gravity is None else gravity_measurement(gravity, up_world)

    def tilt_deg(a: _Answer) -> float:
        """The answer's tilt error against the measured gravity (degrees; NaN without)."""
        if gravity is None:
            return math.nan
        return float(tilt_errors_deg(a.world_from_camera[:3, :3].T, up_world, gravity))

    def against_gravity(a: _Answer) -> bool:
        return gravity is not None and not tilt_deg(a) <= answer_gate_deg(gravity)

    def assess(a: _Answer, runner_up: _Answer | None, others: Sequence[_Answer] = ()
               ) -> tuple[float, dict[str, float], np.ndarray | None]:
        """(confidence, evidence, calibrated covariance) of an answer (``others``: the distinct
        alternatives, for its ``chi2_competitor``)."""
        res = a.refinement
        s2 = math.nan if res is None else residual_variance(res.chi2, res.n_residuals)
        n_refined = 0 if res is None else len(res.per_detection_cost)
        cov = None if res is None else calibrated_covariance(
            key, a.raw_covariance, res.chi2, res.n_residuals, n_refined, res.fixed_information)
        margin = 0.0 if runner_up is None else min(1.0, runner_up.score / max(a.score, 1e-12))
        ev = evidence_features(n_inliers=len(a.inliers), n_usable=len(usable),
                               ious=np.array([m.iou for m in a.inliers]), s2=s2,
                               covariance=cov, margin=margin, n_samples=n_samples,
                               s2_floor=S2_FLOOR.get(key, 0.0),
                               chi2_ratio_log=chi2_competitor(
                                   a.chi2, len(a.inliers),
                                   [(b.chi2_against(a), len(b.inliers))
                                    for b in others if b is not a]),
                               gravity=gravity is not None)
        scale = math.nan if res is None else covariance_scale(key, res.chi2, res.n_residuals,
                                                              n_refined)
        extra = {"s2": s2, "cov_scale": scale, "n_refined": float(n_refined),
                 "iou_competitor": float(_iou_competitor(a, others))}
        if gravity is not None:
            extra["tilt_error_deg"] = tilt_deg(a)
        return confidence_probability(key, ev), {**ev, **extra}, cov

    def finish(a: _Answer, ranked: list[_Answer], ambiguous: bool) -> LocalizationResult:
        runner_up = next((b for b in ranked if b is not a), None)
        conf, ev, cov = assess(a, runner_up, ranked)
        alternatives: tuple[Alternative, ...] = ()
        floor = MIN_CONFIDENCE if options.min_confidence is None else options.min_confidence
        # (the answer fails the gravity gate only when every candidate does)
        reason = ("gravity_mismatch" if against_gravity(a)
                  else "ambiguous" if ambiguous and options.on_ambiguity == "not_localized"
                  else "low_confidence" if conf < floor else None)
        if ambiguous or reason is not None:  # the candidates, each with its probability
            alternatives = tuple(
                Alternative(b.world_from_camera,
                            assess(b, a if b is not a else runner_up, ranked)[0],
                            len(b.inliers), b.score) for b in ranked)
        timings["total"] = (time.perf_counter() - t0) * 1e3
        if reason is not None:
            return LocalizationResult(False, reason, None, None, 0.0, (), metric, evaluated,
                                      False, timings, a.status, None, alternatives,
                                      ev if reason == "ambiguous" else {**ev, "confidence": conf})
        return LocalizationResult(
            True, None, np.array(a.world_from_camera, dtype=float), cov, conf,
            tuple(sorted(a.inliers, key=lambda m: m.detection_index)), metric, evaluated,
            a.source == "prior", timings, a.status, a.source, alternatives, ev)

    prior_answer: _Answer | None = None
    if prior is not None:
        evaluated += 1
        tp = time.perf_counter()
        matches = _prior_matches(scorer, prior, options.inlier_iou)
        if len(matches) >= options.min_inliers:
            prior_answer, _ = _refine_and_verify(matches, detections, scorer,
                                                 prior.world_from_camera, options, prior, deadline,
                                                 measured)
            if prior_answer is not None and against_gravity(prior_answer):
                prior_answer = None  # the search from scratch decides
        timings["prior"] = (time.perf_counter() - tp) * 1e3
        if prior_answer is not None:
            prior_answer.source = "prior"
            if len(prior_answer.inliers) >= len(usable):  # every usable detection explained
                return finish(prior_answer, [prior_answer], False)

    th = time.perf_counter()
    rng = np.random.default_rng(options.seed)
    outcome = ransac(scorer, up_world, inlier_iou=options.inlier_iou,
                     min_inliers=options.min_inliers,
                     max_hypotheses=options.ransac_max_hypotheses, rng=rng, deadline=deadline)
    evaluated += outcome.hypotheses_evaluated
    timings["hypotheses"] = (time.perf_counter() - th) * 1e3
    if outcome.camera_from_world is None:
        if prior_answer is not None:
            return finish(prior_answer, [prior_answer], False)
        return _not_localized(outcome.reason or "no_hypothesis_above_inlier_threshold", metric,
                              evaluated, timings, t0)
    tr = time.perf_counter()
    hyps = list(outcome.alternatives) or [
        Hypothesis(outcome.camera_from_world, outcome.matches, outcome.score)]
    answers: list[_Answer] = []
    first_status: str | None = None
    alternative_options = replace(
        options, max_iterations=min(options.max_iterations, ALTERNATIVE_MAX_ITERATIONS))
    for k, h in enumerate(hyps[:1 + REFINED_ALTERNATIVES]):
        if k > 0 and (h.score < ALTERNATIVE_PREFILTER_RATIO * hyps[0].score
                      or deadline_passed(deadline)):
            break
        if k > 0 and _same_explanation(h, hyps[0]):
            continue  # refines to the best's pose: not a competitor (see _same_explanation)
        got, status = _refine_and_verify(
            list(outcome.matches if k == 0 else h.matches), detections, scorer,
            invert_pose(h.camera_from_world), options if k == 0 else alternative_options, None,
            deadline, measured)
        if k == 0:
            first_status = status
        if got is not None:
            got.capped = (k > 0 and status == "max_iterations"
                          and alternative_options.max_iterations < options.max_iterations)
            answers.append(got)
    if prior_answer is not None:
        answers.append(prior_answer)

    def order(candidates: list[_Answer]) -> None:
        """Best-supported first (inliers, then the sum of their IoUs; the prior wins ties)."""
        candidates.sort(key=lambda a: (*a.support(), a.source == "prior"), reverse=True)

    order(answers)
    # capped alternatives that compete (as many inliers as the first answer: they may rank
    # first, and they are the only runners-up the ambiguity check weighs) are refined in full
    # from where they stopped; one that then fails verification keeps its capped result
    while pending := [a for a in answers
                      if a.capped and len(a.inliers) >= len(answers[0].inliers)]:
        answers = [a for a in answers if a not in pending]  # identity (eq=False)
        for a in pending:
            full, _ = _refine_and_verify(
                [Match(m.detection_index, compiled.index_of(m.object_id), m.iou)
                 for m in a.inliers], detections, scorer, a.world_from_camera, options, None,
                deadline, measured)
            a.capped = False
            answers.append(a if full is None else full)
        order(answers)
    timings["refine"] = (time.perf_counter() - tr) * 1e3
    # an answer whose tilt the measured gravity rules out cannot be correct (gravity module):
    # it is no candidate while another is left
    answers = [a for a in answers if not against_gravity(a)] or answers
    if not answers:
        return _not_localized("refinement_diverged", metric, evaluated, timings, t0,
                              first_status)
    # keep only answers distinct from every better one (the ambiguity candidates)
    ranked: list[_Answer] = []
    for a in answers:
        if all(distinct_poses(invert_pose(a.world_from_camera), invert_pose(b.world_from_camera))
               for b in ranked):
            ranked.append(a)
    return finish(ranked[0], ranked, _is_ambiguous_answer(ranked))
