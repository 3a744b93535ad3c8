"""Hypotheses from constellations: the search of large maps (buildings of many similar rooms).

The one-room search (:mod:`quadloc.service.localization.search`) samples label-compatible
triplets of the whole map: in a building of R rooms almost all of them mix rooms, and the
budget is spent before the right one comes up. Here (maps of at least
:data:`PLACE_SEARCH_MIN_OBJECTS` objects) hypotheses come only from objects that can be seen
together (:mod:`quadloc.maps.places`):

1. detection triples, largest detections first (:func:`detection_triples`);
2. for each, the covisible map triplets with the detections' labels
   (:meth:`quadloc.maps.places.PlaceIndex.pairs_for`, joined on the first object), kept when the
   pair distances can be spanned by the detections' rays at depths within
   :data:`TRIPLET_DEPTH_RATIO` of those their sizes give
   (:func:`quadloc.service.localization.hypotheses.size_depths`; :func:`_pair_possible`, the
   exact pairwise form of the depth test of step 3), at most :data:`MAX_TRIPLETS` per triple:
   those whose pair distances are nearest the distances of the rays' points at those depths
   (:func:`_misfit_term`; at most :data:`SAME_SHAPE_TRIPLETS` of one geometry, the copies of
   a room; :func:`_least_misfit`). Before, a random subset of 3,000: in a 1,000-room
   building of random layouts (tuning seed 5) the true triplet ranks in the first 2 %
   (median; 90th percentile 12 %) by misfit, while the random subset kept it with
   probability 3,000 / T (median 65 %);
3. P3P on the centres (:func:`quadloc.service.localization.hypotheses.p3p_grunert_batch`);
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
import math
from dataclasses import dataclass

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray, IntArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera
from quadloc.factors.jit import jit
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.places import VIEW_RANGE_M, PlaceIndex
from quadloc.service.localization.hypotheses import p3p_grunert_batch, size_depths

__all__ = [
    "MAX_PLACES",
    "MAX_TRIPLES",
    "MAX_TRIPLETS",
    "PLACE_SEARCH_MIN_OBJECTS",
    "PlaceSeeds",
    "centre_hits",
    "compile_place_kernels",
    "detection_triples",
    "place_seeds",
]

#: Maps with at least this many objects are searched by constellations (smaller maps: the
#: one-room search, unchanged).
PLACE_SEARCH_MIN_OBJECTS = 64
#: Detection triples tried (largest detections first) and map triplets per triple.
MAX_TRIPLES = 6
MAX_TRIPLETS = 1000
#: The cap keeps the triplets of least misfit (:func:`_least_misfit`), at most this many of one
#: misfit value (to this resolution): the same objects in exact copies of a room.
SAME_SHAPE_TRIPLETS = 8
SAME_SHAPE_RESOLUTION = 1e-9
#: Detections the triples are drawn from (the largest), and the stop rule of
#: :func:`place_seeds`: a pose with support >= ``STOP_SUPPORT`` x D and >= ``STOP_MIN_SUPPORT``
#: ends the search over triples; at most ``MAX_TOTAL_TRIPLETS`` triplets per frame.
TOP_DETECTIONS = 6
STOP_SUPPORT = 0.95
STOP_MIN_SUPPORT = 2.5
MAX_TOTAL_TRIPLETS = 12000
#: Detection triples (that gave poses) searched over the whole map; the later ones search only
#: the :data:`FOCUS_PLACES` best places found by then (:func:`_focus`): the cost of a frame
#: grows with the rooms for these first triples only. Only once they solved at least
#: :data:`FOCUS_MIN_TRIPLETS` triplets (a small map is searched whole: cheap) and a pose
#: explains at least :data:`FOCUS_MIN_SUPPORT` x D detections (and :data:`STOP_MIN_SUPPORT`):
#: triples spoilt by a wrong detection find chance poses in a few places only, and focusing
#: on those hid every copy of the true room (a false accept on exact copies, report seed).
FULL_TRIPLES = 2
FOCUS_PLACES = 48
FOCUS_MIN_TRIPLETS = 1000
FOCUS_MIN_SUPPORT = 0.6
#: A P3P pose is kept only when its triplet's objects are at depths within this factor of the
#: depths their sizes give (:func:`quadloc.service.localization.hypotheses.size_depths`).
TRIPLET_DEPTH_RATIO = 1.6
#: Places kept (best centre-hit count first) and seed poses per place.
MAX_PLACES = 24
SEEDS_PER_PLACE = 1
#: Rounding slack (m) of the pair-distance test :func:`_pair_possible`.
GEOMETRY_SLACK_M = 0.01
#: A detection is hit when a same-label object's projected centre is inside this multiple of
#: its ellipse.
HIT_SCALE = 1.5
#: Spread of ``ln(depth / depth from size)`` in :func:`centre_hits` (measured on simulated
#: frames: the 5-95 % range of the ratio is 0.76-1.27).
SIZE_LOG_SIGMA = 0.25


@dataclass(frozen=True)
class PlaceSeeds:
    """What the constellation search found.

    Attributes:
        poses: (S, 4, 4) seed poses ``camera_from_world``, best first.
        hits: (S,) their support (:func:`centre_hits`).
        objects: sorted indices of the map objects of the kept places (the sub-map to score).
        places: number of distinct places with a pose; triplets: map triplets solved.
        hinted: (S,) whether each seed's place is one of the hint's (all False without).
    """

    poses: FloatArray
    hits: FloatArray
    objects: IntArray
    places: int
    triplets: int
    hinted: BoolArray


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


@jit
def _pair_possible(za: float, zb: float, dist: float, aa: float, bb: float, ab: float,
                   rho: float, slack: float) -> bool:
    """Whether two objects ``dist`` m apart can sit on two rays ``ray_a``, ``ray_b`` (unit
    depth, camera frame; ``aa``, ``bb``, ``ab``: their dot products) at depths within ``rho``
    (:data:`TRIPLET_DEPTH_RATIO`) of ``za``, ``zb`` (the depths their sizes give): ``dist``
    between the least and the largest distance of ``|x ray_a - y ray_b|`` over that box of
    depths ``(x, y)``. The largest is at a corner; the least (a convex function, its only
    stationary point the origin, outside the box) on an edge, where the free depth is the
    projection clipped to its interval. Exactly the pairwise part of the depth test that
    :func:`place_seeds` applies after P3P: a necessary condition, no triplet that test keeps
    is lost here (``slack``, :data:`GEOMETRY_SLACK_M`, for rounding)."""
    lo_a, hi_a, lo_b, hi_b = za / rho, za * rho, zb / rho, zb * rho
    # squared distances (no roots): dist - slack <= dmax and dist + slack >= dmin
    far = dist - slack
    if far > 0.0 and far * far > max(
            max(_span2(lo_a, lo_b, aa, bb, ab), _span2(lo_a, hi_b, aa, bb, ab)),
            max(_span2(hi_a, lo_b, aa, bb, ab), _span2(hi_a, hi_b, aa, bb, ab))):
        return False
    near = dist + slack
    return near * near >= min(
        min(_span2(lo_a, min(max(lo_a * ab / bb, lo_b), hi_b), aa, bb, ab),
            _span2(hi_a, min(max(hi_a * ab / bb, lo_b), hi_b), aa, bb, ab)),
        min(_span2(min(max(lo_b * ab / aa, lo_a), hi_a), lo_b, aa, bb, ab),
            _span2(min(max(hi_b * ab / aa, lo_a), hi_a), hi_b, aa, bb, ab)))


@jit
def _span2(x: float, y: float, aa: float, bb: float, ab: float) -> float:
    """``|x ray_a - y ray_b|^2`` from the rays' dot products (:func:`_pair_possible`)."""
    return max(x * x * aa + y * y * bb - 2.0 * x * y * ab, 0.0)


