"""Build a map from a recording: association -> per-object Rubino initialisation -> joint
refinement -> :class:`quadloc.maps.model.SceneMap` plus its
:class:`quadloc.maps.building.report.BuildReport`.

Progress is reported as ``progress(stage, percent, objects_found)`` with ``stage`` in
``associating`` (0-50 %), ``refining`` (50-95 %), ``saving`` (95 %); callbacks come at least after
every label and every LM iteration. A ``deadline`` (:class:`quadloc.factors.budget.Deadline`, e.g.
``Deadline.wall_budget(seconds)``) bounds the whole build:
association raises :class:`BuildTimeoutError` when it passes, the refinement stops early and keeps
its current estimate (reported as ``refinement.stopped_early``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.maps.building.association import AssociationOptions, associate
from quadloc.maps.building.joint import ObjectQuality, refine_jointly
from quadloc.maps.building.recording import Recording
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
#: The report's warning when the time budget stopped the joint refinement.
REFINEMENT_STOPPED_WARNING = ("time budget reached during refinement: the map holds the "
                              "estimate at that point")


def _drop_detail(reason: str, shape_problem: str | None, q: ObjectQuality) -> str:
    """A sentence for the report on why an object was left out of the map."""
    if reason == "degenerate_shape":
        return f"not an object's shape: {shape_problem}"
    if reason == "unconstrained":
        return (f"semi-axes {list(q.unconstrained_axes)} not constrained by the views and only "
                f"{q.n_views} views")
    return f"centre uncertain by {q.center_std_m:.3g} m along some direction"


class BuildTimeoutError(RuntimeError):
    """The build ran out of its time budget before a map existed."""


def build_map(
    recording: Recording, *, map_id: str, progress: Progress | None = None,
    deadline: Deadline | None = None, association: AssociationOptions | None = None,
    max_iterations: int = 30, metadata: Mapping[str, Any] | None = None,
    min_views_unconstrained: int = MIN_VIEWS_UNCONSTRAINED,
    max_center_std_m: float | None = MAX_CENTER_STD_M,
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
    report_progress: Progress = progress or (lambda *_: None)
    T_wc = np.array([f.world_from_camera for f in recording.frames])
    obs = recording.observations
    report_progress("associating", 0.0, 0)

    def on_label(_label: str, fraction: float) -> None:
        if deadline_passed(deadline):
            raise BuildTimeoutError("time budget exhausted during association")
        report_progress("associating", 50.0 * fraction, 0)

    objects, rejected = associate(obs, T_wc, recording.camera, association, on_label)
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
            max_iterations=max_iterations, deadline=deadline, progress=on_iter)
    t_refine = time.perf_counter() - t0 - t_assoc
    report_progress("saving", 95.0, len(objects))
    # the report's frame indices are positions in the recording document
    position = [k if f.source_index is None else f.source_index
                for k, f in enumerate(recording.frames)]
    map_objects = []
    obj_reports: list[ObjectReport] = []
    counters: dict[str, int] = {}
    dropped: list[DroppedObject] = []
    for k, h in enumerate(objects):
        assert joint is not None  # refined whenever there are objects
        ell = joint.ellipsoids[k]
        q = joint.quality[k]
        counters[h.label] = counters.get(h.label, 0) + 1
        oid = f"{h.label}_{counters[h.label]}"
        reason = None
        shape_problem = degenerate_shape_reason(ell)
        if shape_problem is not None:
            reason = "degenerate_shape"
        elif q.unconstrained_axes and q.n_views < min_views_unconstrained:
            reason = "unconstrained"
        elif max_center_std_m is not None and not q.center_std_m <= max_center_std_m:
            reason = "center_unconstrained"
        if reason is not None:
            dropped.append(DroppedObject(
                object_id=oid, label=h.label, reason=reason,
                detail=_drop_detail(reason, shape_problem, q), n_views=q.n_views,
                semi_axes_m=ell.axes.tolist()))
            for i in h.observations:
                rejected[i] = f"object_{reason}"
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
    scene = SceneMap(map_id=map_id, name=recording.name, up_axis=recording.up_axis,
                     categories=cats, objects=tuple(map_objects), metadata=meta)
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
