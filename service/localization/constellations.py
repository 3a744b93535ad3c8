"""Hypotheses from constellations: the search of large maps (buildings of many similar rooms).

The one-room search (:mod:`quadloc.service.localization.search`) samples label-compatible
triplets of the whole map: in a building of R rooms almost all of them mix rooms, and the
budget is spent before the right one comes up. Here (maps of at least
:data:`PLACE_SEARCH_MIN_OBJECTS` objects) hypotheses come only from objects that can be seen
together (:mod:`quadloc.maps.places`):

1. detection triples, largest detections first (:func:`detection_triples`);
2. for each, the covisible map triplets with the detections' labels
   (:meth:`quadloc.maps.places.PlaceIndex.pairs_for`, joined on the first object), kept when the
   pair distances agree with the distances implied by the detections' rays at the depths their
   sizes give (:func:`quadloc.service.localization.hypotheses.size_depths`; a coarse test,
   :data:`GEOMETRY_RELATIVE_TOLERANCE`), at most :data:`MAX_TRIPLETS` per triple;
3. P3P on the centres (:func:`quadloc.service.localization.hypotheses.p3p_hypotheses_batch`);
4. each pose is scored against the objects covisible with its triplet's first object only
   (:func:`centre_hits`: detections whose centre sees a same-label object's projected centre
   inside 1.5 x the ellipse): the cost per pose does not depend on the map's size;
5. the best poses of each *place* (the grid cell of the triplet's first object), the
   :data:`MAX_PLACES` best places, become the seeds of the one-room machinery run on the
   sub-map of those places' objects (:class:`PlaceSeeds`; ``pipeline.localize``): exact
   scoring, refinement, and the ambiguity check between places.

Cost: bounded by :data:`MAX_TRIPLETS` per detection triple and :data:`MAX_TRIPLES` triples,
whatever the number of rooms. All poses ``camera_from_world`` (4x4, OpenCV axes).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray, IntArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.places import PlaceIndex
from quadloc.service.localization.hypotheses import p3p_grunert_batch, size_depths

__all__ = [
    "MAX_PLACES",
    "MAX_TRIPLES",
    "MAX_TRIPLETS",
    "PLACE_SEARCH_MIN_OBJECTS",
    "PlaceSeeds",
    "centre_hits",
    "detection_triples",
    "place_seeds",
]

#: Maps with at least this many objects are searched by constellations (smaller maps: the
#: one-room search, unchanged).
PLACE_SEARCH_MIN_OBJECTS = 64
#: Detection triples tried (largest detections first) and map triplets per triple.
MAX_TRIPLES = 6
MAX_TRIPLETS = 3000
#: Detections the triples are drawn from (the largest), and the stop rule of
#: :func:`place_seeds`: a pose with support >= ``STOP_SUPPORT`` x D and >= ``STOP_MIN_SUPPORT``
#: ends the search over triples; at most ``MAX_TOTAL_TRIPLETS`` triplets per frame.
TOP_DETECTIONS = 6
STOP_SUPPORT = 0.65
STOP_MIN_SUPPORT = 2.5
MAX_TOTAL_TRIPLETS = 6000
#: Places kept (best centre-hit count first) and seed poses per place.
MAX_PLACES = 12
SEEDS_PER_PLACE = 2
#: Pair-distance test: ``|predicted - map| <= rel * max(predicted, map) + abs``.
GEOMETRY_RELATIVE_TOLERANCE = 0.5
GEOMETRY_ABSOLUTE_TOLERANCE_M = 0.3
#: A detection is hit when a same-label object's projected centre is inside this multiple of
#: its ellipse.
HIT_SCALE = 1.5
#: Spread of ``ln(depth / depth from size)`` in :func:`centre_hits` (measured on simulated
#: frames: the 5-95 % range of the ratio is 0.76-1.27).
SIZE_LOG_SIGMA = 0.25
#: Most (pose, object, detection) evaluations per block of :func:`centre_hits`.
HIT_BLOCK = 1 << 21
#: Most covisible objects per pose in :func:`centre_hits` (the nearest to the triplet's first).
MAX_LOCAL = 32


@dataclass(frozen=True)
class PlaceSeeds:
    """What the constellation search found.

    Attributes:
        poses: (S, 4, 4) seed poses ``camera_from_world``, best first.
        hits: (S,) their support (:func:`centre_hits`).
        objects: sorted indices of the map objects of the kept places (the sub-map to score).
        places: number of distinct places with a pose; triplets: map triplets solved.
    """

    poses: FloatArray
    hits: FloatArray
    objects: IntArray
    places: int
    triplets: int


#: Six triples of the six largest detections such that every pair of them is avoided by one
#: (a covering design, the one of smallest rank sums; ``tests`` check the property).
_COVER_6 = ((0, 1, 2), (0, 1, 3), (0, 4, 5), (1, 4, 5), (2, 3, 4), (2, 3, 5))


def _avoided(pairs: set[tuple[int, int]], triple: tuple[int, ...]) -> int:
    """How many of ``pairs`` have neither member in ``triple``."""
    return sum(1 for x, y in pairs if x not in triple and y not in triple)


def detection_triples(params: FloatArray, max_triples: int = MAX_TRIPLES
                      ) -> list[tuple[int, ...]]:
    """Up to ``max_triples`` triples of detection rows (of ``params`` (D, 5)) among the
    :data:`TOP_DETECTIONS` largest, in an order that avoids every pair of them early (a
    wrong label or a spurious detection spoils every triple it is in): each next triple is
    the one avoiding the most pairs not yet avoided, then the largest (sum of area ranks)."""
    order = np.argsort(-(params[:, 2] * params[:, 3]), kind="stable").tolist()
    top = order[:min(len(order), TOP_DETECTIONS)]
    n = len(top)
    combos = sorted(_COVER_6 if n == 6 and max_triples >= len(_COVER_6)
                    else itertools.combinations(range(n), 3), key=lambda c: (sum(c), c))
    pending = set(itertools.combinations(range(n), 2))
    picked: list[tuple[int, ...]] = []
    while combos and len(picked) < max_triples:
        best = max(combos, key=lambda c: (_avoided(pending, c), -sum(c)))
        combos.remove(best)
        picked.append(best)
        pending = {(x, y) for x, y in pending if x in best or y in best}
    return [tuple(top[k] for k in c) for c in picked]


def _rays(camera: Camera, params: FloatArray) -> FloatArray:
    """Rays (D, 3) through the ellipse centres, unit depth (z = 1), camera frame."""
    return np.column_stack([(params[:, 0] - camera.cx) / camera.fx,
                            (params[:, 1] - camera.cy) / camera.fy, np.ones(len(params))])


def _geometry_ok(pred: FloatArray, dist: FloatArray) -> BoolArray:
    """Whether predicted and map pair distances (m) agree within the coarse tolerance."""
    return np.abs(pred - dist) <= (GEOMETRY_RELATIVE_TOLERANCE * np.maximum(pred, dist)
                                   + GEOMETRY_ABSOLUTE_TOLERANCE_M)


def _triplets(index: PlaceIndex, compiled: CompiledMap, camera: Camera, params: FloatArray,
              labels: list[str], triple: tuple[int, ...], rng: np.random.Generator
              ) -> IntArray:
    """Map triplets (T, 3) for a detection triple (module docstring, step 2)."""
    a, b, c = triple
    sub = params[[a, b, c]]
    rays = _rays(camera, sub)
    radius = np.prod(compiled.axes, axis=1) ** (1.0 / 3.0)

    def points(k: int, objs: IntArray) -> FloatArray:
        """Points (n, 3) camera frame of the triple's detection ``k`` (0, 1, 2) at the depths
        of objects ``objs``."""
        z = size_depths(camera, sub[k, 2:4], radius[objs])
        pts: FloatArray = z[:, None] * rays[k][None]
        return pts

    i_ab, j_ab, d_ab = index.pairs_for(labels[a], labels[b])
    i_ac, k_ac, d_ac = index.pairs_for(labels[a], labels[c])
    if len(i_ab) == 0 or len(i_ac) == 0:
        return np.zeros((0, 3), dtype=np.intp)
    ok = _geometry_ok(np.linalg.norm(points(0, i_ab) - points(1, j_ab), axis=1), d_ab)
    i_ab, j_ab = i_ab[ok], j_ab[ok]
    ok = _geometry_ok(np.linalg.norm(points(0, i_ac) - points(2, k_ac), axis=1), d_ac)
    i_ac, k_ac = i_ac[ok], k_ac[ok]
    # join on the first object (the pairs come sorted by it)
    lo = np.searchsorted(i_ac, i_ab, side="left")
    hi = np.searchsorted(i_ac, i_ab, side="right")
    count = hi - lo
    total = int(count.sum())
    if total == 0:
        return np.zeros((0, 3), dtype=np.intp)
    rows = np.repeat(np.arange(len(i_ab)), count)
    starts = np.repeat(lo - np.concatenate([[0], np.cumsum(count)[:-1]]), count)
    pos = np.arange(total) + starts
    I, J, K = i_ab[rows], j_ab[rows], k_ac[pos]
    d_jk = np.linalg.norm(compiled.centers[J] - compiled.centers[K], axis=1)
    keep = (J != K) & (d_jk <= index.view_range_m)
    I, J, K, d_jk = I[keep], J[keep], K[keep], d_jk[keep]
    ok = _geometry_ok(np.linalg.norm(points(1, J) - points(2, K), axis=1), d_jk)
    out = np.column_stack([I[ok], J[ok], K[ok]])
    if len(out) > MAX_TRIPLETS:
        out = out[np.sort(rng.choice(len(out), MAX_TRIPLETS, replace=False))]
    return out


def centre_hits(camera: Camera, camera_from_world: FloatArray, local: IntArray,
                local_valid: BoolArray, compiled: CompiledMap, params: FloatArray,
                label_codes: IntArray, object_codes: IntArray) -> FloatArray:
    """How well each pose (M, 4, 4) explains the detections (``params`` (D, 5), label codes
    (D,)) with its local objects ``local`` (M, L) (``local_valid`` (M, L): padding False).

    A detection's support is the best, over same-label local objects in front of the camera
    whose projected centre is inside :data:`HIT_SCALE` x the ellipse, of
    ``exp(-q / 2) exp(-(ln(z / z_size))^2 / (2 SIZE_LOG_SIGMA^2))`` (``q``: the centre's squared
    normalised distance in the ellipse, 1 on its contour; ``z``: the object's depth, ``z_size``:
    the depth its size implies, :func:`quadloc.service.localization.hypotheses.size_depths`);
    0 when there is none. Returns (M,) the sums over the detections (at most D)."""
    m_total, n_local = local.shape
    n_det = len(params)
    out = np.zeros(m_total)
    cos, sin = np.cos(params[:, 4]), np.sin(params[:, 4])
    radius = np.prod(compiled.axes, axis=1) ** (1.0 / 3.0)
    step = max(1, HIT_BLOCK // max(1, n_local * n_det))
    for s in range(0, m_total, step):
        T = camera_from_world[s:s + step]
        L = local[s:s + step]
        X = np.einsum("mij,mlj->mli", T[:, :3, :3], compiled.centers[L]) + T[:, None, :3, 3]
        z = X[..., 2]
        front = (z > 0.05) & local_valid[s:s + step]
        zs = np.where(front, z, 1.0)
        u = camera.fx * X[..., 0] / zs + camera.cx
        v = camera.fy * X[..., 1] / zs + camera.cy
        dx = u[..., None] - params[:, 0]
        dy = v[..., None] - params[:, 1]
        p = (dx * cos + dy * sin) / params[:, 2]
        q = (-dx * sin + dy * cos) / params[:, 3]
        q2 = p * p + q * q
        ok = ((q2 <= HIT_SCALE ** 2) & (object_codes[L][..., None] == label_codes)
              & front[..., None])
        z_size = size_depths(camera, params[None, None, :, 2:4], radius[L][..., None])
        log_ratio = np.log(zs[..., None] / z_size)
        w = np.exp(-0.5 * q2 - 0.5 * (log_ratio / SIZE_LOG_SIGMA) ** 2)
        out[s:s + step] = np.where(ok, w, 0.0).max(axis=1).sum(axis=1)
    return out


def _local_objects(index: PlaceIndex, compiled: CompiledMap, i: int) -> IntArray:
    """Object ``i`` and its covisible neighbours, at most :data:`MAX_LOCAL` (nearest first)."""
    nb = np.concatenate([[i], index.neighbours(i)]).astype(np.intp)
    if len(nb) > MAX_LOCAL:
        d = np.linalg.norm(compiled.centers[nb] - compiled.centers[i], axis=1)
        nb = nb[np.argsort(d, kind="stable")[:MAX_LOCAL]]
    return nb


def place_seeds(compiled: CompiledMap, index: PlaceIndex, camera: Camera, params: FloatArray,
                labels: list[str], rng: np.random.Generator,
                deadline: Deadline | None = None) -> PlaceSeeds:
    """The constellation search (module docstring) for the usable detections ``params``
    (D, 5) px / rad with ``labels`` (D,); D >= 3. Detection triples are tried in the order of
    :func:`detection_triples` until one gives a pose of support >= :data:`STOP_SUPPORT` x D
    (and >= :data:`STOP_MIN_SUPPORT`), :data:`MAX_TOTAL_TRIPLETS` triplets were solved, or the
    ``deadline`` passed."""
    cats = sorted(set(compiled.categories))
    code = {c: k for k, c in enumerate(cats)}
    object_codes = np.array([code[c] for c in compiled.categories], dtype=np.intp)
    label_codes = np.array([code.get(x, -1) for x in labels], dtype=np.intp)
    local: dict[int, IntArray] = {}
    all_poses, all_scores, all_anchor = [], [], []
    n_triplets = 0
    for triple in detection_triples(params):
        if n_triplets >= MAX_TOTAL_TRIPLETS or deadline_passed(deadline):
            break
        trip = _triplets(index, compiled, camera, params, labels, triple, rng)
        trip = trip[:MAX_TOTAL_TRIPLETS - n_triplets]
        n_triplets += len(trip)
        if len(trip) == 0:
            continue
        img = np.broadcast_to(params[list(triple), :2], (len(trip), 3, 2))
        poses, owner = p3p_grunert_batch(img, compiled.centers[trip], camera)
        if len(poses) == 0:
            continue
        anchor = trip[owner, 0]
        uniq, inv = np.unique(anchor, return_inverse=True)
        lists = [local.setdefault(i, _local_objects(index, compiled, i)) for i in uniq.tolist()]
        width = max(len(x) for x in lists)
        table = np.zeros((len(uniq), width), dtype=np.intp)
        valid = np.zeros((len(uniq), width), dtype=bool)
        for r, nb in enumerate(lists):
            table[r, :len(nb)] = nb
            valid[r, :len(nb)] = True
        scores = centre_hits(camera, poses, table[inv], valid[inv], compiled, params,
                             label_codes, object_codes)
        all_poses.append(poses)
        all_scores.append(scores)
        all_anchor.append(anchor)
        if scores.max() >= max(STOP_MIN_SUPPORT, STOP_SUPPORT * len(params)):
            break
    if not all_poses:
        return PlaceSeeds(np.zeros((0, 4, 4)), np.zeros(0), np.zeros(0, dtype=np.intp), 0,
                          n_triplets)
    poses = np.concatenate(all_poses)
    hits = np.concatenate(all_scores)
    anchor = np.concatenate(all_anchor)
    # places: the grid cell of the anchor; the best poses of the best places
    place_key = np.unique(index.cells[anchor], axis=0, return_inverse=True)[1].ravel()
    order = np.lexsort((np.arange(len(hits)), -hits))
    chosen: dict[int, list[int]] = {}
    for m in order.tolist():
        key = int(place_key[m])
        if key not in chosen:
            if len(chosen) >= MAX_PLACES:
                continue
            chosen[key] = []
        if len(chosen[key]) < SEEDS_PER_PLACE:
            chosen[key].append(m)
    picked = np.array(sorted((m for ms in chosen.values() for m in ms),
                             key=lambda m: (-float(hits[m]), m)), dtype=np.intp)
    objects = np.unique(np.concatenate([local[int(anchor[m])] for m in picked]))
    return PlaceSeeds(poses[picked], hits[picked], objects, int(place_key.max()) + 1,
                      n_triplets)
