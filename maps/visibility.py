"""Which map objects a camera pose predicts in view: the one rule of negative evidence.

An object is *predicted in view* from ``camera_from_world`` (4x4, OpenCV camera axes) when

* its centre is in front of the camera at a depth in ``(min_depth_m, max_depth_m)`` m;
* its centre projects inside the image inset by ``inset_fraction`` of the width / height on
  each side;
* with ``max_truncation``: its projected disc (radius ``f r / z`` px, ``r`` the geometric mean
  of its semi-axes, ``f`` the mean focal length) keeps at least ``1 - max_truncation`` of its
  bounding square inside the image (a detector does not report an object cut off beyond
  that), and with ``min_area_px`` that disc's area is at least this many px^2;
* when the map has zones: it is in the zone of the nearest such object (walls hide the other
  rooms; the most specific zone, :meth:`quadloc.maps.zones.ZoneIndex.zone_positions`).

Occlusion by other objects is not modelled: it is part of the detector's miss rate that the
callers weigh the predicted-but-undetected objects with. Users: tracking sessions' place
hypotheses (:mod:`quadloc.service.tracking.places`) and single-frame localization's place
comparison (:mod:`quadloc.service.localization.negative_evidence`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadloc.factors.arrays import FloatArray, IntArray
from quadloc.factors.camera import Camera
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.zones import zone_index

__all__ = ["ViewRule", "object_zones", "predicted_in_view"]


@dataclass(frozen=True)
class ViewRule:
    """The parameters of :func:`predicted_in_view` (module docstring): depths in m,
    ``inset_fraction`` of the image size, ``max_truncation`` a fraction in [0, 1) or None (not
    checked), ``min_area_px`` px^2 or None (not checked)."""

    min_depth_m: float = 0.3
    max_depth_m: float = 6.0
    inset_fraction: float = 0.0
    max_truncation: float | None = None
    min_area_px: float | None = None


def object_zones(compiled: CompiledMap) -> IntArray:
    """Per map object (N,), the position of its most specific zone (-1: none;
    :meth:`~quadloc.maps.zones.ZoneIndex.zone_positions`); memoised on the compiled map."""
    memo: IntArray | None = compiled.__dict__.get("_object_rooms")
    if memo is None:
        memo = np.array(zone_index(compiled.scene_map).zone_positions(compiled.object_ids),
                        dtype=np.int64).reshape(-1)
        compiled.__dict__["_object_rooms"] = memo
    return memo


def predicted_in_view(compiled: CompiledMap, camera: Camera, camera_from_world: FloatArray,
                      rule: ViewRule) -> IntArray:
    """Sorted indices (into ``compiled``) of the objects predicted in view from
    ``camera_from_world`` (4x4) under ``rule`` (module docstring)."""
    T = np.asarray(camera_from_world, dtype=float)
    # the depth test on every object, the rest on those it keeps (a building map: thousands of
    # objects, a few dozen within reach)
    z_all = compiled.centers @ T[2, :3] + T[2, 3]
    idx = np.flatnonzero((z_all > rule.min_depth_m) & (z_all < rule.max_depth_m))
    if not len(idx):
        return np.zeros(0, dtype=np.intp)
    c = compiled.centers[idx] @ T[:3, :3].T + T[:3, 3]
    z = c[:, 2]
    u = camera.fx * c[:, 0] / z + camera.cx
    v = camera.fy * c[:, 1] / z + camera.cy
    w, h = float(camera.width), float(camera.height)
    mx, my = rule.inset_fraction * w, rule.inset_fraction * h
    ok = (u >= mx) & (u < w - mx) & (v >= my) & (v < h - my)
    if rule.max_truncation is not None or rule.min_area_px is not None:
        r = 0.5 * (camera.fx + camera.fy) * compiled.mean_radii[idx] / z
        if rule.min_area_px is not None:
            ok &= np.pi * r * r >= rule.min_area_px
        if rule.max_truncation is not None:
            inside = ((np.clip(u + r, 0.0, w) - np.clip(u - r, 0.0, w))
                      * (np.clip(v + r, 0.0, h) - np.clip(v - r, 0.0, h)))
            ok &= inside >= (1.0 - rule.max_truncation) * 4.0 * r * r
    idx, z = idx[ok], z[ok]
    rooms = object_zones(compiled)
    if len(idx) and len(rooms) and rooms.max() >= 0:
        # the room of the nearest object in view: walls hide the others
        room = rooms[idx[int(np.argmin(z))]]
        idx = idx[rooms[idx] == room]
    out: IntArray = idx.astype(np.intp)
    return out
