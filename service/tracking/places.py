"""Place hypotheses of a tracking session: which place (room) of the map the walk is in.

A hypothesis is a rigid alignment ``world_from_odom`` (4x4) of the app's odometry frame to the
map: the pose of frame ``k`` under it is ``world_from_odom @ odom_from_camera_k``, so the
odometry's consistency is built in (a hypothesis is one rigid placement of the whole walk).
Every frame scores every live hypothesis (at most :data:`MAX_HYPOTHESES`) with the
frame's detections:

    LL_h = IOU_GAIN * sum(min(IoU, IOU_SATURATION) of its one-to-one inliers) / IOU_SATURATION
           - MISS_PENALTY * min(1, n / AGEING_DETECTIONS)
             * (objects of its place predicted in view, not detected)

for a frame of ``n`` usable detections (:func:`_miss_weight`: detectors drop out in bursts),
and a *null* hypothesis ("somewhere else") that explains each usable detection of a frame of at
least :data:`NULL_MIN_DETECTIONS` usable detections with ``NULL_GAIN`` (a lone detection gains it
nothing) and misses as few predicted objects as the best-placed hypothesis (misses are evidence
between listed places, not against the places not listed). Scores are discounted
sums ``S_h <- d * S_h + TEMPERATURE * LL_h`` with ``d = DISCOUNT ** min(1, n /
AGEING_DETECTIONS)`` for a frame of ``n`` usable detections (consecutive 30 Hz frames are far
from independent: the temperature and discount make the evidence of about one second count, not
of thirty frames; the past ages with new detections, not with the clock, so a walk between
rooms keeps its place); the posterior of the places is
``softmax(S)`` over the hypotheses and the null. The constants were chosen on the tuning
seeds of ``python -m bench.tracking --building`` (docs/tracking.md, "Places").

"Predicted in view": the shared rule :func:`quadloc.maps.visibility.predicted_in_view` with
:data:`VIEW_RULE` (the object's centre projects inside the image inset by :data:`VIEW_INSET` at
a depth in ``(0.3, MAX_VIEW_DEPTH_M)`` m, and the object is in the zone of the nearest such
object when the map has zones: walls hide other rooms). Poses are
``world_from_camera`` (OpenCV camera axes) unless named otherwise.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from quadloc.factors.arrays import FloatArray, IntArray
from quadloc.factors.camera import Camera
from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import invert_pose, rotation_angle
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.places import place_index
from quadloc.maps.visibility import ViewRule, object_zones, predicted_in_view
from quadloc.maps.zones import zone_index
from quadloc.service.localization.constellations import PLACE_SEARCH_MIN_OBJECTS
from quadloc.service.localization.copies import copy_transforms
from quadloc.service.localization.scoring import MatchScorer, greedy_assignment

__all__ = [
    "COMMIT_PROBABILITY",
    "KEEP_PROBABILITY",
    "MAX_HYPOTHESES",
    "PlaceCandidate",
    "PlaceHypothesis",
    "PlaceSet",
    "same_place",
    "single_place",
]

#: Live hypotheses per session (beyond it, the least supported are dropped: :func:`_support`).
MAX_HYPOTHESES = 8
#: Log-likelihood gain of an inlier whose IoU reaches :data:`IOU_SATURATION` (less below it),
#: and penalty per object predicted in view but not detected (the detector misses about a third
#: of visible objects, occlusion included). The saturation keeps a hypothesis's alignment error
#: (a few cm: IoU 0.6-0.9) from counting as evidence: identical rooms stay tied, while objects
#: moved by 0.1-0.5 m fall below it.
IOU_GAIN = 3.0
IOU_SATURATION = 0.5
MISS_PENALTY = 0.5
#: What the null hypothesis ("another place") gains per usable detection of a frame of at least
#: :data:`NULL_MIN_DETECTIONS` usable detections.
NULL_GAIN = 1.2
#: A frame with fewer usable detections than this is no evidence for a place not listed: one
#: ellipse fits an object of its label at some pose of any place (one ellipse-ellipsoid pair
#: leaves the 6-dof pose under-determined, two determine it), so a lone detection unexplained by
#: the listed places cannot tell "another place" from a spurious detection. It still scores the
#: listed hypotheses, whose poses are fixed by their alignments. (Before, a session walking
#: between rooms with only spurious detections in view, 0-2 a frame, gave its place up to the
#: null: ``python -m bench.tracking --building``, tuning seeds.)
NULL_MIN_DETECTIONS = 2
#: Per-frame weight of the evidence and the per-frame discount of past scores.
TEMPERATURE = 0.25
DISCOUNT = 0.93
#: A frame with at least this many usable detections applies the whole :data:`DISCOUNT`; one
#: with fewer, ``DISCOUNT ** (n / AGEING_DETECTIONS)`` (none without detections): the past
#: evidence ages with the new evidence, not with the clock, so a sparse stretch (0-2
#: detections) does not wash out what the dense frames before it established.
AGEING_DETECTIONS = 3
#: A session commits to a place when its posterior is at least this (and it explains
#: :data:`MIN_COMMIT_OBJECTS` distinct objects); a committed place is given up when a rival's
#: posterior exceeds its own (``ambiguous``) or its own falls below :data:`KEEP_PROBABILITY`.
COMMIT_PROBABILITY = 0.99
MIN_COMMIT_OBJECTS = 3
#: On a map of several places, an object counts towards :data:`MIN_COMMIT_OBJECTS` once the
#: place has matched it in this many frames: another room that explains the two objects a walk
#: sees for seconds also matches, now and then, a spurious or mislabelled detection with a
#: third object of its own (5 frames of 66, building walks, twins, tuning seed 0), while an
#: object really in view is matched frame after frame. A one-place map (:func:`single_place`)
#: has no other room to explain them: there one frame counts.
MIN_OBJECT_FRAMES = 10
#: A committed place whose posterior falls below this is given up (the session is ``lost``).
KEEP_PROBABILITY = 0.5
#: Hypotheses whose posterior falls below this are dropped.
DROP_PROBABILITY = 1e-4
#: Candidates listed in an answer: posterior at least this.
LIST_PROBABILITY = 0.01
#: Two alignments are the same place when the current camera positions they give are closer
#: than this (m) and the orientations within :data:`SAME_PLACE_DEG`.
SAME_PLACE_M = 0.5
SAME_PLACE_DEG = 10.0
VIEW_INSET = 0.1
MAX_VIEW_DEPTH_M = 6.0
#: "Predicted in view" (:func:`quadloc.maps.visibility.predicted_in_view`): the centre inside
#: the image inset by :data:`VIEW_INSET`, depth in (0.3, :data:`MAX_VIEW_DEPTH_M`) m, the zone
#: of the nearest such object.
VIEW_RULE = ViewRule(min_depth_m=0.3, max_depth_m=MAX_VIEW_DEPTH_M, inset_fraction=VIEW_INSET)
#: A map is one place (:func:`single_place`) when its objects are in at most one room and span
#: at most this (m): about a large room (the Chess room's objects span 1.9 m; the generated
#: buildings' rooms are 12 m apart).
SINGLE_PLACE_EXTENT_M = 8.0


@dataclass(frozen=True)
class PlaceCandidate:
    """A place of an answer: the camera pose ``world_from_camera`` under it, its posterior
    ``probability`` and its ``zone`` (:mod:`quadloc.maps.zones`, from the objects it matched;
    None without zones)."""

    world_from_camera: FloatArray
    probability: float
    zone: str | None


@dataclass(eq=False)
class PlaceHypothesis:
    """One place: its odometry alignment, discounted score, the map objects (indices) it
    matched and in how many frames each, its zone (None until it matched an object of a zone),
    and ``rounds``: the proposal rounds it has lived through (:meth:`PlaceSet.new_round`)."""

    world_from_odom: FloatArray
    score: float = 0.0
    rounds: int = 0
    #: per matched map object (index), the number of frames that matched it
    frames_matched: Counter[int] = field(default_factory=Counter)
    zone: str | None = None

    @property
    def objects(self) -> frozenset[int]:
        """The distinct map objects (indices) matched over the hypothesis's life."""
        return frozenset(self.frames_matched)

    def established_objects(self, min_frames: int = MIN_OBJECT_FRAMES) -> int:
        """The distinct objects matched in at least ``min_frames`` frames."""
        return sum(n >= min_frames for n in self.frames_matched.values())


