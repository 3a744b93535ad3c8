"""RANSAC scoring (fast IoU, vectorised projection, assignment) and the search itself."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadloc.factors import metrics
from quadloc.factors.budget import Deadline
from quadloc.factors.camera import Ellipsoid, project_ellipsoid
from quadloc.factors.conics import Ellipse
from quadloc.factors.rotations import invert_pose
from quadloc.maps.compiled import compile_map
from quadloc.maps.model import MapObject, SceneMap
from quadloc.service.localization.hypotheses import project_objects
from quadloc.service.localization.scoring import (
    MatchScorer,
    ellipse_points,
    greedy_assignment,
    iou_estimates,
    sunflower_disk,
)
from quadloc.service.localization.search import ransac
from tests.service.localization.test_hypotheses import BACK, CAM, UP, look_at


def random_ellipse(rng: np.random.Generator) -> Ellipse:
    return Ellipse(rng.uniform(100, 500), rng.uniform(100, 400), rng.uniform(10, 80),
                   rng.uniform(10, 80), rng.uniform(-math.pi, math.pi))


def estimate_iou(detection: Ellipse, projection: Ellipse, n_points: int = 256) -> float:
    """The production estimator (:func:`iou_estimates`) on one pair of ellipses."""
    pts = ellipse_points(detection.params()[None], sunflower_disk(n_points))[0]
    _, S = projection.gaussian()
    return float(iou_estimates(pts, np.array(detection.area), projection.center, S))


def dense_scores(dense: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Oracle of ``MatchScorer.pair_scores`` on the dense IoU matrix (H, D, N): (score (H,),
    inlier count (H,)) with each detection taking its best object."""
    best = dense.max(axis=2)
    inl = best >= threshold
    return np.where(inl, best, 0.0).sum(axis=1), inl.sum(axis=1)


def test_estimate_iou_matches_exact_metric():
    rng = np.random.default_rng(0)
    errs = []
    for _ in range(60):
        a = random_ellipse(rng)
        b = Ellipse(a.cx + rng.normal(0, 15), a.cy + rng.normal(0, 15), a.a * rng.uniform(.7, 1.3),
                    a.b * rng.uniform(.7, 1.3), a.angle + rng.normal(0, 0.3))
        exact = 1.0 - metrics.cost("iou", a, b)
        errs.append(abs(estimate_iou(a, b, 256) - exact))
    assert max(errs) < 0.03
    assert np.mean(errs) < 0.01


def test_estimate_iou_closed_forms():
    # concentric circles: IoU = (r1 / r2)^2; disjoint: 0; identical: 1 (to sampling accuracy)
    assert estimate_iou(Ellipse(0, 0, 10, 10, 0), Ellipse(0, 0, 20, 20, 0)) == pytest.approx(
        0.25, abs=0.01)
    assert estimate_iou(Ellipse(0, 0, 20, 20, 0), Ellipse(0, 0, 10, 10, 0)) == pytest.approx(
        0.25, abs=0.01)
    assert estimate_iou(Ellipse(0, 0, 10, 5, 0), Ellipse(100, 0, 10, 5, 0)) == 0.0
    assert estimate_iou(Ellipse(3, 4, 10, 5, 0.3), Ellipse(3, 4, 10, 5, 0.3)) == pytest.approx(
        1.0, abs=1e-12)


def test_project_objects_matches_geometry():
    rng = np.random.default_rng(1)
    E = [Ellipsoid(rng.uniform(-1, 1, 3), rng.uniform(.1, .4, 3)) for _ in range(5)]
    poses = np.array([invert_pose(look_at(rng.uniform(-1, 1, 3) + BACK, np.zeros(3)))
                      for _ in range(3)])
    cen, inv_shape, valid, pc = project_objects(
        CAM, poses, np.array([e.center for e in E]), np.array([e.shape_matrix() for e in E]),
        np.array([e.dual_quadric() for e in E]))
    assert valid.all()
    for h, T in enumerate(poses):
        for s, e in enumerate(E):
            ref = project_ellipsoid(CAM, T, e)
            assert np.allclose(cen[h, s], ref.center, atol=1e-8)
            assert np.allclose(inv_shape[h, s], ref.gaussian()[1], rtol=1e-8, atol=1e-6)
            assert np.allclose(pc[h, s], CAM.project_points(T, e.center[None])[0], atol=1e-8)
    # the camera turned 180 degrees about its own Y axis: every object is behind it -> invalid
    flipped = np.einsum("ij,hjk->hik", np.diag([-1.0, 1.0, -1.0, 1.0]), poses)
    _, _, valid2, _ = project_objects(
        CAM, flipped, np.array([e.center for e in E]), np.array([e.shape_matrix() for e in E]),
        np.array([e.dual_quadric() for e in E]))
    assert not valid2.any()


