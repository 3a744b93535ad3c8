"""Walks through several rooms of a generated building (:mod:`tests.support.buildings`): the
tracking sessions' building benchmark (``python -m bench.tracking --building``) and tests.

A walk starts in a random room, follows :data:`KEYPOSES_PER_ROOM` consecutive real Chess poses
placed in that room (at <= 0.4 m/s, as :func:`tests.support.walks.make_walk`), walks at
:data:`TRANSIT_SPEED_M_S` to the nearest other room and follows Chess poses there; frames of the
transit see the room they are closer to. Detections: :func:`tests.support.simulate.simulate_frame`
on the current room's objects only (walls hide the others), with the building frames' detector
(wrong labels 0.05, spurious rate 0.3). Object stretches: every third 3-second stretch keeps only
0-2 (seeded) detections per frame. Odometry: :func:`tests.support.walks.simulate_odometry`.
Poses ``world_from_camera`` (OpenCV camera axes), metres; deterministic in the seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadloc.factors.camera import Camera
from quadloc.service.tracking.session import FrameInput
from tests.support.buildings import Building, Room
from tests.support.reference_data import load_chess_world_from_camera
from tests.support.simulate import SimulationConfig, simulate_frame
from tests.support.walks import HZ, make_walk, simulate_odometry

__all__ = ["KEYPOSES_PER_ROOM", "TRANSIT_SPEED_M_S", "BuildingWalk", "building_walk"]

KEYPOSES_PER_ROOM = 30
TRANSIT_SPEED_M_S = 1.2
SPARSE_STRETCH_S = 3.0


@dataclass(frozen=True, eq=False)
class BuildingWalk:
    """A walk: the session's frames, the true poses, each frame's room and the true object ids
    of its detections (None: spurious)."""

    camera: Camera
    frames: list[FrameInput]
    poses: list[np.ndarray]
    rooms: list[Room]
    object_ids: list[tuple[str | None, ...]]


def building_walk(building: Building, seed: int, n_rooms: int = 2) -> BuildingWalk:
    """A walk through ``n_rooms`` rooms of ``building`` (fewer if it has fewer; module
    docstring)."""
    camera, chess, _ = load_chess_world_from_camera()
    rng = np.random.default_rng(seed)
    rooms = [building.rooms[int(rng.integers(len(building.rooms)))]]
    while len(rooms) < min(n_rooms, len(building.rooms)):
        here = rooms[-1].world_from_room[:3, 3]
        others = [r for r in building.rooms if all(r is not x for x in rooms)]
        rooms.append(min(others, key=lambda r: float(np.linalg.norm(
            r.world_from_room[:3, 3] - here))))
    poses: list[np.ndarray] = []
    where: list[Room] = []
    for k, room in enumerate(rooms):
        start = int(rng.integers(len(chess) - KEYPOSES_PER_ROOM + 1))
        inside = make_walk([room.world_from_room @ T
                            for T in chess[start:start + KEYPOSES_PER_ROOM]])
        if k:
            transit = make_walk([poses[-1], inside[0]], TRANSIT_SPEED_M_S)[1:-1]
            half = len(transit) // 2
            poses += transit
            where += [rooms[k - 1]] * half + [room] * (len(transit) - half)
        poses += inside
        where += [room] * len(inside)
    odom = simulate_odometry(poses, rng)
    cfg = SimulationConfig(wrong_label_probability=0.05, spurious_rate=0.3)
    frames, ids = [], []
    for i, (T, To, room) in enumerate(zip(poses, odom, where, strict=True)):
        f = simulate_frame(building.room_map(room), camera, T, rng, cfg)
        keep = list(range(len(f.detections)))
        if int(i / (SPARSE_STRETCH_S * HZ)) % 3 == 2 and keep:
            keep = [int(j) for j in rng.permutation(len(keep))[:int(rng.integers(0, 3))]]
        frames.append(FrameInput([f.detections[j] for j in keep], To, i / HZ, str(i)))
        ids.append(tuple(f.object_ids[j] for j in keep))
    return BuildingWalk(camera, frames, poses, where, ids)
