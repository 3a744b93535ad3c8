"""Copies of a constellation: where else in the map the objects that support an answer occur
with the same labels and the same geometry (exact copies of a room).

A pose found in one copy of a room explains the detections exactly as well in every other
copy; the search does not always find them all (a P3P of three centres can be metres off, and
the search stops when one pose explains the frame), so an answer could name a copy with no
rival listed. :func:`copy_transforms` finds the rigid transforms ``G`` (4x4, world to world)
carrying the answer's supporting objects onto another same-label set within
:data:`COPY_TOLERANCE_M`; ``G @ world_from_camera`` is then the same view in that copy, a
candidate that the caller verifies (refinement, inliers) and weighs in the ambiguity check.
"""

from __future__ import annotations

import itertools

import numpy as np

from quadloc.factors.arrays import FloatArray, IntArray
from quadloc.factors.rotations import pose_matrix, rigid_fit, so3_exp
from quadloc.maps.compiled import CompiledMap

__all__ = ["COPY_TOLERANCE_M", "MAX_COPIES", "copy_transforms"]

#: Two constellations are copies when every pair distance and every centre after the rigid
#: fit agree within this (m). Perturbed copies (objects moved 0.1-0.5 m) are not copies: the
#: search and the scoring tell them apart.
COPY_TOLERANCE_M = 0.05
#: At most this many copies are returned (nearest to the original first).
MAX_COPIES = 6


def copy_transforms(compiled: CompiledMap, objects: IntArray,
                    tolerance_m: float = COPY_TOLERANCE_M, max_copies: int = MAX_COPIES
                    ) -> list[FloatArray]:
    """Rigid transforms (4x4, world to world) carrying the objects ``objects`` (indices into
    ``compiled``, at least 2) onto other same-label objects of ``compiled`` whose centres match
    within ``tolerance_m`` after the fit (module docstring), the identity excluded; nearest
    copies first (by how far they move the objects' centroid), at most ``max_copies``. Three
    or more objects: the three of largest spread are the anchor triplet, then every object is
    checked; two: turns about the map's up axis only (:func:`_pair_copies`)."""
    idx = np.asarray(objects, dtype=np.intp)
    if len(idx) < 2:
        return []
    P = compiled.centers[idx]
    labels = [compiled.categories[i] for i in idx.tolist()]
    if len(idx) == 2:
        return _pair_copies(compiled, idx, tolerance_m, max_copies)
    # the anchor triplet: the largest triangle (perimeter)
    trip = max(itertools.combinations(range(len(idx)), 3),
               key=lambda t: sum(float(np.linalg.norm(P[a] - P[b]))
                                 for a, b in itertools.combinations(t, 2)))
    a, b, c = trip
    A, B, C = (compiled.indices_for(labels[k]) for k in trip)
    cen = compiled.centers

    def dist(x: IntArray, y: IntArray) -> FloatArray:
        d: FloatArray = np.linalg.norm(cen[x][:, None] - cen[y][None], axis=2)
        return d

    ok_ab = np.abs(dist(A, B) - np.linalg.norm(P[a] - P[b])) <= tolerance_m
    ok_ac = np.abs(dist(A, C) - np.linalg.norm(P[a] - P[c])) <= tolerance_m
    ok_bc = np.abs(dist(B, C) - np.linalg.norm(P[b] - P[c])) <= tolerance_m
    out: list[tuple[float, FloatArray]] = []
    for i, j in zip(*np.nonzero(ok_ab), strict=True):
        for k in np.flatnonzero(ok_ac[i] & ok_bc[j]):
            q = np.array([A[i], B[j], C[k]])
            if len(set(q.tolist())) < 3 or set(q.tolist()) == {idx[a], idx[b], idx[c]}:
                continue
            G = rigid_fit(P[[a, b, c]], cen[q])
            moved = P @ G[:3, :3].T + G[:3, 3]
            if not all(_has_object(compiled, moved[m], labels[m], tolerance_m)
                       for m in range(len(idx))):
                continue
            if np.allclose(G, np.eye(4), atol=1e-6):
                continue
            centroid = P.mean(axis=0)
            out.append((float(np.linalg.norm(G[:3, :3] @ centroid + G[:3, 3] - centroid)), G))
    out.sort(key=lambda x: x[0])
    return [G for _, G in out[:max_copies]]


def _has_object(compiled: CompiledMap, point: FloatArray, label: str, tolerance_m: float
                ) -> bool:
    """Whether an object labelled ``label`` has its centre within ``tolerance_m`` of
    ``point`` (3,)."""
    same = compiled.indices_for(label)
    return bool(len(same)) and float(
        np.min(np.linalg.norm(compiled.centers[same] - point, axis=1))) <= tolerance_m


def _pair_copies(compiled: CompiledMap, idx: IntArray, tolerance_m: float, max_copies: int
                 ) -> list[FloatArray]:
    """:func:`copy_transforms` of two objects: two points fix a rigid transform only up to a
    turn about their line, so copies are taken upright (a turn about the map's up axis and a
    translation, as rooms are copied): same-label pairs whose distance and height difference
    match within ``tolerance_m``."""
    up = np.asarray(compiled.scene_map.up, dtype=float)
    up = up / np.linalg.norm(up)
    P = compiled.centers[idx]
    a_set = compiled.indices_for(compiled.categories[int(idx[0])])
    b_set = compiled.indices_for(compiled.categories[int(idx[1])])
    cen = compiled.centers

    def flat(v: FloatArray) -> FloatArray:
        out: FloatArray = v - np.outer(v @ up, up) if v.ndim == 2 else v - (v @ up) * up
        return out

    dp = P[1] - P[0]
    hp, lp = float(dp @ up), flat(dp)
    D = cen[b_set][None] - cen[a_set][:, None]  # (A, B, 3)
    ok = (np.abs(np.linalg.norm(D, axis=2) - np.linalg.norm(dp)) <= tolerance_m) & (
        np.abs(D @ up - hp) <= tolerance_m)
    out: list[tuple[float, FloatArray]] = []
    centroid = P.mean(axis=0)
    for i, j in zip(*np.nonzero(ok), strict=True):
        qa, qb = int(a_set[i]), int(b_set[j])
        if qa == qb or {qa, qb} == set(idx.tolist()):
            continue
        lq = flat(cen[qb] - cen[qa])
        theta = float(np.arctan2(np.cross(lp, lq) @ up, lp @ lq))
        R = so3_exp(theta * up)
        G = pose_matrix(R, cen[qa] - R @ P[0])
        if np.allclose(G, np.eye(4), atol=1e-6):
            continue
        out.append((float(np.linalg.norm(G[:3, :3] @ centroid + G[:3, 3] - centroid)), G))
    out.sort(key=lambda x: x[0])
    return [G for _, G in out[:max_copies]]