def test_greedy_assignment_is_one_to_one_and_thresholded():
    iou = np.array([[0.9, 0.8, 0.0], [0.85, 0.3, 0.0], [0.1, 0.15, 0.05]])
    m = greedy_assignment(iou, [4, 7, 9], 0.2)
    assert [(x.detection_index, x.object_index) for x in m] == [(4, 0), (7, 1)]
    assert all(x.iou >= 0.2 for x in m)


def synthetic_map(rng: np.random.Generator, n: int = 8, labels=("a", "b", "c", "a", "b", "d",
                                                              "e", "a")) -> SceneMap:
    objs = []
    for i in range(n):
        c = np.array([rng.uniform(-1.5, 1.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.8, 0.8)])
        objs.append(MapObject(f"o{i}", labels[i], Ellipsoid(c, rng.uniform(0.1, 0.25, 3))))
    return SceneMap("synthetic", "synthetic", (0.0, 0.0, 1.0), tuple(sorted(set(labels))),
                    tuple(objs))


def exact_detections(compiled, T_cw):
    ells, labels = [], []
    for e, lab in zip(compiled.ellipsoids, compiled.categories, strict=True):
        ells.append(project_ellipsoid(CAM, T_cw, e))
        labels.append(lab)
    return ells, labels


def test_ransac_exact_finds_pose_and_all_matches():
    rng = np.random.default_rng(2)
    cm = compile_map(synthetic_map(rng))
    T_cw = invert_pose(look_at(np.array([0.2, -4.0, 0.3]), np.zeros(3)))
    ells, labels = exact_detections(cm, T_cw)
    scorer = MatchScorer(cm, CAM, ells, labels, list(range(len(ells))))
    out = ransac(scorer, UP, inlier_iou=0.2, min_inliers=2, max_hypotheses=500,
                 rng=np.random.default_rng(0))
    assert out.camera_from_world is not None
    # P3P on centres is close to the truth (ellipse centre != projected centre: ~mm level)
    c_est = invert_pose(out.camera_from_world)[:3, 3]
    assert np.linalg.norm(c_est - invert_pose(T_cw)[:3, 3]) < 0.05
    assert sorted((m.detection_index, m.object_index) for m in out.matches) == [
        (i, i) for i in range(len(ells))]
    assert all(m.iou > 0.9 for m in out.matches)


def test_ransac_with_outliers_and_wrong_labels():
    rng = np.random.default_rng(3)
    cm = compile_map(synthetic_map(rng))
    T_cw = invert_pose(look_at(np.array([-0.3, -4.0, 0.6]), np.zeros(3)))
    ells, labels = exact_detections(cm, T_cw)
    noisy = [Ellipse(e.cx + rng.normal(0, 2), e.cy + rng.normal(0, 2), e.a * rng.uniform(.93, 1.07),
                     e.b * rng.uniform(.93, 1.07), e.angle + rng.normal(0, .05)) for e in ells]
    labels = list(labels)
    labels[2] = "e" if labels[2] != "e" else "d"  # a wrong label
    spurious = [random_ellipse(rng) for _ in range(3)]  # spurious detections
    all_ells = noisy + spurious
    all_labels = [*labels, "a", "b", "c"]
    scorer = MatchScorer(cm, CAM, all_ells, all_labels, list(range(len(all_ells))))
    out = ransac(scorer, UP, inlier_iou=0.3, min_inliers=3, max_hypotheses=2000,
                 rng=np.random.default_rng(0))
    assert out.camera_from_world is not None
    c_est = invert_pose(out.camera_from_world)[:3, 3]
    assert np.linalg.norm(c_est - invert_pose(T_cw)[:3, 3]) < 0.3
    pairs = {(m.detection_index, m.object_index) for m in out.matches}
    correct = {(i, i) for i in range(len(ells)) if i != 2}
    assert len(pairs & correct) >= len(correct) - 1
    assert all(d < len(ells) and d == o for d, o in pairs)  # no outlier matched


