"""The shared rule of which map objects a pose predicts in view (``quadloc.maps.visibility``),
checked against positions placed by hand and against an independent per-object computation;
tracking sessions keep their rule (centre inset, depth range, zone of the nearest object)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.maps.compiled import compile_map
from quadloc.maps.model import MapObject, MapZone, SceneMap
from quadloc.maps.visibility import ViewRule, predicted_in_view
from quadloc.service.tracking.places import VIEW_RULE as TRACKING_RULE
from tests.support.buildings import make_building
from tests.support.scenes import synthetic_map

CAMERA = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)


def _map(centres: list[tuple[float, float, float]], radius: float = 0.1,
         zones: tuple[MapZone, ...] = ()) -> SceneMap:
    objs = [MapObject(f"o{k}", "chair", Ellipsoid(np.array(c, float), np.full(3, radius),
                                                   np.eye(3))) for k, c in enumerate(centres)]
    return SceneMap("m", "m", (0.0, -1.0, 0.0), ("chair",), tuple(objs), zones=zones)


def test_objects_placed_by_hand() -> None:
    # camera at the origin looking along +z (camera_from_world = identity)
    centres = [(0.0, 0.0, 2.0),    # 0: in view
               (0.0, 0.0, -2.0),   # 1: behind
               (0.0, 0.0, 7.0),    # 2: beyond 6 m
               (3.0, 0.0, 2.0),    # 3: projects at u = 1070 px, outside
               (0.62, 0.0, 2.0),   # 4: centre at u = 475 px, in the image
               (0.0, 0.0, 0.2)]    # 5: nearer than 0.3 m
    cm = compile_map(_map(centres))
    got = predicted_in_view(cm, CAMERA, np.eye(4), ViewRule())
    assert got.tolist() == [0, 4]
    # inset of a quarter of the width on each side: u must lie in [160, 480) px
    inset = predicted_in_view(cm, CAMERA, np.eye(4), ViewRule(inset_fraction=0.25))
    assert inset.tolist() == [0, 4]
    inset = predicted_in_view(cm, CAMERA, np.eye(4), ViewRule(inset_fraction=0.26))
    assert inset.tolist() == [0]  # 475 >= 640 - 166.4


def test_truncation_and_area() -> None:
    # a 0.4 m ball at 2 m: disc radius 500 * 0.4 / 2 = 100 px; centred 40 px inside the right
    # border (u = 600): the square [500, 700] keeps (640 - 500) / 200 = 70 % of its width
    u = 600.0
    x = (u - CAMERA.cx) * 2.0 / CAMERA.fx
    cm = compile_map(_map([(x, 0.0, 2.0)], radius=0.4))
    kept = 140.0 / 200.0
    assert predicted_in_view(cm, CAMERA, np.eye(4), ViewRule(max_truncation=0.31)).size == 1
    assert predicted_in_view(cm, CAMERA, np.eye(4), ViewRule(max_truncation=0.29)).size == 0
    assert math.isclose(1.0 - kept, 0.3, abs_tol=1e-12)
    area = math.pi * 100.0 ** 2
    assert predicted_in_view(cm, CAMERA, np.eye(4), ViewRule(min_area_px=area * 0.99)).size == 1
    assert predicted_in_view(cm, CAMERA, np.eye(4), ViewRule(min_area_px=area * 1.01)).size == 0


def test_zone_of_the_nearest_object() -> None:
    # two rooms in the same view: only the nearer object's room is predicted
    zones = (MapZone("a", None, ("o0", "o1")), MapZone("b", None, ("o2",)))
    cm = compile_map(_map([(0.0, 0.0, 2.0), (0.3, 0.0, 2.5), (-0.2, 0.0, 4.0)], zones=zones))
    assert predicted_in_view(cm, CAMERA, np.eye(4), ViewRule()).tolist() == [0, 1]
    far = compile_map(_map([(0.0, 0.0, 5.0), (0.3, 0.0, 5.5), (-0.2, 0.0, 4.0)], zones=zones))
    assert predicted_in_view(far, CAMERA, np.eye(4), ViewRule()).tolist() == [2]


def _old_tracking_rule(cm, camera: Camera, cfw: np.ndarray) -> set[int]:
    """The tracking rule as it was written before it was shared, object by object."""
    zone_of = {}
    sizes = [len(z.object_ids) for z in cm.scene_map.zones]
    for k, z in enumerate(cm.scene_map.zones):
        for o in z.object_ids:
            zone_of.setdefault(o, []).append(k)
    out = []
    for i, X in enumerate(cm.centers):
        c = cfw[:3, :3] @ X + cfw[:3, 3]
        if not 0.3 < c[2] < 6.0:
            continue
        u = camera.fx * c[0] / c[2] + camera.cx
        v = camera.fy * c[1] / c[2] + camera.cy
        if (0.1 * camera.width <= u < 0.9 * camera.width
                and 0.1 * camera.height <= v < 0.9 * camera.height):
            out.append((c[2], i))
    if not out or not zone_of:
        return {i for _, i in out}

    def room(i: int) -> int:
        ks = zone_of.get(cm.object_ids[i], [])
        return min(ks, key=lambda k: (sizes[k], k)) if ks else -1

    nearest = room(min(out)[1])
    return {i for _, i in out if room(i) == nearest}


@pytest.mark.parametrize("which", ["building", "synthetic"])
def test_tracking_rule_unchanged(which: str) -> None:
    scene = (make_building(4, "perturbed", 3).scene_map if which == "building"
             else synthetic_map(60, 4))
    cm = compile_map(scene)
    rng = np.random.default_rng(8)
    lo, hi = cm.centers.min(0), cm.centers.max(0)
    checked = 0
    for _ in range(200):
        eye = rng.uniform(lo, hi)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        w, x, y, z = q
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        cfw = np.eye(4)
        cfw[:3, :3], cfw[:3, 3] = R, -R @ eye
        want = _old_tracking_rule(cm, CAMERA, cfw)
        got = set(predicted_in_view(cm, CAMERA, cfw, TRACKING_RULE).tolist())
        assert got == want
        checked += bool(want)
    assert checked >= 20  # the poses do see objects
