"""Association of detections across posed views into objects, without track ids.

Per label (detections of different labels never share an object; docs/design/maps.md,
"Association"): candidate centres from pairs of diverging viewing rays, greedy clustering of the
detections whose rays support a candidate (one per frame), verification by reconstruction and
reprojection (IoU at least ``min_iou`` kept, ``recruit_iou`` recruited), then same-label
duplicates merged and ghosts of another label's object dissolved. Detections in no object are
rejected (``fits_no_object``).

With track ids (:attr:`Observation.track_id`), detections are grouped by ``(label,
track_id)`` directly; detections without one go through the steps above.

Coordinates: world frame of the recording's ``world_from_camera`` poses, metres.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Collection, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray, IntArray
from quadloc.factors.camera import Camera, Ellipsoid, project_ellipsoid, touches_border
from quadloc.factors.conics import Ellipse
from quadloc.factors.overlap import intersection_areas
from quadloc.factors.rotations import invert_pose
from quadloc.maps.building.loops import object_frames_of, places
from quadloc.maps.building.recording import Observation
from quadloc.maps.reconstruct import (
    ReconstructionError,
    max_ray_angle_deg,
    reconstruct_ellipsoid,
    triangulate,
)

__all__ = ["AssociationOptions", "ObjectHypothesis", "associate", "associate_windowed",
           "ellipse_iou", "merge_duplicates", "reconstruct_initial", "recruit_views",
           "verify_objects"]


@dataclass(frozen=True)
class AssociationOptions:
    """Thresholds of :func:`associate` (module docstring); angles in degrees."""

    min_views: int = 5
    min_pair_angle_deg: float = 3.0
    min_spread_deg: float = 3.0
    ray_tolerance: float = 0.5
    size_ratio: float = 2.0
    min_iou: float = 0.3
    recruit_iou: float = 0.5
    max_candidates: int = 1500
    max_init_views: int = 15
    init_log_axes_prior_sigma: float = 1.0
    merge_factor: float = 1.0
    max_shared_frames: float = 0.1
    ghost_ratio: float = 3.0
    verify_iou: float = 0.1
    partial_cover: float = 0.8
    partial_min_iou: float = 0.2
    seed: int = 0


@dataclass
class ObjectHypothesis:
    """An associated object: its ``label``, observation indices (into the recording's
    ``observations``), the initial ellipsoid and how it was associated (``geometric`` or
    ``track:<id>``)."""

    label: str
    observations: list[int]
    ellipsoid: Ellipsoid
    source: str = "geometric"
    ious: dict[int, float] = field(default_factory=dict)


def ellipse_ious(p1: FloatArray, p2: FloatArray) -> FloatArray:
    """Intersection over union (N,) of N pairs of filled ellipses given as params (N, 5) each
    (exact areas, ``quadloc.factors.overlap``); 0 where the union is empty."""
    p1, p2 = np.asarray(p1, dtype=float).reshape(-1, 5), np.asarray(p2, dtype=float).reshape(-1, 5)
    if len(p1) == 0:
        return np.zeros(0)
    inter = intersection_areas(p1, p2)
    union = np.pi * (p1[:, 2] * p1[:, 3] + p2[:, 2] * p2[:, 3]) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def ellipse_iou(e1: Ellipse, e2: Ellipse) -> float:
    """Intersection over union of two filled ellipses (one pair of :func:`ellipse_ious`)."""
    return float(ellipse_ious(e1.params(), e2.params())[0])


def _rays(obs: Sequence[Observation], camera: Camera, T_wc: FloatArray
          ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Origins (n, 3), unit directions (n, 3) and angular sizes (n,) of the detections."""
    f = np.array([o.frame for o in obs])
    d = np.stack([np.array([(o.ellipse.cx - camera.cx) / camera.fx,
                            (o.ellipse.cy - camera.cy) / camera.fy, 1.0]) for o in obs])
    d = np.einsum("nij,nj->ni", T_wc[f, :3, :3], d)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rho = np.array([math.sqrt(o.ellipse.a * o.ellipse.b) for o in obs]) / math.sqrt(
        camera.fx * camera.fy)
    return T_wc[f, :3, 3], d, rho


#: Most detection pairs of one label that :func:`_pair_candidates` evaluates: all pairs when
#: ``n (n - 1) / 2`` is within it, else the pairs of frame buckets (:func:`_bucket_offsets`).
MAX_LABEL_PAIRS = 2_000_000
#: Pairs (or candidate x detection cells) evaluated per vectorised chunk: bounds the temporary
#: arrays (about 30 float64 arrays of this length: ~60 MB).
PAIR_CHUNK = 250_000


def _all_pairs(n: int) -> Iterator[tuple[IntArray, IntArray]]:
    """The pairs ``i < j`` of ``range(n)`` in ``np.triu_indices(n, 1)`` order, in chunks of
    about :data:`PAIR_CHUNK` (whole rows of ``i``)."""
    i0 = 0
    while i0 < n - 1:
        i1, count = i0, 0
        while i1 < n - 1 and (count == 0 or count + (n - 1 - i1) <= PAIR_CHUNK):
            count += n - 1 - i1
            i1 += 1
        rows = np.arange(i0, i1)
        lengths = n - 1 - rows
        i = np.repeat(rows, lengths)
        starts = np.cumsum(lengths) - lengths
        j = np.arange(len(i)) - np.repeat(starts, lengths) + i + 1
        yield i, j
        i0 = i1


def _bucket_offsets(counts: IntArray, max_pairs: int) -> IntArray:
    """Frame-rank offsets ``o`` (ascending) whose frame pairs ``(r, r + o)`` hold at most
    ``max_pairs`` detection pairs in all (``counts[r]`` detections in the r-th frame of the
    label): geometrically spaced from 1 (short baselines) to the whole walk (loop closures),
    as many as fit."""
    n_frames = len(counts)
    best = np.ones(1, dtype=np.intp)
    for k in range(2, n_frames):
        offsets = np.unique(np.round(np.geomspace(1, n_frames - 1, k)).astype(np.intp))
        pairs = sum(int(counts[:-o] @ counts[o:]) for o in offsets)
        if pairs > max_pairs:
            break
        best = offsets
        if len(offsets) == n_frames - 1:
            break
    return best