def test_ransac_sampling_budget_and_determinism():
    rng = np.random.default_rng(4)
    labels = ("a",) * 8  # one label: C(8,3) * 8*7*6 = 18816 P3P samples, > budget
    cm = compile_map(synthetic_map(rng, labels=labels))
    T_cw = invert_pose(look_at(np.array([0.0, -4.0, 0.2]), np.zeros(3)))
    ells, labs = exact_detections(cm, T_cw)
    scorer = MatchScorer(cm, CAM, ells, labs, list(range(len(ells))))
    outs = [ransac(scorer, UP, inlier_iou=0.2, min_inliers=2, max_hypotheses=300,
                   rng=np.random.default_rng(7)) for _ in range(2)]
    assert not outs[0].exhaustive and outs[0].samples_tried <= 300
    assert np.array_equal(outs[0].camera_from_world, outs[1].camera_from_world)
    assert outs[0].samples_tried == outs[1].samples_tried


def test_ransac_two_detections_uses_p2e():
    rng = np.random.default_rng(5)
    E = [Ellipsoid(np.array([-0.5, 0.0, 0.0]), np.array([0.2, 0.15, 0.25])),
         Ellipsoid(np.array([0.6, 0.3, 0.2]), np.array([0.25, 0.2, 0.15]))]
    sm = SceneMap("two", "two", (0.0, 0.0, 1.0), ("x", "y"),
                  (MapObject("A", "x", E[0]), MapObject("B", "y", E[1])))
    cm = compile_map(sm)
    T_cw = invert_pose(look_at(np.array([0.3, -4.0, 0.8]), np.array([0.0, 0.0, 0.1])))
    ells = [project_ellipsoid(CAM, T_cw, e) for e in E]
    scorer = MatchScorer(cm, CAM, ells, ["x", "y"], [0, 1])
    out = ransac(scorer, UP, inlier_iou=0.5, min_inliers=2, max_hypotheses=10, rng=rng)
    assert out.camera_from_world is not None
    assert np.max(np.abs(out.camera_from_world - T_cw)) < 1e-7
    # no compatible pair (both detections labelled "x", one "x" object) -> no_label_match
    scorer2 = MatchScorer(cm, CAM, ells, ["x", "x"], [0, 1])
    out2 = ransac(scorer2, UP, inlier_iou=0.5, min_inliers=2, max_hypotheses=10, rng=rng)
    assert out2.camera_from_world is None and out2.reason == "no_label_match"


def test_sample_counts_are_per_label_and_enumeration_is_complete():
    """count_samples (closed form per label) == a brute-force walk over detection tuples."""
    import itertools

    from quadloc.service.localization.sampling import count_samples, enumerate_samples

    rng = np.random.default_rng(6)
    cm = compile_map(synthetic_map(rng))  # labels a a a b b c d e
    labs = ["a", "a", "b", "c", "a", "e", "a", "b"]
    ells = [random_ellipse(rng) for _ in labs]
    scorer = MatchScorer(cm, CAM, ells, labs, list(range(len(labs))))
    for size in (2, 3):
        brute = sorted(
            (dets, objs) for dets in itertools.combinations(range(len(labs)), size)
            for objs in itertools.product(*(scorer.compatible_objects(d).tolist() for d in dets))
            if len(set(objs)) == size)
        assert count_samples(scorer, size) == len(brute)
        assert sorted(enumerate_samples(scorer, size, len(brute))) == brute
        assert enumerate_samples(scorer, size, len(brute) - 1) is None


@pytest.mark.parametrize("seed", [6, 7, 8])
def test_most_promising_first_is_the_stable_sort_of_every_sample(seed):
    """most_promising_first (triples sorted, their samples generated lazily) == every sample
    of all_samples stably sorted by (compatible-object product, -triangle area), also with
    duplicate detections (equal keys of different triples: their samples interleave)."""
    from quadloc.service.localization.sampling import (
        all_samples,
        most_promising_first,
        triangle_areas,
    )

    rng = np.random.default_rng(seed)
    cm = compile_map(synthetic_map(rng))  # labels a a a b b c d e
    labs = ["a", "a", "b", "c", "a", "e", "a", "b"][:5 + seed % 3]
    ells = [random_ellipse(rng) for _ in labs]
    # duplicates: the triples (0, x, y) and (1, x, y) tie (their samples do not interleave),
    # so do (x, y, 2) and (x, y, n) (their samples interleave: a later label group)
    ells[1], labs[1] = ells[0], labs[0]
    ells.append(ells[2])
    labs.append(labs[2])
    scorer = MatchScorer(cm, CAM, ells, labs, list(range(len(labs))))
    every = list(all_samples(scorer.label_groups, 3))
    n_compat = scorer.compat.sum(axis=1).astype(float)
    dets = np.array([sm[0] for sm in every])
    order = np.lexsort((-triangle_areas(scorer, dets), np.prod(n_compat[dets], axis=1)))
    expected = [every[k] for k in order.tolist()]
    assert len(expected) > 50
    assert list(most_promising_first(scorer)) == expected


