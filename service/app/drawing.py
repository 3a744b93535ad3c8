"""A localization drawn as SVG: the frame's detections (inliers, outliers), the map's
ellipsoids projected at the returned pose (matched or not), a line from each inlier to its
object with IoU and cost, and a summary; the JSON answer inside ``<metadata>``. One drawing for
server and client: the SDK's :func:`quadloc_sdk.overlay.render_overlay_svg` draws it, from
projections computed here with the map version the answer used. What is drawn:
docs/design/service.md#visual-inspector.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from quadloc.factors.camera import Camera, project_ellipsoid
from quadloc.factors.conics import DegenerateProjectionError
from quadloc.factors.rotations import invert_pose
from quadloc.maps.compiled import CompiledMap
from quadloc.service.app.conversions import convert_pose
from quadloc.service.schemas.localize import LocalizeRequest, LocalizeResponse
from quadloc_sdk.overlay import (
    DrawnProjection,
    ImageEllipse,
    drawn_detections,
    overlay_summary,
    render_overlay_svg,
)

__all__ = ["render_localization_svg"]


def _image_ellipse(e: Any) -> ImageEllipse:
    return ImageEllipse(float(e.cx), float(e.cy), float(e.a), float(e.b), float(e.angle))


def render_localization_svg(compiled: CompiledMap, request: LocalizeRequest,
                            response: LocalizeResponse) -> str:
    """The frame of ``request`` drawn with the answer ``response`` against ``compiled`` (the map
    version the answer used); what is drawn: docs/design/service.md#visual-inspector."""
    req: dict[str, Any] = request.model_dump(mode="json")
    resp: dict[str, Any] = response.model_dump(mode="json")
    c = request.camera
    projections: list[DrawnProjection] = []
    pose = response.world_from_camera
    if response.localized and pose is not None:
        world_from_camera = convert_pose(np.array(pose.matrix), pose.convention, "opencv")
        camera = Camera(c.fx, c.fy, c.cx, c.cy, c.width, c.height)
        camera_from_world = invert_pose(world_from_camera)
        for object_id, category, ellipsoid in zip(compiled.object_ids, compiled.categories,
                                                  compiled.ellipsoids, strict=True):
            try:
                ellipse = _image_ellipse(project_ellipsoid(camera, camera_from_world, ellipsoid))
            except DegenerateProjectionError:
                ellipse = None
            projections.append(DrawnProjection(object_id, category, ellipse))
    detections = drawn_detections(req, resp)
    return render_overlay_svg(c.width, c.height, detections, projections,
                              overlay_summary(resp, len(detections)), metadata=resp)
