"""localize(): the whole pipeline on the real Chess map, its reasons, input errors, priors."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import quadloc.service.localization.pipeline as pipeline
from quadloc.factors.conics import Ellipse
from quadloc.factors.names import GeometryError
from quadloc.factors.rotations import rotation_angle
from quadloc.maps.compiled import compile_map
from quadloc.service.localization.pipeline import localize
from quadloc.service.localization.types import (
    Detection,
    LocalizationInputError,
    LocalizationOptions,
    LocalizationResult,
    PosePrior,
)
from tests.support.helpers import PerfCounterJump
from tests.support.reference_data import load_chess_map, load_chess_world_from_camera, perturb_pose
from tests.support.simulate import SimulationConfig, simulate_frame

MAP = load_chess_map()
CM = compile_map(MAP)
CAMERA, POSES, _ = load_chess_world_from_camera()  # POSES: world_from_camera


def rot_err_deg(A: np.ndarray, B: np.ndarray) -> float:
    return math.degrees(float(rotation_angle(A[:3, :3], B[:3, :3])))


@pytest.mark.parametrize("index", [0, 20, 40, 60, 80, 100])
def test_exact_detections_localize_within_a_micrometre(index):
    T = POSES[index]
    frame = simulate_frame(MAP, CAMERA, T, index, SimulationConfig.exact())
    r = localize(frame.detections, MAP, CAMERA)
    assert r.localized and r.reason is None and not r.used_prior
    assert np.linalg.norm(r.world_from_camera[:3, 3] - T[:3, 3]) < 1e-6
    assert rot_err_deg(r.world_from_camera, T) < 1e-4
    assert len(r.inliers) == len(frame)
    for m in r.inliers:  # the inliers are the true objects
        assert m.object_id == frame.object_ids[m.detection_index]
        assert m.iou > 0.97  # estimated IoU of identical ellipses (sampling ~1e-2)
    assert r.covariance is not None and r.covariance.shape == (6, 6)
    assert np.all(np.linalg.eigvalsh(r.covariance) > 0)
    assert 0.0 < r.confidence <= 1.0
    assert set(r.timings_ms) >= {"validate", "hypotheses", "refine", "total"}
    assert r.metric == "level_set" and r.hypotheses_evaluated >= 1


def test_noisy_detections_with_outliers():
    """Spurious detections and wrong labels: the solver (confidence gate off) still finds the
    pose on most frames, never with a spurious inlier; with the default gate every answer
    given is right (the frames it drops are "low_confidence", an honest answer)."""
    cfg = SimulationConfig(wrong_label_probability=0.1, spurious_rate=1.0)
    errs, gated = [], []
    for i in range(3, 108, 15):
        frame = simulate_frame(MAP, CAMERA, POSES[i], i, cfg)
        for out, min_confidence in ((errs, 0.0), (gated, None)):
            r = localize(frame.detections, CM, CAMERA,
                         LocalizationOptions(robust="huber", min_confidence=min_confidence))
            out.append(np.linalg.norm(r.world_from_camera[:3, 3] - POSES[i][:3, 3])
                       if r.localized else np.inf)
            if r.localized:
                for m in r.inliers:
                    assert frame.object_ids[m.detection_index] is not None  # no spurious inlier
            else:
                assert r.reason in ("low_confidence", "ambiguous"), r.reason
    errs, gated = np.array(errs), np.array(gated)
    assert np.mean(errs < 0.2) >= 0.7
    assert np.median(errs) < 0.1
    assert np.all(gated[np.isfinite(gated)] < 0.2) and np.isfinite(gated).sum() >= 3


def test_no_refinement_metric():
    frame = simulate_frame(MAP, CAMERA, POSES[5], 5, SimulationConfig.exact())
    r = localize(frame.detections, MAP, CAMERA, LocalizationOptions(metric="none"))
    assert r.localized and r.covariance is None and r.metric == "none"
    assert "refine" in r.timings_ms
    for m in r.inliers:
        assert m.cost == pytest.approx(1.0 - m.iou)
    # P3P on centres: close but biased (ellipse centre != projected ellipsoid centre)
    err = np.linalg.norm(r.world_from_camera[:3, 3] - POSES[5][:3, 3])
    assert 1e-6 < err < 0.1


def test_two_detections_localize_with_p2e():
    # frame 0's objects; keep two (ids differ in category, so the match is unique)
    frame = simulate_frame(MAP, CAMERA, POSES[0], 0, SimulationConfig.exact())
    cats = {}
    for i, d in enumerate(frame.detections):
        cats.setdefault(d.label, []).append(i)
    singles = [v[0] for k, v in cats.items() if len(v) == 1 and len(CM.indices_for(k)) == 1]
    dets = [frame.detections[i] for i in singles[:2]]  # Games and Timer
    # the geometry, not the acceptance policy: two detections alone are rarely trusted by the
    # calibrated confidence (tests/service/localization/test_trust.py), so accept any verified pose
    # here
    r = localize(dets, MAP, CAMERA, LocalizationOptions(min_confidence=0.0))
    assert r.hypotheses_evaluated >= 1
    # P2E (6-DoF, starts at rolls around the up axis) + level-set refinement of two exact
    # ellipses: this pair gives the true pose (98.6 % of exact Chess pairs localize)
    assert r.localized, r.reason
    assert len(r.inliers) == 2
    assert np.linalg.norm(r.world_from_camera[:3, 3] - POSES[0][:3, 3]) < 1e-6
    assert rot_err_deg(r.world_from_camera, POSES[0]) < 1e-4


def test_reasons_for_not_localized():
    frame = simulate_frame(MAP, CAMERA, POSES[10], 10, SimulationConfig.exact())
    d = list(frame.detections)
    r = localize(d[:1], MAP, CAMERA)
    assert not r.localized and r.reason == "too_few_detections" and r.world_from_camera is None
    assert r.confidence == 0.0 and r.inliers == ()
    unknown = [dataclasses.replace(x, label="Sofa") for x in d]
    assert localize(unknown, MAP, CAMERA).reason == "no_label_match"
    r = localize(d, MAP, CAMERA, LocalizationOptions(time_budget_ms=1e-6))
    assert r.reason == "time_budget_exceeded"
    # detections nowhere near any object's projection at any P3P pose: all far, tiny
    junk = [Detection(Ellipse(20 + 200 * k, 20 + 100 * (k % 2), 4, 3, 0.0), x.label)
            for k, x in enumerate(d[:4])]
    r = localize(junk, MAP, CAMERA, LocalizationOptions(inlier_iou=0.9))
    assert r.reason == "no_hypothesis_above_inlier_threshold"
    # two detections, only one with a map label: no_label_match (too_few_detections counts
    # the request's detections, whatever their labels)
    r = localize([d[0], dataclasses.replace(d[1], label="Sofa")], MAP, CAMERA)
    assert r.reason == "no_label_match"
    with pytest.raises(ValueError, match="reason"):
        LocalizationResult(False, "not_a_reason", None, None, 0.0, (), "level_set", 0, False)


def test_refinement_diverged_reason(monkeypatch):
    frame = simulate_frame(MAP, CAMERA, POSES[30], 30, SimulationConfig.exact())
    real = pipeline.refine

    def broken(*args, **kwargs):
        res = real(*args, **kwargs)
        return dataclasses.replace(res, status="diverged", converged=False)

    monkeypatch.setattr(pipeline, "refine", broken)
    r = localize(frame.detections, MAP, CAMERA)
    assert not r.localized and r.reason == "refinement_diverged"


def test_input_errors_name_the_field():
    frame = simulate_frame(MAP, CAMERA, POSES[0], 0, SimulationConfig.exact())
    d = list(frame.detections)
    with pytest.raises(LocalizationInputError, match=r"^detections: must not be empty"):
        localize([], MAP, CAMERA)
    with pytest.raises(LocalizationInputError, match=r"detections\[1\]: must be a Detection"):
        localize([d[0], "x"], MAP, CAMERA)
    bad = [d[0], dataclasses.replace(d[1], label="Sofa"), d[2]]
    with pytest.raises(LocalizationInputError, match=r"detections\[1\]\.label: 'Sofa'"):
        localize(bad, MAP, CAMERA, LocalizationOptions(unknown_label_policy="error"))
    # "ignore" (default) drops the unknown label and still localizes
    assert localize([*d, Detection(Ellipse(10, 10, 5, 5, 0), "Sofa")], MAP, CAMERA).localized
    with pytest.raises(LocalizationInputError, match="camera"):
        localize(d, MAP, "K")
    with pytest.raises(LocalizationInputError, match="scene_map"):
        localize(d, {"objects": []}, CAMERA)
    with pytest.raises(GeometryError, match=r"Ellipse\.a"):
        Detection(Ellipse(1, 1, 0.0, 1, 0), "TV")
    with pytest.raises(GeometryError, match=r"Ellipse\.cx"):
        Ellipse(float("nan"), 1, 1, 1, 0)
    with pytest.raises(GeometryError, match="sigma"):
        Detection(Ellipse(1, 1, 1, 1, 0), "TV", sigma=-1.0)
    for kwargs, field in [({"metric": "l2"}, "options.metric"),
                          ({"inlier_iou": 0.0}, "options.inlier_iou"),
                          ({"min_inliers": 1}, "options.min_inliers"),
                          ({"robust": "tukey"}, "options.robust"),
                          ({"robust_scale": 1.0}, "options.robust_scale"),
                          ({"unknown_label_policy": "drop"}, "options.unknown_label_policy"),
                          ({"ransac_max_hypotheses": 0}, "options.ransac_max_hypotheses"),
                          ({"time_budget_ms": -5.0}, "options.time_budget_ms"),
                          ({"seed": 1.5}, "options.seed")]:
        with pytest.raises(LocalizationInputError, match=field.replace(".", r"\.")):
            LocalizationOptions(**kwargs)
    with pytest.raises(LocalizationInputError, match=r"prior\.world_from_camera"):
        PosePrior(np.eye(3))
    with pytest.raises(LocalizationInputError, match=r"prior\.world_from_camera.*rotation"):
        PosePrior(np.diag([1.0, 1.0, 2.0, 1.0]))
    with pytest.raises(LocalizationInputError, match=r"prior\.covariance.*positive definite"):
        PosePrior(np.eye(4), -np.eye(6))


def test_prior_path_and_fallback():
    rng = np.random.default_rng(0)
    T = POSES[50]
    frame = simulate_frame(MAP, CAMERA, T, 50, SimulationConfig.exact())
    start = perturb_pose(T, rng, 0.05, 2.0)
    r = localize(frame.detections, MAP, CAMERA, prior=PosePrior(start))
    assert r.localized and r.used_prior and "hypotheses" not in r.timings_ms
    assert np.linalg.norm(r.world_from_camera[:3, 3] - T[:3, 3]) < 1e-6  # start point only
    # with a covariance the prior is also a factor: the estimate moves from the prior towards
    # the detections' pose, and stays between them
    cov = np.diag([1e-3] * 3 + [1e-2] * 3)
    r = localize(frame.detections, MAP, CAMERA, prior=PosePrior(start, cov))
    assert r.localized and r.used_prior
    err = np.linalg.norm(r.world_from_camera[:3, 3] - T[:3, 3])
    assert 1e-6 < err < 0.5 * np.linalg.norm(start[:3, 3] - T[:3, 3])
    # a prior pointing the camera elsewhere fails the inlier check: RANSAC takes over
    far = PosePrior(perturb_pose(T, rng, 1.5, 90.0))
    r = localize(frame.detections, MAP, CAMERA, prior=far)
    assert r.localized and not r.used_prior and "hypotheses" in r.timings_ms
    assert np.linalg.norm(r.world_from_camera[:3, 3] - T[:3, 3]) < 1e-6


def test_determinism_and_confidence():
    frame = simulate_frame(MAP, CAMERA, POSES[70], 70, SimulationConfig())
    opts = LocalizationOptions(seed=3, ransac_max_hypotheses=50)
    a = localize(frame.detections, MAP, CAMERA, opts)
    b = localize(frame.detections, MAP, CAMERA, opts)
    assert a.localized and b.localized
    assert np.array_equal(a.world_from_camera, b.world_from_camera)
    assert a.confidence == b.confidence and 0.0 < a.confidence <= 1.0


def test_level_set_resampling_reaches_the_optimum_from_far():
    """The adaptive level-set samples are laid out for the misalignment at the start of a
    solve; from a far start one solve stops at a biased pose, and refine()'s second solve with
    the samples re-laid at its result reaches the optimum found from the ground truth."""
    from quadloc.service.localization.refine import _build_graph, _solve, refine

    rng = np.random.default_rng(1)
    gaps_single, gaps_resampled = [], []
    for i in (9, 45, 63):
        frame = simulate_frame(MAP, CAMERA, POSES[i], i, SimulationConfig(miss_probability=0.0))
        dets = list(frame.detections)
        ells = [MAP.object_by_id(o).ellipsoid for o in frame.object_ids]
        optimum = refine(dets, ells, CAMERA, POSES[i], "level_set").world_from_camera
        start = perturb_pose(POSES[i], rng, 0.4, 20.0)
        graph, model, _ = _build_graph(dets, ells, CAMERA, start, "level_set",
                                       [d.sigma for d in dets], None, None, None, None, None)
        single = _solve(graph, model, start, 50).T
        resampled = refine(dets, ells, CAMERA, start, "level_set").world_from_camera
        gaps_single.append(np.linalg.norm(single[:3, 3] - optimum[:3, 3]))
        gaps_resampled.append(np.linalg.norm(resampled[:3, 3] - optimum[:3, 3]))
    assert max(gaps_resampled) < 1e-3
    assert max(gaps_single) > 3e-3


def test_integral_numpy_options_are_accepted_and_stored_as_int():
    frame = simulate_frame(MAP, CAMERA, POSES[0], 0, SimulationConfig.exact())
    opts = LocalizationOptions(max_iterations=np.int64(20), min_inliers=np.int32(2),
                               ransac_max_hypotheses=np.int64(100), seed=np.int64(1))
    assert type(opts.max_iterations) is int and type(opts.seed) is int
    r = localize(frame.detections, MAP, CAMERA, opts)  # used to raise inside refine
    assert r.localized and r.refinement_status == "converged"


@pytest.mark.parametrize("options, key", [({"foo": 1}, "foo"), ({"n_azimuths": -3}, "n_azimuths"),
                                          ({"n_azimuths": "6"}, "n_azimuths"),
                                          ({"scale": 0.0}, "scale")])
def test_metric_options_are_validated_up_front(options, key):
    with pytest.raises(LocalizationInputError, match=rf"^options\.metric_options\.{key}:"):
        LocalizationOptions(metric_options=options)
    with pytest.raises(LocalizationInputError, match=r"options\.metric_options\.image_size"):
        LocalizationOptions(metric="wasserstein", metric_options={"image_size": (640, 480)})
    ok = LocalizationOptions(metric="qbbox", metric_options={"image_size": (640, 480)})
    assert dict(ok.metric_options) == {"image_size": (640, 480)}


def test_budget_exhausted_at_the_refine_stage_is_reported(monkeypatch):
    """The hypothesis search uses up the budget: the pose comes unrefined from RANSAC and the
    result says so (refinement_status "time_budget"), instead of passing for a refined one."""
    frame = simulate_frame(MAP, CAMERA, POSES[30], 30, SimulationConfig())
    real = pipeline.ransac
    clock = PerfCounterJump(monkeypatch)

    def slow_ransac(*args, **kwargs):
        out = real(*args, **{**kwargs, "deadline": None})
        # the search ran into the budget: here its wall-clock hard limit (the CPU budget
        # passes the same way: test_deadline_clocks)
        clock.past(kwargs["deadline"].wall)
        return out

    monkeypatch.setattr(pipeline, "ransac", slow_ransac)
    opts = LocalizationOptions(time_budget_ms=300.0)
    r = localize(frame.detections, MAP, CAMERA, opts)
    assert r.localized and r.refinement_status == "time_budget"
    monkeypatch.setattr(pipeline, "ransac", real)
    r = localize(frame.detections, MAP, CAMERA, opts)
    assert r.localized and r.refinement_status in ("converged", "max_iterations")
    r = localize(frame.detections, MAP, CAMERA, LocalizationOptions(metric="none"))
    assert r.localized and r.refinement_status is None


def test_budget_counts_the_solving_threads_cpu_time_so_load_does_not_change_the_result(
        monkeypatch):
    """Issue 14 part 4: ``time_budget_ms`` counts CPU time of the solving thread. The same iou
    solve with a budget of 10x its CPU cost gives the identical result quietly and while other
    threads of this process burn CPU holding the GIL: the solve then gets a small fraction of
    the wall clock (2 burners: wall 4x to 70x its quiet CPU time; burners are added until the
    wall time exceeds the budget, so a wall-clock budget of the same size would have cut it),
    and its own CPU time grows too (GIL hand-offs: ~3-5x), hence the 10x budget. The
    wall-clock hard limit is widened here: it is the latency guarantee, tested in
    ``test_deadline_clocks``."""
    import threading
    import time

    import quadloc.factors.budget as budget

    monkeypatch.setattr(budget, "WALL_LIMIT_FACTOR", 100.0)

    frame = simulate_frame(MAP, CAMERA, POSES[12], 12, SimulationConfig())
    unbounded = LocalizationOptions(metric="iou", time_budget_ms=None, max_iterations=8)

    def solve(opts: LocalizationOptions) -> tuple[object, float, float]:
        c0, t0 = time.thread_time(), time.perf_counter()
        r = localize(frame.detections, MAP, CAMERA, opts)
        return r, time.thread_time() - c0, time.perf_counter() - t0

    ref, cpu, _ = solve(unbounded)
    assert ref.localized and ref.refinement_status != "time_budget"
    budget_ms = 10e3 * cpu
    opts = dataclasses.replace(unbounded, time_budget_ms=budget_ms)
    quiet, _, _ = solve(opts)
    stop = threading.Event()

    def burn() -> None:
        x = 0
        while not stop.is_set():
            x = (x * 31 + 7) % 1_000_003  # pure Python: holds the GIL

    # The GIL hand-offs vary from run to run (wall 4x to 70x the quiet CPU time with 2 burners):
    # add burners until the busy solve's wall time exceeds the budget, i.e. until a wall-clock
    # budget of the same size would have been binding.
    results = [quiet]
    for n_burners in (2, 4, 8, 16):
        stop.clear()
        burners = [threading.Thread(target=burn, daemon=True) for _ in range(n_burners)]
        for t in burners:
            t.start()
        try:
            busy, _, wall_busy = solve(opts)
        finally:
            stop.set()
            for t in burners:
                t.join()
        results.append(busy)
        if wall_busy * 1e3 > budget_ms:
            break
    assert wall_busy * 1e3 > budget_ms, (n_burners, wall_busy, budget_ms)
    for r in results:
        assert r.localized == ref.localized and r.reason == ref.reason
        assert r.refinement_status == ref.refinement_status
        np.testing.assert_array_equal(r.world_from_camera, ref.world_from_camera)
        assert r.hypotheses_evaluated == ref.hypotheses_evaluated


def test_deadline_clocks():
    """A Deadline passes on the solving thread's CPU time (busy loop) and, for a thread that
    gets no CPU (sleeping), on its wall-clock hard limit (WALL_LIMIT_FACTOR x the budget)."""
    import time

    from quadloc.factors.budget import WALL_LIMIT_FACTOR, Deadline, deadline_passed

    c0 = time.thread_time()
    d = Deadline.cpu_budget(20.0)
    d = Deadline(cpu=d.cpu)  # the CPU clock alone (the wall limit may pass first under load)
    while not d.passed():
        pass
    assert time.thread_time() - c0 >= 0.020
    t0 = time.perf_counter()
    d = Deadline.cpu_budget(20.0)
    while not d.passed():
        time.sleep(0.002)  # no CPU used: only the wall limit can stop it
    assert time.perf_counter() - t0 >= WALL_LIMIT_FACTOR * 0.020
    assert d.cpu > time.thread_time()  # the CPU budget was not the one that passed
    assert Deadline.cpu_budget(None) is None and not deadline_passed(None)


def test_deadline_reads_the_cpu_clock_only_once_the_cpu_stop_is_reachable(monkeypatch):
    """Before ``cpu_check_from`` (the wall instant at which the thread's CPU time could first
    reach the stop: CPU time grows no faster than wall time) ``passed`` reads no CPU clock;
    a busy loop still stops exactly when its CPU time passes the budget (checked against the
    CPU clock read directly), and the bound held (the stop came after ``cpu_check_from``)."""
    import time

    from quadloc.factors import budget
    from quadloc.factors.budget import Deadline, earliest

    c0 = time.thread_time()
    d = Deadline.cpu_budget(30.0)
    d = Deadline(cpu=d.cpu, cpu_check_from=d.cpu_check_from)  # no wall limit (load)
    assert d.cpu_check_from >= time.perf_counter() - 1e-3
    reads = []
    real = time.thread_time
    monkeypatch.setattr(budget.time, "thread_time", lambda: reads.append(1) or real())
    assert not d.passed() and not reads  # 30 ms of CPU cannot have gone yet
    while not d.passed():
        pass
    stop_wall, stop_cpu = time.perf_counter(), real()
    assert stop_cpu - c0 >= 0.030 and stop_cpu <= d.cpu + 5e-3
    assert stop_wall >= d.cpu_check_from and reads
    # combining deadlines keeps the earliest of each instant, the CPU check bound included
    e = earliest(d, Deadline(cpu=1.0, wall=2.0))
    assert e.cpu_check_from == -float("inf") and e.cpu == min(d.cpu, 1.0)


def test_a_wall_clock_budget_passes_on_the_wall_clock_and_never_reads_the_cpu_clock(
        monkeypatch):
    """``Deadline.wall_budget`` (a map build, a session's initialisation) passes once its wall
    time has gone, for a thread that uses no CPU (sleeping), and never reads the CPU clock."""
    import time

    from quadloc.factors import budget
    from quadloc.factors.budget import Deadline

    reads = []
    real = time.thread_time
    monkeypatch.setattr(budget.time, "thread_time", lambda: reads.append(1) or real())
    t0 = time.perf_counter()
    d = Deadline.wall_budget(0.05)
    while not d.passed():
        time.sleep(0.002)
    assert time.perf_counter() - t0 >= 0.05
    assert not reads
    assert Deadline.wall_budget(1.0, start=t0 - 2.0).passed()
    assert not Deadline.wall_budget(60.0).passed()


def test_a_capped_alternative_that_competes_is_refined_in_full(monkeypatch):
    """Alternatives are refined with at most ``ALTERNATIVE_MAX_ITERATIONS`` LM iterations; one
    that competes (as many inliers as the first answer) is then refined in full, so the pose
    returned does not depend on the cap: with a cap of 1 iteration, every frame localized with
    and without the cap (2 and 3 detections of simulated Chess frames, where alternatives are
    refined) has the same pose up to the LM's stopping tolerance (1e-3 here; an alternative
    left after 1 iteration is centimetres off)."""
    from tests.support.simulate import reduce_frame

    frames = []
    for i in range(0, len(POSES), 6):
        f = simulate_frame(MAP, CAMERA, POSES[i], 1000 + i, SimulationConfig())
        rng = np.random.default_rng(i)
        frames += [d for d in (reduce_frame(f.detections, f.object_ids, k, rng) for k in (2, 3))
                   if d is not None]
    opts = LocalizationOptions(min_confidence=0.0, on_ambiguity="best")
    results = {}
    for cap in (1, 50):
        monkeypatch.setattr(pipeline, "ALTERNATIVE_MAX_ITERATIONS", cap)
        results[cap] = [localize(d, MAP, CAMERA, opts) for d in frames]
    both = [(a, b) for a, b in zip(results[1], results[50], strict=True)
            if a.localized and b.localized]
    assert len(both) >= 0.8 * len(frames)
    for a, b in both:
        np.testing.assert_allclose(a.world_from_camera, b.world_from_camera, atol=1e-3)