@pytest.mark.parametrize("seed", range(6))
def test_sweep_triple_counts_match_a_direct_count(seed):
    """sweep_samples' closed-form assignment counts pick the triple a direct count picks."""
    import itertools
    from collections import Counter

    from quadloc.service.localization.sampling import (
        SWEEP_MAX_SAMPLES,
        sweep_samples,
        triangle_areas,
    )

    rng = np.random.default_rng(seed)
    cm = compile_map(synthetic_map(rng))  # labels a a a b b c d e
    labs = list(rng.choice(["a", "b", "c", "d", "e"], size=int(rng.integers(3, 12))))
    scorer = MatchScorer(cm, CAM, [random_ellipse(rng) for _ in labs], labs,
                         list(range(len(labs))))
    n_obj = {d: len(scorer.compatible_objects(d)) for d in range(len(labs))}
    order = sorted(range(len(labs)), key=lambda d: (n_obj[d], d))
    tris = list(itertools.combinations(sorted(order[:8]), 3))
    counts = np.array([math.prod(math.perm(len(cm.indices_for(lab)), m)
                                 for lab, m in Counter(labs[d] for d in tri).items())
                       for tri in tris])
    ok = np.flatnonzero((counts > 0) & (counts <= SWEEP_MAX_SAMPLES))
    got = sweep_samples(scorer)
    if len(ok) == 0:
        assert got == []
        return
    tri = tris[ok[np.argmax(triangle_areas(scorer, np.array(tris)[ok]))]]
    assert {sm[0] for sm in got} == {tri}
    assert len(got) == counts[tris.index(tri)]


def test_time_budget_holds_with_hundreds_of_same_label_detections():
    """256 detections all labelled like one of 2 map objects: no P3P sample exists and the
    P2E samples are too many to list; the search must stop near its deadline (it used to walk
    all C(256, 3) detection triples first: ~10 s)."""
    import time

    rng = np.random.default_rng(8)
    cm = compile_map(synthetic_map(rng, labels=("a", "a", "b", "c", "d", "e", "f", "g")))
    ells = [random_ellipse(rng) for _ in range(256)]
    scorer = MatchScorer(cm, CAM, ells, ["a"] * 256, list(range(256)))
    t0 = time.perf_counter()
    out = ransac(scorer, UP, inlier_iou=0.2, min_inliers=2, max_hypotheses=300,
                 rng=np.random.default_rng(0), deadline=Deadline.wall_budget(0.1, start=t0))
    assert time.perf_counter() - t0 < 1.0  # budget 0.1 s, generous bound
    assert not out.exhaustive


def test_exhaustive_search_does_not_depend_on_the_seed():
    rng = np.random.default_rng(3)
    cm = compile_map(synthetic_map(rng))
    T_cw = invert_pose(look_at(np.array([-0.3, -4.0, 0.6]), np.zeros(3)))
    ells, labels = exact_detections(cm, T_cw)
    noisy = [Ellipse(e.cx + rng.normal(0, 3), e.cy + rng.normal(0, 3), e.a * rng.uniform(.9, 1.1),
                     e.b * rng.uniform(.9, 1.1), e.angle + rng.normal(0, .05)) for e in ells]
    scorer = MatchScorer(cm, CAM, noisy, labels, list(range(len(noisy))))
    outs = [ransac(scorer, UP, inlier_iou=0.2, min_inliers=2, max_hypotheses=2000,
                   rng=np.random.default_rng(seed)) for seed in range(6)]
    assert all(o.exhaustive for o in outs)
    for o in outs[1:]:
        assert o.samples_tried == outs[0].samples_tried
        assert np.array_equal(o.camera_from_world, outs[0].camera_from_world)


