"""``localize()``: relocalization from scratch (paper section V-B) or from a client prior.

Stages (wall time of each in ``LocalizationResult.timings_ms``), one function each:
``validate`` (:func:`_validate`: input, compiled map, usable detections), ``prior``
(:func:`_prior_stage`, only with a :class:`PosePrior`: gated association and refinement from
it; an answer explaining every usable detection is returned at once), ``hypotheses``
(:func:`_search_stage`: :func:`quadloc.service.localization.search.ransac`), ``refine``
(:func:`_refine_stage`: :func:`quadloc.service.localization.refine.refine` of the best
hypothesis and up to :data:`REFINED_ALTERNATIVES` distinct runners-up, with re-association,
each verified into a :class:`quadloc.service.localization.candidates.Candidate`) and ``assess``
(:func:`_answer`: the :class:`Assessment` of the best candidate — calibrated covariance,
confidence, evidence, :mod:`quadloc.service.localization.confidence` — and the ambiguity
check). The time budget (:class:`quadloc.factors.budget.Deadline`) bounds the whole call: no LM
iteration starts after it (``refinement_status == "time_budget"``). Each stage's rules in
detail: ``docs/design/localization.md``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray, IntArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.gravity_factor import GravityMeasurement
from quadloc.factors.pose_residuals import expmap_pose3
from quadloc.factors.rotations import invert_pose
from quadloc.maps.compiled import CompiledMap, compile_map, compiled_subset
from quadloc.maps.model import SceneMap
from quadloc.maps.places import place_index
from quadloc.service.limits import NO_REFINEMENT
from quadloc.service.localization.calibration import S2_FLOOR
from quadloc.service.localization.calibration_fit import (
    CalibrationConstants,
    map_calibration_applies,
)
from quadloc.service.localization.candidates import (
    Candidate,
    competes,
    distinct_ranking,
    iou_competitor,
    sort_by_support,
)
from quadloc.service.localization.confidence import (
    calibrated_covariance,
    calibration_key,
    chi2_competitor,
    confidence_probability,
    covariance_scale,
    evidence_features,
    residual_variance,
)
from quadloc.service.localization.constellations import (
    PLACE_SEARCH_MIN_OBJECTS,
    PlaceSeeds,
    place_seeds,
)
from quadloc.service.localization.copies import COPY_TOLERANCE_M, copy_transforms, is_copy
from quadloc.service.localization.gravity import (
    answer_gate_deg,
    gravity_measurement,
    tilt_errors_deg,
)
from quadloc.service.localization.negative_evidence import weigh_misses
from quadloc.service.localization.refine import RefinementResult, refine
from quadloc.service.localization.sampling import count_map_samples, count_samples
from quadloc.service.localization.scoring import (
    HARD_STOP_FACTOR,
    Match,
    MatchScorer,
    ellipse_points,
    greedy_assignment,
    sunflower_disk,
)
from quadloc.service.localization.search import (
    KEEP_DISTINCT,
    Hypothesis,
    RansacOutcome,
    competitor_sweep,
    distinct_poses,
    ransac,
)
from quadloc.service.localization.types import (
    Alternative,
    Detection,
    Gravity,
    InlierMatch,
    LocalizationInputError,
    LocalizationOptions,
    LocalizationResult,
    PlaceHint,
    PosePrior,
    check_detections,
)

__all__ = ["Assessment", "localize", "prior_gate_poses", "refine_pose"]

#: Alternatives (beyond the best) refined for the ambiguity check, and the RANSAC score ratio
#: below which an alternative is not worth refining (a refinement changes the sum of IoUs by
#: far less than this).
REFINED_ALTERNATIVES = 2
ALTERNATIVE_PREFILTER_RATIO = 0.5
#: A large map's search (places) keeps this many distinct hypotheses and refines, beyond the
#: :data:`REFINED_ALTERNATIVES` runners-up, those scoring at least :data:`PLACE_TIE_RATIO` of
#: the best: the candidate places of an ambiguous answer (exact copies of a room), at most
#: this many listed, best-supported first.
PLACE_CANDIDATES = 6
PLACE_TIE_RATIO = 0.9
#: LM iteration cap of an alternative's refinement (a capped alternative that competes is then
#: refined in full from where it stopped; measurements: ``docs/design/localization.md``).
ALTERNATIVE_MAX_ITERATIONS = 15
#: The shipped calibration constants (a map without its own calibration).
SHIPPED_CALIBRATION = CalibrationConstants.shipped()
#: An answer with more inliers than this whose supporting objects have no exact copy is
#: checked again without its weakest match, whose copies then compete with one inlier fewer
#: (``Candidate.copy_but_one``). 4: a copy of the 4 or more objects left is a room's copy; 3
#: objects of a label set recur by chance in a map of thousands (1,000 random rooms: good
#: 4-5 detection answers turned ambiguous).
COPY_BUT_ONE_MIN_INLIERS = 4
#: Prior gating: the association at the prior pose also tries the poses at +-
#: ``PRIOR_GATE_SIGMAS`` standard deviations along each principal axis of the prior's
#: covariance (a pair is kept at its best IoU over these poses).
PRIOR_GATE_SIGMAS = 2.0
#: An alternative whose matches are a subset of the best hypothesis' is not refined when the
#: best has at least this many matches (``_same_explanation``).
SAME_EXPLANATION_MIN_MATCHES = 4
#: A position hint settles a tie between places in favour of the most likely one when every
#: other is at least this many times less likely under the hint (:func:`_hint_ranking`).
HINT_PRIOR_RATIO = 20.0
#: ... over every place the search found with at least this share of the best seed's support
#: (camera centres further than ``HINT_SAME_PLACE_M`` from the chosen one's).
HINT_SEED_SUPPORT = 0.8
HINT_SAME_PLACE_M = 1.0


@dataclass(frozen=True)
class Assessment:
    """What ``localize`` reports about a candidate (:func:`_assess`).

    Attributes:
        confidence: probability in [0, 1] that the pose is within the confidence tolerance
            (:func:`quadloc.service.localization.confidence.confidence_probability`).
        evidence: the confidence model's features plus diagnostics (``s2``, ``cov_scale``,
            ``n_refined``, ``iou_competitor``, with gravity ``tilt_error_deg``).
        covariance: the calibrated 6x6 ``[omega, v]`` covariance (rad, m; body frame), None
            without refinement or when singular.
    """

    confidence: float
    evidence: dict[str, float]
    covariance: FloatArray | None


@dataclass
class _Solve:
    """One ``localize`` call after validation: what every later stage reads (and the two
    things they add to: ``evaluated``, ``timings``).

    Attributes:
        detections: the request's detections; usable: indices of those with a map label.
        options: the options in effect (``use_sigma`` off unless every detection has a sigma).
        calibration_key: :func:`quadloc.service.localization.confidence.calibration_key`.
        calibration: the map's own calibration constants when they apply to the key
            (:func:`map_calibration_applies`), else None (the shipped constants).
        scorer: the usable detections' scorer (its deadline: the hard stop).
        deadline: the budget (CPU time with a wall-clock hard limit); None: no budget.
        gravity, measured_gravity: the client's gravity and its factor input (or None).
        up_world: the map's up axis (3,).
        n_samples: label-compatible P2E samples (an evidence feature).
        t0: ``time.perf_counter()`` at the start of the call, s.
        hinted: the best hypothesis of a place hint's places, refined besides the search's.
        places: whether the map was searched by places (:func:`_place_stage`): up to
            :data:`PLACE_CANDIDATES` candidates.
        whole: the whole map when it was searched by places (the scorer's map is then the
            places kept), else None.
        hint_samples: with a place hint on such a map, the label-compatible samples of the
            hint's places only: an answer that agrees with the hint has its chance matches
            counted there (its confidence is conditional on the hint), not in the whole map.
        evaluated: candidate poses scored so far; timings: wall ms per stage.
    """

    detections: Sequence[Detection]
    usable: list[int]
    options: LocalizationOptions
    calibration_key: str
    scorer: MatchScorer
    calibration: CalibrationConstants | None
    deadline: Deadline | None
    gravity: Gravity | None
    measured_gravity: GravityMeasurement | None
    up_world: FloatArray
    n_samples: int
    t0: float
    timings: dict[str, float] = field(default_factory=dict)
    evaluated: int = 0
    hinted: Hypothesis | None = None
    places: bool = False
    whole: CompiledMap | None = None
    hint_samples: int | None = None

    @property
    def constants(self) -> CalibrationConstants:
        """The calibration constants in effect: the map's own, else the shipped ones."""
        return self.calibration or SHIPPED_CALIBRATION


