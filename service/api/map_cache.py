"""Short-lived cache of compiled maps for the localization routes.

``MapStore.compiled`` already caches the solver arrays, but resolves the version with one
database query per call (~0.5 ms on SQLite, a network round trip on PostgreSQL). The API keeps
the resolved :class:`CompiledMap` per ``(map_id, version)`` for ``ttl_s`` seconds
(``QUADLOC_MAP_CACHE_TTL_S``, default 1 s; 0 disables it). Writes through this process
invalidate the map at once; a write through another replica is seen within ``ttl_s``.

Race: a reader that misses the cache, reads the old version from the database and is slow to
store it could otherwise re-cache the old version *after* a local write invalidated the map.
Each map has a generation counter, bumped by :meth:`MapCache.invalidate`; a reader stores its
result only if the generation it saw before reading the database is still current.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from maps.compiled import CompiledMap

__all__ = ["MapCache"]


class MapCache:
    """TTL cache in front of ``store.compiled(map_id, version)`` (thread-safe)."""

    def __init__(self, store: Any, ttl_s: float, max_entries: int = 64) -> None:
        self.store = store
        self.ttl_s = ttl_s
        self.max_entries = max_entries
        self._entries: dict[tuple[str, int | None], tuple[float, CompiledMap]] = {}
        self._lock = threading.Lock()
        self._generations: dict[str, int] = {}

    def get(self, map_id: str, version: int | None = None) -> CompiledMap:
        """The compiled map (raises the store's ``MapNotFound``)."""
        key = (map_id, version)
        now = time.monotonic()
        if self.ttl_s <= 0:
            return self.store.compiled(map_id, version)
        with self._lock:
            hit = self._entries.get(key)
            generation = self._generations.get(map_id, 0)
        if hit is not None and hit[0] > now:
            return hit[1]
        compiled = self.store.compiled(map_id, version)
        with self._lock:
            if self._generations.get(map_id, 0) == generation:  # no write since we read
                if len(self._entries) >= self.max_entries:
                    self._entries = {k: v for k, v in self._entries.items() if v[0] > now}
                    if len(self._entries) >= self.max_entries:
                        self._entries.clear()
                self._entries[key] = (now + self.ttl_s, compiled)
        return compiled

    def invalidate(self, map_id: str) -> None:
        """Forget every cached version of ``map_id`` (after a local write)."""
        with self._lock:
            self._generations[map_id] = self._generations.get(map_id, 0) + 1
            self._entries = {k: v for k, v in self._entries.items() if k[0] != map_id}