class _FixedIouScorer:
    """Scorer stand-in with prescribed IoUs (H=2 candidate poses, 3 detections, 3 objects)."""

    def __init__(self, dense: np.ndarray) -> None:
        self.dense = dense
        self.n_det = 3
        self.detection_indices = [0, 1, 2]
        self.labels = ["x", "x", "x"]
        self.params = np.zeros((3, 5))
        self.camera = CAM
        self.compiled = type("C", (), {"centers": np.zeros((3, 3))})()
        # every (detection, object) pair is compatible, in row-major order
        self.pair_d, self.pair_o = (i.ravel() for i in np.indices((3, 3)))
        self.pair_starts = np.array([0, 3, 6])
        self._has_pairs = np.ones(3, dtype=bool)
        self.compat = np.ones((3, 3), dtype=bool)
        self.label_groups = [([0, 1, 2], np.array([0, 1, 2]))]

    def compatible_objects(self, d: int) -> np.ndarray:
        return np.array([0, 1, 2])

    def pair_iou(self, poses: np.ndarray, **_: object) -> np.ndarray:
        return self.dense[np.round(poses[:, 0, 3]).astype(int)].reshape(len(poses), 9)

    def pair_scores(self, iou, threshold):
        return MatchScorer.pair_scores(self, iou, threshold)

    def pair_assignment(self, iou, threshold):
        return MatchScorer.pair_assignment(self, iou, threshold)

    def matches(self, camera_from_world, threshold):
        return greedy_assignment(self.dense[round(camera_from_world[0, 3])],
                                 self.detection_indices, threshold)


@pytest.mark.parametrize("case", ["higher_score_fewer_inliers", "shared_object"])
def test_pose_acceptance_uses_min_inliers_and_one_to_one_counts(monkeypatch, case):
    """min_inliers=3. Pose 0 outscores pose 1 on the per-detection-best sum but has only 2
    one-to-one inliers (case 1: the third IoU is below the threshold; case 2: two detections
    share object 0); pose 1 has 3 one-to-one inliers at a lower score and must be chosen."""
    import quadloc.service.localization.search as search_module

    dense = np.zeros((2, 3, 3))
    if case == "higher_score_fewer_inliers":
        dense[0, 0, 0] = dense[0, 1, 1] = 0.95
        dense[0, 2, 2] = 0.05
    else:
        dense[0, 0, 0] = dense[0, 1, 0] = dense[0, 2, 2] = 0.9
    dense[1, 0, 0] = dense[1, 1, 1] = dense[1, 2, 2] = 0.5
    poses = np.stack([np.eye(4), np.eye(4)])
    poses[1, 0, 3] = 1.0  # pose k's IoUs are dense[k]
    monkeypatch.setattr(search_module, "p3p_checked_batch",
                        lambda *a: (poses, np.zeros(len(poses), dtype=int)))
    out = ransac(_FixedIouScorer(dense), UP, inlier_iou=0.2, min_inliers=3, max_hypotheses=10,
                 rng=np.random.default_rng(0))
    assert out.camera_from_world is not None, out.reason
    assert out.camera_from_world[0, 3] == 1.0
    assert len(out.matches) == 3
    assert out.score == pytest.approx(1.5)


# ------------------------------------------------------------------ bounded cost (issue 11)


def _crowded(n: int, n_det: int, seed: int = 11):
    """A map of ``n`` same-label objects crowded in front of the camera and ``n_det`` detections
    of that label spread over the image: every detection overlaps many projections."""
    rng = np.random.default_rng(seed)
    objs = tuple(MapObject(f"o{i}", "a", Ellipsoid(rng.uniform([-1.5, -0.6, -1], [1.5, 0.6, 1]),
                                                     rng.uniform(0.1, 0.4, 3))) for i in range(n))
    cm = compile_map(SceneMap("crowd", "crowd", (0.0, 0.0, 1.0), ("a",), objs))
    ells = [random_ellipse(rng) for _ in range(n_det)]
    return cm, MatchScorer(cm, CAM, ells, ["a"] * n_det, list(range(n_det)))


