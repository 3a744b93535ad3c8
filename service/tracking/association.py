"""Data association of a new frame at its predicted pose, gated by the predicted covariance.

Innovation: detection ellipse centre minus projected object centre (px), covariance
``S = J Sigma J^T + s_d^2 I`` (``Sigma`` the 6x6 ``[omega, v]`` pose covariance, body frame,
right perturbation; ``J`` from :func:`centre_jacobians`), for the objects in the field of view
(:func:`_in_field_of_view`); gates :data:`GATE_CHI2` and
:data:`SIZE_RATIO_GATE`; a detection with two gated objects of nearly equal distance is
left out (:data:`AMBIGUITY_MARGIN_CHI2`); one-to-one greedy by distance. Details:
docs/design/service.md#data-association.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray
from quadloc.factors.budget import Deadline, deadline_passed
from quadloc.factors.camera import Camera
from quadloc.factors.rotations import invert_pose, skew
from quadloc.maps.compiled import CompiledMap
from quadloc.service.localization.hypotheses import project_objects

__all__ = ["AMBIGUITY_MARGIN_CHI2", "GATE_CHI2", "Association", "associate", "centre_jacobians"]

GATE_CHI2 = 11.6
DETECTION_CENTRE_FRACTION = 0.25
DETECTION_CENTRE_FLOOR_PX = 3.0
SIZE_RATIO_GATE = (0.4, 2.5)
#: A detection whose second-nearest gated object is within this of its nearest (squared
#: Mahalanobis distance; a likelihood ratio below ``exp(2)``, about 7) is ambiguous and left
#: unassociated: the pose is too uncertain to say which of two objects of its label it is
#: (after odometry-only stretches, entering a room; the nearest was the wrong one in the
#: building walks, and its factor dragged the estimate so that it stayed the nearest).
AMBIGUITY_MARGIN_CHI2 = 4.0


@dataclass(frozen=True)
class Association:
    """Detection ``detection_index`` (index into the frame's detections) -> map object index,
    with its squared Mahalanobis distance at the predicted pose."""

    detection_index: int
    object_index: int
    mahalanobis2: float


def centre_jacobians(camera: Camera, world_from_camera: FloatArray,
                     points_world: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Pixel projections (N, 2) of world points (N, 3) and their Jacobians (N, 2, 6) w.r.t. the
    pose tangent ``[omega, v]`` (right perturbation: ``T @ Exp(xi)``).

    In the camera frame ``p(xi) = Exp(-omega) (p - v)`` to first order ``p + [p]x omega - v``;
    ``u = (fx x / z + cx, fy y / z + cy)``."""
    T = np.asarray(world_from_camera, dtype=float)
    p = (points_world - T[:3, 3]) @ T[:3, :3]
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    fx, fy = camera.fx, camera.fy
    u = np.column_stack([fx * x / z + camera.cx, fy * y / z + camera.cy])
    du_dp = np.zeros((len(p), 2, 3))
    du_dp[:, 0, 0] = fx / z
    du_dp[:, 0, 2] = -fx * x / z ** 2
    du_dp[:, 1, 1] = fy / z
    du_dp[:, 1, 2] = -fy * y / z ** 2
    dp = np.concatenate([skew(p), -np.broadcast_to(np.eye(3), (len(p), 3, 3))], axis=2)
    return u, du_dp @ dp


def _in_field_of_view(camera: Camera, camera_from_world: FloatArray, centers: FloatArray,
                      radii: FloatArray, point_centres: FloatArray) -> BoolArray:
    """Whether each object (centres (N, 3) m world frame, mean radii (N,) m, centre
    projections (N, 2) px) can be in the image: its centre's projection within the image grown
    by its apparent radius ``f r / distance`` px. Far off the optical axis the projected ellipse
    of an object in front of the camera stretches over thousands of px and the centre Jacobian
    grows as ``1 + x^2 / z^2``: the linearised gate then admits an object tens of metres away
    behind a wall (building walks: a spurious detection associated with an object 57 m off)."""
    p = centers @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    r = 0.5 * (camera.fx + camera.fy) * radii / np.linalg.norm(p, axis=1)
    u, v = point_centres[:, 0], point_centres[:, 1]
    inside: BoolArray = (u > -r) & (u < camera.width + r) & (v > -r) & (v < camera.height + r)
    return inside


def associate(
    compiled: CompiledMap, camera: Camera, world_from_camera: FloatArray,
    covariance: FloatArray, ellipses: FloatArray, labels: list[str],
    detection_indices: list[int], deadline: Deadline | None = None,
) -> list[Association]:
    """One-to-one gated associations (module docstring); none (an empty list) once
    ``deadline`` (None: no limit) has passed: the caller checks it.

    Args:
        ellipses: (D, 5) detection params ``(cx, cy, a, b, angle)`` px / rad.
        labels: the D labels; detection_indices: their indices in the frame.
        covariance: predicted 6x6 pose covariance (``[omega, v]``, body frame).
    """
    cands: list[tuple[float, int, int]] = []
    cfw = invert_pose(world_from_camera)[None]
    by_label: dict[str, list[int]] = {}
    for d, label in enumerate(labels):
        by_label.setdefault(label, []).append(d)
    for label, dets in by_label.items():  # the objects projected once per label
        objs = compiled.indices_for(label)
        if len(objs) == 0:
            continue
        cen, inv_shape, valid, point_cen = project_objects(
            camera, cfw, compiled.centers[objs], compiled.shape_matrices[objs],
            compiled.dual_quadrics[objs])
        # only valid projections in the field of view can pass the gate
        assert point_cen is not None
        keep = np.flatnonzero(valid[0] & _in_field_of_view(
            camera, cfw[0], compiled.centers[objs], compiled.mean_radii[objs], point_cen[0]))
        objs, cen, inv_shape = objs[keep], cen[0][keep], inv_shape[0][keep]
        _, J = centre_jacobians(camera, world_from_camera, compiled.centers[objs])
        JSJ = J @ covariance @ J.transpose(0, 2, 1)
        det = np.maximum(inv_shape[:, 0, 0] * inv_shape[:, 1, 1] - inv_shape[:, 0, 1] ** 2,
                         1e-300)
        proj_size = det ** 0.25
        for d in dets:
            if deadline_passed(deadline):
                return []
            e = ellipses[d]
            s_d = DETECTION_CENTRE_FRACTION * np.sqrt(e[2] * e[3]) + DETECTION_CENTRE_FLOOR_PX
            S = JSJ + (s_d ** 2) * np.eye(2)
            r = e[:2] - cen
            m2 = np.einsum("ni,ni->n", r, np.linalg.solve(S, r[..., None])[..., 0])
            ratio = np.sqrt(e[2] * e[3]) / proj_size
            ok = (m2 <= GATE_CHI2) & (ratio >= SIZE_RATIO_GATE[0]) \
                & (ratio <= SIZE_RATIO_GATE[1])
            gated = np.flatnonzero(ok)
            if len(gated) >= 2:
                best, second = np.partition(m2[gated], 1)[:2]
                if second - best < AMBIGUITY_MARGIN_CHI2:
                    continue  # ambiguous: left unassociated
            for k in gated:
                cands.append((float(m2[k]), d, int(objs[k])))
    cands.sort()
    used_d: set[int] = set()
    used_o: set[int] = set()
    out = []
    for m2, d, o in cands:
        if d in used_d or o in used_o:
            continue
        used_d.add(d)
        used_o.add(o)
        out.append(Association(detection_indices[d], o, m2))
    return sorted(out, key=lambda a: a.detection_index)