@jit
def _possible_pairs(first: IntArray, second: IntArray, dist: FloatArray, allowed: BoolArray,
                    restrict: bool, z_first: float, z_second: float, radius: FloatArray,
                    aa: float, bb: float, ab: float, rho: float, slack: float) -> IntArray:
    """Positions of the object pairs ``(first[p], second[p])`` (``dist[p]`` m apart) of two
    detections that pass :func:`_pair_possible` (``z_first``, ``z_second``: the detections'
    size depths per metre of object radius; ``aa``, ``bb``, ``ab``: their rays' dot
    products); with ``restrict``, only pairs whose first object ``allowed`` marks. In order."""
    keep = np.empty(len(first), dtype=np.intp)
    m = 0
    for p in range(len(first)):
        i = first[p]
        if restrict and not allowed[i]:
            continue
        if _pair_possible(z_first * radius[i], z_second * radius[second[p]], dist[p], aa, bb, ab,
                          rho, slack):
            keep[m] = p
            m += 1
    return keep[:m]


@jit
def _triplets_kernel(i_ab: IntArray, j_ab: IntArray, d_ab: FloatArray, i_ac: IntArray,
                     k_ac: IntArray, d_ac: FloatArray, allowed: BoolArray, restrict: bool,
                     dots: FloatArray, z_unit: FloatArray, radius: FloatArray,
                     centers: FloatArray, rho: float, slack: float, view_range: float
                     ) -> tuple[IntArray, FloatArray]:
    """:func:`_triplets` before its cap: the pairs ``(i, j)`` of detections 0-1 and ``(i, k)``
    of 0-2 (sorted by ``i``; with ``restrict``, only those whose ``i`` ``allowed`` marks)
    that pass :func:`_pair_possible`, joined on ``i`` (the 0-1 pairs' order, then the 0-2
    pairs'), kept when ``j != k``, ``|c_j - c_k| <= view_range`` and the pair ``(j, k)``
    passes :func:`_pair_possible` for detections 1-2. ``dots`` (3, 3): the rays' dot
    products; ``z_unit`` (3,): each detection's size depth per metre of object radius.
    Returns (T, 3) object indices and their (T,) misfits (the sums of :func:`_misfit_term`
    over the three pairs: the order of :func:`_triplets`' cap)."""
    keep_ab = _possible_pairs(i_ab, j_ab, d_ab, allowed, restrict, z_unit[0], z_unit[1], radius,
                              dots[0, 0], dots[1, 1], dots[0, 1], rho, slack)
    keep_ac = _possible_pairs(i_ac, k_ac, d_ac, allowed, restrict, z_unit[0], z_unit[2], radius,
                              dots[0, 0], dots[2, 2], dots[0, 2], rho, slack)
    m_ab, m_ac = len(keep_ab), len(keep_ac)
    # the misfit terms of the kept pairs 0-1 and 0-2 (each pair's once, not per triplet)
    t_ab = np.empty(m_ab)
    for r in range(m_ab):
        pa = keep_ab[r]
        t_ab[r] = _misfit_term(z_unit[0] * radius[i_ab[pa]], z_unit[1] * radius[j_ab[pa]],
                               dots[0, 0], dots[1, 1], dots[0, 1], d_ab[pa])
    t_ac = np.empty(m_ac)
    for r in range(m_ac):
        pc = keep_ac[r]
        t_ac[r] = _misfit_term(z_unit[0] * radius[i_ac[pc]], z_unit[2] * radius[k_ac[pc]],
                               dots[0, 0], dots[2, 2], dots[0, 2], d_ac[pc])
    # the join on the first object (both lists sorted by it), into a buffer grown by doubling
    out = np.empty((1024, 3), dtype=np.intp)
    misfit = np.empty(1024)
    n = 0
    q = 0
    for r in range(m_ab):
        pa = keep_ab[r]
        i, j = i_ab[pa], j_ab[pa]
        while q < m_ac and i_ac[keep_ac[q]] < i:
            q += 1
        e = q
        while e < m_ac and i_ac[keep_ac[e]] == i:
            k = k_ac[keep_ac[e]]
            e += 1
            if j == k:
                continue
            dx = centers[j, 0] - centers[k, 0]
            dy = centers[j, 1] - centers[k, 1]
            dz = centers[j, 2] - centers[k, 2]
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            if not d <= view_range:
                continue
            if _pair_possible(z_unit[1] * radius[j], z_unit[2] * radius[k], d, dots[1, 1],
                              dots[2, 2], dots[1, 2], rho, slack):
                if n == len(out):
                    grown = np.empty((2 * len(out), 3), dtype=np.intp)
                    grown[:n] = out
                    out = grown
                    grown_m = np.empty(2 * len(misfit))
                    grown_m[:n] = misfit
                    misfit = grown_m
                out[n, 0] = i
                out[n, 1] = j
                out[n, 2] = k
                misfit[n] = t_ab[r] + t_ac[e - 1] + _misfit_term(
                    z_unit[1] * radius[j], z_unit[2] * radius[k], dots[1, 1], dots[2, 2],
                    dots[1, 2], d)
                n += 1
    return out[:n].copy(), misfit[:n].copy()


