"""Places in a recording: objects grouped by co-observation, loop closure through objects, and
the zones proposed for the built map.

A **place** is a connected group of objects seen together: two objects are linked when at least
``min_shared_frames`` frames detect both (walls hide other rooms, so a room's objects form one
place; a place seen at two visits far apart in time is two places until a loop closure joins
them).

**Loop closure through objects** (:func:`close_loops`): a later place ``P`` is matched to an
earlier place ``Q`` when one rigid transform ``G`` (world frame of the app's poses, metres)
carries at least ``min_inliers`` of P's object centres (and ``min_inlier_fraction`` of the
smaller place) onto same-label object centres of Q within ``inlier_m``, one to one, and moves
P's centroid by at most ``max_offset_m`` (the largest drift the app may accumulate between two
visits of one place: rooms with the same layout closer than that are not told apart). Hypotheses
come from pairs of same-label correspondences (a yaw about the up axis and a translation, the
drift's dominant part), refined by Kabsch on their inliers. The matched objects are merged and
the transform becomes a relative-pose constraint between a frame of each visit in the pose graph
of :func:`corrected_poses`, which spreads the drift over the walk (GTSAM, LM, the app's relative
poses as between factors with :class:`quadloc.maps.building.recording.OdometryNoise`).

Zones (:func:`proposed_zones`): one per place with at least ``min_objects`` objects, in the map
document's zone format (:class:`quadloc.maps.model.MapZone`, ``"place-<k>"``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.factors.pose_factors import pose3
from quadloc.factors.rotations import invert_pose, pose_matrix, rigid_fit
from quadloc.maps.building.recording import Observation, OdometryNoise
from quadloc.maps.model import MapZone

__all__ = ["LoopClosure", "LoopOptions", "close_loops", "corrected_poses", "places",
           "proposed_zones"]


@dataclass(frozen=True)
class LoopOptions:
    """Thresholds of :func:`close_loops` and :func:`places` (module docstring); metres."""

    min_shared_frames: int = 2
    min_inliers: int = 4
    min_inlier_fraction: float = 0.6
    inlier_m: float = 0.15
    max_offset_m: float = 5.0
    constraint_sigma_m: float = 0.02
    constraint_sigma_rad: float = 0.005


@dataclass(frozen=True)
class LoopClosure:
    """A loop closed between an earlier place and a later one: ``world_from_world`` (4x4) maps
    the later visit's coordinates onto the earlier's, ``pairs`` the merged ``(earlier, later)``
    object indices, ``frames`` a frame of each visit ``(earlier, later)``."""

    world_from_world: FloatArray
    pairs: tuple[tuple[int, int], ...]
    frames: tuple[int, int]


class _UnionFind:
    def __init__(self, n: int) -> None:
        self.parent = list(range(n))

    def find(self, a: int) -> int:
        while self.parent[a] != a:
            self.parent[a] = self.parent[self.parent[a]]
            a = self.parent[a]
        return a

    def union(self, a: int, b: int) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.parent[max(ra, rb)] = min(ra, rb)


def places(object_frames: Sequence[Sequence[int]], min_shared_frames: int = 2
           ) -> list[list[int]]:
    """Objects (indices) grouped into places by co-observation: ``object_frames[k]`` the frames
    detecting object k; linked when at least ``min_shared_frames`` frames detect both. Places in
    the order of their first frame, each sorted."""
    by_frame: dict[int, list[int]] = {}
    for k, frames in enumerate(object_frames):
        for f in set(frames):
            by_frame.setdefault(f, []).append(k)
    shared: dict[tuple[int, int], int] = {}
    for ks in by_frame.values():
        for a, b in itertools.combinations(sorted(ks), 2):
            shared[(a, b)] = shared.get((a, b), 0) + 1
    uf = _UnionFind(len(object_frames))
    for (a, b), n in shared.items():
        if n >= min_shared_frames:
            uf.union(a, b)
    groups: dict[int, list[int]] = {}
    for k in range(len(object_frames)):
        groups.setdefault(uf.find(k), []).append(k)
    first = [min(f) if len(f) else 0 for f in object_frames]
    return sorted(groups.values(), key=lambda g: min(first[k] for k in g))


def _yaw_rotation(theta: float, up: FloatArray) -> FloatArray:
    """Rotation by ``theta`` (rad) about the unit ``up`` axis (Rodrigues)."""
    K = np.array([[0.0, -up[2], up[1]], [up[2], 0.0, -up[0]], [-up[1], up[0], 0.0]])
    R: FloatArray = np.eye(3) + math.sin(theta) * K + (1.0 - math.cos(theta)) * K @ K
    return R


def _inliers(T: FloatArray, P: FloatArray, p_labels: Sequence[str], Q: FloatArray,
             q_labels: Sequence[str], tol: float) -> list[tuple[int, int]]:
    """One-to-one same-label pairs ``(i in P, j in Q)`` within ``tol`` after ``T``, greedily by
    distance."""
    moved = P @ T[:3, :3].T + T[:3, 3]
    d = np.linalg.norm(moved[:, None] - Q[None], axis=2)
    same = np.array(p_labels)[:, None] == np.array(q_labels)[None]
    d = np.where(same, d, np.inf)
    out: list[tuple[int, int]] = []
    used_p: set[int] = set()
    used_q: set[int] = set()
    for flat in np.argsort(d, axis=None):
        i, j = divmod(int(flat), d.shape[1])
        if d[i, j] > tol:
            break
        if i not in used_p and j not in used_q:
            out.append((i, j))
            used_p.add(i)
            used_q.add(j)
    return out


def align_places(P: FloatArray, p_labels: Sequence[str], Q: FloatArray,
                 q_labels: Sequence[str], up: FloatArray, opt: LoopOptions
                 ) -> tuple[FloatArray, list[tuple[int, int]]] | None:
    """The rigid transform carrying place P's centres (n, 3) onto place Q's (m, 3) and its
    inlier pairs, or None when no transform passes the module's rule."""
    need = max(opt.min_inliers, math.ceil(opt.min_inlier_fraction * min(len(P), len(Q))))
    if min(len(P), len(Q)) < need:
        return None
    corr = [(i, j) for i in range(len(P)) for j in range(len(Q)) if p_labels[i] == q_labels[j]]
    best: tuple[FloatArray, list[tuple[int, int]]] | None = None
    u = up / np.linalg.norm(up)

    def flat(v: FloatArray) -> FloatArray:
        return v - (v @ u) * u

    for (i, j), (k, l) in itertools.combinations(corr, 2):
        if i == k or j == l:
            continue
        vp, vq = flat(P[k] - P[i]), flat(Q[l] - Q[j])
        lp, lq = float(np.linalg.norm(vp)), float(np.linalg.norm(vq))
        if abs(lp - lq) > 2 * opt.inlier_m or lp < 0.3:
            continue
        theta = math.atan2(float(np.cross(vp, vq) @ u), float(vp @ vq))
        R = _yaw_rotation(theta, u)
        T = pose_matrix(R, Q[j] - R @ P[i])
        pairs = _inliers(T, P, p_labels, Q, q_labels, opt.inlier_m)
        if len(pairs) < need or (best is not None and len(pairs) <= len(best[1])):
            continue
        T = rigid_fit(P[[a for a, _ in pairs]], Q[[b for _, b in pairs]])
        pairs = _inliers(T, P, p_labels, Q, q_labels, opt.inlier_m)
        centroid = P.mean(axis=0)
        offset = float(np.linalg.norm(T[:3, :3] @ centroid + T[:3, 3] - centroid))
        if len(pairs) >= need and offset <= opt.max_offset_m:
            best = (T, pairs)
    return best


