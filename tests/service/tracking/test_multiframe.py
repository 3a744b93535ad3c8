"""Multi-frame RANSAC's sampling (service/tracking/multiframe.py)."""

from __future__ import annotations

import numpy as np

from quadloc.service.tracking.multiframe import _draw_unused


def _draw_from_the_list(objects: np.ndarray, used: set[int], rng: np.random.Generator
                        ) -> int | None:
    """The rule written out: list the objects not used, draw one uniformly."""
    free = [int(o) for o in objects if int(o) not in used]
    return free[int(rng.integers(len(free)))] if free else None


def test_a_draw_skips_the_used_objects_as_the_list_of_free_ones_would() -> None:
    """Same object and same generator state as drawing from the list of the free objects, in
    any order of the objects, with 0-2 used (some not among them), none left included."""
    g = np.random.default_rng(3)
    for _ in range(5000):
        objects = g.choice(40, int(g.integers(1, 7)), replace=False)
        used = {int(x) for x in g.choice(40, int(g.integers(0, 2)), replace=False)}
        used |= {int(x) for x in g.choice(objects, min(len(objects), int(g.integers(0, 3))),
                                           replace=False)}
        a, b = np.random.default_rng(7), np.random.default_rng(7)
        assert _draw_unused(objects, used, a) == _draw_from_the_list(objects, used, b)
        assert a.integers(1 << 30) == b.integers(1 << 30)  # as many draws consumed


def test_every_unused_object_is_drawn_and_no_used_one() -> None:
    objects = np.array([9, 2, 7, 4, 5])
    rng = np.random.default_rng(0)
    drawn = {_draw_unused(objects, {7, 5}, rng) for _ in range(300)}
    assert drawn == {9, 2, 4}
    assert _draw_unused(np.array([3]), {3}, rng) is None