@jit
def _misfit_term(za: float, zb: float, aa: float, bb: float, ab: float, dist: float) -> float:
    """How far two map objects ``dist`` m apart are from the distance ``d_size`` of two points
    on rays ``a``, ``b`` (unit depth; ``aa``, ``bb``, ``ab`` their dot products) at the depths
    ``za``, ``zb`` their sizes give: ``tanh(ln(d_size / dist))^2 = ((r - 1) / (r + 1))^2``
    with ``r = (d_size / dist)^2``; 0 for equal distances, symmetric in the ratio and its
    inverse, below 1 (one wildly wrong size counts as one term, not without bound)."""
    r = _span2(za, zb, aa, bb, ab) / max(dist * dist, 1e-12)
    t = (r - 1.0) / (r + 1.0)
    return t * t


def _triplets(index: PlaceIndex, camera: Camera, params: FloatArray,
              labels: list[str], triple: tuple[int, ...], allowed: BoolArray | None = None
              ) -> IntArray:
    """Map triplets (T, 3) for a detection triple (module docstring, step 2); with
    ``allowed`` (N,), only those whose first object it marks; at most :data:`MAX_TRIPLETS`,
    those of least misfit (:func:`_least_misfit`), in the kernel's order. One compiled
    kernel (:func:`_triplets_kernel`) over the label pairs' covisible pairs: no temporaries
    of their size."""
    a, b, c = triple
    sub = params[[a, b, c]]
    rays = _rays(camera, sub)
    i_ab, j_ab, d_ab = index.pairs_for(labels[a], labels[b])
    i_ac, k_ac, d_ac = index.pairs_for(labels[a], labels[c])
    if len(i_ab) == 0 or len(i_ac) == 0:
        return np.zeros((0, 3), dtype=np.intp)
    out, misfit = _triplets_kernel(
        i_ab, j_ab, d_ab, i_ac, k_ac, d_ac,
        np.ones(1, dtype=bool) if allowed is None else np.array(allowed, dtype=bool),
        allowed is not None, np.array(rays @ rays.T, dtype=float),
        np.array(size_depths(camera, sub[:, 2:4], 1.0), dtype=float), index.radius,
        index.centers, TRIPLET_DEPTH_RATIO, GEOMETRY_SLACK_M, index.view_range_m)
    if len(out) > MAX_TRIPLETS:
        out = out[np.sort(_least_misfit(misfit, MAX_TRIPLETS, SAME_SHAPE_TRIPLETS))]
    return out