def test_blocked_and_pruned_iou_equals_the_direct_estimate(monkeypatch):
    """dense_iou (blocks, bounding-circle and area pruning) == iou_estimates of every pair at
    once (the unblocked formula), wherever the value can reach the floor."""
    import quadloc.service.localization.scoring as rm

    cm, scorer = _crowded(40, 12)
    poses = np.array([invert_pose(look_at(np.array([x, -4.0, 0.2]), np.zeros(3)))
                      for x in (-0.5, 0.0, 0.7)])
    cen, inv_shape, valid, _ = project_objects(CAM, poses, cm.centers, cm.shape_matrices,
                                               cm.dual_quadrics)
    direct = rm.iou_estimates(scorer.points[:, None][None], scorer.areas[None, :, None],
                              cen[:, None], inv_shape[:, None])
    direct = np.where(valid[:, None, :], direct, 0.0)
    assert (direct > 0.2).sum() > 10  # the comparison covers real overlaps
    monkeypatch.setattr(rm, "PAIR_BLOCK", 7)
    monkeypatch.setattr(rm, "POINT_BLOCK", 96 * 5)
    monkeypatch.setattr(rm, "PROJECT_BLOCK", 30)
    np.testing.assert_allclose(scorer.dense_iou(poses), direct, atol=1e-12)
    floored = scorer.dense_iou(poses, floor=0.2)
    np.testing.assert_allclose(floored[direct >= 0.2], direct[direct >= 0.2], atol=1e-12)
    assert np.all(floored[direct < 0.2] <= direct[direct < 0.2] + 1e-12)
    # stage 1 by blocks == the direct centre test
    _, _, _, pc = project_objects(CAM, poses, cm.centers, cm.shape_matrices, cm.dual_quadrics)
    pc_minus = pc[:, None, :, :] - scorer.params[None, :, None, :2]
    shape = np.array([Ellipse(*p).shape_matrix() for p in scorer.params])
    phi = np.einsum("hdsi,dij,hdsj->hds", pc_minus, shape, pc_minus)
    expected = ((phi <= 4.0) & valid[:, None, :]).any(axis=2).sum(axis=1)
    np.testing.assert_array_equal(scorer.centre_hits(poses), expected)


def test_centre_hits_equal_the_direct_centre_test_on_many_poses():
    """Stage 1 (the compiled kernel: centres and depth margins projected per object, not the
    dual quadrics) == the direct test of every (pose, detection, object) with the batched
    projection's validity, on 300 poses around a crowded map, some looking away or standing
    inside objects."""
    cm, scorer = _crowded(40, 12)
    rng = np.random.default_rng(5)
    poses = np.array([invert_pose(look_at(rng.uniform([-3, -5, -1], [3, 1, 1]),
                                          rng.uniform([-2, -1, -1], [2, 1, 1])))
                      for _ in range(300)])
    _, _, valid, pc = project_objects(CAM, poses, cm.centers, cm.shape_matrices,
                                      cm.dual_quadrics)
    pc_minus = pc[:, None, :, :] - scorer.params[None, :, None, :2]
    shape = np.array([Ellipse(*p).shape_matrix() for p in scorer.params])
    phi = np.einsum("hdsi,dij,hdsj->hds", pc_minus, shape, pc_minus)
    expected = ((phi <= 4.0) & valid[:, None, :]).any(axis=2).sum(axis=1)
    assert expected.max() >= 3 and (~valid).any() and valid.any()  # hits, and invalid objects
    np.testing.assert_array_equal(scorer.centre_hits(poses), expected)


def test_search_memory_does_not_grow_with_hypotheses_or_candidates():
    """Peak traced memory of a search on 2,000 objects x 128 same-label detections stays within
    a small multiple of detections x objects (it used to hold candidates x pairs x points
    arrays: ~10 GB here), and 100,000 hypotheses cost no more memory than 300."""
    import time
    import tracemalloc

    _, scorer = _crowded(2000, 128)
    pairs = 2000 * 128
    peaks = []
    for budget in (300, 100_000):
        tracemalloc.start()
        t0 = time.perf_counter()
        ransac(scorer, UP, inlier_iou=0.2, min_inliers=2, max_hypotheses=budget,
               rng=np.random.default_rng(0), deadline=Deadline.wall_budget(0.3, start=t0))
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
        assert time.perf_counter() - t0 < 3.0  # deadline 0.3 s; generous bound (shared CI)
    assert max(peaks) < 40 * pairs + 40e6, peaks
    assert peaks[1] < 1.5 * peaks[0] + 5e6, peaks


def test_scoring_past_the_scorers_deadline_raises():
    from quadloc.service.localization.scoring import ScoringTimeoutError

    _, scorer = _crowded(50, 10)
    scorer.deadline = Deadline(wall=0.0)  # long past
    pose = invert_pose(look_at(np.array([0.0, -4.0, 0.2]), np.zeros(3)))
    with pytest.raises(ScoringTimeoutError):
        scorer.matches(pose, 0.2)


