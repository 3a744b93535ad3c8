"""The nine ellipse-ellipse metrics, checked against independent computations: closed forms,
matrix-function formulas (scipy), rasters and dense polygons, invariances, and the paper's
qualitative properties (flat IoU / GIoU regions, bbox not rotation invariant)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from scipy.linalg import sqrtm

from quadloc.factors.conics import Ellipse
from quadloc.factors.metrics import (
    DEFAULT_LEVEL_SET_SCALE,
    METRIC_NAMES,
    clipped_bbox,
    convex_hull_area,
    cost,
    ellipse_intersection_area,
    level_set_sample_points,
    level_set_sampling_scale,
    overlap_residual,
    residual,
    residual_size,
)
from quadloc.factors.overlap import quadrant_areas
from tests.support.helpers import level, transformed
from tests.support.oracles import metrics_reference

IMAGE = (640, 480)
ellipses = st.builds(
    Ellipse,
    cx=st.floats(-50, 700), cy=st.floats(-50, 530),
    a=st.floats(3.0, 150.0), b=st.floats(3.0, 150.0),
    angle=st.floats(-math.pi, math.pi),
)


def opts(name: str) -> dict:
    return {"image_size": IMAGE} if name == "qbbox" else {}


def rigid(e: Ellipse, ang: float, t: tuple[float, float]) -> Ellipse:
    return transformed(e, ang, t)


# --------------------------------------------------------------------------- the contract


def test_metric_names_are_the_contract():
    assert METRIC_NAMES == ("iou", "giou", "bbox", "qbbox", "algebraic", "frobenius",
                            "wasserstein", "bhattacharyya", "level_set")


@settings(max_examples=40, deadline=None)
@given(ellipses, ellipses)
@example(Ellipse(cx=0.0, cy=0.0, a=4.0, b=5.0, angle=0.0),  # tangent contact at (+-4, 0)
         Ellipse(cx=0.0, cy=0.0, a=4.0, b=4.0, angle=3.0))
def test_cost_is_squared_residual_norm_with_fixed_length(d: Ellipse, p: Ellipse):
    for name in METRIC_NAMES:
        r = residual(name, d, p, **opts(name))
        c = cost(name, d, p, **opts(name))
        assert r.ndim == 1 and r.shape == (residual_size(name, **opts(name)),)
        assert np.all(np.isfinite(r)) and c >= 0.0
        if name in ("iou", "giou"):  # non-negative quadrant rows summing to Delta
            # 1e-7, not 1e-9: where the two boundaries touch (tangent contact, e.g. a circle of
            # radius 4 inside a 4 x 5 ellipse, found by hypothesis) the contact points are double
            # roots, located only to ~sqrt(machine eps); the quadrant split then moves ~1e-8 of
            # Delta between the quadrant path and the whole-area path.
            assert np.all(r >= -1e-12) and abs(float(r.sum()) - c) <= 1e-7, name
        else:
            assert abs(float(r @ r) - c) <= 1e-12 * max(c, 1e-300) + 1e-300, name


@settings(max_examples=40, deadline=None)
@given(ellipses, ellipses)
def test_smooth_metrics_equal_the_scalar_oracle(d: Ellipse, p: Ellipse):
    """The batched smooth metrics (``conic_residuals``, N = 1 through ``residual``) equal their
    former scalar forms (``tests/support/oracles/metrics_reference.py``), pair by pair, to 1e-9 of
    the residual's size (the batched wasserstein reads the semi-axes and angle from ``Sigma``: a
    nearly circular projection's angle is ill-conditioned there, its ``k sin(delta)`` ~1e-10
    off)."""
    for name in ("bbox", "algebraic", "frobenius", "wasserstein", "bhattacharyya"):
        got, want = residual(name, d, p), metrics_reference.residual(name, d, p)
        scale = 1.0 + float(np.abs(want).max())
        if name == "wasserstein":
            # r[4] = k sin(delta) flips sign at perpendicular major axes (delta = -pi/2 or
            # pi/2, the same cost): rounding may pick either branch there
            delta = (d.canonical().angle - p.canonical().angle) % math.pi
            if abs(delta - 0.5 * math.pi) < 1e-9:
                got[4], want[4] = abs(got[4]), abs(want[4])
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * scale, err_msg=name)


@settings(max_examples=40, deadline=None)
@given(ellipses)
def test_every_metric_is_zero_for_identical_ellipses(e: Ellipse):
    for name in METRIC_NAMES:
        assert cost(name, e, e, **opts(name)) <= 1e-12, name
    # also when given with swapped axes labels (same point set)
    swapped = Ellipse(e.cx, e.cy, e.b, e.a, e.angle + math.pi / 2)
    for name in METRIC_NAMES:
        assert cost(name, e, swapped, **opts(name)) <= 1e-9 * (1 + e.cx**2 + e.cy**2), name


def test_errors_name_the_problem():
    e = Ellipse(0, 0, 2, 1, 0)
    with pytest.raises(ValueError, match="valid names: iou, giou"):
        cost("hausdorff", e, e)
    with pytest.raises(ValueError, match="valid names"):
        residual("IoU", e, e)
    with pytest.raises(TypeError, match="'n_samples'"):
        cost("level_set", e, e, n_samples=3)
    with pytest.raises(TypeError, match="'image_size'"):
        cost("bbox", e, e, image_size=IMAGE)
    with pytest.raises(ValueError, match="image_size"):
        cost("qbbox", e, e)
    with pytest.raises(ValueError, match="width"):
        cost("qbbox", e, e, image_size=(0, 10))
    with pytest.raises(ValueError, match="n_azimuths"):
        residual("level_set", e, e, n_azimuths=0)
    with pytest.raises(ValueError, match="scale"):
        residual("level_set", e, e, scale=-1.0)
    with pytest.raises(TypeError, match="detection"):
        cost("iou", (0, 0, 2, 1, 0), e)
    with pytest.raises(TypeError, match="projection"):
        residual("iou", e, None)


def test_residual_sizes():
    assert residual_size("level_set") == 24
    assert residual_size("level_set", n_azimuths=40, n_levels=40) == 1600
    sizes = {n: residual_size(n, **opts(n)) for n in METRIC_NAMES if n != "level_set"}
    assert sizes == {"iou": 4, "giou": 4, "bbox": 4, "qbbox": 4, "algebraic": 5,
                     "frobenius": 5, "wasserstein": 5, "bhattacharyya": 5}


# --------------------------------------------------------------------------- IoU / GIoU


@pytest.mark.parametrize(("r1", "r2"), [(10.0, 20.0), (5.0, 5.5), (1.0, 100.0)])
def test_iou_of_concentric_circles(r1, r2):
    d, p = Ellipse(100, 80, r1, r1, 0.3), Ellipse(100, 80, r2, r2, -1.0)
    assert cost("iou", d, p) == pytest.approx(1.0 - (r1 / r2) ** 2, abs=1e-12)
    # containment: GIoU's hull term vanishes, so GIoU == IoU
    assert cost("giou", d, p) == pytest.approx(1.0 - (r1 / r2) ** 2, abs=1e-12)


def test_iou_with_internal_tangency_and_thin_identical_ellipses():
    # Circle of radius 3 inside a 3 x 4 ellipse, touching it at two points.
    d, p = Ellipse(0, 0, 3, 3, 0.0), Ellipse(0, 0, 3, 4, 0.0)
    assert cost("iou", d, p) == pytest.approx(0.25, abs=1e-12)
    assert cost("iou", p, d) == pytest.approx(0.25, abs=1e-12)
    assert cost("giou", d, p) == pytest.approx(0.25, abs=1e-12)
    thin = Ellipse(0, 0, 3, 137, 0.75)  # rounding in Phi is amplified by the eccentricity
    assert cost("iou", thin, thin) == 0.0


def test_iou_of_scaled_concentric_ellipses_is_scale_squared():
    d = Ellipse(10, 20, 30, 12, 0.7)
    p = Ellipse(10, 20, 30 * 0.6, 12 * 0.6, 0.7 + math.pi)
    assert cost("iou", d, p) == pytest.approx(1.0 - 0.36, abs=1e-12)


def raster_intersection(e1: Ellipse, e2: Ellipse, n: int = 2500) -> float:
    b1, b2 = e1.bbox(), e2.bbox()
    x0, y0 = max(b1[0], b2[0]), max(b1[1], b2[1])
    x1, y1 = min(b1[2], b2[2]), min(b1[3], b2[3])
    if x1 <= x0 or y1 <= y0:
        return 0.0
    xs = x0 + (np.arange(n) + 0.5) * (x1 - x0) / n
    ys = y0 + (np.arange(n) + 0.5) * (y1 - y0) / n
    X, Y = np.meshgrid(xs, ys)
    P = np.stack([X, Y], -1)
    inside = (level(e1, P) <= 1.0) & (level(e2, P) <= 1.0)
    return float(inside.mean() * (x1 - x0) * (y1 - y0))


def test_intersection_area_against_a_high_resolution_raster():
    rng = np.random.default_rng(7)
    checked = 0
    while checked < 6:
        e1 = Ellipse(*rng.uniform(0, 60, 2), *rng.uniform(8, 60, 2), rng.uniform(-3, 3))
        e2 = Ellipse(*rng.uniform(0, 60, 2), *rng.uniform(8, 60, 2), rng.uniform(-3, 3))
        ours = ellipse_intersection_area(e1, e2)
        if ours < 0.05 * min(e1.area, e2.area):
            continue  # substantial overlaps only (relative errors of slivers are meaningless)
        ref = raster_intersection(e1, e2, n=1500)
        assert abs(ours - ref) <= 1e-3 * ref
        assert ours == pytest.approx(ellipse_intersection_area(e2, e1), rel=1e-9)  # symmetric
        checked += 1


@pytest.mark.parametrize(("e1", "e2"), [
    # nested, nearly identical, thin: cases where cv2.intersectConvexConvex is unreliable
    (Ellipse(12.34, 18.79, 7.58, 37.08, 3.03), Ellipse(7.67, 19.20, 7.81, 53.34, 0.546)),
    (Ellipse(27.4, 10.6, 71.6, 60.8, -3.24), Ellipse(27.4, 10.6, 72.8, 60.8, -0.0993)),
    (Ellipse(9.17, 23.96, 27.03, 42.34, -1.66), Ellipse(9.17, 23.96, 42.34, 27.03, -0.092)),
    (Ellipse(0, 0, 40, 10, 0.0), Ellipse(0, 0, 39.9, 10.1, 0.001)),
])
def test_intersection_area_hard_cases(e1, e2):
    ref = raster_intersection(e1, e2, n=1500)
    assert abs(ellipse_intersection_area(e1, e2) - ref) <= 1e-3 * ref
    iou = 1.0 - cost("iou", e1, e2)
    assert iou == pytest.approx(ref / (e1.area + e2.area - ref), abs=1e-3)


def test_iou_is_flat_for_disjoint_ellipses():
    ref = Ellipse(0, 0, 20, 10, 0.2)
    values = [cost("iou", ref, Ellipse(x, 5, 15, 8, 1.0)) for x in (60.0, 100.0, 500.0)]
    assert values == [1.0, 1.0, 1.0]
    # the quadrant rows still sum to Delta = 1 (their squares are not flat: they are smallest
    # when the projection spreads evenly over the detection's quadrants, quadloc.factors.metrics)
    assert residual("iou", ref, Ellipse(60, 5, 15, 8, 1.0)).sum() == pytest.approx(1.0)


def test_giou_grows_with_distance_for_disjoint_ellipses():
    ref = Ellipse(0, 0, 20, 10, 0.2)
    values = [cost("giou", ref, Ellipse(x, 5, 15, 8, 1.0)) for x in (60.0, 100.0, 500.0)]
    assert 1.0 < values[0] < values[1] < values[2] < 2.0


def test_giou_is_flat_when_one_ellipse_contains_the_other():
    big = Ellipse(100, 100, 60, 40, 0.3)
    values = [cost("giou", big, Ellipse(100 + dx, 100 + dy, 10, 6, ang))
              for dx, dy, ang in [(0, 0, 0), (15, -10, 1.0), (-20, 5, 2.0)]]
    assert values[0] > 0.9
    assert max(values) - min(values) <= 1e-12


def dense_hull_area(e1: Ellipse, e2: Ellipse, n: int = 20000) -> float:
    pts = np.vstack([e1.contour_points(n), e2.contour_points(n)]) - e1.center
    return float(cv2.contourArea(cv2.convexHull(pts.astype(np.float32))))


def test_convex_hull_area_against_dense_hull():
    rng = np.random.default_rng(3)
    for _ in range(25):
        e1 = Ellipse(*rng.uniform(0, 80, 2), *rng.uniform(5, 60, 2), rng.uniform(-3, 3))
        e2 = Ellipse(*rng.uniform(0, 80, 2), *rng.uniform(5, 60, 2), rng.uniform(-3, 3))
        ref = dense_hull_area(e1, e2)
        assert abs(convex_hull_area(e1, e2) - ref) <= 1e-4 * ref


def test_giou_closed_form_for_two_equal_circles():
    # Two circles of radius r, centres 2r + g apart (disjoint): hull = stadium
    # (pi r^2 + 2r (2r + g)), IoU = 0, so 1 - GIoU = 1 + (hull - 2 pi r^2) / hull.
    r, g = 10.0, 7.0
    d, p = Ellipse(0, 0, r, r, 0), Ellipse(2 * r + g, 0, r, r, 0.5)
    hull = math.pi * r * r + 2 * r * (2 * r + g)
    assert cost("giou", d, p) == pytest.approx(1.0 + (hull - 2 * math.pi * r * r) / hull,
                                               rel=1e-9)


@pytest.mark.parametrize("direction", [0.0, 0.3, math.pi / 2, 2.0, math.pi, -0.7])
@pytest.mark.parametrize("shift", [1e-6, 0.5, 30.0, 200.0])
def test_hull_of_an_ellipse_and_its_translated_copy(direction, shift):
    # Closed form: hull(E, E + delta) = area + |delta| * (width of E across delta), the width
    # being 2 sqrt(m^T Sigma m) for the unit normal m of delta (Minkowski sum with a segment).
    e = Ellipse(10, 20, 40, 12, 0.4)
    delta = shift * np.array([math.cos(direction), math.sin(direction)])
    m = np.array([-math.sin(direction), math.cos(direction)])
    _, S = e.gaussian()
    expected = e.area + shift * 2 * math.sqrt(m @ S @ m)
    moved = Ellipse(e.cx + delta[0], e.cy + delta[1], e.a, e.b, e.angle + math.pi)
    assert convex_hull_area(e, moved) == pytest.approx(expected, rel=1e-9)
    assert convex_hull_area(moved, e) == pytest.approx(expected, rel=1e-9)


# --------------------------------------------------------------------------- boxes


def test_bbox_residual_and_rotation_dependence():
    d, p = Ellipse(100, 100, 40, 10, 0.0), Ellipse(110, 95, 35, 12, 0.3)
    np.testing.assert_allclose(residual("bbox", d, p), d.bbox() - p.bbox())
    # A common rotation of both ellipses changes the bbox cost (not rotation invariant).
    c0 = cost("bbox", d, p)
    c1 = cost("bbox", rigid(d, 0.8, (0, 0)), rigid(p, 0.8, (0, 0)))
    assert abs(c1 - c0) > 1e-3 * c0
    # Two different ellipses with the same box: bbox cost 0, level set not.
    e1 = Ellipse(0, 0, 30, 10, 0.4)
    box = e1.bbox()
    hx, hy = (box[2] - box[0]) / 2, (box[3] - box[1]) / 2
    e2 = Ellipse(0, 0, 30, 10, -0.4)  # the mirror image has the same axis-aligned box
    np.testing.assert_allclose(e2.bbox(), [-hx, -hy, hx, hy], atol=1e-12)
    assert cost("bbox", e1, e2) < 1e-20 and cost("level_set", e1, e2) > 0.1


def dense_clipped_box(e: Ellipse, W: float, H: float) -> np.ndarray | None:
    """Box of e ∩ [0, W] x [0, H] from a dense sampling of the clipped region's boundary."""
    contour = e.contour_points(200000)
    t = np.linspace(0.0, 1.0, 200001)
    border = np.vstack([np.column_stack([t * W, 0 * t]), np.column_stack([t * W, H + 0 * t]),
                        np.column_stack([0 * t, t * H]), np.column_stack([W + 0 * t, t * H])])
    pts = np.vstack([contour, border[level(e, border) <= 1.0]])
    keep = (pts[:, 0] >= 0) & (pts[:, 0] <= W) & (pts[:, 1] >= 0) & (pts[:, 1] <= H)
    pts = pts[keep]
    if not len(pts):
        return None
    return np.array([pts[:, 0].min(), pts[:, 1].min(), pts[:, 0].max(), pts[:, 1].max()])