def _rank_in_runs(sorted_keys: np.ndarray) -> IntArray:
    """Each element's position (0, 1, ...) within its run of equal values of ``sorted_keys``
    (n,) (equal values adjacent)."""
    n = len(sorted_keys)
    start = np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]])
    rank: IntArray = np.arange(n) - np.repeat(start, np.diff(np.r_[start, n]))
    return rank


def _least_misfit(misfit: FloatArray, cap: int, per_shape: int) -> IntArray:
    """Positions of the ``cap`` triplets of least ``misfit`` (T,), at most ``per_shape`` of
    each value (rounded to :data:`SAME_SHAPE_RESOLUTION`): exact copies of a room give the
    same misfit for the same objects, and without this the cap would hold one explanation of
    the detections repeated in ``cap`` rooms. Sorted within a pool of the least misfits
    (partition: linear), grown while it holds fewer than ``cap`` distinct enough."""
    pool = min(len(misfit), 4 * cap)
    while True:
        part = (np.argpartition(misfit, pool - 1)[:pool] if pool < len(misfit)
                else np.arange(len(misfit)))
        order = part[np.argsort(misfit[part], kind="stable")]
        rank = _rank_in_runs(np.round(misfit[order] / SAME_SHAPE_RESOLUTION))
        picked: IntArray = order[rank < per_shape][:cap]
        if len(picked) == cap or pool == len(misfit):
            return picked
        pool = min(len(misfit), 4 * pool)