def _bucket_pairs(frames: IntArray, max_pairs: int) -> Iterator[tuple[IntArray, IntArray]]:
    """Pairs of detections in different frames, only between frames ``r`` and ``r + o`` (frame
    ranks, ``o`` from :func:`_bucket_offsets`), in chunks of about :data:`PAIR_CHUNK`."""
    order = np.argsort(frames, kind="stable")
    ranks, starts, counts = np.unique(frames[order], return_index=True, return_counts=True)
    del ranks
    offsets = _bucket_offsets(counts, max_pairs)
    for o in offsets.tolist():
        ci, cj = counts[:-o], counts[o:]
        si, sj = starts[:-o], starts[o:]
        per = ci * cj
        r0 = 0
        while r0 < len(per):
            r1, total = r0, 0
            while r1 < len(per) and (total == 0 or total + per[r1] <= PAIR_CHUNK):
                total += int(per[r1])
                r1 += 1
            blocks = np.arange(r0, r1)
            size = per[blocks]
            blk = np.repeat(blocks, size)
            local = np.arange(int(size.sum())) - np.repeat(np.cumsum(size) - size, size)
            i = si[blk] + local // cj[blk]
            j = sj[blk] + local % cj[blk]
            yield order[i], order[j]
            r0 = r1


def _pair_candidates(o: FloatArray, d: FloatArray, rho: FloatArray, frames: IntArray,
                     opt: AssociationOptions, rng: np.random.Generator,
                     tick: Callable[[], None] | None = None,
                     max_pairs: int = MAX_LABEL_PAIRS) -> tuple[FloatArray, FloatArray]:
    """Candidate centres (m, 3) and sizes (m,) from pairs of diverging rays (at most
    ``max_candidates``, drawn by ``rng`` when more). All pairs when ``n (n - 1) / 2 <=
    max_pairs`` (in ``np.triu_indices`` order), else the frame buckets of
    :func:`_bucket_pairs`: memory and time bounded by ``max_pairs`` whatever ``n``."""
    n = len(o)
    chunks = _all_pairs(n) if n * (n - 1) // 2 <= max_pairs else _bucket_pairs(frames, max_pairs)
    cos_max = math.cos(math.radians(opt.min_pair_angle_deg))
    xs: list[FloatArray] = []
    ss: list[FloatArray] = []
    for i, j in chunks:
        if tick is not None:
            tick()
        keep = frames[i] != frames[j]
        i, j = i[keep], j[keep]
        cos = np.einsum("ij,ij->i", d[i], d[j])
        keep = cos < cos_max
        i, j, cos = i[keep], j[keep], cos[keep]
        w = o[i] - o[j]
        a_dw = np.einsum("ij,ij->i", d[i], w)
        b_dw = np.einsum("ij,ij->i", d[j], w)
        den = 1.0 - cos * cos
        ti = (cos * b_dw - a_dw) / den
        tj = (b_dw - cos * a_dw) / den
        pi = o[i] + ti[:, None] * d[i]
        pj = o[j] + tj[:, None] * d[j]
        si, sj = ti * rho[i], tj * rho[j]
        gap = np.linalg.norm(pi - pj, axis=1)
        size = 0.5 * (si + sj)
        ok = (ti > 0.05) & (tj > 0.05) & (gap <= opt.ray_tolerance * size) \
            & (np.abs(np.log(np.maximum(si, 1e-9) / np.maximum(sj, 1e-9)))
               <= math.log(opt.size_ratio))
        xs.append(0.5 * (pi[ok] + pj[ok]))
        ss.append(size[ok])
    X = np.concatenate(xs) if xs else np.zeros((0, 3))
    S = np.concatenate(ss) if ss else np.zeros(0)
    if len(X) > opt.max_candidates:
        sel = rng.choice(len(X), opt.max_candidates, replace=False)
        X, S = X[sel], S[sel]
    return X, S


def _support(X: FloatArray, S: FloatArray, o: FloatArray, d: FloatArray, rho: FloatArray,
             opt: AssociationOptions) -> tuple[BoolArray, FloatArray]:
    """Consistency (m, n) bool and normalised ray distance (m, n) of candidates vs detections."""
    v = X[:, None, :] - o[None, :, :]  # (m, n, 3)
    t = np.einsum("mnk,nk->mn", v, d)
    perp = np.linalg.norm(v - t[..., None] * d[None], axis=2)
    implied = np.maximum(t, 1e-9) * rho[None]
    dist = perp / S[:, None]
    ok = (t > 0.05) & (dist <= opt.ray_tolerance) \
        & (np.abs(np.log(implied / S[:, None])) <= math.log(opt.size_ratio))
    return ok, dist


