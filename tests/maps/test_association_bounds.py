"""The association's work is bounded by its input size (issue 32, item 1): pairs evaluated in
chunks, all pairs only up to ``MAX_LABEL_PAIRS`` (frame buckets beyond), and the overlap
pre-filter of the verification never skips a detection that overlaps."""

from __future__ import annotations

import numpy as np
import pytest

from quadloc.factors.budget import Deadline
from quadloc.factors.camera import DegenerateProjectionError, Ellipsoid, project_ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import invert_pose
from quadloc.maps.building import association as assoc
from quadloc.maps.building.association import AssociationOptions, ellipse_iou
from quadloc.maps.building.build import BuildTimeoutError, build_map
from quadloc.service.app.builds import recording_of as parse_recording
from tests.support.helpers import random_rotation
from tests.support.hostile import HOSTILE_CAMERA, hostile_recording, look_at


@pytest.mark.parametrize("n", [0, 1, 2, 7, 900])
def test_all_pairs_chunks_are_triu_indices_in_order(n: int, monkeypatch: pytest.MonkeyPatch
                                                   ) -> None:
    monkeypatch.setattr(assoc, "PAIR_CHUNK", 50)
    chunks = list(assoc._all_pairs(n))
    i = np.concatenate([c[0] for c in chunks]) if chunks else np.zeros(0, int)
    j = np.concatenate([c[1] for c in chunks]) if chunks else np.zeros(0, int)
    ti, tj = np.triu_indices(n, 1)
    assert np.array_equal(i, ti) and np.array_equal(j, tj)
    # each chunk within the bound unless one row alone is longer
    assert all(len(c[0]) <= max(50, n - 1) for c in chunks)


def test_frame_buckets_stay_within_the_pair_budget_and_pair_distinct_frames() -> None:
    rng = np.random.default_rng(3)
    frames = np.sort(rng.integers(0, 400, 6000))
    rng.shuffle(frames)  # detection order need not follow frames
    max_pairs = 200_000
    pairs = list(assoc._bucket_pairs(frames, max_pairs))
    i = np.concatenate([p[0] for p in pairs])
    j = np.concatenate([p[1] for p in pairs])
    assert len(i) <= max_pairs
    assert np.all(frames[i] != frames[j])
    # no pair twice, in either order
    key = np.minimum(i, j) * len(frames) + np.maximum(i, j)
    assert len(np.unique(key)) == len(key)
    # short and long baselines: consecutive frames and frames half the walk apart
    ranks = np.unique(frames, return_inverse=True)[1]
    gaps = np.abs(ranks[i] - ranks[j])
    assert gaps.min() == 1 and gaps.max() >= len(np.unique(frames)) // 2
    # the brute-force count of the pairs of the chosen offsets (independent of the chunking)
    counts = np.bincount(ranks)
    offsets = assoc._bucket_offsets(counts, max_pairs)
    assert set(np.unique(gaps).tolist()) == set(offsets.tolist())
    assert len(i) == sum(int(counts[a] * counts[a + o]) for o in offsets.tolist()
                         for a in range(len(counts) - o))


def test_pair_candidates_beyond_the_budget_use_buckets_and_stay_bounded(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A label with more pairs than the budget: the candidates come from the bucketed pairs
    only (fewer pairs evaluated, every candidate one of the all-pairs candidates)."""
    rec = parse_recording(hostile_recording(120, 10, 9, seed=1))
    T = np.array([f.world_from_camera for f in rec.frames])
    box = [o for o in rec.observations if o.label == "Box"]
    o, d, rho = assoc._rays(box, rec.camera, T)
    frames = np.array([b.frame for b in box])
    opt = AssociationOptions(max_candidates=10 ** 9)
    X_all, _ = assoc._pair_candidates(o, d, rho, frames, opt, np.random.default_rng(0))
    evaluated: list[int] = []
    real = assoc._bucket_pairs

    def counting(fr: np.ndarray, max_pairs: int):  # type: ignore[no-untyped-def]
        for i, j in real(fr, max_pairs):
            evaluated.append(len(i))
            yield i, j

    monkeypatch.setattr(assoc, "_bucket_pairs", counting)
    X_b, _ = assoc._pair_candidates(o, d, rho, frames, opt, np.random.default_rng(0),
                                    max_pairs=20_000)
    assert 0 < sum(evaluated) <= 20_000 < len(box) * (len(box) - 1) // 2
    assert 0 < len(X_b) < len(X_all)
    rows = {tuple(x) for x in np.round(X_all, 12).tolist()}
    assert all(tuple(x) in rows for x in np.round(X_b, 12).tolist())


def test_support_mask_in_chunks_equals_the_whole_computation(
        monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(5)
    o, d = rng.normal(size=(300, 3)), rng.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rho = rng.uniform(0.01, 0.2, 300)
    X, S = rng.normal(size=(70, 3)), rng.uniform(0.1, 1.0, 70)
    opt = AssociationOptions(ray_tolerance=2.0, size_ratio=10.0)
    monkeypatch.setattr(assoc, "PAIR_CHUNK", 1000)
    whole = assoc._support(X, S, o, d, rho, opt)[0]
    assert whole.any() and not whole.all()
    assert np.array_equal(assoc._support_mask(X, S, o, d, rho, opt), whole)


def test_overlap_prefilter_never_drops_an_overlapping_detection() -> None:
    """Against the exact IoU of the projection: every detection with IoU > 0 passes."""
    rng = np.random.default_rng(7)
    cam = HOSTILE_CAMERA
    kept = overlapping = 0
    for _ in range(300):
        ell = Ellipsoid(rng.uniform(-1, 1, 3), rng.uniform(0.05, 0.6, 3), random_rotation(rng))
        eye = rng.uniform(-4, 4, 3)
        T = look_at(eye, ell.center + rng.normal(0, 0.8, 3))
        try:
            proj = project_ellipsoid(cam, invert_pose(T), ell)
        except DegenerateProjectionError:
            continue
        dets = [Ellipse(proj.cx + float(rng.normal(0, 60)), proj.cy + float(rng.normal(0, 60)),
                        float(rng.uniform(3, 80)), float(rng.uniform(3, 80)),
                        float(rng.uniform(-1.5, 1.5))) for _ in range(8)]
        may = assoc._may_overlap(ell, np.repeat(T[None], len(dets), 0), cam, dets)
        for det, m in zip(dets, may.tolist(), strict=True):
            iou = ellipse_iou(proj, det)
            overlapping += iou > 0
            kept += (iou > 0) and m
            assert m or iou == 0.0
    assert overlapping > 200 and kept == overlapping


def test_a_hostile_build_stops_at_its_time_budget() -> None:
    """The issue's repro shape (random ellipses, 9 of 10 per frame labelled Box, cameras on a
    ring looking at one point), smaller: the deadline is checked inside every stage, so a build
    past its budget fails with BuildTimeoutError instead of running on (the bench measures
    the full-size one: bench/adversarial.py)."""
    rec = parse_recording(hostile_recording(400, 10, 9))
    with pytest.raises(BuildTimeoutError):
        build_map(rec, map_id="hostile", deadline=Deadline.wall_budget(0.5))
