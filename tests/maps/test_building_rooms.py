"""Map building at building scale: the windowed association never merges objects of two rooms
(quadloc.maps.building.association.associate_windowed on a drifting walk through generated
rooms; the generator knows each detection's true object and so its room)."""

from __future__ import annotations

from collections import Counter

import numpy as np

from quadloc.maps.building.association import associate_windowed
from quadloc.maps.building.recording import Observation
from tests.support.buildings import building_recording


def test_windowed_association_keeps_the_objects_of_three_rooms_apart() -> None:
    # 3 rooms, 700 frames (2 windows of 400 chained, rooms revisited, app poses drifting):
    # before the fix this walk gave 2 objects holding detections of two rooms (a TV stretched
    # between two rooms' TVs, an Xbox with a detection of the next room)
    br = building_recording(3, 700, seed=3)
    obs: list[Observation] = []
    room: list[str | None] = []
    for f, frame in enumerate(br.frames):
        for i, d in enumerate(frame.detections):
            obs.append(Observation(f, i, d.label, d.ellipse, d.sigma))
            oid = frame.object_ids[i]
            room.append(br.building.zone_of(oid) if oid is not None else None)
    objects, rejected = associate_windowed(obs, np.array(br.app_poses), br.camera)
    rooms_of = [Counter(room[k] for k in h.observations if room[k] is not None)
                for h in objects]
    assert all(len(r) == 1 for r in rooms_of), [dict(r) for r in rooms_of if len(r) > 1]
    # not by dropping everything: most of every visited room's objects are built
    visited = {z for z, _, _ in br.visits}
    for z in visited:
        true_ids = {oid for frame in br.frames for oid in frame.object_ids
                    if oid is not None and br.building.zone_of(oid) == z}
        built = sum(1 for r in rooms_of if z in r)
        assert built >= 0.7 * len(true_ids), (z, built, len(true_ids))
    assert len(rejected) + sum(len(h.observations) for h in objects) == len(obs)