def single_place(compiled: CompiledMap) -> bool:
    """Whether the map is one place: its objects are in at most one room (their most specific zones,
    :func:`quadloc.maps.visibility.object_zones`; objects of no zone count as one more room) and
    their centres are at most :data:`SINGLE_PLACE_EXTENT_M` apart. Such a map has no copy of a
    room elsewhere for a later proposal round to find, so a session need not wait for rounds
    (``session.MIN_PROPOSAL_ROUNDS``); rivals inside the room are still the first round's
    proposals (multi-frame RANSAC and ``localize`` with its alternatives), scored against each
    other. Memoised on the map."""
    memo: bool | None = compiled.__dict__.get("_single_place")
    if memo is None:
        c = np.asarray(compiled.centers, float).reshape(-1, 3)
        extent = float(np.linalg.norm(c.max(axis=0) - c.min(axis=0))) if len(c) else 0.0
        memo = len(set(object_zones(compiled).tolist())) <= 1 \
            and extent <= SINGLE_PLACE_EXTENT_M
        compiled.__dict__["_single_place"] = memo
    return memo


class PlaceSet:
    """The live place hypotheses of a session and the null's score (module docstring).

    Args:
        compiled: the session's map; camera: its intrinsics; inlier_iou: the inlier threshold.
    """

    def __init__(self, compiled: CompiledMap, camera: Camera, inlier_iou: float) -> None:
        self.compiled = compiled
        self.camera = camera
        self.inlier_iou = inlier_iou
        self.hypotheses: list[PlaceHypothesis] = []
        self.null_score = 0.0
        self._zones = zone_index(compiled.scene_map)
        self._copies: dict[frozenset[int], bool] = {}
        # per object, its room for has_copy: its zone (object_zones), -1 for no zone and for
        # a zone of fewer objects than a constellation (e.g. one exhibit: no room)
        room = object_zones(compiled)
        self._rooms: IntArray = np.where(
            (np.bincount(room + 1) < MIN_COMMIT_OBJECTS)[room + 1], -1, room)

    def discard(self, hypotheses: Sequence[PlaceHypothesis]) -> None:
        """Drop ``hypotheses`` (by identity)."""
        self.hypotheses = [h for h in self.hypotheses if not any(h is x for x in hypotheses)]

    def clear(self) -> None:
        """Drop every hypothesis and the null's score."""
        self.hypotheses.clear()
        self.null_score = 0.0

    # ------------------------------------------------------------------ evidence
    def frame_log_likelihoods(self, world_from_cameras: FloatArray, ellipses: FloatArray,
                              labels: Sequence[str]
                              ) -> tuple[FloatArray, list[set[int]], FloatArray]:
        """``LL_h`` of one frame for poses (H, 4, 4), the matched objects of each and the
        number of objects each predicts in view but were not detected.

        Args:
            ellipses: (D, 5) ``(cx, cy, a, b, angle)`` px / rad of the usable detections.
            labels: their D labels.
        """
        H = len(world_from_cameras)
        ll = np.zeros(H)
        matched: list[set[int]] = [set() for _ in range(H)]
        if H == 0:
            return ll, matched, np.zeros(0)
        cfw: FloatArray = np.linalg.inv(np.asarray(world_from_cameras, dtype=float))
        if len(labels):
            sc = MatchScorer(self.compiled, self.camera,
                             [Ellipse(*map(float, e)) for e in ellipses], list(labels),
                             list(range(len(labels))))
            dense = sc.dense_iou(cfw)
            for h in range(H):
                ms = greedy_assignment(dense[h], sc.detection_indices, self.inlier_iou)
                ll[h] = _inlier_gain([m.iou for m in ms])
                matched[h] = {int(m.object_index) for m in ms}
        misses = np.array([len(self._in_view(cfw[h]) - matched[h]) for h in range(H)],
                          dtype=float)
        return ll - MISS_PENALTY * _miss_weight(len(labels)) * misses, matched, misses

    def predicts_objects_in_view(self, world_from_camera: FloatArray) -> bool:
        """Whether any object of the map is predicted in view from ``world_from_camera``
        (:data:`VIEW_RULE`, the rule of the misses of ``LL_h``)."""
        return bool(self._in_view(invert_pose(np.asarray(world_from_camera, float))))

    def _in_view(self, camera_from_world: FloatArray) -> set[int]:
        """Objects (indices) predicted in view (:data:`VIEW_RULE`,
        :func:`quadloc.maps.visibility.predicted_in_view`)."""
        return {int(i) for i in predicted_in_view(self.compiled, self.camera, camera_from_world,
                                                  VIEW_RULE)}

    def update(self, odom_from_camera: FloatArray, ellipses: FloatArray, labels: Sequence[str],
               committed_world_from_camera: FloatArray | None = None,
               committed: PlaceHypothesis | None = None,
               committed_inliers: Sequence[tuple[int, float]] | None = None) -> None:
        """Score one frame: every hypothesis at ``world_from_odom @ odom_from_camera`` (the
        ``committed`` one at ``committed_world_from_camera``, the smoother's estimate, when
        given), the null with its gain; discounted sums; drops the hypotheses whose
        posterior fell below :data:`DROP_PROBABILITY` (never ``committed``).

        ``committed_inliers``: the ``(object index, IoU)`` one-to-one inliers the frame
        already verified at ``committed_world_from_camera`` (the session's answer): the
        committed place is scored on them instead of matching the frame again (a tracking
        session's usual case, one live place, then needs no matching here)."""
        if not self.hypotheses:
            return
        miss_weight = _miss_weight(len(labels))
        reuse = committed is not None and committed_world_from_camera is not None \
            and committed_inliers is not None
        rest = [h for h in self.hypotheses if not (reuse and h is committed)]
        poses = np.array([committed_world_from_camera
                          if h is committed and committed_world_from_camera is not None
                          else h.world_from_odom @ odom_from_camera for h in rest]
                         ).reshape(-1, 4, 4)
        ll_rest, matched_rest, misses_rest = self.frame_log_likelihoods(poses, ellipses, labels)
        by_h = {id(h): (float(x), m, float(k)) for h, x, m, k in zip(
            rest, ll_rest, matched_rest, misses_rest, strict=True)}
        if reuse:
            assert committed is not None and committed_inliers is not None
            m = {int(o) for o, _ in committed_inliers}
            k = float(len(self._in_view(invert_pose(np.asarray(committed_world_from_camera,
                                                               float))) - m))
            by_h[id(committed)] = (_inlier_gain([q for _, q in committed_inliers])
                                   - MISS_PENALTY * miss_weight * k, m, k)
        ll = np.array([by_h[id(h)][0] for h in self.hypotheses])
        matched = [by_h[id(h)][1] for h in self.hypotheses]
        misses = np.array([by_h[id(h)][2] for h in self.hypotheses])
        d = _discount(labels)
        for h, x, m in zip(self.hypotheses, ll, matched, strict=True):
            h.score = d * h.score + TEMPERATURE * float(x)
            self._remember(h, m)
        self.null_score = d * self.null_score + TEMPERATURE * (
            _null_gain(len(labels)) - MISS_PENALTY * miss_weight * float(misses.min()))
        p = self.posteriors()
        self.hypotheses = [h for h, q in zip(self.hypotheses, p, strict=True)
                           if q >= DROP_PROBABILITY or h is committed]

    def _remember(self, h: PlaceHypothesis, matched: set[int]) -> None:
        if matched:
            h.frames_matched.update(matched)
            zone = self._zones.zone_of(self.compiled.object_ids[i] for i in matched)
            h.zone = zone if zone is not None else h.zone

    def has_copy(self, h: PlaceHypothesis) -> bool:
        """Whether the evidence of ``h`` cannot tell its place from a copy: no room's share of
        the objects it matched (those of one zone, :func:`quadloc.maps.visibility.object_zones`;
        objects of no zone, and of zones of fewer than :data:`MIN_COMMIT_OBJECTS` objects in the
        map, are one more room), of at least :data:`MIN_COMMIT_OBJECTS` objects,
        is without an exact copy elsewhere in the map (same labels, every centre within 5 cm
        after a rigid fit: :func:`quadloc.service.localization.copies.copy_transforms`,
        through the place index on a large map). Such a place differs from its copies only
        by how well each alignment was proposed, whatever the scores. The objects of two rooms
        are not taken together: the session knows where one room lies from the other only
        through the odometry of the walk between them, whose drift (degrees and decimetres
        over a transit) hides the difference between two copied rooms and another pair of the
        same copies placed a few degrees otherwise (a walk between two floors of 200 exact
        copies committed 60 m off with confidence 1.0: the union of the two rooms' objects
        had no copy, the pair it took was 5 deg and 16 cm from the true one). Memoised per set
        of objects."""
        key = h.objects
        found = self._copies.get(key)
        if found is None:
            index = (place_index(self.compiled) if len(self.compiled) >= PLACE_SEARCH_MIN_OBJECTS
                     else None)
            objects = np.array(sorted(key), dtype=np.intp)
            zones = self._rooms[objects]
            found = not any(
                len(share) >= MIN_COMMIT_OBJECTS
                and not copy_transforms(self.compiled, share, max_copies=1, index=index)
                for share in (objects[zones == z] for z in np.unique(zones)))
            self._copies[key] = found
        return found

    def posteriors(self) -> FloatArray:
        """Posterior of each hypothesis (same order); the null's is ``1 - sum``."""
        s = np.array([h.score for h in self.hypotheses] + [self.null_score])
        w = np.exp(s - s.max())
        out: FloatArray = (w / w.sum())[:-1]
        return out

    # ------------------------------------------------------------------ proposals
    def new_round(self) -> None:
        """A proposal round begins: every live hypothesis has lived through one more."""
        for h in self.hypotheses:
            h.rounds += 1

    def restart_rounds(self) -> None:
        """Every live hypothesis counts its proposal rounds from 0 again."""
        for h in self.hypotheses:
            h.rounds = 0

    def propose(self, alignments: Sequence[FloatArray], odom_from_camera: FloatArray,
                history: Sequence[tuple[FloatArray, FloatArray, tuple[str, ...]]],
                protect: PlaceHypothesis | None = None, rounds: int = 0) -> None:
        """Add proposed alignments ``world_from_odom``; one of a place already held refreshes
        that hypothesis (its alignment replaced by the newer one, its score kept; never
        ``protect``'s). New ones are scored together on ``history`` (``(odom_from_camera,
        ellipses, labels)`` of the recent frames, oldest first, with the discount), so that
        hypotheses born at different frames compare on the same evidence. Beyond
        :data:`MAX_HYPOTHESES` the weakest (never ``protect``) are dropped. New hypotheses start
        with ``rounds`` proposal rounds lived (1 when proposed by a round)."""
        new: list[PlaceHypothesis] = []
        for W in alignments:
            T = W @ odom_from_camera
            same = next((h for h in [*self.hypotheses, *new] if _same_place(
                h.world_from_odom @ odom_from_camera, T)), None)
            if same is None:
                new.append(PlaceHypothesis(np.asarray(W, float), rounds=rounds))
            elif same is not protect:
                same.world_from_odom = np.asarray(W, float)
        if not new:
            return
        # weight of each history frame: the discounts of the frames after it (as update's)
        weights = np.ones(len(history))
        for k in range(len(history) - 2, -1, -1):
            weights[k] = weights[k + 1] * _discount(history[k + 1][2])
        for (T_oc, ell, labels), w in zip(history, weights, strict=True):
            ll, matched, _ = self.frame_log_likelihoods(
                np.array([h.world_from_odom @ T_oc for h in new]), ell, labels)
            for h, x, m in zip(new, ll, matched, strict=True):
                h.score += float(w) * TEMPERATURE * float(x)
                self._remember(h, m)
        self.hypotheses += new
        while len(self.hypotheses) > MAX_HYPOTHESES:
            self.hypotheses.remove(min((h for h in self.hypotheses if h is not protect),
                                       key=_support))

    def candidates(self, odom_from_camera: FloatArray,
                   committed: PlaceHypothesis | None = None,
                   committed_world_from_camera: FloatArray | None = None
                   ) -> tuple[PlaceCandidate, ...]:
        """The places with posterior >= :data:`LIST_PROBABILITY`, most probable first."""
        p = self.posteriors()
        out = []
        for h, q in sorted(zip(self.hypotheses, p, strict=True), key=lambda x: -x[1]):
            if q < LIST_PROBABILITY:
                continue
            T = committed_world_from_camera if (h is committed and committed_world_from_camera
                                                is not None) \
                else h.world_from_odom @ odom_from_camera
            out.append(PlaceCandidate(T, float(q), h.zone))
        return tuple(out)

    def place_probabilities(self) -> list[float]:
        """Per live hypothesis (in :attr:`hypotheses` order), the posterior of its place: the
        sum over it and the live hypotheses of the same place (:func:`same_place`)."""
        p = self.posteriors()
        return [self._place_posterior(h, p) for h in self.hypotheses]

    def place_probability(self, h: PlaceHypothesis) -> float:
        """The posterior of the place of ``h`` (:meth:`place_probabilities`; 0 when ``h`` is not
        live)."""
        if not any(x is h for x in self.hypotheses):
            return 0.0
        return self._place_posterior(h, self.posteriors())

    def _place_posterior(self, h: PlaceHypothesis, posteriors: FloatArray) -> float:
        """The sum of ``posteriors`` (per live hypothesis) over ``h`` and the live hypotheses of
        its place (:func:`same_place`)."""
        return float(sum(q for x, q in zip(self.hypotheses, posteriors, strict=True)
                         if x is h or same_place(x, h)))

    def best(self) -> tuple[PlaceHypothesis | None, float]:
        """The most probable hypothesis and its posterior (None, 0 without any)."""
        if not self.hypotheses:
            return None, 0.0
        p = self.posteriors()
        k = int(np.argmax(p))
        return self.hypotheses[k], float(p[k])


