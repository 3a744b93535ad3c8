"""Negative evidence between candidate places (``negative_evidence``): a place whose predicted
objects were not detected loses a tie, exact copies stay tied; copies of a constellation
(``copies``) are found where they are and nowhere else."""

from __future__ import annotations

import math

import numpy as np

from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.rotations import pose_matrix, so3_exp
from quadloc.maps.compiled import compile_map
from quadloc.maps.model import MapObject, MapZone, SceneMap
from quadloc.maps.places import place_index
from quadloc.service.localization.candidates import Candidate
from quadloc.service.localization.copies import copy_transforms
from quadloc.service.localization.negative_evidence import (
    MISS_RATE,
    NEGATIVE_EVIDENCE_RATIO,
    miss_margin,
    missed_objects,
    weigh_misses,
)
from quadloc.service.localization.types import InlierMatch
from tests.support.buildings import make_building

CAMERA = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)
SHIFT = np.array([20.0, 0.0, 0.0])  # room B is room A moved by this
#: room A's objects, camera frame of a camera at the origin looking along +z (all in view)
ROOM = [(-0.5, 0.0, 2.0), (0.4, 0.2, 2.5), (0.0, -0.3, 3.0)]


def _two_rooms(extra_in_b: int, moved_m: float = 0.0) -> SceneMap:
    """Room A (3 chairs) and room B (the same 3 chairs moved by SHIFT, its chair 1 by
    ``moved_m`` more along x, plus ``extra_in_b`` tables in the same view), zones ``a``, ``b``."""
    objs, a_ids, b_ids = [], [], []
    for k, c in enumerate(ROOM):
        for room, shift, ids in (("a", np.zeros(3), a_ids), ("b", SHIFT, b_ids)):
            oid = f"{room}/{k}"
            centre = np.array(c) + shift + (moved_m * np.eye(3)[0] if oid == "b/1" else 0.0)
            objs.append(MapObject(oid, "chair", Ellipsoid(centre, np.full(3, 0.2), np.eye(3))))
            ids.append(oid)
    for j in range(extra_in_b):
        c = np.array([-0.6 + 0.3 * j, 0.35, 2.8]) + SHIFT
        objs.append(MapObject(f"b/t{j}", "table", Ellipsoid(c, np.full(3, 0.2), np.eye(3))))
        b_ids.append(f"b/t{j}")
    return SceneMap("two", "two", (0.0, -1.0, 0.0), ("chair", "table"), tuple(objs),
                    zones=(MapZone("a", None, tuple(a_ids)), MapZone("b", None, tuple(b_ids))))


def _candidate(room: str, shift: np.ndarray, iou: float = 0.8) -> Candidate:
    """A candidate in ``room`` (camera at ``shift``, identity rotation) matching its chairs."""
    return Candidate(pose_matrix(np.eye(3), shift), None,
                     [InlierMatch(k, f"{room}/{k}", iou, 0.1) for k in range(3)], None, None)


def test_margin_is_the_likelihood_ratio() -> None:
    k = miss_margin()
    # the fewest misses whose likelihood ratio (1 / MISS_RATE)^k reaches the ratio
    assert (1.0 / MISS_RATE) ** k >= NEGATIVE_EVIDENCE_RATIO * (1 - 1e-12)
    assert (1.0 / MISS_RATE) ** (k - 1) < NEGATIVE_EVIDENCE_RATIO
    assert miss_margin(0.5, 8.0) == 3 and miss_margin(0.1, 100.0) == 2


def test_misses_counted_by_hand() -> None:
    cm = compile_map(_two_rooms(4))
    assert missed_objects(cm, CAMERA, _candidate("a", np.zeros(3))) == 0
    assert missed_objects(cm, CAMERA, _candidate("b", SHIFT)) == 4  # the 4 tables
    # a candidate matching only 2 chairs misses the third
    c = _candidate("a", np.zeros(3))
    c.inliers = c.inliers[:2]
    assert missed_objects(cm, CAMERA, c) == 1


def test_a_place_with_undetected_objects_loses_the_tie() -> None:
    k = miss_margin()
    cm = compile_map(_two_rooms(k))
    a, b = _candidate("a", np.zeros(3)), _candidate("b", SHIFT)
    # tied on the detections (same inliers, same IoUs): the misses decide, in either order
    for ranked in ([a, b], [b, a]):
        out, ambiguous, misses = weigh_misses(ranked, cm, CAMERA)
        assert out[0] is a and not ambiguous
        assert misses[id(a)] == 0 and misses[id(b)] == k
    # one miss fewer than the margin: still a tie
    cm = compile_map(_two_rooms(k - 1))
    out, ambiguous, _ = weigh_misses([b, a], cm, CAMERA)
    assert ambiguous and out[0] is b