def _square_of_spheres():
    """Four same-label spheres on a square facing a camera on its axis: rolling the camera by
    90, 180 or 270 deg about the optical axis gives the same image (the objects relabelled),
    so four distinct poses explain all four detections exactly."""
    centres = [(-0.5, 0.0, -0.5), (0.5, 0.0, -0.5), (0.5, 0.0, 0.5), (-0.5, 0.0, 0.5)]
    objs = tuple(MapObject(f"s{i}", "a", Ellipsoid(np.array(c), np.full(3, 0.15)))
                 for i, c in enumerate(centres))
    cm = compile_map(SceneMap("square", "square", (0.0, 0.0, 1.0), ("a",), objs))
    camera_from_world = invert_pose(look_at(np.array([0.0, -4.0, 0.0]), np.zeros(3)))
    ells = [project_ellipsoid(CAM, camera_from_world, o.ellipsoid) for o in objs]
    return cm, MatchScorer(cm, CAM, ells, ["a"] * 4, list(range(4))), camera_from_world


def test_early_exit_still_finds_every_competitor_that_explains_the_frame():
    """The first batch explains the frame (early exit), and the search still returns the rolled
    poses that explain it too (the competitor sweep runs every assignment of one detection
    triple): the ambiguity check gets them."""
    from quadloc.service.localization.sampling import sweep_samples
    from quadloc.service.localization.search import distinct_poses

    _cm, scorer, _ = _square_of_spheres()

    def explaining(out):
        full = [h for h in out.alternatives if len(h.matches) == 4]
        distinct = []
        for h in full:
            if all(distinct_poses(h.camera_from_world, g.camera_from_world) for g in distinct):
                distinct.append(h)
        return out, distinct

    out, full = explaining(ransac(scorer, UP, inlier_iou=0.2, min_inliers=2,
                                  max_hypotheses=300, rng=np.random.default_rng(0)))
    assert out.samples_tried < 96  # the early exit happened (96 samples in all)
    assert len(sweep_samples(scorer)) == 24  # one triple, every assignment to 4 objects
    assert len(full) >= 2
    for h in full:  # each is an exact explanation
        assert all(m.iou > 0.9 for m in h.matches)


def test_symmetric_map_is_ambiguous_not_a_confident_pose():
    from quadloc.service.localization.pipeline import localize
    from quadloc.service.localization.types import Detection, LocalizationOptions

    cm, _scorer, camera_from_world = _square_of_spheres()
    dets = [Detection(project_ellipsoid(CAM, camera_from_world, e), "a", None)
            for e in cm.ellipsoids]
    r = localize(dets, cm, CAM, LocalizationOptions(time_budget_ms=None))
    assert not r.localized and r.reason == "ambiguous", (r.reason, r.confidence)