def centre_hits(camera: Camera, camera_from_world: FloatArray, local: IntArray,
                local_valid: BoolArray, compiled: CompiledMap, params: FloatArray,
                label_codes: IntArray, object_codes: IntArray) -> FloatArray:
    """How well each pose (M, 4, 4) explains the detections (``params`` (D, 5), label codes
    (D,)) with its local objects ``local`` (M, L) (``local_valid`` (M, L): padding False).

    A detection's support is the best, over same-label local objects in front of the camera
    (depth > 0.05 m) whose projected centre is inside :data:`HIT_SCALE` x the ellipse, of
    ``exp(-q / 2) exp(-(ln(z / z_size))^2 / (2 SIZE_LOG_SIGMA^2))`` (``q``: the centre's squared
    normalised distance in the ellipse, 1 on its contour; ``z``: the object's depth, ``z_size``:
    the depth its size implies, :func:`quadloc.service.localization.hypotheses.size_depths`);
    0 when there is none. Returns (M,) the sums over the detections (at most D). One compiled
    kernel (:func:`_centre_hits_kernel`): no (M, L, D) temporaries. The place search calls
    :func:`_anchor_hits` (the same kernel on the place index's own tables)."""
    radius = compiled.mean_radii
    codes = np.asarray(object_codes, dtype=np.intp)
    return _hits(camera, camera_from_world, np.arange(len(camera_from_world), dtype=np.intp),
                 _readonly(local, np.intp), _readonly(local_valid, bool),
                 _readonly(compiled.centers, float), _readonly(radius, float),
                 _readonly(codes, np.intp), np.ones(int(codes.max(initial=0)) + 1, dtype=bool),
                 params, label_codes)


def _readonly(a: np.ndarray, dtype: type) -> np.ndarray:
    """``a`` as a read-only C array of ``dtype`` (the place index's arrays are: one kernel
    specialisation for both callers of :func:`_hits`)."""
    out: np.ndarray = np.array(a, dtype=dtype, order="C")
    out.setflags(write=False)
    return out


def _anchor_hits(camera: Camera, camera_from_world: FloatArray, anchor: IntArray,
                 index: PlaceIndex, wanted: BoolArray, params: FloatArray,
                 label_codes: IntArray) -> FloatArray:
    """:func:`centre_hits` of poses (M, 4, 4) with the local objects of their ``anchor`` (M,)
    objects (:attr:`quadloc.maps.places.PlaceIndex.local`), those of a label ``wanted``
    (labels,) only (the others hit no detection): read from the index, nothing gathered or
    copied per request."""
    return _hits(camera, camera_from_world, np.array(anchor, dtype=np.intp), index.local,
                 index.local_valid, index.centers, index.radius, index.codes,
                 np.array(wanted, dtype=bool), params, label_codes)