def same_place(a: PlaceHypothesis, b: PlaceHypothesis) -> bool:
    """Whether two hypotheses are alignments of one place: they matched at least
    :data:`MIN_COMMIT_OBJECTS` of the same map objects. Two alignments a few degrees apart in
    one room both explain its objects (the IoU saturates at :data:`IOU_SATURATION`) and split
    its posterior between them; they are two poses of one place, not two places (copies of a
    room are other objects)."""
    return len(a.objects & b.objects) >= MIN_COMMIT_OBJECTS


def _support(h: PlaceHypothesis) -> tuple[int, float]:
    """What keeps a hypothesis when the cap (:data:`MAX_HYPOTHESES`) is reached: the distinct
    map objects it has matched over its life, then its score. Copies of a room tie on the
    score of the recent frames; the alignment that also explains the rooms walked through
    before has matched more objects."""
    return len(h.objects), h.score


def _inlier_gain(ious: Sequence[float]) -> float:
    """The inlier part of ``LL_h`` (module docstring) of one-to-one inlier IoUs."""
    return IOU_GAIN / IOU_SATURATION * float(sum(min(float(q), IOU_SATURATION) for q in ious))


def _null_gain(n: int) -> float:
    """What the null gains on a frame of ``n`` usable detections: ``NULL_GAIN * n``, 0 below
    :data:`NULL_MIN_DETECTIONS` (module docstring)."""
    return NULL_GAIN * n if n >= NULL_MIN_DETECTIONS else 0.0


