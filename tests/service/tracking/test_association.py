"""Data association of tracking frames (service/tracking/association.py): the gate and the
ambiguity rule, on a two-object scene whose projections are computed independently."""

from __future__ import annotations

import numpy as np

from quadloc.factors.camera import Camera, Ellipsoid, project_ellipsoid
from quadloc.factors.conics import ellipse_params
from quadloc.maps.compiled import compile_map
from quadloc.maps.model import MapObject, SceneMap
from quadloc.service.tracking.association import (
    AMBIGUITY_MARGIN_CHI2,
    DETECTION_CENTRE_FLOOR_PX,
    DETECTION_CENTRE_FRACTION,
    GATE_CHI2,
    associate,
)

CAMERA = Camera(525.0, 525.0, 320.0, 240.0, 640, 480)
#: world_from_camera: the camera at the origin looking along +z (OpenCV axes)
POSE = np.eye(4)


def _scene(second_label: str) -> SceneMap:
    objs = (MapObject("a", "chair", Ellipsoid(np.array([-0.15, 0.0, 3.0]), np.full(3, 0.1),
                                              np.eye(3))),
            MapObject("b", second_label, Ellipsoid(np.array([0.15, 0.0, 3.0]), np.full(3, 0.1),
                                                   np.eye(3))))
    return SceneMap("two", "two", (0.0, -1.0, 0.0), ("chair", "table"), objs)


def test_a_detection_between_two_objects_of_its_label_within_the_margin_is_left_out() -> None:
    """The detection is object a's projection. With a tight pose covariance, b (52 px away) is
    outside the gate: a is associated. With the rotation uncertain by 0.08 rad (about 42 px
    here), both are gated and b is within AMBIGUITY_MARGIN_CHI2 of a: nothing is associated,
    unless b has another label (then a is the only candidate)."""
    a = project_ellipsoid(CAMERA, np.linalg.inv(POSE), _scene("chair").objects[0].ellipsoid)
    det = ellipse_params([a])
    b_centre_u = CAMERA.cx + CAMERA.fx * 0.15 / 3.0
    s_d = DETECTION_CENTRE_FRACTION * np.sqrt(a.a * a.b) + DETECTION_CENTRE_FLOOR_PX
    tight = np.diag([1e-8] * 3 + [1e-8] * 3)
    assert ((b_centre_u - a.cx) / s_d) ** 2 > GATE_CHI2  # b outside the gate when tight
    loose = np.diag([0.08 ** 2] * 3 + [1e-8] * 3)
    same = compile_map(_scene("chair"))
    got = associate(same, CAMERA, POSE, tight, det, ["chair"], [0])
    assert [(x.detection_index, same.object_ids[x.object_index]) for x in got] == [(0, "a")]
    assert got[0].mahalanobis2 < 1e-6
    assert associate(same, CAMERA, POSE, loose, det, ["chair"], [0]) == []
    other = compile_map(_scene("table"))
    got = associate(other, CAMERA, POSE, loose, det, ["chair"], [0])
    assert [other.object_ids[x.object_index] for x in got] == ["a"]
    assert AMBIGUITY_MARGIN_CHI2 > 0


def test_the_margin_is_measured_between_the_two_nearest() -> None:
    """A detection 40 % of the way from a's projection to b's, with a covariance that gates
    both: associated to a when the squared distances differ by the margin or more, left out
    when they differ by less (the distances computed here from the closed form of the
    innovation covariance: rotation about the camera's y axis moves both centres by fx * w
    in u, to first order, at the image centre row)."""
    same = compile_map(_scene("chair"))
    a = project_ellipsoid(CAMERA, np.linalg.inv(POSE), same.ellipsoids[0])
    b = project_ellipsoid(CAMERA, np.linalg.inv(POSE), same.ellipsoids[1])
    for sd_rad, expect in ((0.013, ["a"]), (0.06, [])):
        det = ellipse_params([a])
        det[0, 0] = a.cx + 0.4 * (b.cx - a.cx)
        cov = np.diag([1e-10, sd_rad ** 2, 1e-10, 1e-10, 1e-10, 1e-10])
        s_d = DETECTION_CENTRE_FRACTION * np.sqrt(det[0, 2] * det[0, 3]) \
            + DETECTION_CENTRE_FLOOR_PX
        m2 = []
        for e in (a, b):
            # du/dw_y at a point (x, z): fx (1 + x^2 / z^2); 3 m deep, |x| = 0.15 m
            j = CAMERA.fx * (1 + (0.15 / 3.0) ** 2)
            m2.append((det[0, 0] - e.cx) ** 2 / (j ** 2 * sd_rad ** 2 + s_d ** 2))
        assert max(m2) <= GATE_CHI2
        assert (m2[1] - m2[0] < AMBIGUITY_MARGIN_CHI2) == (expect == [])
        got = associate(same, CAMERA, POSE, cov, det, ["chair"], [0])
        assert [same.object_ids[x.object_index] for x in got] == expect


def test_objects_out_of_the_field_of_view_are_not_candidates() -> None:
    """An object in front of the camera but 50 m to the side (its centre projects ~6,700 px
    right of the image; the linearised gate, with the rotation uncertain by 0.05 rad, would
    admit a detection at the image's right edge of its projected size) is not associated; an
    object whose centre projects just outside the image, by less than its apparent radius
    (truncated, partly in view), still is."""
    far = compile_map(SceneMap("far", "far", (0.0, -1.0, 0.0), ("chair",), (
        MapObject("far", "chair", Ellipsoid(np.array([50.0, 0.0, 3.9]), np.full(3, 0.3),
                                            np.eye(3))),)))
    e = project_ellipsoid(CAMERA, np.linalg.inv(POSE), far.ellipsoids[0])
    assert e.cx > 10 * CAMERA.width
    det = ellipse_params([e])
    det[0, :2] = [CAMERA.width - 1.0, CAMERA.cy]
    loose = np.diag([0.05 ** 2] * 3 + [0.01] * 3)
    assert associate(far, CAMERA, POSE, loose, det, ["chair"], [0]) == []
    # a chair 2 m deep whose centre is 20 px right of the image (apparent radius ~79 px): the
    # detection of its visible part, centred inside the image
    x = (CAMERA.width + 20.0 - CAMERA.cx) * 2.0 / CAMERA.fx
    edge = compile_map(SceneMap("edge", "edge", (0.0, -1.0, 0.0), ("chair",), (
        MapObject("edge", "chair", Ellipsoid(np.array([x, 0.0, 2.0]), np.full(3, 0.3),
                                             np.eye(3))),)))
    e = project_ellipsoid(CAMERA, np.linalg.inv(POSE), edge.ellipsoids[0])
    assert CAMERA.width < e.cx < CAMERA.width + 0.5 * e.a
    det = ellipse_params([e])
    det[0, 0] = CAMERA.width - 20.0
    got = associate(edge, CAMERA, POSE, np.diag([1e-6] * 3 + [1e-6] * 3), det, ["chair"], [0])
    assert [edge.object_ids[x.object_index] for x in got] == ["edge"]
