"""Place hypotheses of tracking sessions in buildings (service/tracking/places.py): walks
through generated buildings (tests/support/building_walks.py), seeds of the tests only."""

from __future__ import annotations

import math

import numpy as np

from quadloc.service.tracking.places import COMMIT_PROBABILITY, LIST_PROBABILITY
from quadloc.service.tracking.session import FrameInput, SessionOptions, TrackingSession
from tests.support.building_walks import building_walk
from tests.support.buildings import make_building
from tests.support.errors import pose_errors
from tests.support.simulate import SimulationConfig, simulate_frame


def _run(building, walk, frames=None):
    s = TrackingSession(building.compiled, walk.camera, SessionOptions())
    out = []
    for f, T in list(zip(walk.frames, walk.poses, strict=True))[:frames]:
        r = s.add_frame(f)
        out.append((r, pose_errors(r.world_from_camera, T)))
    return s, out


def test_exact_copies_are_ambiguous_with_the_true_room_listed_never_a_wrong_pose() -> None:
    b = make_building(3, "exact", 5)
    walk = building_walk(b, 7, n_rooms=1)
    _, out = _run(b, walk, 150)
    posed = [e for r, e in out if r.world_from_camera is not None]
    # every pose answered is in the right copy (an exact copy can only be told apart by luck)
    assert all(e[0] <= 0.5 for e in posed)
    amb = [(r, walk.poses[r.frame_index]) for r, _ in out if r.reason == "ambiguous"]
    assert len(amb) >= 50
    for r, T in amb:
        assert len(r.candidates) >= 2
        probs = [c.probability for c in r.candidates]
        assert probs == sorted(probs, reverse=True) and sum(probs) <= 1 + 1e-9
        assert min(probs) >= LIST_PROBABILITY and max(probs) < COMMIT_PROBABILITY
        # the candidates are in different rooms (zones), the true one among them
        assert len({c.zone for c in r.candidates}) >= 2
        assert min(pose_errors(c.world_from_camera, T)[0] for c in r.candidates) <= 0.5


def test_perturbed_building_walk_commits_to_the_right_rooms_and_is_deterministic() -> None:
    b = make_building(10, "perturbed", 3)
    walk = building_walk(b, 11)
    _, out = _run(b, walk, 300)
    tracked = [(r, e) for r, e in out if r.state == "tracking"]
    assert tracked, "never committed"
    assert all(e[0] <= 0.5 for _, e in tracked)
    assert np.mean([e[0] <= 0.1 and e[1] <= 5 for _, e in tracked]) >= 0.95
    # the answer names the walk's room; its place is the only listed one
    r, _ = tracked[-1]
    assert r.candidates[0].zone == walk.rooms[r.frame_index].zone_id
    assert r.confidence <= r.candidates[0].probability + 1e-12
    # the same inputs give the same answers (no clock decides anything)
    _, again = _run(b, walk, 300)
    for (r1, _), (r2, _) in zip(out, again, strict=True):
        assert (r1.state, r1.reason, len(r1.candidates)) == (r2.state, r2.reason,
                                                             len(r2.candidates))
        if r1.world_from_camera is not None:
            np.testing.assert_allclose(r1.world_from_camera, r2.world_from_camera, atol=1e-9)


#: A committed session whose detections come from another room says so within this many frames.
GIVE_UP_FRAMES = 5


def test_a_committed_session_carried_to_another_room_says_so_and_recovers() -> None:
    b = make_building(4, "perturbed", 2)
    walk = building_walk(b, 3, n_rooms=1)
    s = TrackingSession(b.compiled, walk.camera, SessionOptions())
    for f in walk.frames[:120]:
        r = s.add_frame(f)
    assert r.state == "tracking"
    # the device is carried to another room without its odometry knowing (e.g. a reset
    # glossed over): the detections now come from room `other`, the odometry continues
    other = next(x for x in b.rooms if x is not walk.rooms[0])
    rel = other.world_from_room @ np.linalg.inv(walk.rooms[0].world_from_room)
    rng = np.random.default_rng(0)
    answers = []
    for k, (f, T) in enumerate(zip(walk.frames[120:400], walk.poses[120:400], strict=True)):
        T_other = rel @ T  # the walk's pose, in the other room
        sim = simulate_frame(b.room_map(other), walk.camera, T_other, rng,
                             SimulationConfig(wrong_label_probability=0.05, spurious_rate=0.3))
        r = s.add_frame(FrameInput(list(sim.detections), f.odom_from_camera, f.timestamp))
        answers.append((k, r, pose_errors(r.world_from_camera, T_other)))
    first_off = next(k for k, r, _ in answers if r.state != "tracking")
    assert first_off < GIVE_UP_FRAMES
    assert all(e[0] > 0.5 for k, r, e in answers[:first_off])  # (the old room's poses)
    # and it relocalizes in the right room
    back = [(r, e) for _, r, e in answers[first_off:] if r.state == "tracking"]
    assert back and all(e[0] <= 0.5 for _, e in back)
    assert math.isfinite(back[0][1][0])