def _hits(camera: Camera, camera_from_world: FloatArray, rows: IntArray, local: IntArray,
          valid: BoolArray, centers: FloatArray, radius: FloatArray, codes: IntArray,
          wanted: BoolArray, params: FloatArray, label_codes: IntArray) -> FloatArray:
    """:func:`_centre_hits_kernel` with the camera's and the detections' arguments."""
    p = np.array(params, dtype=float)
    # the depth each detection's size gives per unit object radius (size_depths, r = 1)
    z_unit = np.array(size_depths(camera, p[:, 2:4], 1.0), dtype=float)
    out: FloatArray = _centre_hits_kernel(
        np.array(camera_from_world, dtype=float), rows, local, valid, centers, radius, codes,
        wanted, p, z_unit, np.array(label_codes, dtype=np.intp), float(camera.fx),
        float(camera.fy), float(camera.cx), float(camera.cy), HIT_SCALE ** 2,
        1.0 / SIZE_LOG_SIGMA ** 2)
    return out


def compile_place_kernels() -> None:
    """Compile (or load from numba's cache) the place search's kernels (:func:`centre_hits`,
    :func:`_triplets_kernel`, :func:`quadloc.service.localization.hypotheses.p3p_grunert_batch`),
    so that no request pays for it: the service calls it at start-up with
    :func:`quadloc.factors.pose_residuals.compile_kernels`."""
    camera = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)
    p3p_grunert_batch(np.array([[[300.0, 200.0], [350.0, 260.0], [280.0, 250.0]]]),
                      np.array([[[0.0, 0.0, 3.0], [0.3, 0.2, 3.1], [-0.1, 0.3, 2.9]]]), camera)
    # the argument types of the requests' calls: the place index's arrays are read-only
    one_i, one_f = _readonly(np.zeros(1), np.intp), _readonly(np.ones(1), float)
    _hits(camera, np.eye(4)[None], np.zeros(1, dtype=np.intp), _readonly(np.zeros((1, 1)), np.intp),
          _readonly(np.ones((1, 1)), bool), _readonly(np.array([[0.0, 0.0, 2.0]]), float), one_f,
          one_i, np.ones(1, dtype=bool), np.array([[320.0, 240.0, 50.0, 40.0, 0.1]]),
          np.zeros(1, dtype=np.intp))
    _triplets_kernel(one_i, one_i, one_f, one_i, one_i, one_f, np.ones(1, dtype=bool), False,
                     np.eye(3), np.ones(3), one_f, _readonly(np.zeros((1, 3)), float),
                     TRIPLET_DEPTH_RATIO, GEOMETRY_SLACK_M, VIEW_RANGE_M)


@jit
def _centre_hits_kernel(T: FloatArray, rows: IntArray, local: IntArray, valid: BoolArray,
                        centers: FloatArray, radius: FloatArray, codes: IntArray,
                        wanted: BoolArray, params: FloatArray, z_unit: FloatArray,
                        label_codes: IntArray, fx: float, fy: float, cx: float, cy: float,
                        hit2: float, inv_s2: float) -> FloatArray:
    """:func:`centre_hits` (its arguments as arrays): pose ``m`` against the objects of row
    ``rows[m]`` of the table ``local`` / ``valid`` whose label ``wanted`` marks; ``z_unit``
    (D,): the size depth per metre of object radius; ``hit2``: HIT_SCALE^2; ``inv_s2``:
    1 / SIZE_LOG_SIGMA^2."""
    m_total = len(rows)
    n_local = local.shape[1]
    n_det = params.shape[0]
    out = np.zeros(m_total)
    best = np.zeros(n_det)
    cos = np.cos(params[:, 4])
    sin = np.sin(params[:, 4])
    for m in range(m_total):
        best[:] = 0.0
        row = rows[m]
        for k in range(n_local):
            if not valid[row, k]:
                continue
            o = local[row, k]
            if not wanted[codes[o]]:
                continue
            X = centers[o]
            x = T[m, 0, 0] * X[0] + T[m, 0, 1] * X[1] + T[m, 0, 2] * X[2] + T[m, 0, 3]
            y = T[m, 1, 0] * X[0] + T[m, 1, 1] * X[1] + T[m, 1, 2] * X[2] + T[m, 1, 3]
            z = T[m, 2, 0] * X[0] + T[m, 2, 1] * X[1] + T[m, 2, 2] * X[2] + T[m, 2, 3]
            if not z > 0.05:
                continue
            u = fx * x / z + cx
            v = fy * y / z + cy
            for d in range(n_det):
                if label_codes[d] != codes[o]:
                    continue
                dx = u - params[d, 0]
                dy = v - params[d, 1]
                a = (dx * cos[d] + dy * sin[d]) / params[d, 2]
                b = (-dx * sin[d] + dy * cos[d]) / params[d, 3]
                q2 = a * a + b * b
                if q2 > hit2:
                    continue
                lr = np.log(z / (z_unit[d] * radius[o]))
                w = np.exp(-0.5 * q2 - 0.5 * lr * lr * inv_s2)
                if w > best[d]:
                    best[d] = w
        out[m] = best.sum()
    return out