@pytest.mark.parametrize("e", [
    Ellipse(20, 200, 80, 30, 0.5),     # crosses the left border
    Ellipse(630, 470, 60, 25, -0.7),   # crosses a corner
    Ellipse(320, 240, 500, 400, 0.2),  # contains the whole image
    Ellipse(320, -10, 200, 40, 0.1),   # crosses the top border, wide
    Ellipse(300, 200, 50, 20, 1.0),    # fully inside
])
def test_clipped_bbox_against_dense_sampling_of_the_clipped_contour(e):
    ref = dense_clipped_box(e, *IMAGE)
    box = clipped_bbox(e, IMAGE)
    np.testing.assert_allclose(box, ref, atol=2e-3)


def test_qbbox_truncation():
    inside_d, inside_p = Ellipse(300, 200, 50, 20, 1.0), Ellipse(310, 210, 40, 25, 0.2)
    np.testing.assert_allclose(residual("qbbox", inside_d, inside_p, image_size=IMAGE),
                               residual("bbox", inside_d, inside_p), atol=1e-9)
    # A projection sticking out of the image: only its visible part counts.
    p = Ellipse(-30, 240, 100, 40, 0.0)  # visible x range [0, 70]
    d = Ellipse(35, 240, 35, 40 * math.sqrt(1 - 0.3**2), 0.0)  # box [0, 70] x [...]
    r = residual("qbbox", d, p, image_size=IMAGE)
    assert abs(r[0]) < 1e-9 and abs(r[2]) < 1e-9
    assert abs(r[1]) < 1e-6 and abs(r[3]) < 1e-6  # same y extent (x = 0 chord of p)
    assert cost("bbox", d, p) > 100.0
    # Entirely outside the image: finite, pointing back inside.
    out = Ellipse(-500, 240, 30, 20, 0.0)
    assert np.all(np.isfinite(residual("qbbox", d, out, image_size=IMAGE)))
    assert clipped_bbox(out, IMAGE) is None


