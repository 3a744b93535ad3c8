"""Places, loop closure through objects and proposed zones (quadloc.maps.building.loops)."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from quadloc.factors.rotations import invert_pose, pose_matrix, rotation_angle
from quadloc.maps.building.loops import (
    LoopOptions,
    align_places,
    close_loops,
    corrected_poses,
    places,
    proposed_zones,
)
from quadloc.maps.building.recording import OdometryNoise

UP = np.array([0.0, 0.0, 1.0])
LABELS = ["Chair", "Chair", "TV", "Table", "Plant", "Lamp", "Sofa"]


def _yaw(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _room(rng: np.random.Generator) -> np.ndarray:
    return np.column_stack([rng.uniform(-2, 2, (len(LABELS), 2)),
                            rng.uniform(0.2, 1.2, len(LABELS))])


def test_places_group_by_co_observation() -> None:
    # objects 0-2 seen together, 3-4 together, 5 alone; one shared frame is not a link
    frames = [[0, 1, 2], [1, 2, 3], [2, 3], [10, 11, 12], [11, 12], [3, 20]]
    assert places(frames) == [[0, 1, 2], [5], [3, 4]]
    zones = proposed_zones([f"o{k}" for k in range(6)], frames)
    assert [z.object_ids for z in zones] == [("o0", "o1", "o2"), ("o3", "o4")]


def test_align_places_recovers_the_drift_and_refuses_another_layout() -> None:
    rng = np.random.default_rng(3)
    Q = _room(rng)
    G = pose_matrix(_yaw(0.2), [1.5, -0.8, 0.05])  # the drift between the two visits
    P = (Q - G[:3, 3]) @ G[:3, :3] + rng.normal(0, 0.02, Q.shape)  # inv(G) applied, noise
    found = align_places(P, LABELS, Q, LABELS, UP, LoopOptions())
    assert found is not None
    T, pairs = found
    assert sorted(pairs) == [(k, k) for k in range(len(LABELS))]
    assert np.allclose(T, G, atol=0.05)
    # a perturbed copy (every object moved 0.3 m) is another room, however it is turned
    moved = P.copy()
    phi = rng.uniform(-math.pi, math.pi, len(P))
    moved[:, :2] += 0.3 * np.column_stack([np.cos(phi), np.sin(phi)])
    assert align_places(moved, LABELS, Q, LABELS, UP, LoopOptions()) is None
    # the same layout farther than the drift allowed is not this place
    far = P + np.array([12.0, 0.0, 0.0])
    assert align_places(far, LABELS, Q, LABELS, UP, LoopOptions(max_offset_m=5.0)) is None


def test_close_loops_and_pose_graph_correct_a_drifted_revisit() -> None:
    rng = np.random.default_rng(5)
    room = _room(rng)
    # a straight walk out and back: 41 frames 0.25 m apart, the app's poses drifting by a
    # yaw growing to 0.1 rad about the start and a shift growing to 0.3 m; the room is seen
    # at frames 0-4 and 36-40
    n = 41
    x = np.concatenate([np.linspace(0, 5, 21), np.linspace(5, 0, 21)[1:]])
    truth = np.array([pose_matrix(np.eye(3), [xi, 0.0, 0.0]) for xi in x])
    drift = [pose_matrix(_yaw(0.1 * f / (n - 1)), [0.0, 0.3 * f / (n - 1), 0.0])
             for f in range(n)]
    app = np.array([D @ T for D, T in zip(drift, truth, strict=True)])
    later = room @ drift[-1][:3, :3].T + drift[-1][:3, 3]  # as the drifted app sees it
    centres = np.vstack([room, later])
    labels = LABELS + LABELS
    frames = [[0, 1, 2, 3, 4]] * len(LABELS) + [[36, 37, 38, 39, 40]] * len(LABELS)
    closures = close_loops(centres, labels, frames, UP)
    assert len(closures) == 1
    assert sorted(closures[0].pairs) == [(k, k + len(LABELS)) for k in range(len(LABELS))]
    # odometry noise of the order of this drift (10x the default)
    fixed = corrected_poses(app, closures, OdometryNoise(0.05, 0.1, 0.005, 0.01))
    err_before = max(float(np.linalg.norm(a[:3, 3] - t[:3, 3])) for a, t in zip(app, truth,
                                                                               strict=True))
    g, f = closures[0].frames
    assert g in range(5) and f in range(36, 41)
    # the revisit's frame now sits where it truly is relative to the first visit's frame
    rel_true = invert_pose(truth[g]) @ truth[f]
    rel_fixed = invert_pose(fixed[g]) @ fixed[f]
    rel_app = invert_pose(app[g]) @ app[f]
    assert np.linalg.norm(rel_app[:3, 3] - rel_true[:3, 3]) > 0.2
    assert np.linalg.norm(rel_fixed[:3, 3] - rel_true[:3, 3]) < 0.05
    assert rotation_angle(rel_fixed[:3, :3], rel_true[:3, :3]) < 0.02
    assert err_before > 0.2


@pytest.mark.slow
def test_a_two_room_build_keeps_its_rooms_apart_and_proposes_them_as_zones() -> None:
    from bench.map_building import _det_json
    from quadloc.maps.building.build import build_map
    from quadloc.maps.building.recording import recording_to_dict
    from quadloc.service.app.builds import recording_of
    from tests.support.buildings import building_recording

    br = building_recording(2, 450, seed=7)
    rec = recording_of(recording_to_dict(
        br.camera, [(str(i), br.app_poses[i], [_det_json(d) for d in f.detections])
                    for i, f in enumerate(br.frames)]))
    truth = [br.frames[o.frame].object_ids[o.index] for o in rec.observations]
    scene, report = build_map(rec, map_id="two")
    index = {(o.frame, o.index): k for k, o in enumerate(rec.observations)}
    room_of_object = {}
    for obj in report.objects:
        rooms = Counter(truth[index[(d.frame_index, d.detection_index)]].split("/")[0]
                        for d in obj.detections
                        if truth[index[(d.frame_index, d.detection_index)]] is not None)
        assert len(rooms) == 1, obj.object_id
        room_of_object[obj.object_id] = next(iter(rooms))
    assert len(scene.zones) == 2
    for zone in scene.zones:
        assert len({room_of_object[o] for o in zone.object_ids}) == 1
    assert {r.zone_id for r in br.building.rooms} == set(room_of_object.values())
