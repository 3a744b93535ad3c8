"""Generated buildings: many rooms with the same objects, and simulated frames inside them.

A building is ``n_rooms`` rooms on a grid (:data:`ROOM_SPACING_M` apart, :data:`ROOMS_PER_FLOOR`
rooms per floor, floors :data:`FLOOR_HEIGHT_M` apart), every room made from the real Chess map
(``maps/data/chess.json``, 11 objects, 7 categories) turned by a random yaw about +Z (the map's
up) and moved to its grid cell. How rooms repeat (``mode``):

* ``"exact"``: exact copies (rigid copies of one room: truly ambiguous, the only right answer to
  a frame is ``ambiguous``, or not localized);
* ``"perturbed"``: every object moved by 0.1-0.5 m (uniform length, random horizontal
  direction), one random object dropped with probability 0.5 and one object of a random
  category added (a copy of a Chess object's shape at a random place of the room) with
  probability 0.3;
* ``"random"``: the room's own random layout of the Chess objects (each object at a uniformly
  random place of the room's floor box, its height kept, random yaw);
* ``"twins"``: random layouts, but each room after the first repeats the layout of a random
  earlier room with probability :data:`TWIN_PROBABILITY` (a hotel: a few identical rooms among
  different ones). A frame in a room whose layout another room has (:attr:`Building.twinned`)
  is truly ambiguous, as in an exact building.

Objects of a room never interpenetrate, as in the real Chess room (no two of its ellipsoids
intersect): every move, added object and random place is drawn again, up to
:data:`PLACEMENT_DRAWS` times, until its ellipsoid intersects none of the room's objects placed
before it (:func:`tests.support.scenes.ellipsoids_intersect`).

With ``corridors``, a corridor runs along each row of rooms with a few objects (random Chess
shapes) every :data:`CORRIDOR_STEP_M`. Maps hold at most ``LIMITS["max_objects"]`` objects: a
building that would exceed it drops the fewest objects per room that fit (the same ones in every
room of an exact building; 1,000 rooms with corridors: 8 objects per room).

Zones: every room is a zone ``"f<floor>-r<row>-c<col>"`` (:attr:`Building.rooms`), corridors
zones ``"f<floor>-corridor-<row>"``, both inside their floor's zone ``"f<floor>"`` (the map's
``zones``). Object ids are ``"<zone>/<chess id>"`` (``+<k>`` for added
objects).

Frames (:func:`building_frames`): the 108 real Chess poses placed in a room (its rigid transform
applied, perturbed and random rooms included), and new poses looking at the room's objects;
detections by :func:`tests.support.simulate.simulate_frame` on the room's own objects only (walls
hide the other rooms). Seeds: tune on :data:`TUNE_SEEDS`, report on :data:`REPORT_SEEDS`.

Poses are ``world_from_camera`` (4x4, OpenCV camera axes) unless named otherwise; metres.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from quadloc.factors.camera import Camera, Ellipsoid
from quadloc.factors.rotations import pose_matrix
from quadloc.maps.compiled import CompiledMap, compile_map
from quadloc.maps.demo import load_demo_map
from quadloc.maps.model import LIMITS, MapObject, MapZone, SceneMap
from tests.support.reference_data import load_chess_world_from_camera
from tests.support.scenes import ellipsoids_intersect, look_at
from tests.support.simulate import SimulatedFrame, SimulationConfig, simulate_frame

__all__ = [
    "FLOOR_HEIGHT_M",
    "MODES",
    "REPORT_SEEDS",
    "ROOMS_PER_FLOOR",
    "ROOM_SPACING_M",
    "TUNE_SEEDS",
    "Building",
    "BuildingFrame",
    "BuildingRecording",
    "Room",
    "building_frames",
    "building_recording",
    "make_building",
]

ROOM_SPACING_M = 12.0
FLOOR_HEIGHT_M = 4.0
ROOMS_PER_FLOOR = 100
MODES = ("exact", "perturbed", "random", "twins")
#: ``"twins"`` buildings: probability that a room repeats an earlier room's layout.
TWIN_PROBABILITY = 0.25
#: Base seeds of the benchmark (``bench.building --seed``; it derives each case's building and
#: frame seeds from one): tune (thresholds, calibration) on these ...
TUNE_SEEDS = tuple(range(0, 100))
#: ... and report on these (never used for tuning).
REPORT_SEEDS = tuple(range(1000, 1100))
#: Corridor objects: one every this many metres along a row of rooms.
CORRIDOR_STEP_M = 6.0
#: Draws of a move or place before the generator gives up (an error: the room is too full).
PLACEMENT_DRAWS = 200


@dataclass(frozen=True)
class Room:
    """One room of a building.

    Attributes:
        zone_id: ``"f<floor>-r<row>-c<col>"`` (corridors: ``"f<floor>-corridor-<row>"``).
        world_from_room: (4, 4) the rigid transform of the Chess frame into the world (yaw
            about +Z and a translation; for random layouts the frame the layout was drawn in).
        object_ids: ids of the room's objects.
    """

    zone_id: str
    world_from_room: np.ndarray
    object_ids: tuple[str, ...]


@dataclass(frozen=True)
class Building:
    """A generated building: the map (world frame, metres, +Z up), its rooms (zones), corridors
    and how it was made; ``twinned``: the zones of the rooms whose layout another room repeats
    exactly (every room of an exact building with more than one room; ``"twins"`` buildings:
    the rooms of a repeated layout)."""

    scene_map: SceneMap
    rooms: tuple[Room, ...]
    corridors: tuple[Room, ...]
    mode: str
    seed: int
    twinned: frozenset[str] = frozenset()

    @property
    def compiled(self) -> CompiledMap:
        return compile_map(self.scene_map)

    def zone_of(self, object_id: str) -> str:
        """The zone of an object (the prefix of its id)."""
        return object_id.split("/", 1)[0]

    def room_map(self, room: Room) -> CompiledMap:
        """The room's objects alone (what a camera inside it can see: walls hide the rest),
        compiled; memoised on the room."""
        memo: CompiledMap | None = room.__dict__.get("_compiled")
        if memo is None:
            sm = self.scene_map
            ids = set(room.object_ids)
            memo = compile_map(SceneMap(f"{sm.map_id}-{room.zone_id}", room.zone_id, sm.up_axis,
                                        sm.categories,
                                        tuple(o for o in sm.objects if o.object_id in ids)))
            object.__setattr__(room, "_compiled", memo)
        return memo


def _yaw(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _moved(obj: MapObject, object_id: str, world_from_room: np.ndarray,
           offset_room: np.ndarray | None = None, yaw: float = 0.0) -> MapObject:
    """``obj`` (Chess frame) with id ``object_id``, optionally moved by ``offset_room`` (m,
    Chess frame) and turned by ``yaw`` (rad) about its centre, then placed by
    ``world_from_room``."""
    e = obj.ellipsoid
    R = world_from_room[:3, :3]
    centre = e.center + (0.0 if offset_room is None else offset_room)
    rotation = R @ _yaw(yaw) @ e.rotation
    return MapObject(object_id, obj.category, type(e)(R @ centre + world_from_room[:3, 3],
                                                      e.axes.copy(), rotation))


def _free_draw(obj: MapObject, placed: list[Ellipsoid],
                draw: Callable[[MapObject], tuple[np.ndarray, float]]) -> tuple[np.ndarray, float]:
    """The first ``(offset_room, yaw)`` of ``draw(obj)`` (see :func:`_moved`) that puts
    ``obj``'s ellipsoid where it intersects none of ``placed`` (room frame), which it then
    joins."""
    for _ in range(PLACEMENT_DRAWS):
        offset, yaw = draw(obj)
        ell = _moved(obj, obj.object_id, np.eye(4), offset, yaw).ellipsoid
        if not any(ellipsoids_intersect(ell, other) for other in placed):
            placed.append(ell)
            return offset, yaw
    raise RuntimeError(f"no place for object {obj.object_id!r} that intersects no other in "
                       f"{PLACEMENT_DRAWS} draws")


def make_building(n_rooms: int, mode: str = "perturbed", seed: int = 0, *,
                  corridors: bool = False, yaw: bool = True) -> Building:
    """A building of ``n_rooms`` rooms (see the module docstring); deterministic in ``seed``.

    Args:
        n_rooms: rooms (>= 1); the first room of an exact building is the Chess room itself
            moved to its cell.
        mode: ``"exact"``, ``"perturbed"``, ``"random"`` or ``"twins"`` (:data:`MODES`).
        seed: the generator's seed.
        corridors: add corridor objects along each row of rooms.
        yaw: turn each room by a random yaw (else every room keeps the Chess orientation).
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if n_rooms < 1:
        raise ValueError("n_rooms must be >= 1")
    rng = np.random.default_rng(seed)
    chess = load_demo_map()
    base = list(chess.objects)
    centres = np.array([o.ellipsoid.center for o in base])
    middle = np.array([*centres[:, :2].mean(axis=0), 0.0])
    lo, hi = centres[:, :2].min(axis=0) - 0.5, centres[:, :2].max(axis=0) + 0.5
    per_room_hall = ROOM_SPACING_M / CORRIDOR_STEP_M if corridors else 0.0
    room_budget = (LIMITS["max_objects"] - per_room_hall * n_rooms) / n_rooms
    n_drop = max(0, math.ceil(len(base) - room_budget))
    drop_all = n_drop > 0
    exact_drop = set(rng.choice(len(base), n_drop, replace=False).tolist())
    side = math.ceil(math.sqrt(min(n_rooms, ROOMS_PER_FLOOR)))
    objects: list[MapObject] = []
    rooms: list[Room] = []
    layouts: list[list[tuple[np.ndarray, float]]] = []  # "twins": each room's (offset, yaw)
    layout_of: list[int] = []  # "twins": the room whose layout each room has

    def moved(obj: MapObject) -> tuple[np.ndarray, float]:  # "perturbed": 0.1-0.5 m sideways
        phi, length = rng.uniform(-math.pi, math.pi), rng.uniform(0.1, 0.5)
        return length * np.array([math.cos(phi), math.sin(phi), 0.0]), 0.0

    def anywhere(obj: MapObject) -> tuple[np.ndarray, float]:  # the floor box, height kept
        target = np.array([*rng.uniform(lo, hi), obj.ellipsoid.center[2]])
        return target - obj.ellipsoid.center, float(rng.uniform(-math.pi, math.pi))

    for k in range(n_rooms):
        floor, cell = divmod(k, ROOMS_PER_FLOOR)
        row, col = divmod(cell, side)
        zone = f"f{floor}-r{row}-c{col}"
        origin = np.array([col * ROOM_SPACING_M, row * ROOM_SPACING_M, floor * FLOOR_HEIGHT_M])
        theta = float(rng.uniform(-math.pi, math.pi)) if yaw else 0.0
        R = _yaw(theta)
        world_from_room = pose_matrix(R, origin - R @ middle)
        mine: list[MapObject] = []
        drop = exact_drop
        if mode == "perturbed":
            drop = set(rng.choice(len(base), max(n_drop, int(rng.random() < 0.5)),
                                  replace=False).tolist())
        placed: list[Ellipsoid] = []  # the room's objects so far, room frame
        if mode == "twins":
            layout_of.append(layout_of[int(rng.integers(k))] if k and
                             rng.random() < TWIN_PROBABILITY else k)
            if layout_of[k] == k:
                layouts.append([_free_draw(obj, placed, anywhere) for obj in base])
            else:
                layouts.append(layouts[layout_of[k]])
        for j, obj in enumerate(base):
            if j in drop:
                continue
            oid = f"{zone}/{obj.object_id}"
            if mode == "exact":
                mine.append(_moved(obj, oid, world_from_room))
            elif mode == "twins":
                mine.append(_moved(obj, oid, world_from_room, *layouts[k][j]))
            else:
                mine.append(_moved(obj, oid, world_from_room, *_free_draw(
                    obj, placed, moved if mode == "perturbed" else anywhere)))
        if mode == "perturbed" and not drop_all and rng.random() < 0.3:
            src = base[int(rng.integers(len(base)))]
            mine.append(_moved(src, f"{zone}/{src.object_id}+1", world_from_room,
                               *_free_draw(src, placed, anywhere)))
        objects += mine
        rooms.append(Room(zone, world_from_room, tuple(o.object_id for o in mine)))
    halls: list[Room] = []
    if corridors:
        halls = _corridors(rooms, side, base, rng, objects)
    sm = SceneMap(f"building-{mode}-{n_rooms}-{seed}", f"{n_rooms} rooms ({mode}), seed {seed}",
                  chess.up_axis, chess.categories, tuple(objects),
                  zones=_zones([*rooms, *halls]))
    twinned: frozenset[str] = frozenset()
    if mode == "exact" and n_rooms > 1:
        twinned = frozenset(r.zone_id for r in rooms)
    elif mode == "twins":
        repeated = {m for m in layout_of if layout_of.count(m) > 1}
        twinned = frozenset(r.zone_id for r, m in zip(rooms, layout_of, strict=True)
                            if m in repeated)
    return Building(sm, tuple(rooms), tuple(halls), mode, seed, twinned)