# --------------------------------------------------------------------------- conic metrics


@settings(max_examples=30, deadline=None)
@given(ellipses, ellipses)
def test_algebraic_and_frobenius_against_dual_conics(d: Ellipse, p: Ellipse):
    D = d.dual_conic() - p.dual_conic()
    iu = np.triu_indices(3)
    upper = D[iu][:5]  # C00, C01, C02, C11, C12 (C22 differs by 0)
    np.testing.assert_allclose(residual("algebraic", d, p), upper,
                               atol=1e-9 * (1 + np.abs(D).max()))
    fro = np.linalg.norm(D, "fro")
    assert cost("frobenius", d, p) == pytest.approx(fro**2, rel=1e-9, abs=1e-12)


def test_algebraic_is_not_translation_invariant():
    d, p = Ellipse(0, 0, 20, 10, 0.0), Ellipse(3, 0, 20, 10, 0.0)
    c0 = cost("algebraic", d, p)
    c1 = cost("algebraic", rigid(d, 0.0, (200, 100)), rigid(p, 0.0, (200, 100)))
    assert abs(c1 - c0) > 0.1 * c0


# --------------------------------------------------------------------------- Gaussian metrics


def w2_reference(d: Ellipse, p: Ellipse) -> float:
    m1, S1 = d.gaussian()
    m2, S2 = p.gaussian()
    r1 = sqrtm(S1)
    return float(np.sum((m1 - m2) ** 2) + np.trace(S1 + S2 - 2 * sqrtm(r1 @ S2 @ r1)).real)