def close_loops(centres: FloatArray, labels: Sequence[str],
                object_frames: Sequence[Sequence[int]], up: FloatArray,
                opt: LoopOptions | None = None) -> list[LoopClosure]:
    """Loop closures between the places of the objects (``centres`` (n, 3), ``labels``,
    ``object_frames`` as in :func:`places`), each later place against every earlier place (the
    best by inliers); a place matched to an earlier one joins it (a third visit matches either).
    """
    opt = opt or LoopOptions()
    groups = places(object_frames, opt.min_shared_frames)
    closures: list[LoopClosure] = []
    for gi, P in enumerate(groups):
        best: tuple[FloatArray, list[tuple[int, int]]] | None = None
        for Q in groups[:gi]:
            found = align_places(centres[P], [labels[k] for k in P], centres[Q],
                                 [labels[k] for k in Q], up, opt)
            if found is not None and (best is None or len(found[1]) > len(best[1])):
                best = (found[0], [(Q[b], P[a]) for a, b in found[1]])
        if best is None:
            continue
        T, pairs = best
        later = sorted(f for _, b in pairs for f in object_frames[b])
        earlier = sorted(f for a, _ in pairs for f in object_frames[a])
        closures.append(LoopClosure(T, tuple(pairs), (earlier[len(earlier) // 2],
                                                        later[len(later) // 2])))
    return closures


def corrected_poses(world_from_camera: FloatArray, closures: Sequence[LoopClosure],
                    odometry: OdometryNoise | None = None, opt: LoopOptions | None = None,
                    max_iterations: int = 50) -> FloatArray:
    """The frames' poses (F, 4, 4) after the loop closures: a pose graph of every frame, the
    app's relative poses between consecutive frames (stds of ``odometry``), the first frame
    fixed, and per closure ``(g, f)`` the constraint ``inv(T_g) G T_f`` between frames g and f
    (stds ``constraint_sigma_*``); LM. Without closures, the app's poses."""
    T = np.asarray(world_from_camera, dtype=float)
    if not closures:
        return T.copy()
    opt = opt or LoopOptions()
    noise = odometry or OdometryNoise()
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for f in range(len(T)):
        values.insert(f, pose3(T[f]))
    graph.add(gtsam.PriorFactorPose3(0, pose3(T[0]), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
    steps = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
    for f in range(len(T) - 1):
        graph.add(gtsam.BetweenFactorPose3(
            f, f + 1, pose3(invert_pose(T[f]) @ T[f + 1]),
            gtsam.noiseModel.Diagonal.Sigmas(noise.sigmas(float(steps[f]), 1))))
    sig = np.array([opt.constraint_sigma_rad] * 3 + [opt.constraint_sigma_m] * 3)
    for c in closures:
        g, f = c.frames
        graph.add(gtsam.BetweenFactorPose3(
            g, f, pose3(invert_pose(T[g]) @ c.world_from_world @ T[f]),
            gtsam.noiseModel.Diagonal.Sigmas(sig)))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    return np.array([result.atPose3(f).matrix() for f in range(len(T))])


def proposed_zones(object_ids: Sequence[str], object_frames: Sequence[Sequence[int]],
                   min_objects: int = 2, min_shared_frames: int = 2) -> tuple[MapZone, ...]:
    """Zones of the built map: one per place (:func:`places`) of at least ``min_objects``
    objects, ``"place-<k>"`` (k from 1, in walking order)."""
    out: list[MapZone] = []
    for group in places(object_frames, min_shared_frames):
        if len(group) >= min_objects:
            k = len(out) + 1
            out.append(MapZone(f"place-{k}", f"place {k}",
                               tuple(object_ids[i] for i in group)))
    return tuple(out)


def object_frames_of(objects: Sequence[Sequence[int]], observations: Sequence[Observation]
                     ) -> list[list[int]]:
    """Per object (its observation indices), the frames detecting it (sorted)."""
    return [sorted({observations[i].frame for i in idx}) for idx in objects]
