"""quadloc.maps.cache.CompiledMapCache: the one compiled-map cache (LRU bounds, TTL on a fake
clock)."""

from __future__ import annotations

from quadloc.maps.cache import CompiledMapCache
from tests.support.helpers import FakeClock


def _compiled(n_objects: int) -> list[str]:
    """A stand-in for a CompiledMap: only its len() (object count) matters to the cache."""
    return ["object"] * n_objects


def test_least_recently_used_version_is_evicted_first() -> None:
    cache = CompiledMapCache(max_entries=2)
    a, b, c = _compiled(1), _compiled(1), _compiled(1)
    cache.put(("a", 1, "h"), a)  # type: ignore[arg-type]
    cache.put(("b", 1, "h"), b)  # type: ignore[arg-type]
    assert cache.get(("a", 1, "h")) is a  # a is now the most recently used
    cache.put(("c", 1, "h"), c)  # type: ignore[arg-type]
    assert len(cache) == 2 and cache.get(("b", 1, "h")) is None
    assert cache.get(("a", 1, "h")) is a and cache.get(("c", 1, "h")) is c


def test_object_bound_keeps_the_newest_map_however_large() -> None:
    cache = CompiledMapCache(max_objects=10)
    cache.put(("a", 1, "h"), _compiled(6))  # type: ignore[arg-type]
    cache.put(("b", 1, "h"), _compiled(6))  # type: ignore[arg-type]  # 12 > 10: a goes
    assert cache.get(("a", 1, "h")) is None and len(cache) == 1
    big = _compiled(50)
    cache.put(("c", 1, "h"), big)  # type: ignore[arg-type]
    assert cache.get(("c", 1, "h")) is big and len(cache) == 1


def test_forget_drops_only_that_maps_versions_and_resolutions() -> None:
    clock = FakeClock()
    cache = CompiledMapCache(resolve_ttl_s=5.0, clock=clock)
    a1, a2, b1 = _compiled(1), _compiled(1), _compiled(1)
    for key, value in ((("a", 1, "h1"), a1), (("a", 2, "h2"), a2), (("b", 1, "h"), b1)):
        cache.put(key, value)  # type: ignore[arg-type]
    cache.resolved_as("a", None, ("a", 2, "h2"), cache.generation("a"))
    cache.resolved_as("b", None, ("b", 1, "h"), cache.generation("b"))
    assert cache.resolution("a", None) is a2 and cache.resolution("b", None) is b1
    cache.forget("a")
    assert cache.resolution("a", None) is None
    assert cache.get(("a", 1, "h1")) is None and cache.get(("a", 2, "h2")) is None
    assert cache.resolution("b", None) is b1 and len(cache) == 1
    clock.advance(5.0)  # the TTL is a strict bound: at expiry the database is asked again
    assert cache.resolution("b", None) is None


def test_zero_ttl_never_remembers_a_resolution() -> None:
    cache = CompiledMapCache(resolve_ttl_s=0.0)
    c = _compiled(1)
    cache.put(("a", 1, "h"), c)  # type: ignore[arg-type]
    cache.resolved_as("a", None, ("a", 1, "h"), cache.generation("a"))
    assert cache.resolution("a", None) is None and cache.get(("a", 1, "h")) is c