def _support_mask(X: FloatArray, S: FloatArray, o: FloatArray, d: FloatArray, rho: FloatArray,
                  opt: AssociationOptions, tick: Callable[[], None] | None = None) -> BoolArray:
    """The consistency (m, n) of :func:`_support`, computed in chunks of candidates (its
    temporaries stay within :data:`PAIR_CHUNK` cells)."""
    ok = np.zeros((len(X), len(o)), dtype=bool)
    step = max(1, PAIR_CHUNK // max(1, len(o)))
    for r in range(0, len(X), step):
        if tick is not None:
            tick()
        ok[r:r + step] = _support(X[r:r + step], S[r:r + step], o, d, rho, opt)[0]
    return ok


def _one_per_frame(idx: IntArray, dist: FloatArray, frames: IntArray) -> IntArray:
    """Of detections ``idx`` keep the closest (smallest ``dist``) per frame."""
    best: dict[int, int] = {}
    for k in idx[np.argsort(dist[idx])]:
        best.setdefault(int(frames[k]), int(k))
    return np.array(sorted(best.values()), dtype=int)


def _geometric_clusters(o: FloatArray, d: FloatArray, rho: FloatArray, frames: IntArray,
                        opt: AssociationOptions, rng: np.random.Generator,
                        tick: Callable[[], None] | None = None) -> list[IntArray]:
    X, S = _pair_candidates(o, d, rho, frames, opt, rng, tick)
    free = np.ones(len(o), dtype=bool)
    clusters: list[IntArray] = []
    if not len(X):
        return clusters
    ok_all = _support_mask(X, S, o, d, rho, opt, tick)  # once per label; masked below
    # support counted in detections of free rays (one per frame is enforced on members),
    # kept up to date as detections leave the free set
    free_support = ok_all.sum(axis=1)
    alive = np.ones(len(X), dtype=bool)
    while alive.any() and free.sum() >= opt.min_views:
        if tick is not None:
            tick()
        counts = np.where(alive, free_support, -1)
        best = int(np.argmax(counts))
        if counts[best] < opt.min_views:
            break
        x, s = X[best], S[best]
        members = np.flatnonzero(ok_all[best] & free)
        dist_row = _support(X[best:best + 1], S[best:best + 1], o, d, rho, opt)[1][0]
        for _ in range(2):
            members = _one_per_frame(members, dist_row, frames)
            if len(members) < 2:
                break
            x = triangulate(o[members], d[members])
            t = np.einsum("nk,nk->n", x - o[members], d[members])
            s = float(np.median(np.maximum(t, 1e-9) * rho[members]))
            ok1, dist1 = _support(x[None], np.array([s]), o, d, rho, opt)
            dist_row = dist1[0]
            members = np.flatnonzero(ok1[0] & free)
        if len(members):
            members = _one_per_frame(members, dist_row, frames)
        # drop the used candidate whatever happens, and the candidates it explains
        near = np.linalg.norm(X - x, axis=1) <= opt.ray_tolerance * s
        near[best] = True
        alive &= ~near
        if len(members) >= opt.min_views and max_ray_angle_deg(d[members]) >= opt.min_spread_deg:
            clusters.append(members)
            free[members] = False
            free_support -= ok_all[:, members].sum(axis=1)
    return clusters


def reconstruct_initial(idx: Sequence[int], obs: Sequence[Observation], T_wc: FloatArray,
                 camera: Camera, opt: AssociationOptions) -> Ellipsoid | None:
    """Initial ellipsoid: Rubino + LM (``reconstruct_ellipsoid``, weak log-axes prior against
    flat collapse) from an evenly spread subset of the untruncated views (all views if fewer
    than ``min_views`` are untruncated); a sphere at the triangulated centre if that fails."""
    sel = [k for k in idx if not touches_border(obs[k].ellipse, camera)]
    if len(sel) < opt.min_views:
        sel = list(idx)
    if len(sel) > opt.max_init_views:  # evenly spread subset: the init need not see them all
        sel = [sel[k] for k in np.linspace(0, len(sel) - 1, opt.max_init_views).astype(int)]
    try:
        res = reconstruct_ellipsoid([obs[k].ellipse for k in sel],
                                    [T_wc[obs[k].frame] for k in sel], camera,
                                    min_ray_angle_deg=opt.min_spread_deg,
                                    log_axes_prior_sigma=opt.init_log_axes_prior_sigma)
        return res.ellipsoid
    except (ReconstructionError, ValueError, RuntimeError):
        pass
    sub = [obs[k] for k in idx]
    o, d, rho = _rays(sub, camera, T_wc)
    try:
        x = triangulate(o, d)
    except np.linalg.LinAlgError:
        return None
    t = np.einsum("nk,nk->n", x - o, d)
    if np.any(t <= 0):
        return None
    r = float(np.median(t * rho))
    return Ellipsoid(x, np.full(3, r))


def _may_overlap(ell: Ellipsoid, T_wc: FloatArray, camera: Camera,
                 detections: Sequence[Ellipse]) -> BoolArray:
    """False (k,) where detection k CANNOT overlap the projection of ``ell`` from the pose
    ``T_wc[k]`` (k, 4, 4): the angle between the ray through its centre and the direction of
    the ellipsoid's centre exceeds the angular radius of the ellipsoid's bounding sphere plus
    the detection's (its major semi-axis over ``min(fx, fy)``: a pixel step subtends at most
    step / f radians). A necessary condition for a positive IoU, so filtering by it changes no
    IoU test; it spares projecting the ellipsoid into frames that look elsewhere."""
    if not len(detections):
        return np.zeros(0, dtype=bool)
    par = np.array([dt.params() for dt in detections]).reshape(-1, 5)
    ray = np.column_stack([(par[:, 0] - camera.cx) / camera.fx,
                           (par[:, 1] - camera.cy) / camera.fy, np.ones(len(par))])
    ray = np.einsum("kij,kj->ki", T_wc[:, :3, :3], ray)
    to_c = ell.center[None] - T_wc[:, :3, 3]
    dist = np.linalg.norm(to_c, axis=1)
    r = float(ell.axes.max())
    cos = np.einsum("ki,ki->k", ray, to_c) / np.maximum(
        np.linalg.norm(ray, axis=1) * dist, 1e-300)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    reach = np.arcsin(np.minimum(1.0, r / np.maximum(dist, 1e-300))) \
        + np.maximum(par[:, 2], par[:, 3]) / min(camera.fx, camera.fy) + 1e-6
    out: BoolArray = (dist <= r) | (angle <= reach)
    return out


def _projected_pairs(ell: Ellipsoid, T_wc: FloatArray, camera: Camera,
                     detections: Sequence[Ellipse], tick: Callable[[], None] | None = None
                     ) -> tuple[BoolArray, FloatArray, FloatArray]:
    """The detections (k) that may overlap the projection of ``ell`` from the poses ``T_wc``
    (k, 4, 4) (:func:`_may_overlap`) and where it projects to an ellipse: the mask (k,), and
    the params (n, 5) of those projections and of those detections (n = mask count); ``tick``
    is called every 256 projections."""
    T_wc = np.asarray(T_wc, dtype=float).reshape(-1, 4, 4)
    may = _may_overlap(ell, T_wc, camera, detections)
    proj: list[FloatArray] = []
    det: list[FloatArray] = []
    ok = np.zeros(len(detections), dtype=bool)
    for n, i in enumerate(np.flatnonzero(may).tolist()):
        T, d = T_wc[i], detections[i]
        if tick is not None and n % 256 == 255:
            tick()
        try:
            proj.append(project_ellipsoid(camera, invert_pose(T), ell).params())
        except ValueError:
            continue
        det.append(d.params())
        ok[i] = True
    return ok, np.array(proj).reshape(-1, 5), np.array(det).reshape(-1, 5)


def _projected_ious(ell: Ellipsoid, T_wc: FloatArray, camera: Camera,
                    detections: Sequence[Ellipse], tick: Callable[[], None] | None = None
                    ) -> FloatArray:
    """IoUs (k,) of ``detections`` (k) with the projections of ``ell`` from the poses ``T_wc``
    (k, 4, 4) (0 where it does not project or cannot overlap: :func:`_projected_pairs`), the
    areas of all pairs in one batched call; ``tick`` is called every 256 projections."""
    ok, proj, det = _projected_pairs(ell, T_wc, camera, detections, tick)
    ious = np.zeros(len(detections))
    ious[ok] = ellipse_ious(proj, det)
    return ious


def _projected_cover(ell: Ellipsoid, T_wc: FloatArray, camera: Camera,
                     detections: Sequence[Ellipse]) -> tuple[FloatArray, FloatArray]:
    """Per detection (k): the fraction of its area inside the projection of ``ell`` from the
    pose ``T_wc`` (k, 4, 4), and its IoU with that projection (both 0 where it does not project
    or cannot overlap: :func:`_projected_pairs`)."""
    ok, proj, det = _projected_pairs(ell, T_wc, camera, detections)
    cover, ious = np.zeros(len(detections)), np.zeros(len(detections))
    if ok.any():
        inter = intersection_areas(proj, det)
        det_area = np.pi * det[:, 2] * det[:, 3]
        union = np.pi * proj[:, 2] * proj[:, 3] + det_area - inter
        cover[ok] = np.where(det_area > 0, inter / np.where(det_area > 0, det_area, 1.0), 0.0)
        ious[ok] = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
    return cover, ious


def recruit_views(objects: Sequence[ObjectHypothesis], rejected: dict[int, str],
                  obs: Sequence[Observation], T_wc: FloatArray, camera: Camera,
                  opt: AssociationOptions, min_shared_frames: int = 2, *,
                  reasons: Collection[str] = ("fits_no_object",),
                  whole_iou: float | None = None) -> int:
    """Give the objects the views that fit them: a detection rejected for one of ``reasons``
    joins an object of its label that has no detection in its frame, in a frame of the
    object's place (:func:`quadloc.maps.building.loops.places` with ``min_shared_frames``: the
    frames detecting any object seen with it; walls hide other rooms, so another room's view of
    a same-label object brought close by drift is never offered), when at least
    ``partial_cover`` of its area lies inside the object's projection from that frame's pose
    ``T_wc`` and their IoU is at least ``partial_min_iou`` (the visible part of a truncated or
    occluded object: its ellipse is that of the part, inside the whole's, so its IoU can fall
    below ``min_iou``; the IoU floor keeps out a small detection inside a large projection),
    or, with ``whole_iou``, when their IoU is at least that whatever the cover; and no other
    object of its label qualifies (ambiguous detections stay rejected). One detection per
    object and frame (the largest IoU). Updates ``objects`` (their ``observations`` and
    ``ious``) and ``rejected`` in place; returns how many detections joined."""
    by_label: dict[str, list[int]] = {}
    for k in rejected:
        if rejected[k] in reasons:
            by_label.setdefault(obs[k].label, []).append(k)
    object_frames = object_frames_of([h.observations for h in objects], obs)
    place_frames: dict[int, set[int]] = {}
    for group in places(object_frames, min_shared_frames):
        frames = {f for j in group for f in object_frames[j]}
        for j in group:
            place_frames[j] = frames
    offers: dict[int, list[tuple[int, float]]] = {}  # detection -> (object, iou)
    for j, h in enumerate(objects):
        used = set(object_frames[j])
        cand = [k for k in by_label.get(h.label, [])
                if obs[k].frame not in used and obs[k].frame in place_frames[j]]
        if not cand:
            continue
        cover, ious = _projected_cover(h.ellipsoid, T_wc[[obs[k].frame for k in cand]], camera,
                                       [obs[k].ellipse for k in cand])
        for k, c, iou in zip(cand, cover.tolist(), ious.tolist(), strict=True):
            if ((c >= opt.partial_cover and iou >= opt.partial_min_iou)
                    or (whole_iou is not None and iou >= whole_iou)):
                offers.setdefault(k, []).append((j, iou))
    best: dict[tuple[int, int], tuple[float, int]] = {}  # (object, frame) -> (iou, detection)
    for k, js in offers.items():
        if len(js) != 1:
            continue
        j, iou = js[0]
        if iou > best.get((j, obs[k].frame), (-1.0, -1))[0]:
            best[(j, obs[k].frame)] = (iou, k)
    for (j, _), (iou, k) in best.items():
        h = objects[j]
        h.observations = sorted([*h.observations, k])
        h.ious[k] = iou
        del rejected[k]
    return len(best)


def associate(
    observations: Sequence[Observation], world_from_camera: FloatArray, camera: Camera,
    options: AssociationOptions | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> tuple[list[ObjectHypothesis], dict[int, str]]:
    """Group ``observations`` into objects (module docstring).

    ``world_from_camera`` (F, 4x4) are the frames' poses. Returns the objects (each with an
    initial ellipsoid) and the rejected observations ``{index: reason}``. ``progress(label,
    fraction)`` is called within and after each label (at least once per hypothesis).
    """
    opt = options or AssociationOptions()
    rng = np.random.default_rng(opt.seed)
    labels = sorted({o.label for o in observations})
    state: dict[str, str | float] = {"label": "", "fraction": 0.0}

    def tick() -> None:
        if progress is not None:
            progress(str(state["label"]), float(state["fraction"]))
    T_wc = np.asarray(world_from_camera, dtype=float)
    objects: list[ObjectHypothesis] = []
    rejected: dict[int, str] = {}
    for li, label in enumerate(labels):
        state["label"], state["fraction"] = label, li / max(1, len(labels))
        idx_all = np.array([k for k, o in enumerate(observations) if o.label == label])
        tracked: dict[str, list[int]] = {}
        untracked: list[int] = []
        for k in idx_all:
            t = observations[k].track_id
            (tracked.setdefault(t, []) if t is not None else untracked).append(int(k))
        for tid, members in tracked.items():
            ell = reconstruct_initial(members, observations, T_wc, camera, opt) \
                if len(members) >= opt.min_views else None
            if ell is None:
                for k in members:
                    rejected[k] = "track_not_reconstructible"
                continue
            objects.append(ObjectHypothesis(label, sorted(members), ell, f"track:{tid}"))
        if untracked:
            un = np.array(untracked)
            sub = [observations[k] for k in un]
            o, d, rho = _rays(sub, camera, T_wc)
            frames = np.array([s.frame for s in sub])
            clusters = _geometric_clusters(o, d, rho, frames, opt, rng, tick)
            assigned: set[int] = set()  # observation indices in an object of this label
            label_objs = []
            for cluster in clusters:
                glob = [int(un[m]) for m in cluster]
                tick()
                ell = reconstruct_initial(glob, observations, T_wc, camera, opt)
                if ell is not None:
                    label_objs.append((glob, ell))
                    assigned.update(glob)
            # verification: drop poor fits, recruit good unassigned ones, reconstruct again
            for glob, ell in label_objs:
                ious = dict(zip(glob, _projected_ious(
                    ell, T_wc[[observations[k].frame for k in glob]], camera,
                    [observations[k].ellipse for k in glob]).tolist(), strict=True))
                keep = [k for k in glob if ious[k] >= opt.min_iou]
                dropped = set(glob) - set(keep)
                assigned -= dropped
                used_frames = {observations[k].frame for k in keep}
                best_new: dict[int, tuple[float, int]] = {}
                candidates = [k for k in untracked if k not in assigned and k not in dropped
                              and observations[k].frame not in used_frames]
                tick()
                cand_ious = _projected_ious(
                    ell, T_wc[[observations[k].frame for k in candidates]],
                    camera, [observations[k].ellipse for k in candidates], tick)
                for k, iou in zip(candidates, cand_ious.tolist(), strict=True):
                    fr = observations[k].frame
                    if iou >= opt.recruit_iou and iou > best_new.get(fr, (0.0, -1))[0]:
                        best_new[fr] = (iou, k)
                for iou, k in best_new.values():
                    keep.append(k)
                    ious[k] = iou
                    assigned.add(k)
                if len(keep) < opt.min_views:
                    assigned -= set(keep)
                    continue
                if set(keep) != set(glob):
                    ell2 = reconstruct_initial(sorted(keep), observations, T_wc, camera, opt)
                    ell = ell2 if ell2 is not None else ell
                objects.append(ObjectHypothesis(label, sorted(keep), ell, "geometric",
                                                {k: ious[k] for k in keep}))
            for k in untracked:
                if k not in assigned:
                    rejected[k] = "fits_no_object"
        if progress is not None:
            progress(label, (li + 1) / len(labels))
    objects = merge_duplicates(objects, observations, T_wc, camera, opt, tick)
    objects = _drop_label_ghosts(objects, rejected, opt)
    return objects, rejected


def _overlapping(a: Ellipsoid, b: Ellipsoid, factor: float) -> bool:
    return bool(float(np.linalg.norm(a.center - b.center))
                <= factor * max(a.axes.max(), b.axes.max()))


def _inside(point: FloatArray, ell: Ellipsoid) -> bool:
    d = ell.rotation.T @ (point - ell.center)
    return float(np.sum((d / ell.axes) ** 2)) <= 1.0


def _same_size(a: Ellipsoid, b: Ellipsoid, ratio: float) -> bool:
    """True if the largest semi-axes of ``a`` and ``b`` are within ``ratio`` of each other."""
    return bool(max(a.axes.max(), b.axes.max()) <= ratio * min(a.axes.max(), b.axes.max()))


def _explains(ell: Ellipsoid, a: ObjectHypothesis, b: ObjectHypothesis,
              obs: Sequence[Observation], T_wc: FloatArray, camera: Camera,
              opt: AssociationOptions) -> bool:
    """True if ``ell`` (reconstructed from the views of ``a`` and ``b`` together) is one object
    of their size that overlaps the projection on at least half the views of EACH by ``verify_iou``
    (two objects, e.g. of two rooms brought together by drift, give an ellipsoid stretched
    between them that explains neither part's views)."""
    if not _same_size(ell, a.ellipsoid, opt.size_ratio):
        return False
    for h in (a, b):
        ious = _projected_ious(ell, T_wc[[obs[k].frame for k in h.observations]], camera,
                               [obs[k].ellipse for k in h.observations])
        if float(np.mean(ious >= opt.verify_iou)) < 0.5:
            return False
    return True


def merge_duplicates(objects: list[ObjectHypothesis], obs: Sequence[Observation],
                      T_wc: FloatArray, camera: Camera, opt: AssociationOptions,
                      tick: Callable[[], None], *, verify_union: bool = False,
                      max_gap_frames: int | None = None) -> list[ObjectHypothesis]:
    """Merge same-label objects whose centres lie within ``merge_factor`` x the larger one's
    largest semi-axis and that (almost) never appear in the same frame: one physical object split
    in two (typically by pose drift between two passes). With ``verify_union`` (across windows
    and after the loop closure, where two rooms' objects can meet by drift, and an object
    stretched over several of them overlaps everything near) the merge also needs spatial
    consistency: both of a similar size (largest semi-axes within ``size_ratio``) and the
    ellipsoid of their views together of that size and explaining each one's views
    (:func:`_explains`). With ``max_gap_frames``, objects whose detections are more than that
    many frames apart (the frames between the last detection of one and the first of the
    other) are not merged: two visits of a place are joined by loop closure only, where the
    whole place must agree (:mod:`quadloc.maps.building.loops`); one object alone cannot tell
    the drift between two visits from the spacing of two same-label objects. In a shared frame
    the larger object's detection is kept."""
    merged = True
    while merged:
        merged = False
        order = sorted(range(len(objects)), key=lambda k: -len(objects[k].observations))
        for ia in order:
            a = objects[ia]
            fa = {obs[k].frame for k in a.observations}
            for ib in order:
                b = objects[ib]
                if ib == ia or b.label != a.label or len(b.observations) > len(a.observations):
                    continue
                if not _overlapping(a.ellipsoid, b.ellipsoid, opt.merge_factor):
                    continue
                fb = {obs[k].frame for k in b.observations}
                if max_gap_frames is not None and max(min(fa) - max(fb), min(fb) - max(fa)) \
                        > max_gap_frames:
                    continue
                if len(fa & fb) > opt.max_shared_frames * min(len(fa), len(fb)):
                    continue
                if verify_union and not _same_size(a.ellipsoid, b.ellipsoid, opt.size_ratio):
                    continue
                union = sorted(a.observations + [k for k in b.observations
                                                 if obs[k].frame not in fa])
                tick()
                ell = reconstruct_initial(union, obs, T_wc, camera, opt)
                if ell is None or (verify_union
                                   and not _explains(ell, a, b, obs, T_wc, camera, opt)):
                    continue
                objects[ia] = ObjectHypothesis(a.label, union, ell, a.source,
                                               {**b.ious, **a.ious})
                del objects[ib]
                merged = True
                break
            if merged:
                break
    return objects


def _drop_label_ghosts(objects: list[ObjectHypothesis], rejected: dict[int, str],
                       opt: AssociationOptions) -> list[ObjectHypothesis]:
    """Dissolve an object whose centre lies inside an object of ANOTHER label with
    ``ghost_ratio`` x more views: two objects cannot occupy the same space, so the few views are
    wrong labels of the other object (their detections are rejected as ``label_conflict``)."""
    keep = []
    for a in objects:
        ghost = any(b is not a and b.label != a.label
                    and len(b.observations) >= opt.ghost_ratio * len(a.observations)
                    and _inside(a.ellipsoid.center, b.ellipsoid)
                    for b in objects)
        if ghost:
            for k in a.observations:
                rejected[k] = "label_conflict"
        else:
            keep.append(a)
    return keep


#: Frames per window of :func:`associate_windowed` (windows overlap by half).
WINDOW_FRAMES = 400


def associate_windowed(
    observations: Sequence[Observation], world_from_camera: FloatArray, camera: Camera,
    options: AssociationOptions | None = None,
    progress: Callable[[str, float], None] | None = None,
    window_frames: int = WINDOW_FRAMES,
) -> tuple[list[ObjectHypothesis], dict[int, str]]:
    """:func:`associate` in windows of ``window_frames`` consecutive frames overlapping by half
    (time and memory linear in the frames; drift within a window is small), then the objects of
    overlapping windows chained where they share at least half of the detections either holds
    in the shared frames (and 2). A chain keeps one detection per frame (the one most windows
    gave it) and a detection claimed by two chains goes to the larger. A recording within one
    window is :func:`associate` itself. Each window's objects are verified
    (:func:`verify_objects`) before they are chained: a window can hold the visits of two
    rooms, and an object stretched across two same-label objects is cut to its largest visit
    there, where it would otherwise pass the chain's size test as the chain's largest object.
    A chain whose ellipsoid (all its views) is not of its largest object's size
    (``size_ratio``) is split into its agreeing parts
    (:func:`_split_chain`), and a part that still fails is its largest object with the part's
    detections that object's ellipsoid explains (IoU >= ``min_iou``); otherwise it keeps that
    ellipsoid or its largest object's, whichever explains more of its views (IoU >=
    ``verify_iou``). The objects are verified
    (:func:`verify_objects`). Then the same-label objects split by the drift between
    two passes are merged (:func:`merge_duplicates`), only where their detections are at most
    ``window_frames`` frames apart (visits further apart are loop closure's). Same arguments
    and result as :func:`associate`; ``progress(label, fraction)`` over the whole
    recording."""
    opt = options or AssociationOptions()
    frames_all = np.array([o.frame for o in observations], dtype=int)
    if not len(frames_all) or frames_all.max() - frames_all.min() < window_frames:
        return associate(observations, world_from_camera, camera, opt, progress)
    step = max(1, window_frames // 2)
    starts = list(range(int(frames_all.min()), int(frames_all.max()) + 1, step))
    hyps: list[ObjectHypothesis] = []
    window_of: list[int] = []
    rejected_any: dict[int, str] = {}
    for w, s in enumerate(starts):
        sel = np.flatnonzero((frames_all >= s) & (frames_all < s + window_frames))
        if not len(sel):
            continue

        def sub_progress(label: str, fraction: float, w: int = w) -> None:
            if progress is not None:
                progress(label, (w + fraction) / len(starts))

        window_obs = [observations[k] for k in sel.tolist()]
        objs, rej = associate(window_obs, world_from_camera, camera, opt, sub_progress)
        # a window can hold two rooms' visits: an object stretched across two same-label
        # objects is cut back to one before it is chained (its other views left free)
        objs = verify_objects(objs, window_obs, world_from_camera, camera, opt)
        for h in objs:
            hyps.append(ObjectHypothesis(h.label, [int(sel[k]) for k in h.observations],
                                         h.ellipsoid, h.source,
                                         {int(sel[k]): v for k, v in h.ious.items()}))
            window_of.append(w)
        for k, reason in rej.items():
            rejected_any.setdefault(int(sel[k]), reason)
    # chain the objects of overlapping windows
    parent = list(range(len(hyps)))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    owners: dict[int, list[int]] = {}
    for h_i, h in enumerate(hyps):
        for k in h.observations:
            owners.setdefault(k, []).append(h_i)
    shared: dict[tuple[int, int], int] = {}
    links: list[tuple[int, int]] = []  # the pairs of window objects chained
    for hs in owners.values():
        for a, b in itertools.combinations(sorted(hs), 2):
            shared[(a, b)] = shared.get((a, b), 0) + 1
    for (a, b), n in shared.items():
        lo = max(starts[window_of[b]], starts[window_of[a]])
        hi = min(starts[window_of[a]], starts[window_of[b]]) + window_frames

        def in_overlap(h: ObjectHypothesis, lo: int = lo, hi: int = hi) -> int:
            return sum(lo <= observations[k].frame < hi for k in h.observations)

        if n >= 2 and n >= 0.5 * min(in_overlap(hyps[a]), in_overlap(hyps[b])):
            links.append((a, b))
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    chains: dict[int, list[int]] = {}
    for h_i in range(len(hyps)):
        chains.setdefault(find(h_i), []).append(h_i)
    T_wc = np.asarray(world_from_camera, dtype=float)
    chain_list = [part for members in chains.values()
                  for part in _split_chain(members, hyps, links, observations, T_wc, camera, opt)]
    votes = [_chain_votes(members, hyps) for members in chain_list]
    size = [len(v) for v in votes]
    claim: dict[int, int] = {}
    for c, v in enumerate(votes):
        for k in v:
            if k not in claim or size[c] > size[claim[k]]:
                claim[k] = c
    objects: list[ObjectHypothesis] = []
    for c, members in enumerate(chain_list):
        per_frame: dict[int, int] = {}
        for k, n in sorted(votes[c].items()):
            if claim[k] != c:
                continue
            f = observations[k].frame
            if f not in per_frame or n > votes[c][per_frame[f]]:
                per_frame[f] = k
        idx = sorted(per_frame.values())
        if len(idx) < opt.min_views:
            continue
        largest = max(members, key=lambda h_i: len(hyps[h_i].observations))
        ell = hyps[largest].ellipsoid
        if len(members) > 1:
            chained = reconstruct_initial(idx, observations, T_wc, camera, opt)
            if chained is None or not _same_size(chained, ell, opt.size_ratio):
                # no ellipsoid of the objects' size fits the chain's views together: the
                # chain joins two objects (e.g. of two rooms); the largest window's object
                # is kept with its detections and those of the chain its ellipsoid explains
                # (IoU >= min_iou: the other object's views do not overlap it)
                own = {k for k in hyps[largest].observations if claim[k] == c}
                fit = _projected_ious(ell, T_wc[[observations[k].frame for k in idx]], camera,
                                      [observations[k].ellipse for k in idx])
                idx = sorted(k for k, v in zip(idx, fit.tolist(), strict=True)
                             if k in own or v >= opt.min_iou)
                if len(idx) < opt.min_views:
                    continue
            else:
                # the chain's ellipsoid, unless its largest window's explains more of its views
                # (a short object of another window chained in can pull the joint fit off)
                views = T_wc[[observations[k].frame for k in idx]]
                ellipses = [observations[k].ellipse for k in idx]
                explained = [int(np.count_nonzero(_projected_ious(e, views, camera, ellipses)
                                                  >= opt.verify_iou)) for e in (chained, ell)]
                if explained[0] >= explained[1]:
                    ell = chained
        kept = set(idx)
        ious = {k: v for h_i in members for k, v in hyps[h_i].ious.items() if k in kept}
        objects.append(ObjectHypothesis(hyps[largest].label, idx, ell, hyps[largest].source,
                                        ious))
    objects = verify_objects(objects, observations, T_wc, camera, opt)
    objects = merge_duplicates(objects, observations, T_wc, camera, opt,
                               lambda: progress("", 1.0) if progress is not None else None,
                               verify_union=True, max_gap_frames=window_frames)
    assigned = {k for h in objects for k in h.observations}
    rejected = {k: rejected_any.get(k, "fits_no_object") for k in range(len(observations))
                if k not in assigned}
    return objects, rejected


def _chain_votes(members: Sequence[int], hyps: Sequence[ObjectHypothesis]) -> dict[int, int]:
    """Per detection of a chain of window objects (``members``, indices into ``hyps``): how
    many of its windows' objects hold it."""
    v: dict[int, int] = {}
    for h_i in members:
        for k in hyps[h_i].observations:
            v[k] = v.get(k, 0) + 1
    return v


def _split_chain(members: list[int], hyps: Sequence[ObjectHypothesis],
                 links: Sequence[tuple[int, int]], obs: Sequence[Observation],
                 T_wc: FloatArray, camera: Camera, opt: AssociationOptions) -> list[list[int]]:
    """A chain of window objects (``members``, indices into ``hyps``; ``links``: the chained
    pairs) as it is when the ellipsoid of its views together (one detection per frame, the one
    most windows gave) is of its largest object's size (``size_ratio``); otherwise split into
    the connected parts of its AGREEING links only: both objects' ellipsoids of one size
    (``size_ratio``) with centres within ``merge_factor`` x the larger largest semi-axis. A
    chain fails when a window's object bridges two physical objects (e.g. a few detections of
    another room's object, close by drift): its links to each side cannot both agree, so the
    split gives each object back its chain instead of keeping only the chain's largest window
    object (the others' detections were lost)."""
    if len(members) < 2:
        return [members]
    votes = _chain_votes(members, hyps)
    per_frame: dict[int, int] = {}
    for k, n in sorted(votes.items()):
        f = obs[k].frame
        if f not in per_frame or n > votes[per_frame[f]]:
            per_frame[f] = k
    largest = max(members, key=lambda h_i: len(hyps[h_i].observations))
    chained = reconstruct_initial(sorted(per_frame.values()), obs, T_wc, camera, opt)
    if chained is not None and _same_size(chained, hyps[largest].ellipsoid, opt.size_ratio):
        return [members]
    inside = set(members)
    parent = {h_i: h_i for h_i in members}

    def find(a: int) -> int:
        while parent[a] != a:
            a = parent[a]
        return a

    for a, b in links:
        if a not in inside or b not in inside:
            continue
        ea, eb = hyps[a].ellipsoid, hyps[b].ellipsoid
        if _same_size(ea, eb, opt.size_ratio) and _overlapping(ea, eb, opt.merge_factor):
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    parts: dict[int, list[int]] = {}
    for h_i in members:
        parts.setdefault(find(h_i), []).append(h_i)
    return list(parts.values())


#: Frames without a detection of an object that end one of its time segments
#: (:func:`_anchored`).
SEGMENT_GAP_FRAMES = 10


def _anchored(h: ObjectHypothesis, obs: Sequence[Observation], T_wc: FloatArray,
              camera: Camera, opt: AssociationOptions) -> ObjectHypothesis | None:
    """``h`` checked against its time segments (runs of its detections less than
    :data:`SEGMENT_GAP_FRAMES` apart): with two segments or more, None if none has
    ``min_views`` views (no visit alone reconstructs it, so nothing shows that its visits saw
    one object); ``h`` itself if one segment's ellipsoid is of ``h``'s size (largest semi-axes
    within ``size_ratio``; not the centres: a segment's depth is loosely constrained), or if
    the largest segment's ellipsoid is larger than ``h``'s (that segment's narrow cone of views
    leaves its depth unconstrained, stretching it: it cannot show ``h`` too large); else the
    object of the largest segment: its ellipsoid with those of ``h``'s detections whose views it
    explains (IoU >= ``min_iou``). The detections of two objects (e.g. of two rooms visited
    within one window, brought together by drift) give an ellipsoid stretched between them,
    larger than what any visit's views alone reconstruct."""
    ks = sorted(h.observations, key=lambda k: obs[k].frame)
    frames = np.array([obs[k].frame for k in ks])
    segments = np.split(np.array(ks), np.flatnonzero(np.diff(frames) > SEGMENT_GAP_FRAMES) + 1)
    if len(segments) < 2:
        return h
    usable = sorted((seg for seg in segments if len(seg) >= opt.min_views), key=len,
                    reverse=True)
    if not usable:
        return None
    anchor = None
    for seg in usable:
        ell = reconstruct_initial(seg.tolist(), obs, T_wc, camera, opt)
        if ell is not None and _same_size(ell, h.ellipsoid, opt.size_ratio):
            return h
        if seg is usable[0]:
            anchor = ell
    if anchor is None or anchor.axes.max() > h.ellipsoid.axes.max():
        return h
    ious = dict(zip(h.observations, _projected_ious(
        anchor, T_wc[[obs[k].frame for k in h.observations]], camera,
        [obs[k].ellipse for k in h.observations]).tolist(), strict=True))
    keep = {k: v for k, v in ious.items() if v >= opt.min_iou}
    return ObjectHypothesis(h.label, list(keep), anchor, h.source, keep)


#: :func:`verify_objects` drops an object whose largest semi-axis exceeds this many times the
#: median size its views imply (distance x angular radius).
MAX_SIZE_FACTOR = 4.0


def verify_objects(objects: Sequence[ObjectHypothesis], observations: Sequence[Observation],
                   world_from_camera: FloatArray, camera: Camera, opt: AssociationOptions
                   ) -> list[ObjectHypothesis]:
    """The objects checked against their time segments (:func:`_anchored`: none with
    ``min_views`` views, dropped; the largest not of the object's size, its object instead),
    with only their detections that overlap the projection of their ellipsoid
    by at least ``verify_iou`` (poses ``world_from_camera``; lower than ``min_iou``: the
    ellipsoid of a chain of windows sees the drift between them), those left with fewer than
    ``min_views`` dropped, and those whose largest semi-axis exceeds :data:`MAX_SIZE_FACTOR`
    times the median size their views imply (an ellipsoid stretched across views of two
    objects, e.g. of two rooms)."""
    T_wc = np.asarray(world_from_camera, dtype=float)
    out = []
    for h in objects:
        anchored = _anchored(h, observations, T_wc, camera, opt)
        if anchored is None:
            continue
        h = anchored
        frames = [observations[k].frame for k in h.observations]
        ious = _projected_ious(h.ellipsoid, T_wc[frames], camera,
                               [observations[k].ellipse for k in h.observations])
        keep = [k for k, iou in zip(h.observations, ious.tolist(), strict=True)
                if iou >= opt.verify_iou]
        if len(keep) < opt.min_views:
            continue
        o, d, rho = _rays([observations[k] for k in keep], camera, T_wc)
        t = np.einsum("nk,nk->n", h.ellipsoid.center - o, d)
        if h.ellipsoid.axes.max() > MAX_SIZE_FACTOR * float(np.median(np.maximum(t, 0) * rho)):
            continue
        out.append(h if len(keep) == len(h.observations) else ObjectHypothesis(
            h.label, keep, h.ellipsoid, h.source, {k: h.ious[k] for k in keep if k in h.ious}))
    return out