def localize(
    detections: Sequence[Detection],
    scene_map: SceneMap | CompiledMap,
    camera: Camera,
    options: LocalizationOptions = LocalizationOptions(),  # noqa: B008 (frozen, immutable)
    prior: PosePrior | None = None,
    gravity: Gravity | None = None,
    calibration: CalibrationConstants | None = None,
    hint: PlaceHint | None = None,
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
        calibration: the map's own calibration (``quadloc calibrate``;
            :mod:`quadloc.service.localization.map_calibration`): its covariance scale, s^2
            floor, confidence model and default ``min_confidence`` replace the shipped ones for
            the calibration keys it was fitted for; None: the shipped constants.
        hint: optional coarse place hint (:class:`PlaceHint`): weights the search of a large
            map and settles an ambiguity between places in its favour (:func:`_hint_ranking`).

    Returns:
        :class:`LocalizationResult`; ``localized=False`` with a ``reason`` is a normal answer.

    Raises:
        LocalizationInputError: (a ``ValueError``) bad input, the message names the field.
        ScoringTimeoutError: scoring ran past 1.05 x ``time_budget_ms`` (huge map x detections).
    """
    t0 = time.perf_counter()
    cpu0 = time.thread_time()  # the budget counts this thread's CPU time (quadloc.factors.budget)
    timings: dict[str, float] = {}
    compiled, options, usable = _validate(detections, scene_map, camera, options, prior,
                                          gravity, hint)
    timings["validate"] = (time.perf_counter() - t0) * 1e3
    if len(detections) < 2:
        return _not_localized("too_few_detections", options.metric, 0, timings, t0)
    if len(usable) < 2:
        return _not_localized("no_label_match", options.metric, 0, timings, t0)
    seeds: PlaceSeeds | None = None
    whole = compiled
    hinted: BoolArray | None = None
    if len(compiled) >= PLACE_SEARCH_MIN_OBJECTS and len(usable) >= 3:
        hinted = None if hint is None else _hinted_objects(compiled, hint)
        compiled, seeds = _place_stage(detections, usable, compiled, camera, options, t0, cpu0,
                                       timings, hinted)
        if seeds is None:
            return _not_localized("no_hypothesis_above_inlier_threshold", options.metric, 0,
                                  timings, t0)
        usable = [i for i in usable if len(compiled.indices_for(detections[i].label)) > 0]
        if len(usable) < 2:
            return _not_localized("no_label_match", options.metric, 0, timings, t0)
    solve = _start(detections, usable, compiled, camera, options, gravity, t0, cpu0, timings,
                   calibration)
    if seeds is not None:  # the chance matches of the whole map, not of the places kept
        labels = [detections[i].label for i in usable]
        solve.n_samples = count_map_samples(whole, labels, 2)
        solve.places = True
        solve.whole = whole
        if hinted is not None and hinted.any():
            solve.hint_samples = count_map_samples(
                compiled_subset(whole, np.flatnonzero(hinted)), labels, 2)
    prior_candidate = None if prior is None else _prior_stage(solve, prior)
    if prior_candidate is not None and len(prior_candidate.inliers) >= len(usable):
        return _answer(solve, prior_candidate, [prior_candidate], ambiguous=False)
    room = None
    if hint is not None and hinted is not None and _room_hint(hinted):
        hint_ids = {whole.object_ids[k] for k in np.flatnonzero(hinted).tolist()}
        room = np.array([k for k, o in enumerate(compiled.object_ids) if o in hint_ids],
                        dtype=np.intp)
    outcome = _search_stage(solve, seeds, hint, room)
    if outcome.camera_from_world is None:
        if prior_candidate is not None:
            return _answer(solve, prior_candidate, [prior_candidate], ambiguous=False)
        return _not_localized(outcome.reason or "no_hypothesis_above_inlier_threshold",
                              options.metric, solve.evaluated, timings, t0)
    candidates, first_status = _refine_stage(solve, outcome, prior_candidate)
    # a candidate whose tilt the measured gravity rules out cannot be correct (gravity
    # module): it is no candidate while another is left
    candidates = [a for a in candidates if not _against_gravity(solve, a)] or candidates
    if not candidates:
        return _not_localized("refinement_diverged", options.metric, solve.evaluated, timings,
                              t0, first_status)
    # the places compared with the detections, then with the objects each predicts in view
    # that were not detected (negative evidence: a tie between places broken by the misses)
    ranked = distinct_ranking(candidates)
    # a place-search answer of a minimal sample of inliers is held to a larger chi2 ratio
    ratio = solve.constants.answer_chi2_ratio(solve.places, len(ranked[0].inliers))
    ranked, ambiguous, _ = weigh_misses(ranked, whole, camera, chi2_ratio=ratio)
    if ambiguous and hint is not None:
        ranked, ambiguous, _ = weigh_misses(_hint_ranking(ranked, hint, seeds, ratio), whole,
                                            camera, chi2_ratio=ratio)
    if solve.hint_samples is not None and hint is not None and hint.agrees(
            ranked[0].world_from_camera, [m.object_id for m in ranked[0].inliers]):
        solve.n_samples = solve.hint_samples  # chance matches within the hint's places
    return _answer(solve, ranked[0], ranked, ambiguous=ambiguous)


def _hypothesis_agrees(solve: _Solve, h: Hypothesis, hint: PlaceHint) -> bool:
    """:meth:`PlaceHint.agrees` of a search hypothesis (its pose, its matches' objects)."""
    ids = solve.scorer.compiled.object_ids
    return hint.agrees(invert_pose(h.camera_from_world), [ids[m.object_index] for m in h.matches])


def _hint_ranking(ranked: list[Candidate], hint: PlaceHint, seeds: PlaceSeeds | None = None,
                  chi2_ratio: float | None = None) -> list[Candidate]:
    """``ranked`` (best first, mutually distinct, ambiguous) with the hint's say: among the
    best and the runners-up that compete with it (the tie the evidence cannot break), those
    where the hint says (:meth:`PlaceHint.agrees`) are kept, best-supported first, and the
    others of the tie dropped; the candidates the evidence already ranks below the tie are kept
    after them. Unchanged when no candidate of the tie agrees with the hint (the evidence
    rules: a hint never forces an answer the detections do not support). A position hint keeps
    only the most likely of them, and only when every other place the search found about as
    well supported (the candidates of the tie, and the ``seeds`` of a large map with at least
    :data:`HINT_SEED_SUPPORT` of the best seed's support) is :data:`HINT_PRIOR_RATIO` times
    less likely under the hint; else the ranking is unchanged (still ambiguous).
    ``chi2_ratio``: of the tie (:func:`competes`; the best's ratio,
    ``confidence.answer_chi2_ratio``)."""
    tie = [ranked[0]] + [b for b in ranked[1:] if competes(ranked[0], b, chi2_ratio)]
    agree = [a for a in tie if hint.agrees(a.world_from_camera,
                                            [m.object_id for m in a.inliers])]
    if not agree:
        return ranked
    if hint.position is not None and hint.sigma_m is not None:
        position, var2 = hint.position, 2.0 * hint.sigma_m ** 2

        def nll(centre: FloatArray) -> float:
            return float(np.sum((centre - position) ** 2)) / var2

        best = min(agree, key=lambda a: nll(a.world_from_camera[:3, 3]))
        centre = best.world_from_camera[:3, 3]
        others = [a.world_from_camera[:3, 3] for a in tie if a is not best]
        if seeds is not None and len(seeds.poses):
            good = seeds.hits >= HINT_SEED_SUPPORT * seeds.hits.max()
            others += list(invert_pose(seeds.poses[good])[:, :3, 3])
        rivals = [c for c in others if np.linalg.norm(c - centre) > HINT_SAME_PLACE_M]
        if any(nll(c) - nll(centre) < math.log(HINT_PRIOR_RATIO) for c in rivals):
            return ranked
        agree = [best]
    return agree + [b for b in ranked if all(b is not t for t in tie)]


# ------------------------------------------------------------------ validate


def _validate(
    detections: Sequence[Detection], scene_map: SceneMap | CompiledMap, camera: Camera,
    options: LocalizationOptions, prior: PosePrior | None, gravity: Gravity | None = None,
    hint: PlaceHint | None = None,
) -> tuple[CompiledMap, LocalizationOptions, list[int]]:
    """The ``validate`` stage: checks the input (raises :class:`LocalizationInputError` naming
    the field), compiles the map; returns it, the options in effect (sigma weights only when
    every detection has a sigma: mixed weights would have no calibrated covariance or
    confidence, ``confidence.calibration_key``) and the indices of the usable detections
    (label with objects in the map)."""
    check_detections(detections)
    for name, value, types, what in (
            ("scene_map", scene_map, (SceneMap, CompiledMap), "a SceneMap or CompiledMap"),
            ("camera", camera, Camera, "a Camera"),
            ("options", options, LocalizationOptions, "LocalizationOptions"),
            ("prior", prior, (PosePrior, type(None)), "a PosePrior or None"),
            ("gravity", gravity, (Gravity, type(None)), "a Gravity or None"),
            ("hint", hint, (PlaceHint, type(None)), "a PlaceHint or None")):
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
    if options.use_sigma and any(d.sigma is None for d in detections):
        options = replace(options, use_sigma=False)
    usable = [i for i, d in enumerate(detections) if len(compiled.indices_for(d.label)) > 0]
    return compiled, options, usable


def _start(
    detections: Sequence[Detection], usable: list[int], compiled: CompiledMap, camera: Camera,
    options: LocalizationOptions, gravity: Gravity | None, t0: float, cpu0: float,
    timings: dict[str, float], calibration: CalibrationConstants | None = None,
) -> _Solve:
    """The state of a validated call started at ``t0`` (``time.perf_counter()``, s) and
    ``cpu0`` (``time.thread_time()``, s): the budget (CPU time of this thread, with a wall-clock
    hard limit: :meth:`quadloc.factors.budget.Deadline.cpu_budget`) and the scorer, which raises
    ``ScoringTimeoutError`` past ``HARD_STOP_FACTOR`` x the budget."""
    deadline = Deadline.cpu_budget(options.time_budget_ms, cpu_start=cpu0, wall_start=t0)
    scorer = MatchScorer(compiled, camera, [detections[i].ellipse for i in usable],
                         [detections[i].label for i in usable], usable,
                         deadline=Deadline.cpu_budget(options.time_budget_ms, HARD_STOP_FACTOR,
                                                      cpu_start=cpu0, wall_start=t0))
    n_samples = count_samples(scorer, 2)
    up_world = compiled.scene_map.up
    key = calibration_key(options.metric, options.use_sigma)
    return _Solve(
        detections=detections, usable=usable, options=options, calibration_key=key,
        calibration=calibration if map_calibration_applies(calibration, key) else None,
        scorer=scorer,
        deadline=deadline, gravity=gravity,
        measured_gravity=None if gravity is None else gravity_measurement(gravity, up_world),
        up_world=up_world, n_samples=n_samples, t0=t0, timings=timings)


def _not_localized(reason: str, metric: str, evaluated: int, timings: dict[str, float],
                   t0: float, refinement_status: str | None = None) -> LocalizationResult:
    """A result without a verified candidate (``timings["total"]`` from ``t0``,
    ``time.perf_counter()`` s)."""
    timings["total"] = (time.perf_counter() - t0) * 1e3
    return LocalizationResult(
        localized=False, reason=reason, world_from_camera=None, covariance=None,
        confidence=0.0, inliers=(), metric=metric, hypotheses_evaluated=evaluated,
        used_prior=False, timings_ms=timings, refinement_status=refinement_status)


# ------------------------------------------------------------------ prior


def _prior_stage(solve: _Solve, prior: PosePrior) -> Candidate | None:
    """The ``prior`` stage: the prior's gated matches (:func:`_prior_matches`) refined from
    the prior pose and verified; None when too few match, verification fails or its tilt
    disagrees with the measured gravity (the search from scratch then decides)."""
    solve.evaluated += 1
    tp = time.perf_counter()
    candidate: Candidate | None = None
    matches = _prior_matches(solve.scorer, prior, solve.options.inlier_iou)
    if len(matches) >= solve.options.min_inliers:
        candidate, _ = _refine_and_verify(solve, matches, prior.world_from_camera,
                                          solve.options, prior)
        if candidate is not None and _against_gravity(solve, candidate):
            candidate = None
    solve.timings["prior"] = (time.perf_counter() - tp) * 1e3
    if candidate is not None:
        candidate.source = "prior"
    return candidate


def prior_gate_poses(prior: PosePrior) -> FloatArray:
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


# ------------------------------------------------------------------ hypotheses


def _place_stage(
    detections: Sequence[Detection], usable: list[int], compiled: CompiledMap, camera: Camera,
    options: LocalizationOptions, t0: float, cpu0: float, timings: dict[str, float],
    hinted: BoolArray | None = None,
) -> tuple[CompiledMap, PlaceSeeds | None]:
    """The ``places`` stage of a large map (>= ``PLACE_SEARCH_MIN_OBJECTS`` objects): the
    constellation search (:func:`quadloc.service.localization.constellations.place_seeds`;
    ``hinted``: the objects of a hint's places, :func:`_hinted_objects`);
    returns the sub-map of the places it keeps (the later stages score and refine there) and
    the seeds, or (``compiled``, None) when no pose came up."""
    tp = time.perf_counter()
    params = np.array([detections[i].ellipse.params() for i in usable])
    index = place_index(compiled)
    seeds = place_seeds(compiled, index, camera, params, [detections[i].label for i in usable],
                        Deadline.cpu_budget(options.time_budget_ms, cpu_start=cpu0,
                                            wall_start=t0), hinted)
    timings["places"] = (time.perf_counter() - tp) * 1e3
    if len(seeds.poses) == 0:
        return compiled, None
    objects = seeds.objects
    if hinted is not None and _room_hint(hinted):  # searched as one room (_room_search)
        objects = np.union1d(objects, np.flatnonzero(hinted))
    return compiled_subset(compiled, objects), seeds


def _room_hint(hinted: BoolArray | None) -> bool:
    """Whether a hint's objects (N,) are few enough to be searched as one room
    (:func:`_room_search`): fewer than ``PLACE_SEARCH_MIN_OBJECTS``, the size below which a
    map is searched by sampling."""
    return hinted is not None and 0 < int(hinted.sum()) < PLACE_SEARCH_MIN_OBJECTS


def _hinted_objects(compiled: CompiledMap, hint: PlaceHint) -> BoolArray:
    """The objects (N,) of a hint's places: a zone's objects, or those within
    ``PlaceHint.AGREE_SIGMAS`` sigmas plus the view range of a position."""
    hinted = np.zeros(len(compiled), dtype=bool)
    if hint.position is not None and hint.sigma_m is not None:
        index = place_index(compiled)
        hinted[index.near(hint.position, PlaceHint.AGREE_SIGMAS * hint.sigma_m
                          + index.view_range_m)] = True
    elif hint.object_ids is not None:
        positions = compiled.positions
        hinted[[positions[o] for o in hint.object_ids if o in positions]] = True
    return hinted


def _search_stage(solve: _Solve, seeds: PlaceSeeds | None = None,
                  hint: PlaceHint | None = None, room: IntArray | None = None
                  ) -> RansacOutcome:
    """The ``hypotheses`` stage: the RANSAC search (seeded by ``options.seed``) up to the
    budget; with a large map's ``seeds`` (:func:`_place_stage`), those poses only, and with a
    ``hint`` the best hypothesis of the hint's places kept aside (``solve.hinted``: refined as
    an extra runner-up and weighed, :func:`_hint_ranking`) when none of the kept ones agrees
    with it; with the ``room`` of a hint (indices of the hint's objects in the scorer's map,
    :func:`_room_hint`), the best hypothesis of the one-room search there
    (:func:`_room_search`) instead, whatever the kept ones."""
    th = time.perf_counter()
    options = solve.options
    outcome = ransac(solve.scorer, solve.up_world, inlier_iou=options.inlier_iou,
                     min_inliers=options.min_inliers,
                     max_hypotheses=options.ransac_max_hypotheses,
                     rng=np.random.default_rng(options.seed), deadline=solve.deadline,
                     seeds=None if seeds is None else seeds.poses, sample=seeds is None,
                     keep=PLACE_CANDIDATES if solve.places else KEEP_DISTINCT)
    if room is not None and outcome.camera_from_world is not None:
        solve.hinted = _room_search(solve, room)
    elif (hint is not None and seeds is not None and outcome.camera_from_world is not None
            and seeds.hinted.any()
            and not any(_hypothesis_agrees(solve, h, hint) for h in outcome.alternatives)):
        local = ransac(solve.scorer, solve.up_world, inlier_iou=options.inlier_iou,
                       min_inliers=options.min_inliers, max_hypotheses=0,
                       rng=np.random.default_rng(options.seed), deadline=solve.deadline,
                       seeds=seeds.poses[seeds.hinted], sample=False)
        solve.evaluated += local.hypotheses_evaluated
        if local.alternatives:
            solve.hinted = local.alternatives[0]
    solve.evaluated += outcome.hypotheses_evaluated
    solve.timings["hypotheses"] = (time.perf_counter() - th) * 1e3
    return outcome


def _room_search(solve: _Solve, room: IntArray) -> Hypothesis | None:
    """The one-room search (:func:`quadloc.service.localization.search.ransac`, sampling, as
    on a map of that room alone) over the objects ``room`` (indices in the scorer's map: a
    hint's room, :func:`_room_hint`) with the usable detections of their labels, within the
    call's budget; its best hypothesis, matches in the scorer's map (None when none
    qualifies). With a zone hint the search space is that room: the place search's one seed
    per place can miss the pose the room's own search finds."""
    scorer, options = solve.scorer, solve.options
    room_map = compiled_subset(scorer.compiled, room)
    rows = [r for r, label in enumerate(scorer.labels)
            if len(room_map.indices_for(label)) > 0]
    if len(rows) < 2:
        return None
    room_scorer = MatchScorer(room_map, scorer.camera,
                              [Ellipse(*scorer.params[r]) for r in rows],
                              [scorer.labels[r] for r in rows],
                              [scorer.detection_indices[r] for r in rows],
                              deadline=scorer.deadline)
    found = ransac(room_scorer, solve.up_world, inlier_iou=options.inlier_iou,
                   min_inliers=options.min_inliers,
                   max_hypotheses=options.ransac_max_hypotheses,
                   rng=np.random.default_rng(options.seed), deadline=solve.deadline)
    solve.evaluated += found.hypotheses_evaluated
    if found.camera_from_world is None:
        return None
    return Hypothesis(found.camera_from_world,
                      tuple(Match(m.detection_index, int(room[m.object_index]), m.iou)
                            for m in found.matches), found.score)


# ------------------------------------------------------------------ refine


def _refine_stage(solve: _Solve, outcome: RansacOutcome, prior_candidate: Candidate | None
                  ) -> tuple[list[Candidate], str | None]:
    """The ``refine`` stage: the verified candidates (the search's best hypothesis and
    runners-up, :func:`_refine_hypotheses`; the prior's candidate; the rivals of a best that
    refinement grew, :func:`_sweep_refined_best`), best-supported first, the capped ones that
    compete refined in full (:func:`_refine_capped_competitors`); and the
    refinement status of the best hypothesis (None if it was not refined)."""
    tr = time.perf_counter()
    candidates, first_status = _refine_hypotheses(solve, outcome)
    if solve.hinted is not None and not deadline_passed(solve.deadline):
        capped = replace(solve.options, max_iterations=min(solve.options.max_iterations,
                                                           ALTERNATIVE_MAX_ITERATIONS))
        got, status = _refine_and_verify(
            solve, list(solve.hinted.matches), invert_pose(solve.hinted.camera_from_world),
            capped, None)
        if got is not None:
            # refined in full when it competes (_refine_capped_competitors), as a runner-up
            got.capped = (status == "max_iterations"
                          and capped.max_iterations < solve.options.max_iterations)
            candidates.append(got)
    if prior_candidate is not None:
        candidates.append(prior_candidate)
    sort_by_support(candidates)
    candidates = _sweep_refined_best(solve, outcome, candidates)
    candidates = _copy_competitors(solve, candidates)
    candidates = _refine_capped_competitors(solve, candidates)
    solve.timings["refine"] = (time.perf_counter() - tr) * 1e3
    return candidates, first_status


def _refine_hypotheses(solve: _Solve, outcome: RansacOutcome
                       ) -> tuple[list[Candidate], str | None]:
    """The verified candidates of the best hypothesis (with ``outcome.matches``) and of up to
    :data:`REFINED_ALTERNATIVES` distinct runners-up scoring at least
    :data:`ALTERNATIVE_PREFILTER_RATIO` of the best (not once the budget is spent; not those of
    :func:`_same_explanation`), refined with at most :data:`ALTERNATIVE_MAX_ITERATIONS`; on a
    large map (``solve.places``) also the further ones scoring at least
    :data:`PLACE_TIE_RATIO` of the best (the tied candidate places) and, whatever their score,
    those matching more detections than the best; and the best hypothesis' refinement
    status."""
    assert outcome.camera_from_world is not None
    options = solve.options
    hyps = list(outcome.alternatives) or [
        Hypothesis(outcome.camera_from_world, outcome.matches, outcome.score)]
    candidates: list[Candidate] = []
    first_status: str | None = None
    alternative_options = replace(
        options, max_iterations=min(options.max_iterations, ALTERNATIVE_MAX_ITERATIONS))
    for k, h in enumerate(hyps[:PLACE_CANDIDATES if solve.places else 1 + REFINED_ALTERNATIVES]):
        ratio = ALTERNATIVE_PREFILTER_RATIO if k <= REFINED_ALTERNATIVES else PLACE_TIE_RATIO
        if k > 0 and deadline_passed(solve.deadline):
            break
        # a place whose seed matches more detections than the best's is refined whatever its
        # score: a seed is the P3P pose of three centres, whose IoUs underrate it
        more = solve.places and len(h.matches) > len(hyps[0].matches)
        if k > 0 and h.score < ratio * hyps[0].score and not more:
            continue
        if k > 0 and _same_explanation(h, hyps[0]):
            continue  # refines to the best's pose: not a competitor (see _same_explanation)
        got, status = _refine_and_verify(
            solve, list(outcome.matches if k == 0 else h.matches),
            invert_pose(h.camera_from_world), options if k == 0 else alternative_options, None)
        if k == 0:
            first_status = status
        if got is not None:
            # a tied place beyond the first runners-up is listed as refined so far (not
            # refined in full: it only widens the candidate list)
            got.capped = ((0 < k <= REFINED_ALTERNATIVES or more)
                          and status == "max_iterations"
                          and alternative_options.max_iterations < options.max_iterations)
            candidates.append(got)
    return candidates, first_status


def _sweep_refined_best(solve: _Solve, outcome: RansacOutcome, candidates: list[Candidate]
                        ) -> list[Candidate]:
    """``candidates`` (best-supported first) with the competitors of a best that refinement
    grew beyond the search's best hypothesis (inliers among other detections than it matched,
    whose triple the search never swept; a search that was not exhaustive; one-room search
    only: a large map's places list their candidates): the competitor sweep of its inliers,
    :func:`quadloc.service.localization.search.competitor_sweep`, every explanation of its
    sweep triple (e.g. the copies of the room it was found in), up to
    :data:`REFINED_ALTERNATIVES` hypotheses distinct from every candidate refined like the
    runners-up (whatever their score: a P3P pose of three centres is rough, the refinement
    settles whether it explains as much as the best). Best-supported first."""
    if (not candidates or solve.places or outcome.exhaustive
            or deadline_passed(solve.deadline)):
        return candidates
    if ({m.detection_index for m in candidates[0].inliers}
            <= {m.detection_index for m in outcome.matches}):
        return candidates  # the search swept the best's detections (search.ransac)
    options = solve.options
    hyps, evaluated = competitor_sweep(
        solve.scorer, solve.up_world, [m.detection_index for m in candidates[0].inliers],
        inlier_iou=options.inlier_iou, min_inliers=options.min_inliers,
        deadline=solve.deadline)
    solve.evaluated += evaluated
    alternative_options = replace(
        options, max_iterations=min(options.max_iterations, ALTERNATIVE_MAX_ITERATIONS))
    rivals = [h for h in hyps
              if all(distinct_poses(h.camera_from_world, invert_pose(a.world_from_camera))
                     for a in candidates)][:REFINED_ALTERNATIVES]
    for h in rivals:
        if deadline_passed(solve.deadline):
            break
        got, status = _refine_and_verify(solve, list(h.matches),
                                         invert_pose(h.camera_from_world),
                                         alternative_options, None)
        if got is not None:
            got.capped = (status == "max_iterations"
                          and alternative_options.max_iterations < options.max_iterations)
            candidates.append(got)
    sort_by_support(candidates)
    return candidates


def _copy_competitors(solve: _Solve, candidates: list[Candidate], *, again: bool = True
                      ) -> list[Candidate]:
    """``candidates`` (best-supported first) with the best's view in the exact copies of its
    supporting objects (:func:`quadloc.service.localization.copies.copy_transforms`: same
    labels, same geometry within ``COPY_TOLERANCE_M``; e.g. the other copies of a room, which
    the search may miss when its P3P of three centres is metres off, or, on a large map, when
    the place search's cap on map triplets left out the twin of the best's room), each refined
    like the runners-up and verified unless a candidate that competes with the best
    (:func:`~quadloc.service.localization.candidates.competes`) is already there (one refined
    to a poorer optimum there does not count; the ambiguity check then weighs it: a copy
    explains the detections as well, the answer is ``ambiguous``).

    A small map: every such copy. A large map (>= ``PLACE_SEARCH_MIN_OBJECTS`` objects; the
    whole map, ``solve.whole``, when it was searched by places): copies looked up in its place
    index; none is refined when one is already a candidate (the tie is there), else they are
    refined nearest first until one verifies, the scorer's map extended by the objects around
    each copy's camera (:func:`_extend_scorer`). Best-supported first.

    When the best's supporting objects have no copy and it has more than
    :data:`COPY_BUT_ONE_MIN_INLIERS` inliers, the same without one match (its weakest, else
    the one farthest from the others: :func:`_odd_matches`): a spurious detection that lands
    on an object of a neighbouring room, or an object of a corridor seen through a door,
    makes the best's set unique, its copy's view then explains every detection but that one
    and still competes (``Candidate.copy_but_one``): one match is no evidence between exact
    copies.

    When a copy refined here becomes the best-supported candidate (the search's best was a
    poorer fit of the same detections, e.g. objects of two rooms), its own copies are looked up
    the same way (``again``: once): without them, nothing competes with it, and in exact
    copies of a room it would be answered as if its room were the only one."""
    if not candidates or deadline_passed(solve.deadline):
        return candidates
    best = candidates[0]
    compiled = solve.scorer.compiled if solve.whole is None else solve.whole
    index = place_index(compiled) if len(compiled) >= PLACE_SEARCH_MIN_OBJECTS else None
    if index is not None and any(a is not best and competes(best, a)
                                 and _copy_of(compiled, best, a) for a in candidates):
        return candidates  # a copy is a competing candidate already: the tie is there
    supporting = list(best.inliers)
    transforms = copy_transforms(compiled, np.array(
        [compiled.index_of(m.object_id) for m in supporting], dtype=np.intp), index=index)
    but_one = not transforms and len(supporting) > COPY_BUT_ONE_MIN_INLIERS
    if but_one:  # without one match (a spurious detection landing on an object)
        for drop in _odd_matches(compiled, supporting):
            rest = supporting[:drop] + supporting[drop + 1:]
            transforms = copy_transforms(compiled, np.array(
                [compiled.index_of(m.object_id) for m in rest], dtype=np.intp), index=index)
            if transforms:
                supporting = rest
                break
    covered = [any(a is not best and competes(best, a) and not distinct_poses(
        invert_pose(G @ best.world_from_camera), invert_pose(a.world_from_camera))
        for a in candidates) for G in transforms]
    if index is not None:
        if any(covered):
            return candidates  # a copy is a competing candidate: the tie is there
        if solve.whole is not None and transforms:
            centres = compiled.centers[[compiled.index_of(m.object_id) for m in supporting]]
            _extend_scorer(solve, [G @ best.world_from_camera for G in transforms],
                           [centres @ G[:3, :3].T + G[:3, 3] for G in transforms])
    options = solve.options
    alternative_options = replace(
        options, max_iterations=min(options.max_iterations, ALTERNATIVE_MAX_ITERATIONS))
    added = False
    for G, done in zip(transforms, covered, strict=True):
        if deadline_passed(solve.deadline):
            break
        if done:
            continue  # that copy already has a competing candidate
        T = G @ best.world_from_camera
        got, status = _refine_and_verify(solve, solve.scorer.matches(invert_pose(T),
                                                                     options.inlier_iou),
                                         T, alternative_options, None)
        if got is not None:
            got.capped = (status == "max_iterations"
                          and alternative_options.max_iterations < options.max_iterations)
            got.copy_but_one = but_one
            if but_one:
                # a runner-up refined there before is the same view: flagged too, so the
                # place competes whichever of the two the ranking keeps (equal support)
                view = invert_pose(got.world_from_camera)
                for a in candidates:
                    if a is not best and not distinct_poses(invert_pose(a.world_from_camera),
                                                            view):
                        a.copy_but_one = True
            candidates.append(got)
            added = True
            if index is not None:
                break  # one verified copy makes the tie
    if added:
        sort_by_support(candidates)
        if again and candidates[0] is not best:
            return _copy_competitors(solve, candidates, again=False)
    return candidates


def _odd_matches(compiled: CompiledMap, matches: Sequence[InlierMatch]) -> list[int]:
    """The positions in ``matches`` of the matches :func:`_copy_competitors` leaves out in
    turn, each once: the weakest (least IoU), then the one whose object lies farthest from
    the centroid of the others' (an object of a neighbouring room or corridor: a TV seen
    through a door, or a spurious detection landing there)."""
    centres = compiled.centers[[compiled.index_of(m.object_id) for m in matches]]
    n = len(matches)
    others = (centres.sum(axis=0) - centres) / (n - 1)  # (n, 3) centroid of the others
    farthest = int(np.argmax(np.linalg.norm(centres - others, axis=1)))
    weakest = min(range(n), key=lambda k: matches[k].iou)
    return [weakest] if farthest == weakest else [weakest, farthest]


def _copy_of(compiled: CompiledMap, best: Candidate, other: Candidate) -> bool:
    """Whether ``other``'s inliers on the detections both match are a copy of ``best``'s
    (:func:`quadloc.service.localization.copies.is_copy`; objects of ``compiled``)."""
    theirs = {m.detection_index: m.object_id for m in other.inliers}
    pairs = [(compiled.index_of(m.object_id), compiled.index_of(theirs[m.detection_index]))
             for m in best.inliers if m.detection_index in theirs]
    if len(pairs) < 3:
        return False
    mine, others = (np.array(x, dtype=np.intp) for x in zip(*pairs, strict=True))
    return is_copy(compiled, mine, others)


def _extend_scorer(solve: _Solve, world_from_cameras: Sequence[FloatArray],
                   copied_centres: Sequence[FloatArray]) -> None:
    """Replace ``solve.scorer`` (a large map's places, :func:`_place_stage`) by the scorer of
    its objects and those of the whole map within the place index's view range of each camera
    position of ``world_from_cameras`` (4x4 each) or at ``COPY_TOLERANCE_M`` of a point of
    ``copied_centres`` (each (n, 3) m: where a copy has the best's objects): the same
    detections, deadline and camera. The objects keep their ids, so candidates found before
    stay valid."""
    assert solve.whole is not None
    index, scorer = place_index(solve.whole), solve.scorer
    kept = np.array([solve.whole.index_of(o) for o in scorer.compiled.object_ids], dtype=np.intp)
    near = [index.near(T[:3, 3], index.view_range_m) for T in world_from_cameras]
    near += [index.near(p, COPY_TOLERANCE_M) for ps in copied_centres for p in ps]
    objects = np.unique(np.concatenate([kept, *near]))
    if len(objects) == len(kept):
        return
    solve.scorer = MatchScorer(compiled_subset(solve.whole, objects), scorer.camera,
                               [Ellipse(*p) for p in scorer.params], list(scorer.labels),
                               list(scorer.detection_indices), deadline=scorer.deadline)


def _refine_capped_competitors(solve: _Solve, candidates: list[Candidate]) -> list[Candidate]:
    """``candidates`` (best-supported first) with the capped alternatives that compete (as
    many inliers as the first: they may rank first, and they are the only runners-up the
    ambiguity check weighs) refined in full from where they stopped; one that then fails
    verification keeps its capped result. Best-supported first."""
    while pending := [a for a in candidates
                      if a.capped and len(a.inliers) >= len(candidates[0].inliers)]:
        candidates = [a for a in candidates if a not in pending]  # identity (eq=False)
        for a in pending:
            full, _ = _refine_and_verify(
                solve, [Match(m.detection_index, solve.scorer.compiled.index_of(m.object_id),
                              m.iou) for m in a.inliers],
                a.world_from_camera, solve.options, None)
            a.capped = False
            candidates.append(a if full is None else full)
        sort_by_support(candidates)
    return candidates


def _pairs(matches: Sequence[Match]) -> set[tuple[int, int]]:
    return {(m.detection_index, m.object_index) for m in matches}


def _same_explanation(alternative: Hypothesis, best: Hypothesis) -> bool:
    """Whether ``alternative`` only re-uses the best hypothesis' correspondences (its matches
    are a subset of the best's) while the best has >= :data:`SAME_EXPLANATION_MIN_MATCHES`
    (its refinement then converges to the best's pose: not distinct)."""
    if len(best.matches) < SAME_EXPLANATION_MIN_MATCHES:
        return False
    return _pairs(alternative.matches) <= _pairs(best.matches)


def refine_pose(
    detections: Sequence[Detection], ellipsoids: Sequence[Ellipsoid], camera: Camera,
    initial_world_from_camera: FloatArray, options: LocalizationOptions,
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


def _refine_and_verify(
    solve: _Solve, matches: Sequence[Match], world_from_camera: FloatArray,
    options: LocalizationOptions, prior: PosePrior | None,
) -> tuple[Candidate | None, str | None]:
    """Refine on ``matches`` (with the scorer's map and camera, ``options``' refinement, the
    call's deadline and gravity) from ``world_from_camera``, re-associate, refine again if the
    set changed (and the deadline has not passed). Returns (the candidate, or None if the
    result fails the inlier check; the refinement status — see
    ``LocalizationResult.refinement_status`` — or None with ``metric="none"``)."""
    scorer, deadline = solve.scorer, solve.deadline
    thr, compiled = options.inlier_iou, scorer.compiled
    if options.metric == NO_REFINEMENT:
        final = scorer.matches(invert_pose(world_from_camera), thr)
        if len(final) < options.min_inliers:
            return None, None
        return Candidate(world_from_camera, None, [
            InlierMatch(m.detection_index, compiled.object_ids[m.object_index], m.iou,
                        1.0 - m.iou) for m in final], None, None), None
    current = list(matches)
    T = world_from_camera
    for round_ in range(2):
        res = refine_pose([solve.detections[m.detection_index] for m in current],
                          [compiled.ellipsoids[m.object_index] for m in current],
                          scorer.camera, T, options, prior, deadline, solve.measured_gravity)
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
    return Candidate(T, res.covariance, inliers, res, status), status


# ------------------------------------------------------------------ assess


def _answer(solve: _Solve, best: Candidate, ranked: list[Candidate], *, ambiguous: bool
            ) -> LocalizationResult:
    """The ``assess`` stage: the result for the best candidate among ``ranked`` (best first,
    mutually distinct; ``ambiguous``: a runner-up competes). Not localized when its tilt
    disagrees with the measured gravity (``gravity_mismatch``, only when every candidate's
    does), when ambiguous with ``on_ambiguity="not_localized"``, or when its confidence is
    below ``min_confidence``; the candidates (each with its confidence) are listed then, and
    whenever ambiguous."""
    options = solve.options
    runner_up = next((b for b in ranked if b is not best), None)
    assessment = _assess(solve, best, runner_up, ranked)
    conf, ev = assessment.confidence, assessment.evidence
    default_floor = solve.constants.default_min_confidence(solve.places)
    floor = default_floor if options.min_confidence is None else options.min_confidence
    reason = ("gravity_mismatch" if _against_gravity(solve, best)
              else "ambiguous" if ambiguous and options.on_ambiguity == "not_localized"
              else "low_confidence" if conf < floor else None)
    alternatives: tuple[Alternative, ...] = ()
    if ambiguous or reason is not None:  # the candidates, each with its probability
        alternatives = tuple(
            Alternative(world_from_camera=b.world_from_camera,
                        confidence=_assess(solve, b, best if b is not best else runner_up,
                                           ranked).confidence,
                        n_inliers=len(b.inliers), score=b.score,
                        object_ids=tuple(m.object_id for m in b.inliers)) for b in ranked)
    solve.timings["total"] = (time.perf_counter() - solve.t0) * 1e3
    if reason is not None:
        return LocalizationResult(
            localized=False, reason=reason, world_from_camera=None, covariance=None,
            confidence=0.0, inliers=(), metric=options.metric,
            hypotheses_evaluated=solve.evaluated, used_prior=False, timings_ms=solve.timings,
            refinement_status=best.status, pose_source=None, alternatives=alternatives,
            evidence=ev if reason == "ambiguous" else {**ev, "confidence": conf})
    return LocalizationResult(
        localized=True, reason=None,
        world_from_camera=np.array(best.world_from_camera, dtype=float),
        covariance=assessment.covariance, confidence=conf,
        inliers=tuple(sorted(best.inliers, key=lambda m: m.detection_index)),
        metric=options.metric, hypotheses_evaluated=solve.evaluated,
        used_prior=best.source == "prior", timings_ms=solve.timings,
        refinement_status=best.status, pose_source=best.source, alternatives=alternatives,
        evidence=ev)


def _assess(solve: _Solve, a: Candidate, runner_up: Candidate | None,
            others: Sequence[Candidate] = ()) -> Assessment:
    """The :class:`Assessment` of candidate ``a`` against its ``runner_up`` (its score margin)
    and ``others`` (the distinct candidates, for its ``chi2_competitor``)."""
    key = solve.calibration_key
    c = solve.calibration
    scale, floors = (None, None) if c is None else (c.covariance_scale, c.s2_floor)
    res = a.refinement
    s2 = math.nan if res is None else residual_variance(res.chi2, res.n_residuals)
    n_refined = 0 if res is None else len(res.per_detection_cost)
    cov = None if res is None else calibrated_covariance(
        key, a.raw_covariance, res.chi2, res.n_residuals, n_refined, res.fixed_information,
        scale, floors)
    margin = 0.0 if runner_up is None else min(1.0, runner_up.score / max(a.score, 1e-12))
    ev = evidence_features(n_inliers=len(a.inliers), n_usable=len(solve.usable),
                           ious=np.array([m.iou for m in a.inliers]), s2=s2,
                           covariance=cov, margin=margin, n_samples=solve.n_samples,
                           s2_floor=(S2_FLOOR if floors is None else floors).get(key, 0.0),
                           chi2_ratio_log=chi2_competitor(
                               a.chi2, len(a.inliers),
                               [(b.chi2_against(a), len(b.inliers))
                                for b in others if b is not a]),
                           gravity=solve.gravity is not None, place_search=solve.places)
    factor = math.nan if res is None else covariance_scale(key, res.chi2, res.n_residuals,
                                                           n_refined, scale, floors)
    extra = {"s2": s2, "cov_scale": factor, "n_refined": float(n_refined),
             "iou_competitor": float(iou_competitor(a, others))}
    if solve.gravity is not None:
        extra["tilt_error_deg"] = _tilt_deg(solve, a)
    return Assessment(confidence=confidence_probability(
        key, ev, None if c is None else c.confidence_models), evidence={**ev, **extra},
                      covariance=cov)


def _tilt_deg(solve: _Solve, a: Candidate) -> float:
    """The candidate's tilt error against the measured gravity (degrees; NaN without)."""
    if solve.gravity is None:
        return math.nan
    return float(tilt_errors_deg(a.world_from_camera[:3, :3].T, solve.up_world, solve.gravity))


def _against_gravity(solve: _Solve, a: Candidate) -> bool:
    """Whether the measured gravity rules the candidate out (its tilt error exceeds
    :func:`quadloc.service.localization.gravity.answer_gate_deg`)."""
    return solve.gravity is not None and not _tilt_deg(solve, a) <= answer_gate_deg(
        solve.gravity)
