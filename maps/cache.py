"""THE compiled-map cache of a process (one class, one place; used by
:class:`quadloc.maps.store.MapStore`).

Two tables behind one lock (docs/design/maps.md, "Compiled-map cache"): compiled versions by
``(map_id, version, content_hash)`` (LRU, bounded by :data:`MAX_ENTRIES` maps and
:data:`MAX_OBJECTS` objects), and resolutions ``(map_id, requested version or None) -> key``
remembered for ``resolve_ttl_s`` seconds (0: always ask the database). A per-map generation,
bumped by :meth:`CompiledMapCache.invalidate`, keeps a slow reader from re-caching a resolution
after a local write.

Time comes from an injectable ``clock`` (``time.monotonic`` by default; tests pass a fake one).
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Callable

from quadloc.maps.compiled import CompiledMap

__all__ = ["MAX_ENTRIES", "MAX_OBJECTS", "CompiledMapCache", "MapKey"]

#: Compiled maps kept (least recently used evicted first).
MAX_ENTRIES = 64
#: ... and at most this many objects in all.
MAX_OBJECTS = 50_000

#: ``(map_id, version, content_hash)`` of one stored version.
MapKey = tuple[str, int, str]


class CompiledMapCache:
    """Thread-safe LRU of compiled map versions plus a TTL table of version resolutions."""

    def __init__(self, resolve_ttl_s: float = 0.0, *, max_entries: int = MAX_ENTRIES,
                 max_objects: int = MAX_OBJECTS,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.resolve_ttl_s = float(resolve_ttl_s)
        self.max_entries = max_entries
        self.max_objects = max_objects
        self.clock = clock
        self._compiled: OrderedDict[MapKey, CompiledMap] = OrderedDict()
        self._resolved: dict[tuple[str, int | None], tuple[float, MapKey]] = {}
        self._generations: dict[str, int] = {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        """Number of compiled map versions held."""
        with self._lock:
            return len(self._compiled)

    # ------------------------------------------------------------------ compiled versions
    def get(self, key: MapKey) -> CompiledMap | None:
        """The compiled version ``key`` (marked recently used), or None."""
        with self._lock:
            hit = self._compiled.get(key)
            if hit is not None:
                self._compiled.move_to_end(key)
            return hit

    def put(self, key: MapKey, compiled: CompiledMap) -> None:
        """Remember a compiled version, evicting the least recently used beyond the bounds
        (the newest entry is always kept, however large)."""
        with self._lock:
            self._compiled[key] = compiled
            self._compiled.move_to_end(key)
            total = sum(len(c) for c in self._compiled.values())
            while len(self._compiled) > 1 and (len(self._compiled) > self.max_entries
                                               or total > self.max_objects):
                total -= len(self._compiled.popitem(last=False)[1])

    # ------------------------------------------------------------------ resolutions
    def generation(self, map_id: str) -> int:
        """The map's write generation; pass it back to :meth:`resolved_as`."""
        with self._lock:
            return self._generations.get(map_id, 0)

    def resolution(self, map_id: str, version: int | None) -> CompiledMap | None:
        """The compiled map a still-fresh resolution of ``(map_id, version)`` points to."""
        if self.resolve_ttl_s <= 0:
            return None
        now = self.clock()
        with self._lock:
            hit = self._resolved.get((map_id, version))
            if hit is None or hit[0] <= now:
                return None
            compiled = self._compiled.get(hit[1])
            if compiled is not None:
                self._compiled.move_to_end(hit[1])
            return compiled

    def resolved_as(self, map_id: str, version: int | None, key: MapKey,
                    generation: int) -> None:
        """Remember that ``(map_id, version)`` means ``key`` for ``resolve_ttl_s``, unless the
        map was written since ``generation`` was read."""
        if self.resolve_ttl_s <= 0:
            return
        now = self.clock()
        with self._lock:
            if self._generations.get(map_id, 0) != generation:
                return
            if len(self._resolved) >= self.max_entries:
                self._resolved = {k: v for k, v in self._resolved.items() if v[0] > now}
                if len(self._resolved) >= self.max_entries:
                    self._resolved.clear()
            self._resolved[(map_id, version)] = (now + self.resolve_ttl_s, key)

    def invalidate(self, map_id: str) -> None:
        """After a local write of ``map_id``: forget its resolutions and bump its generation
        (its compiled versions stay valid: versions are immutable)."""
        with self._lock:
            self._generations[map_id] = self._generations.get(map_id, 0) + 1
            self._resolved = {k: v for k, v in self._resolved.items() if k[0] != map_id}

    def forget(self, map_id: str) -> None:
        """After a delete: also drop every compiled version of ``map_id``."""
        self.invalidate(map_id)
        with self._lock:
            for key in [k for k in self._compiled if k[0] == map_id]:
                del self._compiled[key]