def _focus(index: PlaceIndex, anchor: IntArray, hits: FloatArray, hinted: BoolArray | None
           ) -> BoolArray:
    """The objects (N,) mask the later detection triples search: the local objects of the
    best anchor of each of the :data:`FOCUS_PLACES` best places (grid cells of the anchors,
    by their best support) found so far, and the hint's objects."""
    order = np.lexsort((np.arange(len(hits)), -hits))
    _, first = np.unique(index.cell_ids[anchor[order]], return_index=True)
    best = anchor[order[np.sort(first)[:FOCUS_PLACES]]]
    allowed = np.zeros(len(index.codes), dtype=bool)
    allowed[index.local[best][index.local_valid[best]]] = True
    if hinted is not None:
        allowed |= hinted
    return allowed


def _first_per_place(ranking: IntArray, place_key: IntArray, per_place: int) -> IntArray:
    """``ranking`` (pose indices, best first) kept to the first ``per_place`` poses of each
    place (``place_key`` of every pose), in its order: the only ones the choice of seeds of
    :func:`place_seeds` can take (a place takes its best poses not yet taken, at most
    ``per_place``), so its loop runs over places, not over every pose."""
    keys = place_key[ranking]
    by_key = np.argsort(keys, kind="stable")
    rank = _rank_in_runs(keys[by_key])
    keep = np.zeros(len(keys), dtype=bool)
    keep[by_key[rank < per_place]] = True
    out: IntArray = ranking[keep]
    return out