def _zones(parts: list[Room]) -> tuple[MapZone, ...]:
    """The map's zones: one per floor (``"f<floor>"``, every object of the floor) and each room
    and corridor inside its floor (parts without objects have no zone)."""
    floors: dict[str, list[str]] = {}
    for part in parts:
        floors.setdefault(part.zone_id.split("-", 1)[0], []).extend(part.object_ids)
    return (*(MapZone(f, f"floor {f[1:]}", tuple(ids)) for f, ids in floors.items() if ids),
            *(MapZone(p.zone_id, p.zone_id, p.object_ids, p.zone_id.split("-", 1)[0])
              for p in parts if p.object_ids))


def _corridors(rooms: list[Room], side: int, base: list[MapObject], rng: np.random.Generator,
               objects: list[MapObject]) -> list[Room]:
    """Corridor zones (one per row of rooms per floor, half a spacing beside the row), their
    objects appended to ``objects``."""
    halls: list[Room] = []
    rows: dict[tuple[int, int], int] = {}
    for k in range(len(rooms)):
        floor, cell = divmod(k, ROOMS_PER_FLOOR)
        rows.setdefault((floor, cell // side), 0)
        rows[(floor, cell // side)] += 1
    for (floor, row), count in sorted(rows.items()):
        zone = f"f{floor}-corridor-{row}"
        y = (row + 0.5) * ROOM_SPACING_M
        length = count * ROOM_SPACING_M
        world_from_hall = pose_matrix(np.eye(3), [0.0, y, floor * FLOOR_HEIGHT_M])
        ids = []
        for j, x in enumerate(np.arange(-ROOM_SPACING_M / 2 + 1.0, length - ROOM_SPACING_M / 2,
                                        CORRIDOR_STEP_M)):
            src = base[int(rng.integers(len(base)))]
            at = np.array([x, rng.uniform(-1.0, 1.0), src.ellipsoid.center[2]])
            ob = _moved(src, f"{zone}/{j}", world_from_hall, at - src.ellipsoid.center,
                        float(rng.uniform(-math.pi, math.pi)))
            objects.append(ob)
            ids.append(ob.object_id)
        halls.append(Room(zone, world_from_hall, tuple(ids)))
    return halls


@dataclass(frozen=True, eq=False)
class BuildingFrame:
    """One simulated frame of a building: its room, the true pose, the detections, and how the
    pose was made (``"chess"``: a real Chess pose placed in the room, ``"look"``: a new pose
    looking at the room's objects)."""

    room: Room
    frame: SimulatedFrame
    kind: str

    @property
    def world_from_camera(self) -> np.ndarray:
        return self.frame.world_from_camera

    @property
    def n_true(self) -> int:
        """Detections of true objects (with their true label or not)."""
        return sum(o is not None for o in self.frame.object_ids)


def _look_pose(room_map: CompiledMap, rng: np.random.Generator) -> np.ndarray:
    """A pose looking at a random object of the room from 1.5-3.5 m away, eye 1.0-1.8 m above
    the floor, aim jittered by 0.3 m, roll within +-5 degrees."""
    target = room_map.centers[int(rng.integers(len(room_map)))]
    floor_z = math.floor(target[2] / FLOOR_HEIGHT_M) * FLOOR_HEIGHT_M
    phi = rng.uniform(-math.pi, math.pi)
    dist = rng.uniform(1.5, 3.5)
    eye = np.array([target[0] + dist * math.cos(phi), target[1] + dist * math.sin(phi),
                    floor_z + rng.uniform(1.0, 1.8)])
    return look_at(eye, target + rng.normal(0.0, 0.3, 3), roll=math.radians(rng.uniform(-5, 5)))


def building_frames(building: Building, n_frames: int, seed: int, *,
                    config: SimulationConfig | None = None, min_detections: int = 3,
                    look_fraction: float = 0.5, max_tries: int = 50,
                    ) -> tuple[Camera, list[BuildingFrame]]:
    """``n_frames`` frames with at least ``min_detections`` detections of true objects, each in
    a random room: a real Chess pose placed in the room, or (with probability
    ``look_fraction``) a new pose looking at the room's objects; detections by
    :func:`tests.support.simulate.simulate_frame` with ``config`` (default: the simulator's
    default detector with wrong labels at 0.05 and spurious detections at rate 0.3) on the
    room's objects only. Deterministic in ``seed``. Returns (the Chess camera, the frames)."""
    camera, chess_poses, _ = load_chess_world_from_camera()
    cfg = config or SimulationConfig(wrong_label_probability=0.05, spurious_rate=0.3)
    rng = np.random.default_rng(seed)
    out: list[BuildingFrame] = []
    while len(out) < n_frames:
        room = building.rooms[int(rng.integers(len(building.rooms)))]
        room_map = building.room_map(room)
        for _ in range(max_tries):
            look = rng.random() < look_fraction
            if look:
                T = _look_pose(room_map, rng)
            else:
                T = room.world_from_room @ chess_poses[int(rng.integers(len(chess_poses)))]
            f = simulate_frame(room_map, camera, T, rng, cfg)
            bf = BuildingFrame(room, f, "look" if look else "chess")
            if bf.n_true >= min_detections:
                out.append(bf)
                break
    return camera, out


def two_chess_rooms_document(map_id: str, name: str = "Two rooms") -> dict:
    """A map document (docs/maps.md) of two exact copies of the demo Chess room, 20 m apart along
    x, with zones ``room-a`` and ``room-b`` (as the docs/api.md example builds it): the demo frame
    is ambiguous between them; object ids ``<zone>/<chess id>``."""
    chess = load_demo_map().to_dict()
    objects, zones = [], []
    for room, dx in (("room-a", 0.0), ("room-b", 20.0)):
        ids = [f"{room}/{o['object_id']}" for o in chess["objects"]]
        objects += [{**o, "object_id": i, "center": [o["center"][0] + dx, *o["center"][1:]]}
                    for i, o in zip(ids, chess["objects"], strict=True)]
        zones.append({"zone_id": room, "object_ids": ids})
    return {"map_id": map_id, "name": name, "categories": chess["categories"],
            "objects": objects, "zones": zones}


@dataclass(frozen=True, eq=False)
class BuildingRecording:
    """A map-building recording through a building (:func:`building_recording`).

    Attributes:
        building: the generated building (its map is the truth).
        camera: the Chess camera.
        true_poses: (F,) true ``world_from_camera`` 4x4 poses.
        app_poses: (F,) the app's drifting ``world_from_camera`` poses
            (:func:`tests.support.walks.drifting_odometry` over the whole walk).
        frames: (F,) the simulated detections (``object_ids`` name the true objects; transit
            frames between rooms see no object).
        zone_of_frame: (F,) the room a frame is in (``None`` in transit).
        visits: the rooms in walking order (``zone_id``, first frame, end frame exclusive).
    """

    building: Building
    camera: Camera
    true_poses: tuple[np.ndarray, ...]
    app_poses: tuple[np.ndarray, ...]
    frames: tuple[SimulatedFrame, ...]
    zone_of_frame: tuple[str | None, ...]
    visits: tuple[tuple[str, int, int], ...]


def _room_route(building: Building, n_frames: int, frames_per_visit: int,
                rng: np.random.Generator) -> list[int]:
    """Room indices in walking order: every room once along the grid (row by row, alternating
    direction), then revisits, each a random room within two grid steps of the current one or,
    one time in four, any room (a long loop back), until ``n_frames`` are filled."""
    n = len(building.rooms)
    side = math.ceil(math.sqrt(min(n, ROOMS_PER_FLOOR)))
    first = []
    for k in range(n):
        row, col = divmod(k % ROOMS_PER_FLOOR, side)
        first.append((k // ROOMS_PER_FLOOR, row, col if row % 2 == 0 else side - 1 - col))
    order = sorted(range(n), key=lambda k: first[k])
    route = list(order)
    centres = np.array([building.room_map(r).centers.mean(axis=0) for r in building.rooms])
    while len(route) * frames_per_visit < n_frames:
        here = route[-1]
        near = np.flatnonzero((np.linalg.norm(centres - centres[here], axis=1)
                               <= 2.5 * ROOM_SPACING_M) & (np.arange(n) != here))
        pool = near if len(near) and rng.random() >= 0.25 else np.delete(np.arange(n), here)
        route.append(int(rng.choice(pool)) if len(pool) else here)
    return route


def building_recording(n_rooms: int = 20, n_frames: int = 6000, seed: int = 0, *,
                       mode: str = "perturbed", config: SimulationConfig | None = None,
                       transit_step_m: float = 0.5) -> BuildingRecording:
    """A walk through a generated building for map building; deterministic in ``seed``.

    The building: :func:`make_building` (``n_rooms``, ``mode``; rooms turned by random yaws).
    The walk visits every room once (row by row), then revisits rooms (:func:`_room_route`)
    until ``n_frames`` frames: in a room, the real Chess walk (its 108 poses, interpolated:
    :func:`tests.support.walks.resampled_walk`) placed in the room, the whole walk in
    ``~200`` frames at the first visit (forwards or backwards), a random contiguous half of it
    at a revisit; between rooms, a straight transit at eye height with ``transit_step_m`` steps
    in which nothing is detected (walls hide the rooms). Detections: :func:`simulate_frame` on the
    room's own objects with ``config`` (default: the simulator's detector noise, truncation,
    occlusion, 10 % misses, 5 % wrong labels, 0.2 spurious detections per frame). The app's
    poses drift over the whole walk: :func:`tests.support.walks.drifting_odometry` (per step,
    rotation noise N(0, 0.05 deg) about a random axis and translation noise N(0, 1 % of the step
    + 1 mm) per axis, chained from the true first pose: an unbounded random walk, no loop
    closure by the app). The walk is cut at ``n_frames``.
    """
    from tests.support.walks import drifting_odometry, resampled_walk

    building = make_building(n_rooms, mode, seed)
    camera, chess_poses, _ = load_chess_world_from_camera()
    cfg = config or SimulationConfig(wrong_label_probability=0.05, spurious_rate=0.2)
    rng = np.random.default_rng([seed, 29])
    per_visit = 200
    full = resampled_walk(chess_poses, per_visit)
    half_source = resampled_walk(chess_poses, 2 * per_visit)
    route = _room_route(building, n_frames, per_visit, rng)
    poses: list[np.ndarray] = []
    zones: list[str | None] = []
    visits: list[tuple[str, int, int]] = []
    seen: set[int] = set()
    for k in route:
        room = building.rooms[k]
        if k in seen:
            start = int(rng.integers(0, per_visit))
            stretch = half_source[start:start + per_visit]
        else:
            stretch = list(full)
        seen.add(k)
        if rng.random() < 0.5:
            stretch = stretch[::-1]
        inside = [room.world_from_room @ T for T in stretch]
        if poses:  # transit from the last pose to the room's first one
            a, b = poses[-1], inside[0]
            steps = max(2, math.ceil(float(np.linalg.norm(b[:3, 3] - a[:3, 3]))
                                     / transit_step_m))
            transit = resampled_walk([a, b], steps + 1)[1:-1]
            poses += transit
            zones += [None] * len(transit)
        visits.append((room.zone_id, len(poses), len(poses) + len(inside)))
        poses += inside
        zones += [room.zone_id] * len(inside)
        if len(poses) >= n_frames:
            break
    poses, zones = poses[:n_frames], zones[:n_frames]
    visits = [(z, a, min(b, n_frames)) for z, a, b in visits if a < n_frames]
    rooms = {r.zone_id: r for r in building.rooms}
    frames = [SimulatedFrame((), (), (), (), np.zeros(0), T) if z is None
              else simulate_frame(building.room_map(rooms[z]), camera, T, rng, cfg)
              for T, z in zip(poses, zones, strict=True)]
    app = drifting_odometry(poses, rng)
    return BuildingRecording(building, camera, tuple(poses), tuple(app), tuple(frames),
                             tuple(zones), tuple(visits))
