"""The vectorised exact overlap areas (``quadloc.factors.overlap.quadrant_areas_batch``, the pose
factors' path) against the scalar reference construction (the oracle
``tests.support.oracles.overlap_reference.quadrant_areas``; the production areas are also checked
against Monte Carlo, rasters and central differences in ``test_metrics.py``),
pair by pair, on the configurations that exercise every branch: crossing contours (2 and 4
roots), containment either way, disjoint ellipses, identical and nearly identical ellipses
(the regime at a refinement's optimum), a tangent contact, and hulls with and without tangent
segments (including an ellipse poking out of the other between two hull directions)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadloc.factors.metrics import overlap_residual
from quadloc.factors.overlap import quadrant_areas_batch
from tests.support.oracles.overlap_reference import quadrant_areas


def _random_params(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack([rng.uniform(-40, 40, (n, 2)), rng.uniform(4, 60, (n, 2)),
                            rng.uniform(-3, 3, n)])


def _cases() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(11)
    p1 = [_random_params(rng, 40)]
    p2 = [_random_params(rng, 40)]  # crossing, contained, disjoint
    base = _random_params(rng, 40)
    for noise in (1.0, 1e-3, 1e-7):  # close to identical (the optimum of a refinement)
        p1.append(base)
        p2.append(base + rng.normal(0.0, noise, base.shape))
    fixed = np.array([
        [0.0, 0.0, 4.0, 5.0, 0.0], [0.0, 0.0, 4.0, 4.0, 3.0],  # tangent contact at (+-4, 0)
        [0.0, 0.0, 30.0, 10.0, 0.3], [0.0, 0.0, 30.0, 10.0, 0.3],  # identical
        [0.0, 0.0, 50.0, 40.0, 0.0], [5.0, 0.0, 10.0, 8.0, 1.0],  # second inside first
        [5.0, 0.0, 10.0, 8.0, 1.0], [0.0, 0.0, 50.0, 40.0, 0.0],  # first inside second
        [0.0, 0.0, 10.0, 5.0, 0.0], [100.0, 30.0, 8.0, 6.0, 0.5],  # disjoint
        [0.0, 0.0, 40.0, 39.9, 0.0], [0.0, 0.0, 40.2, 1.0, 0.7],  # a thin needle pokes out
    ]).reshape(-1, 2, 5)
    p1.append(fixed[:, 0])
    p2.append(fixed[:, 1])
    return np.concatenate(p1), np.concatenate(p2)


@pytest.mark.parametrize("gradient", [False, True])
def test_batch_equals_the_scalar_reference(gradient):
    p1, p2 = _cases()
    batch = quadrant_areas_batch(p1, p2, True, gradient=gradient)
    tangent = _tangent_index(p1, p2)
    # the tangent contact: its double roots are located only to ~sqrt(eps), and the scalar
    # path is ~1e-8 off there (test_metrics.py); compare with the closed form instead: the
    # circle of radius 4 lies in the 4 x 5 ellipse, a quarter of it per quadrant
    np.testing.assert_allclose(batch["intersection"][0][tangent], 4.0 * math.pi, rtol=1e-9)
    for j in range(p1.shape[0]):
        if j == tangent:
            continue
        ref = quadrant_areas(p1[j], p2[j], True, gradient=gradient)
        for name, (areas, grads) in ref.items():
            b_areas, b_grads = batch[name][0][j], batch[name][1]
            scale = max(float(np.abs(areas).sum()), math.pi * p1[j, 2] * p1[j, 3])
            np.testing.assert_allclose(b_areas, areas, rtol=0, atol=1e-9 * scale,
                                       err_msg=f"{name} pair {j}")
            if gradient:
                g_scale = max(float(np.abs(grads).max()), 1.0)
                np.testing.assert_allclose(b_grads[j], grads, rtol=0,
                                           atol=_gradient_tol(j, 1e-9, name) * g_scale,
                                           err_msg=f"{name} gradient pair {j}")
            else:
                assert b_grads is None


def _gradient_tol(j: int, tol: float, name: str = "") -> float:
    """Ellipses 1e-7 apart (pairs 120-159 of :func:`_cases`): the hull's common tangents are
    zeros of a support-function difference of size ~1e-7 of the ellipses' size. The batch
    takes them as exact roots of the tangency condition (``quadloc.factors.overlap._hull``); the
    oracle compares the support functions on a direction grid with a tolerance of 1e-10 of the
    size, within which it cannot place a tangent: where the supports differ by < 3e-9 px over
    ~1e-2 rad (pair 121), its tangent is ~8e-3 rad off the root. With the two boundaries
    nearly coinciding, the hull's gradient follows whichever ellipse the boundary runs on, so
    it moves with that placement: 1e-1 relative there for the hull (its area still agrees to
    1e-9), 1e-5 for the intersection (whose crossings both place alike), ``tol`` elsewhere."""
    if 120 <= j < 160:
        return 1e-1 if name == "hull" else 1e-5
    return tol


def _tangent_index(p1: np.ndarray, p2: np.ndarray) -> int:
    return int(np.flatnonzero((p1[:, 2] == 4.0) & (p1[:, 3] == 5.0) & (p2[:, 2] == 4.0))[0])


def test_batch_without_hull_and_empty_batch():
    p1, p2 = _cases()
    with_hull = quadrant_areas_batch(p1, p2, True)
    without = quadrant_areas_batch(p1, p2, False)
    assert set(without) == {"second", "intersection"}
    for name in without:
        np.testing.assert_array_equal(without[name][0], with_hull[name][0])
    empty = quadrant_areas_batch(np.zeros((0, 5)), np.zeros((0, 5)), True, gradient=True)
    assert all(v[0].shape == (0, 4) and v[1].shape == (0, 4, 5) for v in empty.values())


def test_batched_overlap_residual_equals_pairwise_calls():
    """``overlap_residual`` on (N, 5) arrays (the vectorised areas) equals N one-pair calls
    (N = 1 batches), rows and gradients; the tangent contact, where the areas are only ~1e-8
    determined (see above), is left out."""
    p1, p2 = _cases()
    tangent = _tangent_index(p1, p2)
    for name in ("iou", "giou"):
        rows, grads = overlap_residual(name, p1, p2, gradient=True)
        assert rows.shape == (p1.shape[0], 4) and grads.shape == (p1.shape[0], 4, 5)
        for j in range(p1.shape[0]):
            if j == tangent:
                continue
            r, g = overlap_residual(name, p1[j], p2[j], gradient=True)
            np.testing.assert_allclose(rows[j], r, rtol=0, atol=1e-10)
            # 1e-7 apart: the giou gap rows take hull_k - union_k, nearly equal, which
            # amplifies the tangents' placement (_gradient_tol) another ~10x
            tol = 10.0 * _gradient_tol(j, 1e-10)
            np.testing.assert_allclose(grads[j], g, rtol=0, atol=tol * np.abs(g).max())


def test_thin_ellipses_equal_the_scalar_reference():
    """Needles (found by random stress tests against the oracle): a crossing function that
    curves so much within its grid cells that plain Newton steps stall at a bracket end (the
    safeguarded finish), and needles (axis ratios 130 to 700) whose normalised frame squeezes
    the normals where the other ellipse supports the hull into ~1e-5 rad (the pokes' sub-grid
    search): areas equal to the oracle to 1e-9."""
    pairs = np.array([
        [[21.75992, -8.301219, 59.816758, 13.924303, -2.107873],
         [-1.620865, 37.923887, 61.778497, 1.061468, -3.279553]],
        [[39.469769, -20.793766, 7.378105, 0.539887, -0.25897],
         [44.874411, 38.503654, 77.765479, 0.521244, 1.516488]],
        [[8.529533, -36.128882, 17.080009, 0.062994, 1.625754],
         [-42.643625, -2.08169, 0.3, 1.285043, 1.081093]],
        [[-39.257198, 48.336418, 0.070768, 49.67406, -3.532909],
         [-37.019152, -22.682585, 0.3, 0.334576, 3.148533]],
    ])
    batch = quadrant_areas_batch(pairs[:, 0], pairs[:, 1], True, gradient=True)
    for j, (p1, p2) in enumerate(pairs):
        ref = quadrant_areas(p1, p2, True, gradient=True)
        for name, (areas, grads) in ref.items():
            scale = max(float(np.abs(areas).sum()), math.pi * p1[2] * p1[3])
            np.testing.assert_allclose(batch[name][0][j], areas, rtol=0, atol=1e-9 * scale,
                                       err_msg=f"{name} pair {j}")
            np.testing.assert_allclose(batch[name][1][j], grads, rtol=0,
                                       atol=1e-7 * max(float(np.abs(grads).max()), 1.0),
                                       err_msg=f"{name} gradient pair {j}")


def test_random_pairs_of_any_eccentricity_equal_the_scalar_reference():
    """Random pairs with semi-axes from 0.05 to 300 px (axis ratios up to ~6000; a quarter of
    them close to identical, some concentric or circles): areas equal to the oracle to 1e-9
    (the stress test that found the needle pairs above)."""
    rng = np.random.default_rng(5)
    n = 400

    def params(k: int) -> np.ndarray:
        return np.column_stack([rng.uniform(-50, 50, (k, 2)),
                                np.exp(rng.uniform(np.log(0.05), np.log(300), (k, 2))),
                                rng.uniform(-4, 4, k)])

    p1, p2 = params(n), params(n)
    m = n // 4
    p2[:m] = p1[:m] + rng.normal(0, 1, (m, 5)) * np.array([1, 1, 0.5, 0.5, 0.05]) \
        * rng.choice([1, 1e-2, 1e-4], (m, 1))
    p2[m:m + 20, :2], p2[m:m + 20, 4] = p1[m:m + 20, :2], p1[m:m + 20, 4]  # concentric
    p2[m + 20:m + 40, 2] = p2[m + 20:m + 40, 3]  # circles
    p2[:, 2:4] = np.maximum(p2[:, 2:4], 0.3)
    batch = quadrant_areas_batch(p1, p2, True)
    for j in range(n):
        for name, (areas, _) in quadrant_areas(p1[j], p2[j], True).items():
            scale = max(float(np.abs(areas).sum()), math.pi * p1[j, 2] * p1[j, 3])
            np.testing.assert_allclose(batch[name][0][j], areas, rtol=0, atol=1e-9 * scale,
                                       err_msg=f"{name} pair {j}")


def test_batch_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="p1 and p2"):
        quadrant_areas_batch(np.zeros((2, 5)), np.zeros((3, 5)), False)


def test_disjoint_hull_rows_are_giou_rows_only_for_disjoint_pairs():
    """``overlap_residual("iou", ..., disjoint_hull=True)`` (the pose factors' iou rows):
    disjoint pairs get the giou rows and gradients, every other pair the iou rows."""
    p1, p2 = _cases()
    inter = quadrant_areas_batch(p1, p2, False)["intersection"][0].sum(axis=1)
    disjoint = inter <= 0.0
    assert 5 <= disjoint.sum() < p1.shape[0] - 5  # both kinds are covered
    rows, grads = overlap_residual("iou", p1, p2, gradient=True, disjoint_hull=True)
    iou = overlap_residual("iou", p1, p2, gradient=True)
    giou = overlap_residual("giou", p1, p2, gradient=True)
    for got, i_ref, g_ref in ((rows, iou[0], giou[0]), (grads, iou[1], giou[1])):
        np.testing.assert_allclose(got[disjoint], g_ref[disjoint], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(got[~disjoint], i_ref[~disjoint], rtol=1e-12, atol=1e-15)
    # disjoint: the iou rows sum to 1 (flat); the giou rows to 2 - U / C > 1, decreasing as
    # the ellipses approach
    assert np.allclose(iou[0][disjoint].sum(axis=1), 1.0)
    assert np.all(rows[disjoint].sum(axis=1) > 1.0)


def test_iou_rows_stay_non_negative_for_nearly_identical_ellipses():
    """Contours closer than 1e-9 count as identical in quadloc.factors.overlap (the intersection is
    then the whole second ellipse); the rows cap the intersection per quadrant at both
    ellipses' quadrant areas, so they stay >= 0 and sum to ~Delta (~6e-10 here: a 1e-8 px
    shift of a 3 x 20 px ellipse)."""
    d = np.array([0.0, 0.0, 3.0, 20.0, 0.0])
    p = np.array([0.0, 1e-8, 3.0, 20.0, 0.0])
    r, g = overlap_residual("iou", d, p, gradient=True)
    assert np.all(r >= 0.0) and r.sum() < 1e-9
    assert np.all(np.isfinite(g))


def _params_from_gaussian(g: np.ndarray) -> np.ndarray:
    """Ellipse params (5,) from ``g = (mu_x, mu_y, s00, s01, s11)`` (closed-form eigen)."""
    s00, s01, s11 = g[2], g[3], g[4]
    half, disc = 0.5 * (s00 + s11), math.hypot(0.5 * (s00 - s11), s01)
    return np.array([g[0], g[1], math.sqrt(half + disc), math.sqrt(half - disc),
                     0.5 * math.atan2(2.0 * s01, s00 - s11)])


@pytest.mark.parametrize("name", ["iou", "giou"])
def test_batched_gradients_match_central_differences(name):
    """The vectorised rows' gradients (iou with ``disjoint_hull``, as the pose factors use it)
    w.r.t. the projection's ``g = (mu, Sigma)``, against central differences of the batched
    rows themselves, on crossing, contained and disjoint pairs."""
    rng = np.random.default_rng(23)
    p1, p2 = _random_params(rng, 12), _random_params(rng, 12)
    p1[0], p2[0] = [0.0, 0.0, 10.0, 5.0, 0.0], [60.0, 20.0, 8.0, 6.0, 0.5]  # disjoint
    rows, grads = overlap_residual(name, p1, p2, gradient=True, disjoint_hull=True)
    c, s = np.cos(p2[:, 4]), np.sin(p2[:, 4])
    a2, b2 = p2[:, 2] ** 2, p2[:, 3] ** 2
    g = np.column_stack([p2[:, 0], p2[:, 1], a2 * c * c + b2 * s * s, (a2 - b2) * c * s,
                         a2 * s * s + b2 * c * c])
    for k in range(5):
        h = 1e-6 * np.maximum(1.0, np.abs(g[:, k]))
        moved = []
        for sgn in (1.0, -1.0):
            gk = g.copy()
            gk[:, k] += sgn * h
            p = np.array([_params_from_gaussian(x) for x in gk])
            moved.append(overlap_residual(name, p1, p, disjoint_hull=True)[0])
        num = (moved[0] - moved[1]) / (2.0 * h[:, None])
        scale = np.maximum(np.abs(num).max(axis=1, keepdims=True), 1e-12)
        np.testing.assert_allclose(grads[:, :, k], num, rtol=0, atol=1e-5 * scale.max() + 1e-9,
                                   err_msg=f"component {k}")
    assert rows[0].sum() > 1.0  # the disjoint pair carries the hull term