def test_pair_scoring_equals_the_dense_matrix_forms():
    """pair_scores / pair_assignment on the pair IoUs == dense_scores / greedy_assignment on the
    dense (detections x objects) matrix, on a crowded same-label map (many ties and conflicts)."""
    _cm, scorer = _crowded(40, 12)
    poses = np.array([invert_pose(look_at(np.array([x, -4.0, 0.2]), np.zeros(3)))
                      for x in (-0.5, 0.0, 0.7)])
    pair = scorer.pair_iou(poses, floor=0.2)
    dense = scorer.dense_iou(poses, floor=0.2)
    np.testing.assert_array_equal(dense[:, scorer.pair_d, scorer.pair_o], pair)
    for a, b in zip(scorer.pair_scores(pair, 0.2), dense_scores(dense, 0.2), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    for h in range(len(poses)):
        assert scorer.pair_assignment(pair[h], 0.2) == greedy_assignment(
            dense[h], scorer.detection_indices, 0.2)


def test_pair_scores_with_a_detection_without_compatible_objects():
    """A detection whose label has no object (not possible in localize(), possible for other
    users of the scorer) scores 0, as in the dense form, and does not shift the others."""
    cm, _ = _crowded(10, 3)
    ells = [Ellipse(100, 100, 20, 10, 0), Ellipse(200, 200, 20, 10, 0),
            Ellipse(300, 200, 20, 10, 0)]
    for labels in (["a", "zz", "a"], ["a", "a", "zz"], ["zz", "a", "a"]):
        scorer = MatchScorer(cm, CAM, ells, labels, [0, 1, 2])
        iou = np.random.default_rng(0).uniform(0, 1, (2, len(scorer.pair_d)))
        dense = np.zeros((2, 3, len(cm)))
        dense[:, scorer.pair_d, scorer.pair_o] = iou
        for a, b in zip(scorer.pair_scores(iou, 0.2), dense_scores(dense, 0.2), strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_split_draw_is_numpy_choice_with_p():
    """random_samples draws its split as rng.choice(n, p=p) does (cdf search of one
    rng.random()): the same values and the same generator stream."""
    for trial in range(50):
        n = 1 + trial % 7
        p = np.random.default_rng(trial).random(n)
        p /= p.sum()
        a, b = np.random.default_rng([trial, 1]), np.random.default_rng([trial, 1])
        cdf = p.cumsum()
        cdf /= cdf[-1]
        for _ in range(20):
            assert int(a.choice(n, p=p)) == int(cdf.searchsorted(b.random(), side="right"))
            assert a.choice(5, 2, replace=False).tolist() == b.choice(5, 2, replace=False).tolist()


def test_combination_rank_is_the_position_in_itertools_combinations():
    """_combination_rank (closed form) == the index in itertools.combinations' listing."""
    import itertools

    from quadloc.service.localization.sampling import _combination_rank

    for n in range(1, 8):
        for m in range(1, min(n, 3) + 1):
            for k, c in enumerate(itertools.combinations(range(n), m)):
                assert _combination_rank(c, n) == k


def test_iou_estimate_kernel_equals_the_rule_written_out_in_numpy():
    """iou_estimates (the compiled point test) == its rule computed here with numpy: the
    fraction of the detection's filling points with (x - c)^T (A^-1)^-1 (x - c) <= 1 (solved,
    not inverted in closed form) times the detection area as the intersection, over the
    union with the projection's area pi sqrt(det A^-1); 0 where det(A^-1) <= 0. A point on
    the boundary may round the other way: at most one point of difference, in few pairs."""
    rng = np.random.default_rng(3)
    n_pairs, n_points = 400, 96
    dets = [random_ellipse(rng) for _ in range(n_pairs)]
    projs = [Ellipse(d.cx + rng.normal(0, 30), d.cy + rng.normal(0, 30),
                     d.a * rng.uniform(0.5, 2), d.b * rng.uniform(0.5, 2),
                     rng.uniform(-math.pi, math.pi)) for d in dets]
    pts = ellipse_points(np.array([d.params() for d in dets]), sunflower_disk(n_points))
    areas = np.array([d.area for d in dets])
    centres = np.array([p.center for p in projs])
    S = np.array([p.gaussian()[1] for p in projs])
    S[:5] = np.array([[1.0, 2.0], [2.0, 1.0]])  # det < 0: no ellipse, IoU 0
    got = iou_estimates(pts, areas, centres, S)
    # the rule, written out
    diff = pts - centres[:, None, :]
    phi = np.einsum("kmi,kmi->km", diff, np.linalg.solve(S[:, None], diff[..., None])[..., 0])
    inter = (phi <= 1.0).mean(axis=1) * areas
    union = areas + math.pi * np.sqrt(np.maximum(np.linalg.det(S), 0.0)) - inter
    want = np.where(np.linalg.det(S) > 0, np.minimum(inter / np.maximum(union, 1e-300), 1.0), 0.0)
    assert np.all(got[:5] == 0.0)
    assert (want > 0.3).sum() > 50  # real overlaps are compared
    close = np.abs(got - want) <= 1e-12
    assert close.mean() >= 0.98
    one_point = areas / n_points / np.maximum(union - areas / n_points, 1e-300)
    assert np.all(np.abs(got - want) <= 1.01 * one_point + 1e-12)


def test_greedy_assignment_equals_the_rule_written_out():
    """greedy_assignment (the compiled walk) == its rule in plain Python: the pairs at or
    above the threshold by decreasing IoU (ties: the later pair in row-major order first),
    each kept when its detection and its object are both still free; sorted by detection.
    IoUs quantised to tenths: many ties."""
    rng = np.random.default_rng(12)
    for _ in range(200):
        n_det, n_obj = rng.integers(1, 7), rng.integers(1, 7)
        iou = np.round(rng.uniform(0, 1, (n_det, n_obj)), 1)
        rows = list(rng.permutation(20)[:n_det])
        pairs = [(float(iou[d, o]), d * n_obj + o, d, o) for d in range(n_det)
                 for o in range(n_obj) if iou[d, o] >= 0.3]
        pairs.sort(key=lambda p: (-p[0], -p[1]))
        used_d, used_o, want = set(), set(), []
        for v, _, d, o in pairs:
            if d not in used_d and o not in used_o:
                used_d.add(d)
                used_o.add(o)
                want.append((int(rows[d]), o, v))
        got = [(m.detection_index, m.object_index, m.iou)
               for m in greedy_assignment(iou, rows, 0.3)]
        assert got == sorted(want, key=lambda t: t[0])