def test_exact_copies_stay_ambiguous_and_the_detections_rule() -> None:
    cm = compile_map(_two_rooms(0))
    a, b = _candidate("a", np.zeros(3)), _candidate("b", SHIFT)
    out, ambiguous, _ = weigh_misses([a, b], cm, CAMERA)
    assert ambiguous and out == [a, b]
    # a runner-up that explains the detections clearly worse is never promoted by misses
    cm = compile_map(_two_rooms(miss_margin() + 2))
    weak_a = _candidate("a", np.zeros(3), iou=0.5)
    out, ambiguous, _ = weigh_misses([b, weak_a], cm, CAMERA)
    assert out[0] is b and not ambiguous


def test_copy_transforms_find_the_other_room_only() -> None:
    cm = compile_map(_two_rooms(2))
    a_idx = np.array([cm.index_of(f"a/{k}") for k in range(3)])
    found = copy_transforms(cm, a_idx)
    assert len(found) == 1
    G = found[0]
    np.testing.assert_allclose(G[:3, :3], np.eye(3), atol=1e-9)
    np.testing.assert_allclose(G[:3, 3], SHIFT, atol=1e-9)
    # an object moved by more than the tolerance: no copy
    cm2 = compile_map(_two_rooms(0, moved_m=0.2))
    assert copy_transforms(cm2, np.array([cm2.index_of(f"a/{k}") for k in range(3)])) == []
    assert math.isclose(float(np.linalg.norm(G[:3, 3])), 20.0, abs_tol=1e-9)


def test_copies_of_two_objects_are_upright() -> None:
    # room B turned by 90 degrees about the up axis (-y) around its first chair
    cm = compile_map(_two_rooms(0))
    a_pair = np.array([cm.index_of("a/0"), cm.index_of("a/1")])
    found = copy_transforms(cm, a_pair)
    assert len(found) == 1  # the swapped pair differs in height: not a copy
    np.testing.assert_allclose(found[0], pose_matrix(np.eye(3), SHIFT), atol=1e-9)
    up = np.array([0.0, -1.0, 0.0])
    R = so3_exp(0.5 * math.pi * up)
    doc_objs = []
    for o in _two_rooms(0).objects:
        c = o.ellipsoid.center
        if o.object_id.startswith("b/"):
            c = R @ (c - SHIFT) + SHIFT
        doc_objs.append(MapObject(o.object_id, o.category, Ellipsoid(c, o.ellipsoid.axes,
                                                                     np.eye(3))))
    turned = compile_map(SceneMap("t", "t", (0.0, -1.0, 0.0), ("chair", "table"),
                                  tuple(doc_objs)))
    found = copy_transforms(turned, a_pair)
    assert len(found) == 1
    moved = turned.centers[a_pair] @ found[0][:3, :3].T + found[0][:3, 3]
    np.testing.assert_allclose(moved, turned.centers[[turned.index_of("b/0"),
                                                      turned.index_of("b/1")]], atol=1e-9)


def test_copy_transforms_from_the_place_index_match_the_dense_search() -> None:
    """A large map's lookup (the place index's constellations and grid) finds the same copies
    as the search over every same-label triplet (and pair), and in the same order, when the
    map has no more copies than asked for: a twins building, every room's first objects."""
    b = make_building(40, "twins", seed=3)
    cm = b.compiled
    index = place_index(cm)
    rooms = 0
    for room in b.rooms:
        for n in (2, 3, 5):
            idx = np.array([cm.index_of(o) for o in room.object_ids[:n]])
            dense = copy_transforms(cm, idx, max_copies=50)
            indexed = copy_transforms(cm, idx, max_copies=50, index=index)
            assert len(indexed) == len(dense)
            for G, H in zip(indexed, dense, strict=True):
                np.testing.assert_allclose(G, H, atol=1e-9)
        rooms += room.zone_id in b.twinned
        if room.zone_id in b.twinned:
            idx = np.array([cm.index_of(o) for o in room.object_ids])
            assert copy_transforms(cm, idx, index=index)  # its twin, at least
    assert rooms >= 4
