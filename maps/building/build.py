"""Build a map from a recording: association -> per-object Rubino initialisation -> joint
refinement -> :class:`quadloc.maps.model.SceneMap` plus its
:class:`quadloc.maps.building.report.BuildReport`.

After the joint refinement, objects that fail a quality test are left out (the report's
``dropped_objects``), and the kept objects take the rejected detections that fit them from the
refined camera poses (:func:`quadloc.maps.building.association.recruit_views` with
``whole_iou`` = ``AssociationOptions.recruit_iou``; rejections of
:data:`RECRUITED_AFTER_REFINEMENT`): views the association refused under the app's drift, and
views of a left-out duplicate. They are listed with the object's detections in the report;
the object's estimate and ``quality.n_views`` are those of the refinement, which did not use
them.

Progress is reported as ``progress(stage, percent, objects_found)`` with ``stage`` in
``associating`` (0-50 %), ``refining`` (50-95 %), ``saving`` (95 %); callbacks come at least after
every label and every LM iteration. A ``deadline`` (:class:`quadloc.factors.budget.Deadline`, e.g.
``Deadline.wall_budget(seconds)``) bounds the whole build:
association raises :class:`BuildTimeoutError` when it passes, the refinement stops early and keeps
its current estimate (reported as ``refinement.stopped_early``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from quadloc.factors.arrays import FloatArray, IntArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.rotations import invert_pose
from quadloc.maps.building.association import (
    AssociationOptions,
    ObjectHypothesis,
    associate_windowed,
    merge_duplicates,
    reconstruct_initial,
    recruit_views,
)
from quadloc.maps.building.joint import ObjectQuality, refine_jointly
from quadloc.maps.building.loops import (
    LoopOptions,
    close_loops,
    corrected_poses,
    object_frames_of,
    places,
    proposed_zones,
)
from quadloc.maps.building.recording import Observation, Recording
from quadloc.maps.building.report import (
    BuildCounts,
    BuildReport,
    DetectionRef,
    DroppedObject,
    ObjectQualityReport,
    ObjectReport,
    RefinementReport,
    RejectedDetection,
)
from quadloc.maps.model import MapObject, SceneMap
from quadloc.maps.reconstruct import degenerate_shape_reason

__all__ = ["BuildTimeoutError", "build_map"]

Progress = Callable[[str, float, int], None]
#: Objects with an unconstrained axis need at least this many views to enter the map.
MIN_VIEWS_UNCONSTRAINED = 15
#: Objects whose centre std (quality report) exceeds this (m) are left out of the map; None
#: keeps them (the default; why: docs/design/maps.md, "Build jobs").
MAX_CENTER_STD_M: float | None = None
#: Objects detected in fewer than this fraction of the frames of their place (:func:`places`)
#: that had them in view (centre in front of the camera and inside the image, and looking at
#: least as large as in the smallest view they were detected in) are left out
#: (``rarely_seen``: a wrong label's phantom, a spurious cluster; a real object is detected in
#: most frames that see it).
MIN_VIEW_FRACTION = 0.25
#: Rejections that the views fitting a kept object from the refined poses lift (the
#: association's refusals under the app's drift, and the views of objects left out).
RECRUITED_AFTER_REFINEMENT = ("fits_no_object", "object_degenerate_shape", "object_rarely_seen",
                              "object_unconstrained", "object_center_unconstrained")
#: The report's warning when the time budget stopped the joint refinement.
REFINEMENT_STOPPED_WARNING = ("time budget reached during refinement: the map holds the "
                              "estimate at that point")


def _drop_detail(reason: str, shape_problem: str | None, q: ObjectQuality) -> str:
    """A sentence for the report on why an object was left out of the map."""
    if reason == "degenerate_shape":
        return f"not an object's shape: {shape_problem}"
    if reason == "rarely_seen":
        return f"detected in only {q.n_views} of the frames that had it in view"
    if reason == "unconstrained":
        return (f"semi-axes {list(q.unconstrained_axes)} not constrained by the views and only "
                f"{q.n_views} views")
    return f"centre uncertain by {q.center_std_m:.3g} m along some direction"


def _in_view_counts(centres: FloatArray, radii: FloatArray,
                    object_frames: Sequence[Sequence[int]], T_wc: FloatArray,
                    camera: Camera, min_shared_frames: int) -> IntArray:
    """Per object, how many frames of its place (:func:`places`: the frames detecting any of
    the place's objects) have its centre (n, 3) in front of the camera and inside the image
    (poses ``T_wc`` (F, 4, 4)) and show it at least as large as the smallest view it was
    detected in (apparent size: ``radii`` (n,), its largest semi-axis in metres, over the
    depth; frames where it looks smaller than in all of its detections do not count: a
    detector misses small far objects, e.g. a light switch across the room)."""
    out = np.zeros(len(centres), dtype=int)
    for group in places(object_frames, min_shared_frames):
        fr = np.unique(np.concatenate([np.asarray(object_frames[k], dtype=int)
                                       for k in group]))
        R, t = T_wc[fr, :3, :3], T_wc[fr, :3, 3]
        # camera coordinates (frames, objects, 3) of the group's centres
        pc = np.einsum("fji,fkj->fki", R, centres[group][None] - t[:, None])
        z = pc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = camera.fx * pc[..., 0] / z + camera.cx
            v = camera.fy * pc[..., 1] / z + camera.cy
            size = radii[group][None] / z  # apparent size (rad), (frames, objects)
        seen = (z > 0.05) & (u >= 0) & (u <= camera.width) & (v >= 0) & (v <= camera.height)
        row = {int(f): i for i, f in enumerate(fr.tolist())}
        for j, k in enumerate(group):
            own = [row[int(f)] for f in object_frames[k]]
            detected = size[own, j][z[own, j] > 0.05]
            if len(detected):
                seen[:, j] &= size[:, j] >= float(detected.min())
        out[group] = seen.sum(axis=0)
    return out


def _move(ell: Ellipsoid, T: FloatArray) -> Ellipsoid:
    """``ell`` moved by the rigid ``T`` (4x4)."""
    return Ellipsoid(T[:3, :3] @ ell.center + T[:3, 3], ell.axes.copy(), T[:3, :3] @ ell.rotation)


def _close_loops(objects: list[ObjectHypothesis], obs: tuple[Observation, ...],
                 T_wc: FloatArray, recording: Recording, opt: AssociationOptions,
                 loops: LoopOptions) -> tuple[list[ObjectHypothesis], FloatArray, int]:
    """Loop closure through objects (:mod:`quadloc.maps.building.loops`): the objects with
    the matched ones merged (one detection per frame, the larger object's on a clash), every
    object moved by its frames' correction, the corrected poses, and the number of loops."""
    frames = object_frames_of([h.observations for h in objects], obs)
    closures = close_loops(np.array([h.ellipsoid.center for h in objects]),
                           [h.label for h in objects], frames, np.asarray(recording.up_axis),
                           loops)
    if not closures:
        return objects, T_wc, 0
    T0 = corrected_poses(T_wc, closures, recording.odometry_noise, loops)
    moved = []
    for h, fr in zip(objects, frames, strict=True):
        f = int(fr[len(fr) // 2])
        moved.append(_move(h.ellipsoid, T0[f] @ invert_pose(T_wc[f])))
    parent = list(range(len(objects)))

    def find(a: int) -> int:
        while parent[a] != a:
            a = parent[a]
        return a

    for c in closures:
        for a, b in c.pairs:
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    groups: dict[int, list[int]] = {}
    for k in range(len(objects)):
        groups.setdefault(find(k), []).append(k)
    out = []
    for members in groups.values():
        members.sort(key=lambda k: -len(objects[k].observations))
        big = objects[members[0]]
        if len(members) == 1:
            out.append(ObjectHypothesis(big.label, big.observations, moved[members[0]],
                                        big.source, big.ious))
            continue
        per_frame: dict[int, int] = {}
        for k in members:
            for i in objects[k].observations:
                per_frame.setdefault(obs[i].frame, i)
        idx = sorted(per_frame.values())
        ell = reconstruct_initial(idx, obs, T0, recording.camera, opt) or moved[members[0]]
        ious = {i: v for k in members for i, v in objects[k].ious.items()}
        out.append(ObjectHypothesis(big.label, idx, ell, big.source, ious))
    return out, T0, len(closures)


class BuildTimeoutError(RuntimeError):
    """The build ran out of its time budget before a map existed."""


def build_map(
    recording: Recording, *, map_id: str, progress: Progress | None = None,
    deadline: Deadline | None = None, association: AssociationOptions | None = None,
    max_iterations: int = 30, metadata: Mapping[str, Any] | None = None,
    min_views_unconstrained: int = MIN_VIEWS_UNCONSTRAINED,
    max_center_std_m: float | None = MAX_CENTER_STD_M,
    min_view_fraction: float = MIN_VIEW_FRACTION, loops: LoopOptions | None = None,
) -> tuple[SceneMap, BuildReport]:
    """The map (version 1, ``map_id``) and the report (module docstring).

    Objects are left out of the map (listed in ``report.dropped_objects``, their detections
    rejected) when their semi-axes leave the map limits (``degenerate_shape``) or when an axis
    is not constrained by the views and fewer than ``min_views_unconstrained`` views support
    them (``unconstrained``: a handful of mislabelled or inconsistent views), or, if
    ``max_center_std_m`` is given, when the views leave their centre uncertain by more than that
    along some direction (``center_unconstrained``, e.g. a large object seen truncated from a
    narrow cone).
    """
    t0 = time.perf_counter()
    loops = loops or LoopOptions()
    report_progress: Progress = progress or (lambda *_: None)
    T_wc = np.array([f.world_from_camera for f in recording.frames])
    obs = recording.observations
    report_progress("associating", 0.0, 0)

    def on_label(_label: str, fraction: float) -> None:
        if deadline_passed(deadline):
            raise BuildTimeoutError("time budget exhausted during association")
        report_progress("associating", 50.0 * fraction, 0)

    opt = association or AssociationOptions()
    objects, rejected = associate_windowed(obs, T_wc, recording.camera, opt, on_label)
    objects, T_init, n_loops = _close_loops(objects, obs, T_wc, recording, opt, loops)
    if n_loops:
        objects = merge_duplicates(objects, obs, T_init, recording.camera, opt,
                                   lambda: on_label("", 1.0), verify_union=True)
    recruit_views(objects, rejected, obs, T_init, recording.camera, opt, loops.min_shared_frames)
    t_assoc = time.perf_counter() - t0
    report_progress("refining", 50.0, len(objects))

    def on_iter(it: float, _err: float) -> None:
        report_progress("refining", 50.0 + 45.0 * min(1.0, it / max_iterations), len(objects))

    joint = None
    if objects:
        joint = refine_jointly(
            recording.camera, T_wc, obs,
            [(h.label, h.observations, h.ellipsoid) for h in objects],
            size_priors=recording.size_priors, refine_cameras=recording.refine_camera_poses,
            odometry=recording.odometry_noise,
            max_iterations=max_iterations, deadline=deadline, progress=on_iter,
            initial_world_from_camera=T_init)
        in_view = _in_view_counts(np.array([e.center for e in joint.ellipsoids]),
                                  np.array([float(e.axes.max()) for e in joint.ellipsoids]),
                                  object_frames_of([h.observations for h in objects], obs),
                                  joint.world_from_camera, recording.camera,
                                  loops.min_shared_frames)
    t_refine = time.perf_counter() - t0 - t_assoc
    report_progress("saving", 95.0, len(objects))
    # the report's frame indices are positions in the recording document
    position = [k if f.source_index is None else f.source_index
                for k, f in enumerate(recording.frames)]
    drops: list[tuple[str | None, str | None]] = []  # per object: (reason, shape problem)
    for k, h in enumerate(objects):
        assert joint is not None  # refined whenever there are objects
        h.ellipsoid, q = joint.ellipsoids[k], joint.quality[k]
        reason = None
        shape_problem = degenerate_shape_reason(h.ellipsoid)
        if shape_problem is not None:
            reason = "degenerate_shape"
        elif q.n_views < min_view_fraction * in_view[k]:
            reason = "rarely_seen"
        elif q.unconstrained_axes and q.n_views < min_views_unconstrained:
            reason = "unconstrained"
        elif max_center_std_m is not None and not q.center_std_m <= max_center_std_m:
            reason = "center_unconstrained"
        drops.append((reason, shape_problem))
        for i in h.observations if reason is not None else ():
            rejected[i] = f"object_{reason}"
    kept = [h for h, (reason, _) in zip(objects, drops, strict=True) if reason is None]
    if joint is not None:
        # the views that fit a kept object from the refined poses (module docstring)
        recruit_views(kept, rejected, obs, joint.world_from_camera, recording.camera, opt,
                      loops.min_shared_frames, reasons=RECRUITED_AFTER_REFINEMENT,
                      whole_iou=opt.recruit_iou)
    map_objects = []
    obj_reports: list[ObjectReport] = []
    counters: dict[str, int] = {}
    dropped: list[DroppedObject] = []
    for k, (h, (reason, shape_problem)) in enumerate(zip(objects, drops, strict=True)):
        assert joint is not None
        ell, q = h.ellipsoid, joint.quality[k]
        counters[h.label] = counters.get(h.label, 0) + 1
        oid = f"{h.label}_{counters[h.label]}"
        if reason is not None:
            dropped.append(DroppedObject(
                object_id=oid, label=h.label, reason=reason,
                detail=_drop_detail(reason, shape_problem, q), n_views=q.n_views,
                semi_axes_m=ell.axes.tolist()))
            continue
        map_objects.append(MapObject(oid, h.label, ell))
        obj_reports.append(ObjectReport(
            object_id=oid, label=h.label, association=h.source,
            detections=[DetectionRef(frame_id=recording.frames[obs[i].frame].frame_id,
                                     frame_index=position[obs[i].frame],
                                     detection_index=obs[i].index)
                        for i in h.observations],
            quality=ObjectQualityReport(
                n_views=q.n_views, view_spread_deg=q.view_spread_deg,
                residual_cost=q.residual_cost, rms_level_residual=q.rms_level_residual,
                log_semi_axis_std=list(q.log_axis_std), center_std_m=q.center_std_m,
                unconstrained_axes=list(q.unconstrained_axes), semi_axes_m=ell.axes.tolist())))
    labels = sorted({o.label for o in obs} | {m.category for m in map_objects})
    cats = tuple(lab for lab in labels if any(m.category == lab for m in map_objects)) \
        or tuple(labels[:1] or ["object"])
    meta = {"built_by": "quadloc.maps.building", "n_frames": len(recording.frames),
            "n_detections": len(obs)}
    meta.update(metadata or {})
    zones = proposed_zones([m.object_id for m in map_objects],
                           object_frames_of([h.observations for h in kept], obs),
                           min_shared_frames=loops.min_shared_frames)
    meta["loop_closures"] = n_loops
    scene = SceneMap(map_id=map_id, name=recording.name, up_axis=recording.up_axis,
                     categories=cats, objects=tuple(map_objects), metadata=meta, zones=zones)
    refinement = None if joint is None else RefinementReport(
        iterations=joint.iterations, initial_error=joint.initial_error,
        final_error=joint.final_error, stopped_early=joint.stopped_early,
        camera_poses_refined=recording.refine_camera_poses)
    report = BuildReport(
        objects=obj_reports,
        dropped_objects=dropped,
        rejected_detections=[
            RejectedDetection(frame_id=recording.frames[obs[i].frame].frame_id,
                              frame_index=position[obs[i].frame], detection_index=obs[i].index,
                              label=obs[i].label, reason=reason)
            for i, reason in sorted(rejected.items())],
        counts=BuildCounts(frames=len(recording.frames), detections=len(obs),
                           objects=len(map_objects), rejected_detections=len(rejected)),
        refinement=refinement,
        timings_s={"association": t_assoc, "refinement": t_refine,
                   "total": time.perf_counter() - t0},
        warnings=[*recording.warnings,
                  *([REFINEMENT_STOPPED_WARNING] if refinement and refinement.stopped_early
                    else [])])
    return scene, report