def _miss_weight(n: int) -> float:
    """Weight of the misses of a frame of ``n`` usable detections in ``LL_h``:
    ``min(1, n / AGEING_DETECTIONS)``. Detectors drop out in bursts (motion blur, light, a
    hand over the lens): a frame of 0-2 detections where its place predicts more in view says
    little of which objects are there, and missing objects are counted, like the ageing of the
    past, only with the detections the frame has."""
    return min(1.0, n / AGEING_DETECTIONS)


def _discount(labels: Sequence[str]) -> float:
    """The discount a frame of ``n`` usable detections applies to the past scores:
    ``DISCOUNT ** min(1, n / AGEING_DETECTIONS)`` (1 without detections: such a frame says
    nothing new about the places but its predicted-in-view misses, so the evidence gathered
    before it is not aged and a walk between rooms keeps its place's posterior)."""
    return float(DISCOUNT ** min(1.0, len(labels) / AGEING_DETECTIONS))


def _same_place(a: FloatArray, b: FloatArray) -> bool:
    """Two camera poses of the same place (:data:`SAME_PLACE_M`, :data:`SAME_PLACE_DEG`)."""
    return bool(np.linalg.norm(a[:3, 3] - b[:3, 3]) < SAME_PLACE_M and math.degrees(
        float(rotation_angle(a[:3, :3], b[:3, :3]))) < SAME_PLACE_DEG)


def alignment(world_from_camera: FloatArray, odom_from_camera: FloatArray) -> FloatArray:
    """``world_from_odom`` of a camera pose and its odometry pose."""
    return np.asarray(world_from_camera, float) @ invert_pose(odom_from_camera)