def bhattacharyya_reference(d: Ellipse, p: Ellipse) -> float:
    m1, S1 = d.gaussian()
    m2, S2 = p.gaussian()
    S = (S1 + S2) / 2
    dm = m1 - m2
    return float(dm @ np.linalg.solve(S, dm) / 8 + 0.5 * math.log(
        np.linalg.det(S) / math.sqrt(np.linalg.det(S1) * np.linalg.det(S2))))


@settings(max_examples=60, deadline=None)
@given(ellipses, ellipses)
def test_wasserstein_and_bhattacharyya_against_matrix_formulas(d: Ellipse, p: Ellipse):
    w = w2_reference(d, p)
    assert cost("wasserstein", d, p) == pytest.approx(w, rel=1e-7, abs=1e-7)
    b = bhattacharyya_reference(d, p)
    assert cost("bhattacharyya", d, p) == pytest.approx(b, rel=1e-7, abs=1e-9)


def test_gaussian_closed_forms():
    # Circles: W2^2 = |dc|^2 + 2 (r1 - r2)^2.
    d, p = Ellipse(1, 2, 5, 5, 0.3), Ellipse(4, 6, 8, 8, 1.1)
    assert cost("wasserstein", d, p) == pytest.approx(25 + 2 * 9, rel=1e-12)
    # Identical covariances: W2^2 = |dc|^2 and B = dc^T Sigma^-1 dc / 8.
    d, p = Ellipse(0, 0, 30, 10, 0.4), Ellipse(7, -3, 30, 10, 0.4 + math.pi)
    assert cost("wasserstein", d, p) == pytest.approx(49 + 9, rel=1e-12)
    _, S = d.gaussian()
    dm = np.array([-7.0, 3.0])
    assert cost("bhattacharyya", d, p) == pytest.approx(dm @ np.linalg.solve(S, dm) / 8,
                                                        rel=1e-12)
    # Concentric circles: B = ln((r1^2 + r2^2) / (2 r1 r2)).
    d, p = Ellipse(0, 0, 2, 2, 0), Ellipse(0, 0, 3, 3, 0)
    assert cost("bhattacharyya", d, p) == pytest.approx(math.log(13 / 12), rel=1e-12)
    # Nearly equal circles (series branch): ln((1 + (1+e)^2) / (2 (1+e))) = log1p(e^2/(2(1+e))).
    for eps in (1e-3, 1e-6, 3e-2):
        d, p = Ellipse(0, 0, 2, 2, 0), Ellipse(0, 0, 2 * (1 + eps), 2 * (1 + eps), 0)
        expected = math.log1p(eps * eps / (2 * (1 + eps)))
        assert cost("bhattacharyya", d, p) == pytest.approx(expected, rel=1e-9)