def place_seeds(compiled: CompiledMap, index: PlaceIndex, camera: Camera, params: FloatArray,
                labels: list[str], deadline: Deadline | None = None,
                hinted: BoolArray | None = None
                ) -> PlaceSeeds:
    """The constellation search (module docstring) for the usable detections ``params``
    (D, 5) px / rad with ``labels`` (D,); D >= 3. Detection triples are tried in the order of
    :func:`detection_triples` until one gives a pose of support >= :data:`STOP_SUPPORT` x D
    (and >= :data:`STOP_MIN_SUPPORT`), :data:`MAX_TOTAL_TRIPLETS` triplets were solved, or the
    ``deadline`` passed; after :data:`FULL_TRIPLES` triples with poses (and the conditions of
    :data:`FOCUS_MIN_TRIPLETS`), only in the best places so far (:func:`_focus`). ``hinted``
    (N,) marks the objects of a place hint: the triples are first tried there only (until one
    explains the frame by the same rule), then
    over the whole map as without a hint (a hint adds candidates, never removes the
    evidence's); half of the :data:`MAX_PLACES` places are the best whose triplet's first
    object is hinted."""
    code = {c: k for k, c in enumerate(index.labels)}
    label_codes = np.array([code.get(x, -1) for x in labels], dtype=np.intp)
    wanted = np.zeros(len(index.labels), dtype=bool)
    wanted[label_codes[label_codes >= 0]] = True
    all_poses: list[FloatArray] = []
    all_scores: list[FloatArray] = []
    all_anchor: list[IntArray] = []
    n_triplets = 0
    n_full = 0  # triples of the whole map that gave poses
    focus: BoolArray | None = None
    triples = detection_triples(params)
    # a hint's places first (every triple there: a few rooms, cheap), then the whole map
    plan: list[tuple[tuple[int, ...], BoolArray | None]] = [
        (t, hinted) for t in (triples if hinted is not None else [])]
    plan += [(t, None) for t in triples]
    hinted_done = hinted is None
    for triple, restrict in plan:
        if n_triplets >= MAX_TOTAL_TRIPLETS or deadline_passed(deadline):
            break
        if restrict is None:
            hinted_done = True
        elif hinted_done:
            continue  # the hint's places explained the frame: on to the whole map
        if (restrict is None and focus is None and n_full >= FULL_TRIPLES
                and n_triplets >= FOCUS_MIN_TRIPLETS
                and max(float(x.max()) for x in all_scores) >= max(
                    STOP_MIN_SUPPORT, FOCUS_MIN_SUPPORT * len(params))):
            focus = _focus(index, np.concatenate(all_anchor), np.concatenate(all_scores),
                           hinted)
        trip = _triplets(index, camera, params, labels, triple,
                         restrict if restrict is not None else focus)
        trip = trip[:MAX_TOTAL_TRIPLETS - n_triplets]
        n_triplets += len(trip)
        if len(trip) == 0:
            continue
        img = np.broadcast_to(params[list(triple), :2], (len(trip), 3, 2))
        # the triplet's own objects must sit at depths their sizes allow (tested in P3P)
        poses, owner = p3p_grunert_batch(
            img, index.centers[trip], camera,
            size_depth=size_depths(camera, params[list(triple), None, 2:4].transpose(1, 0, 2),
                                   index.radius[trip]),
            depth_ratio=TRIPLET_DEPTH_RATIO)
        if len(poses) == 0:
            continue
        anchor = trip[owner, 0]
        # the anchors' local objects (:attr:`PlaceIndex.local`) scored: those of a detected label
        scores = _anchor_hits(camera, poses, anchor, index, wanted, params, label_codes)
        all_poses.append(poses)
        all_scores.append(scores)
        all_anchor.append(anchor)
        n_full += restrict is None
        if scores.max() >= max(STOP_MIN_SUPPORT, STOP_SUPPORT * len(params)):
            if restrict is None:
                break
            hinted_done = True  # the evidence still searches the whole map
    if not all_poses:
        return PlaceSeeds(np.zeros((0, 4, 4)), np.zeros(0), np.zeros(0, dtype=np.intp), 0,
                          n_triplets, np.zeros(0, dtype=bool))
    poses = np.concatenate(all_poses)
    hits = np.concatenate(all_scores)
    anchor = np.concatenate(all_anchor)
    # places: the grid cell of the anchor; the best poses of the best places
    place_key = np.unique(index.cell_ids[anchor], return_inverse=True)[1].ravel()
    order = np.lexsort((np.arange(len(hits)), -hits))
    chosen: dict[int, list[int]] = {}
    passes = [(order, MAX_PLACES)]
    if hinted is not None:
        passes.insert(0, (order[np.asarray(hinted, dtype=bool)[anchor[order]]], MAX_PLACES // 2))
    for ranking, cap in passes:
        for m in _first_per_place(ranking, place_key, SEEDS_PER_PLACE).tolist():
            key = int(place_key[m])
            if key not in chosen:
                if len(chosen) >= cap:
                    if all(len(ms) >= SEEDS_PER_PLACE for ms in chosen.values()):
                        break  # nothing more can be added
                    continue
                chosen[key] = []
            if len(chosen[key]) < SEEDS_PER_PLACE and m not in chosen[key]:
                chosen[key].append(m)
    picked = np.array(sorted((m for ms in chosen.values() for m in ms),
                             key=lambda m: (-float(hits[m]), m)), dtype=np.intp)
    objects = np.unique(index.local[anchor[picked]][index.local_valid[anchor[picked]]])
    hinted_seed = (np.zeros(len(picked), dtype=bool) if hinted is None
                   else np.asarray(hinted, dtype=bool)[anchor[picked]])
    return PlaceSeeds(poses[picked], hits[picked], objects, int(place_key.max()) + 1,
                      n_triplets, hinted_seed)
