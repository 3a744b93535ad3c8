"""The place index (quadloc.maps.places) against brute force: covisible pairs, neighbours,
constellations by labels, the spatial grid; memoised on the compiled map."""

from __future__ import annotations

import numpy as np
import pytest

from quadloc.maps.compiled import compile_map, compiled_subset
from quadloc.maps.model import SceneMap
from quadloc.maps.places import VIEW_RANGE_M, build_place_index, place_index
from tests.support.buildings import make_building
from tests.support.scenes import synthetic_map


def _brute_pairs(centers: np.ndarray, radius: float) -> set[tuple[int, int]]:
    d = np.linalg.norm(centers[:, None] - centers[None], axis=2)
    i, j = np.nonzero((d <= radius) & np.triu(np.ones_like(d, dtype=bool), 1))
    return set(zip(i.tolist(), j.tolist(), strict=True))


def test_covisible_pairs_neighbours_and_constellations_equal_brute_force() -> None:
    cm = compile_map(synthetic_map(400, seed=3))
    for radius in (VIEW_RANGE_M, 2.5):
        idx = build_place_index(cm, radius)
        pairs = set(zip(idx.pair_i.tolist(), idx.pair_j.tolist(), strict=True))
        assert pairs == _brute_pairs(np.asarray(cm.centers), radius)
        assert np.allclose(idx.pair_distance, np.linalg.norm(
            cm.centers[idx.pair_i] - cm.centers[idx.pair_j], axis=1), atol=1e-12)
        for i in range(0, len(cm), 37):
            expected = sorted({b for a, b in pairs if a == i} | {a for a, b in pairs if b == i})
            assert idx.neighbours(i).tolist() == expected
        cats = sorted(set(cm.categories))
        for la in cats[:3]:
            for lb in cats:
                I, J, D = idx.pairs_for(la, lb)
                expected_ordered = {(a, b) for a, b in pairs
                                    if cm.categories[a] == la and cm.categories[b] == lb}
                expected_ordered |= {(b, a) for a, b in pairs
                                     if cm.categories[b] == la and cm.categories[a] == lb}
                assert set(zip(I.tolist(), J.tolist(), strict=True)) == expected_ordered
                assert np.all(np.diff(I) >= 0)  # sorted by the first object (the join needs it)
                assert np.allclose(D, np.linalg.norm(cm.centers[I] - cm.centers[J], axis=1))
    assert idx.pairs_for("no-such", "label")[0].size == 0


def test_near_equals_brute_force() -> None:
    cm = compile_map(synthetic_map(300, seed=5))
    idx = place_index(cm)
    rng = np.random.default_rng(0)
    for _ in range(20):
        p = rng.uniform(-2, 40, 3)
        r = float(rng.uniform(0.5, 15))
        expected = np.flatnonzero(np.linalg.norm(cm.centers - p, axis=1) <= r)
        assert idx.near(p, r).tolist() == expected.tolist()


def test_rooms_are_not_covisible_and_index_is_memoised() -> None:
    b = make_building(6, "perturbed", seed=4)
    cm = b.compiled
    idx = place_index(cm)
    assert place_index(cm) is idx
    zone = [b.zone_of(o) for o in cm.object_ids]
    assert all(zone[i] == zone[j] for i, j in zip(idx.pair_i, idx.pair_j, strict=True))
    # every pair of one room is covisible (a room is smaller than the view range)
    n_room_pairs = sum(len(r.object_ids) * (len(r.object_ids) - 1) // 2 for r in b.rooms)
    assert len(idx.pair_i) == n_room_pairs


def test_compiled_subset_keeps_ids_and_arrays() -> None:
    cm = compile_map(synthetic_map(50, seed=1))
    sel = np.array([3, 7, 8, 20, 49])
    sub = compiled_subset(cm, sel)
    assert sub.object_ids == tuple(cm.object_ids[i] for i in sel)
    assert np.array_equal(sub.centers, cm.centers[sel])
    assert np.array_equal(sub.dual_quadrics, cm.dual_quadrics[sel])
    assert (sub.map_id, sub.version) == (cm.map_id, cm.version)
    # the sub-map (not validated again) is the map a validated construction gives
    sm = cm.scene_map
    validated = SceneMap(sm.map_id, sm.name, sm.up_axis, sm.categories,
                         [sm.objects[i] for i in sel], sm.version)
    assert sub.scene_map.to_dict() == validated.to_dict()


def test_radius_cell_ids_and_positions_equal_their_definitions() -> None:
    cm = compile_map(synthetic_map(300, seed=9))
    idx = place_index(cm)
    axes = np.asarray(cm.axes)
    want = np.array([(a * b * c) ** (1.0 / 3.0) for a, b, c in axes.tolist()])
    np.testing.assert_allclose(idx.radius, want, rtol=1e-12)
    cells = [tuple(c) for c in np.floor(np.asarray(cm.centers) / idx.view_range_m)
             .astype(int).tolist()]
    ids = idx.cell_ids.tolist()
    for a in range(0, len(cm), 7):
        for b in range(len(cm)):
            assert (ids[a] == ids[b]) == (cells[a] == cells[b])
    # the compiled map's positions: each id at its place in object_ids, unknown ids KeyError
    assert [cm.positions[o] for o in cm.object_ids] == list(range(len(cm)))
    assert cm.index_of(cm.object_ids[-1]) == len(cm) - 1
    with pytest.raises(KeyError):
        cm.index_of("no such object")


def test_compiled_subset_equals_compiling_the_sub_map() -> None:
    """The subset's arrays are rows of the parent's: the same numbers compile_map gives a
    map of those objects built anew (atol 1e-12), categories indexed in the subset."""
    sm = synthetic_map(60, seed=4)
    cm = compile_map(sm)
    sel = np.array([0, 5, 6, 17, 33, 59])
    sub = compiled_subset(cm, sel)
    fresh = compile_map(SceneMap(sm.map_id, sm.name, sm.up_axis, sm.categories,
                                 [sm.objects[i] for i in sel], sm.version))
    assert sub.object_ids == fresh.object_ids and sub.categories == fresh.categories
    for name in ("centers", "axes", "rotations", "shape_matrices", "dual_quadrics"):
        np.testing.assert_allclose(getattr(sub, name), getattr(fresh, name), atol=1e-12)
    assert sub.indices_by_category.keys() == fresh.indices_by_category.keys()
    for c, ix in fresh.indices_by_category.items():
        assert np.array_equal(sub.indices_by_category[c], ix)
    assert compile_map(sub.scene_map) is sub  # memoised on its sub-map