def test_gaussian_residuals_are_smooth_at_the_optimum():
    # r(theta) for a rotation of the projection about its centre must be ~linear in theta
    # near 0 (a |theta| cone would make Gauss-Newton fail): r(h) ~ -r(-h) and ~ 2 r(h/2).
    d = Ellipse(50, 40, 30, 12, 0.3)
    for name in ("wasserstein", "bhattacharyya", "level_set"):
        h = 1e-4
        rp = residual(name, d, Ellipse(50, 40, 30, 12, 0.3 + h))
        rm = residual(name, d, Ellipse(50, 40, 30, 12, 0.3 - h))
        rh = residual(name, d, Ellipse(50, 40, 30, 12, 0.3 + h / 2))
        assert np.linalg.norm(rp) > 0
        np.testing.assert_allclose(rp, -rm, atol=1e-3 * np.linalg.norm(rp))  # odd: no cone
        np.testing.assert_allclose(rp, 2 * rh, atol=1e-3 * np.linalg.norm(rp))


# --------------------------------------------------------------------------- invariances


@settings(max_examples=40, deadline=None)
@given(ellipses, ellipses, st.floats(-math.pi, math.pi), st.floats(-300, 300),
       st.floats(-300, 300))
def test_rigid_motion_invariance(d: Ellipse, p: Ellipse, ang: float, tx: float, ty: float):
    d2, p2 = rigid(d, ang, (tx, ty)), rigid(p, ang, (tx, ty))
    for name in ("level_set", "wasserstein", "bhattacharyya", "iou", "giou"):
        c, c2 = cost(name, d, p), cost(name, d2, p2)
        assert c2 == pytest.approx(c, rel=1e-6, abs=1e-9), name


