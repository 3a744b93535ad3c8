"""Copies of a constellation: where else in the map the objects that support an answer occur
with the same labels and the same geometry (exact copies of a room).

A pose found in one copy of a room explains the detections exactly as well in every other
copy; the search does not always find them all (a P3P of three centres can be metres off, and
the search stops when one pose explains the frame), so an answer could name a copy with no
rival listed. :func:`copy_transforms` finds the rigid transforms ``G`` (4x4, world to world)
carrying the answer's supporting objects onto another same-label set within
:data:`COPY_TOLERANCE_M`; ``G @ world_from_camera`` is then the same view in that copy, a
candidate that the caller verifies (refinement, inliers) and weighs in the ambiguity check.

On a large map (with its :class:`~quadloc.maps.places.PlaceIndex`) the candidate copies come from
the index's constellations (same-label pairs at the same distance) and the other objects are
looked up in its grid: no pass over every object of a label. The place search keeps at most
:data:`~quadloc.service.localization.constellations.MAX_TRIPLETS` map triplets per detection
triple (those of least misfit, at most a few of one geometry), so the other copy of a twinned
room can be left out of it: this lookup finds it again.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator

import numpy as np

from quadloc.factors.arrays import FloatArray, IntArray
from quadloc.factors.rotations import pose_matrix, rigid_fit, so3_exp
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.places import PlaceIndex

__all__ = ["COPY_TOLERANCE_M", "MAX_COPIES", "copy_transforms", "is_copy"]

#: Two constellations are copies when every pair distance and every centre after the rigid
#: fit agree within this (m). Perturbed copies (objects moved 0.1-0.5 m) are not copies: the
#: search and the scoring tell them apart.
COPY_TOLERANCE_M = 0.05
#: At most this many copies are returned (nearest to the original first).
MAX_COPIES = 6


def copy_transforms(compiled: CompiledMap, objects: IntArray,
                    tolerance_m: float = COPY_TOLERANCE_M, max_copies: int = MAX_COPIES,
                    index: PlaceIndex | None = None) -> list[FloatArray]:
    """Rigid transforms (4x4, world to world) carrying the objects ``objects`` (indices into
    ``compiled``, at least 2) onto other same-label objects of ``compiled`` whose centres match
    within ``tolerance_m`` after the fit (module docstring), the identity excluded; nearest
    copies first (by how far they move the objects' centroid), at most ``max_copies``. Three
    or more objects: the three of largest spread are the anchor triplet, then every object is
    checked; two: turns about the map's up axis only (:func:`_pair_copies`).

    With ``index`` (``compiled``'s place index), the anchor triplet is the largest whose pairs
    are covisible (within ``index.view_range_m``), its copies come from the index's
    constellations, tried nearest anchor first until ``max_copies`` are found (the nearest by
    that order on a map with more copies); without one, every same-label triplet is tried."""
    idx = np.asarray(objects, dtype=np.intp)
    if len(idx) < 2:
        return []
    P = compiled.centers[idx]
    labels = [compiled.categories[i] for i in idx.tolist()]
    if len(idx) == 2:
        return _pair_copies(compiled, idx, tolerance_m, max_copies, index)

    # the objects' pairwise centre distances and every triple's spread, once, as arrays
    dist = np.sqrt(((P[:, None] - P[None]) ** 2).sum(axis=2))
    triples = np.array(list(itertools.combinations(range(len(idx)), 3)), dtype=np.intp)
    d_ab, d_ac, d_bc = (dist[triples[:, u], triples[:, v]] for u, v in ((0, 1), (0, 2), (1, 2)))
    spread = d_ab + d_ac + d_bc
    if index is not None:
        reach = index.view_range_m - tolerance_m
        covisible = (d_ab <= reach) & (d_ac <= reach) & (d_bc <= reach)
        if not covisible.any():
            return []  # no covisible triplet: the objects are no constellation of the index
        spread = np.where(covisible, spread, -np.inf)
    a, b, c = trip = tuple(int(k) for k in triples[int(np.argmax(spread))])
    if index is None:
        candidates = _dense_triplets(compiled, P, labels, trip, tolerance_m)
    else:
        candidates = _indexed_triplets(index, P, labels, trip, tolerance_m)
    own = {int(idx[a]), int(idx[b]), int(idx[c])}

    def fits() -> Iterator[FloatArray]:
        for q in candidates:
            if len(set(q.tolist())) < 3 or set(q.tolist()) == own:
                continue
            G = rigid_fit(P[[a, b, c]], compiled.centers[q])
            moved = P @ G[:3, :3].T + G[:3, 3]
            if all(_has_object(compiled, moved[m], labels[m], tolerance_m, index)
                   for m in range(len(idx))):
                yield G

    return _nearest_copies(fits(), P, max_copies, stop_early=index is not None)


def _nearest_copies(transforms: Iterable[FloatArray], P: FloatArray, max_copies: int,
                    stop_early: bool) -> list[FloatArray]:
    """The transforms (4x4) of ``transforms`` other than the identity, ordered by how far
    they move the centroid of ``P`` (n, 3), at most ``max_copies``; with ``stop_early``, the
    first ``max_copies`` found (the candidates come nearest first)."""
    centroid = P.mean(axis=0)
    out: list[tuple[float, FloatArray]] = []
    for G in transforms:
        if np.allclose(G, np.eye(4), atol=1e-6):
            continue
        out.append((float(np.linalg.norm(G[:3, :3] @ centroid + G[:3, 3] - centroid)), G))
        if stop_early and len(out) >= max_copies:
            break
    out.sort(key=lambda x: x[0])
    return [G for _, G in out[:max_copies]]


def is_copy(compiled: CompiledMap, objects: IntArray, others: IntArray,
            tolerance_m: float = COPY_TOLERANCE_M) -> bool:
    """Whether the objects ``others`` (indices into ``compiled``, in correspondence with
    ``objects``, at least 3, not the same set) have their labels and, after the rigid fit of
    their centres, every centre within ``tolerance_m`` of theirs: a copy of the constellation
    found directly, from two candidates' matches of the same detections."""
    a, b = np.asarray(objects, dtype=np.intp), np.asarray(others, dtype=np.intp)
    if len(a) < 3 or set(a.tolist()) == set(b.tolist()) or any(
            compiled.categories[i] != compiled.categories[j]
            for i, j in zip(a.tolist(), b.tolist(), strict=True)):
        return False
    P, Q = compiled.centers[a], compiled.centers[b]
    G = rigid_fit(P, Q)
    return bool(np.all(np.linalg.norm(P @ G[:3, :3].T + G[:3, 3] - Q, axis=1) <= tolerance_m))


def _dense_triplets(compiled: CompiledMap, P: FloatArray, labels: list[str],
                    trip: tuple[int, ...], tolerance_m: float) -> list[IntArray]:
    """Every triplet (3,) of objects with the labels of ``trip`` (positions in ``P`` (n, 3),
    ``labels``) whose three distances match ``trip``'s within ``tolerance_m``."""
    a, b, c = trip
    A, B, C = (compiled.indices_for(labels[k]) for k in trip)
    cen = compiled.centers

    def dist(x: IntArray, y: IntArray) -> FloatArray:
        d: FloatArray = np.linalg.norm(cen[x][:, None] - cen[y][None], axis=2)
        return d

    ok_ab = np.abs(dist(A, B) - np.linalg.norm(P[a] - P[b])) <= tolerance_m
    ok_ac = np.abs(dist(A, C) - np.linalg.norm(P[a] - P[c])) <= tolerance_m
    ok_bc = np.abs(dist(B, C) - np.linalg.norm(P[b] - P[c])) <= tolerance_m
    return [np.array([A[i], B[j], C[k]]) for i, j in zip(*np.nonzero(ok_ab), strict=True)
            for k in np.flatnonzero(ok_ac[i] & ok_bc[j])]


def _indexed_triplets(index: PlaceIndex, P: FloatArray, labels: list[str],
                      trip: tuple[int, ...], tolerance_m: float) -> list[IntArray]:
    """:func:`_dense_triplets` from the place index's constellations (covisible same-label
    pairs at the distance within ``tolerance_m``), joined on the first object; nearest to
    ``P[trip[0]]`` first."""
    a, b, c = trip
    empty = (np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp), np.zeros(0))
    ia, jb, dab = index.constellations.get((labels[a], labels[b]), empty)
    ia2, kc, dac = index.constellations.get((labels[a], labels[c]), empty)
    keep_ab = np.abs(dab - np.linalg.norm(P[a] - P[b])) <= tolerance_m
    keep_ac = np.abs(dac - np.linalg.norm(P[a] - P[c])) <= tolerance_m
    ia, jb, ia2, kc = ia[keep_ab], jb[keep_ab], ia2[keep_ac], kc[keep_ac]
    # the join on the first object: every (i, j) with every (i, k)
    order = np.argsort(ia2, kind="stable")
    ia2, kc = ia2[order], kc[order]
    lo = np.searchsorted(ia2, ia, side="left")
    count = np.searchsorted(ia2, ia, side="right") - lo
    first = np.repeat(ia, count)
    second = np.repeat(jb, count)
    third = kc[np.repeat(lo - (np.cumsum(count) - count), count) + np.arange(int(count.sum()))]
    cen = index.centers
    ok = np.abs(np.linalg.norm(cen[second] - cen[third], axis=1)
                - float(np.linalg.norm(P[b] - P[c]))) <= tolerance_m
    first, second, third = first[ok], second[ok], third[ok]
    near_first = np.argsort(np.linalg.norm(cen[first] - P[a], axis=1), kind="stable")
    return list(np.stack([first, second, third], axis=1)[near_first])


def _has_object(compiled: CompiledMap, point: FloatArray, label: str, tolerance_m: float,
                index: PlaceIndex | None = None) -> bool:
    """Whether an object labelled ``label`` has its centre within ``tolerance_m`` of
    ``point`` (3,) (with ``index``: looked up in its grid)."""
    same = (compiled.indices_for(label) if index is None else
            np.array([k for k in index.near(point, tolerance_m).tolist()
                      if compiled.categories[k] == label], dtype=np.intp))
    return bool(len(same)) and float(
        np.min(np.linalg.norm(compiled.centers[same] - point, axis=1))) <= tolerance_m


def _pair_copies(compiled: CompiledMap, idx: IntArray, tolerance_m: float, max_copies: int,
                 index: PlaceIndex | None = None) -> list[FloatArray]:
    """:func:`copy_transforms` of two objects: two points fix a rigid transform only up to a
    turn about their line, so copies are taken upright (a turn about the map's up axis and a
    translation, as rooms are copied): same-label pairs whose distance and height difference
    match within ``tolerance_m`` (with ``index``: its covisible pairs of those labels)."""
    up = np.asarray(compiled.scene_map.up, dtype=float)
    up = up / np.linalg.norm(up)
    P = compiled.centers[idx]
    cen = compiled.centers
    la, lb = compiled.categories[int(idx[0])], compiled.categories[int(idx[1])]

    def flat(v: FloatArray) -> FloatArray:
        out: FloatArray = v - np.outer(v @ up, up) if v.ndim == 2 else v - (v @ up) * up
        return out

    dp = P[1] - P[0]
    hp, lp = float(dp @ up), flat(dp)
    if index is None:
        a_set, b_set = compiled.indices_for(la), compiled.indices_for(lb)
        D = cen[b_set][None] - cen[a_set][:, None]  # (A, B, 3)
        ok = (np.abs(np.linalg.norm(D, axis=2) - np.linalg.norm(dp)) <= tolerance_m) & (
            np.abs(D @ up - hp) <= tolerance_m)
        pairs = [(int(a_set[i]), int(b_set[j])) for i, j in zip(*np.nonzero(ok), strict=True)]
    else:
        empty = (np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp), np.zeros(0))
        pa, pb, pd = index.constellations.get((la, lb), empty)
        sel = np.abs(pd - np.linalg.norm(dp)) <= tolerance_m
        pa, pb = pa[sel], pb[sel]
        sel = np.abs((cen[pb] - cen[pa]) @ up - hp) <= tolerance_m
        pa, pb = pa[sel], pb[sel]
        near_first = np.argsort(np.linalg.norm(cen[pa] - P[0], axis=1), kind="stable")
        pairs = list(zip(pa[near_first].tolist(), pb[near_first].tolist(), strict=True))
    def fits() -> Iterator[FloatArray]:
        for qa, qb in pairs:
            if qa == qb or {qa, qb} == set(idx.tolist()):
                continue
            lq = flat(cen[qb] - cen[qa])
            theta = float(np.arctan2(np.cross(lp, lq) @ up, lp @ lq))
            R = so3_exp(theta * up)
            yield pose_matrix(R, cen[qa] - R @ P[0])

    return _nearest_copies(fits(), P, max_copies, stop_early=index is not None)