# --------------------------------------------------------------------------- level set


def test_level_set_layout():
    d = Ellipse(100, 50, 40, 15, 0.6)
    pts = level_set_sample_points(d)
    assert pts.shape == (24, 2)
    # Level-major: 4 levels of radius s_max (l + 1) / 4, Phi_D = radius^2.
    expected = np.repeat(((np.arange(4) + 1) / 4 * DEFAULT_LEVEL_SET_SCALE) ** 2, 6)
    np.testing.assert_allclose(level(d, pts), expected, rtol=1e-12)
    # Azimuths: 6 per level, equally spaced in parametric angle, staggered by pi/6 per level.
    local = (pts - d.center) @ d.rotation
    phi = np.arctan2(local[:, 1] / d.b, local[:, 0] / d.a)
    want = 2 * np.pi * np.tile(np.arange(6), 4) / 6 + np.pi * np.repeat(np.arange(4), 6) / 6
    np.testing.assert_allclose(np.angle(np.exp(1j * (phi - want))), 0.0, atol=1e-12)
    # Non-default counts.
    assert level_set_sample_points(d, n_azimuths=40, n_levels=40).shape == (1600, 2)


def test_level_set_residual_is_phi_difference_at_the_samples():
    d, p = Ellipse(100, 50, 40, 15, 0.6), Ellipse(120, 45, 30, 20, -0.2)
    pts = level_set_sample_points(d, p)
    np.testing.assert_allclose(residual("level_set", d, p), level(d, pts) - level(p, pts),
                               rtol=1e-10, atol=1e-10)
    assert cost("level_set", d, p) == pytest.approx(
        float(np.sum((level(d, pts) - level(p, pts)) ** 2)), rel=1e-10)


@settings(max_examples=30, deadline=None)
@given(ellipses, st.floats(-math.pi, math.pi), st.floats(-300, 300), st.floats(-300, 300))
def test_level_set_sampling_is_rigid_equivariant_and_label_free(d, ang, tx, ty):
    assume(abs(d.a - d.b) > 1e-6 * d.a)  # a circle has no orientation: its layout follows angle
    R = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    pts = level_set_sample_points(d, adaptive=False)
    moved = level_set_sample_points(rigid(d, ang, (tx, ty)), adaptive=False)

    def as_set(x):
        return x[np.lexsort((np.round(x[:, 1], 6), np.round(x[:, 0], 6)))]

    np.testing.assert_allclose(as_set(moved), as_set(pts @ R.T + [tx, ty]), atol=1e-6)
    relabelled = Ellipse(d.cx, d.cy, d.b, d.a, d.angle + math.pi / 2)
    np.testing.assert_allclose(as_set(level_set_sample_points(relabelled, adaptive=False)),
                               as_set(pts), atol=1e-6)


def test_level_set_adaptive_sampling_area():
    d = Ellipse(0, 0, 20, 10, 0.0)
    near = Ellipse(5, 0, 20, 10, 0.3)  # centre at Phi_D = 1/16: d = 0.25 < scale
    assert level_set_sampling_scale(d, near) == DEFAULT_LEVEL_SET_SCALE
    far = Ellipse(100, 0, 20, 10, 0.3)  # d = 5 detection radii
    assert level_set_sampling_scale(d, far) == pytest.approx(5.0)
    assert level_set_sampling_scale(d, far, adaptive=False) == DEFAULT_LEVEL_SET_SCALE
    pts = level_set_sample_points(d, far)
    assert level(d, pts).max() == pytest.approx(25.0)
    # Freezing the scale reproduces the adaptive layout exactly.
    np.testing.assert_allclose(
        residual("level_set", d, far),
        residual("level_set", d, far, scale=5.0, adaptive=False), rtol=1e-12)


def test_level_set_is_not_flat_when_one_ellipse_contains_the_other():
    big = Ellipse(100, 100, 60, 40, 0.3)
    values = [cost("level_set", big, Ellipse(100 + dx, 100, 10, 6, 0.0)) for dx in (0, 10, 20)]
    assert values[0] < values[1] < values[2]


def test_registration_benchmark_recovers_rigid_transforms():
    from bench.registration_2d import errors, make_pairs, register

    pairs = make_pairs(3, seed=5)
    for i in range(3):
        ref_p, th0, t0 = pairs["ref"][i], float(pairs["theta0"][i]), pairs["t0"][i]
        moving = np.array([ref_p[0] + t0[0], ref_p[1] + t0[1], ref_p[2], ref_p[3],
                           ref_p[4] + th0])
        for name in ("level_set", "wasserstein"):
            pose, _ = register(name, moving, Ellipse(*ref_p))
            pos, rot = errors(pose, th0, t0)
            assert pos < 1e-6 and rot < 1e-6, (name, i, pos, rot)


def test_nonfinite_free_on_extreme_inputs():
    d = Ellipse(0, 0, 1e-3, 1e-3, 0.0)
    p = Ellipse(1e4, -1e4, 500, 1, 1.0)
    for name in METRIC_NAMES:
        assert math.isfinite(cost(name, d, p, **opts(name))), name


@pytest.mark.parametrize("options", [{"n_azimuths": 6.0}, {"n_levels": 4.0},
                                     {"n_azimuths": True}, {"scale": math.nan},
                                     {"scale": "2"}, {"n_levels": 0}])
def test_level_set_options_are_validated_even_when_equal_to_the_defaults(options):
    """Before: ``n_azimuths=6.0`` (== 6) and ``n_levels=4.0`` skipped validation."""
    det = Ellipse(100.0, 80.0, 30.0, 20.0, 0.2)
    proj = Ellipse(104.0, 78.0, 28.0, 21.0, 0.25)
    name = next(iter(options))
    with pytest.raises(ValueError, match=name):
        residual("level_set", det, proj, **options)
    with pytest.raises(ValueError, match=name):
        cost("level_set", det, proj, **options)


# --------------------------------------------------------------------------- area derivatives


def _gaussian_vector(e: Ellipse) -> np.ndarray:
    mu, S = e.gaussian()
    return np.array([mu[0], mu[1], S[0, 0], S[0, 1], S[1, 1]])


def _from_gaussian_vector(g: np.ndarray) -> Ellipse:
    return Ellipse.from_gaussian(g[:2], np.array([[g[2], g[3]], [g[3], g[4]]]))


def _quadrant_rows(d: Ellipse, p: Ellipse) -> np.ndarray:
    """(quadrant areas of P, of D ∩ P, of the hull; iou rows; giou rows), stacked (5, 4)."""
    q = quadrant_areas(d.params(), p.params(), True)
    return np.stack([q["second"][0], q["intersection"][0], q["hull"][0],
                     residual("iou", d, p), residual("giou", d, p)])


def test_quadrant_areas_against_monte_carlo():
    """Quadrant areas (first ellipse's frame) against uniform samples, and their sums against
    the whole areas."""
    rng = np.random.default_rng(3)
    for _ in range(6):
        d = Ellipse(*rng.uniform(-30, 30, 2), *rng.uniform(5, 50, 2), rng.uniform(-3, 3))
        p = Ellipse(*rng.uniform(-30, 30, 2), *rng.uniform(5, 50, 2), rng.uniform(-3, 3))
        q = quadrant_areas(d.params(), p.params(), True)
        assert q["second"][0].sum() == pytest.approx(p.area, rel=1e-9)
        assert q["intersection"][0].sum() == pytest.approx(ellipse_intersection_area(d, p),
                                                           rel=1e-9, abs=1e-9)
        assert q["hull"][0].sum() == pytest.approx(convex_hull_area(d, p), rel=1e-9)
        n, half = 400_000, 120.0
        pts = rng.uniform(-half, half, (n, 2))
        local = (pts - d.center) @ d.rotation  # coordinates along the detection's axes
        quad = np.where(local[:, 1] >= 0, np.where(local[:, 0] >= 0, 0, 1),
                        np.where(local[:, 0] < 0, 2, 3))
        in_d, in_p = level(d, pts) <= 1, level(p, pts) <= 1
        cell = (2 * half) ** 2 / n
        for k in range(4):
            for mask, name in ((in_p, "second"), (in_d & in_p, "intersection")):
                mc = np.sum(mask & (quad == k)) * cell
                # binomial standard error of the estimate, 5 sigma
                assert abs(mc - q[name][0][k]) <= 5 * math.sqrt(max(mc, 50.0) * cell), name


@pytest.mark.parametrize("seed", range(4))
def test_quadrant_gradients_match_central_differences(seed):
    """The exact boundary-integral gradients (quadloc.factors.overlap "Derivatives") of the quadrant
    areas and of the iou / giou rows, against central differences of the exact values w.r.t.
    the second ellipse's (mu_x, mu_y, s00, s01, s11): random pairs (crossing, contained,
    disjoint, hulls with tangent segments)."""
    rng = np.random.default_rng(seed)
    for _ in range(10):
        d = Ellipse(*rng.uniform(-40, 40, 2), *rng.uniform(5, 60, 2), rng.uniform(-3, 3))
        p = Ellipse(*rng.uniform(-40, 40, 2), *rng.uniform(5, 60, 2), rng.uniform(-3, 3))
        mu, S = p.gaussian()
        g = np.array([mu[0], mu[1], S[0, 0], S[0, 1], S[1, 1]])
        num = np.zeros((5, 4, 5))
        for k in range(5):
            h = 1e-6 * max(1.0, abs(g[k]))
            rows = []
            for sgn in (1.0, -1.0):
                gk = g.copy()
                gk[k] += sgn * h
                moved = Ellipse.from_gaussian(gk[:2], np.array([[gk[2], gk[3]], [gk[3], gk[4]]]))
                rows.append(_quadrant_rows(d, moved))
            num[:, :, k] = (rows[0] - rows[1]) / (2 * h)
        q = quadrant_areas(d.params(), p.params(), True, gradient=True)
        exact = [q["second"][1], q["intersection"][1], q["hull"][1],
                 overlap_residual("iou", d.params(), p.params(), gradient=True)[1],
                 overlap_residual("giou", d.params(), p.params(), gradient=True)[1]]
        for i, grad in enumerate(exact):
            scale = max(np.abs(num[i]).max(), 1e-12)
            np.testing.assert_allclose(grad, num[i], atol=1e-6 * scale + 1e-8)
