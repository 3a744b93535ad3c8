"""Short-lived cache of compiled maps for the localization routes.

``MapStore.compiled`` already caches the solver arrays, but resolves the version with one
database query per call (~0.5 ms on SQLite, a network round trip on PostgreSQL). The API keeps
the resolved :class:`CompiledMap` per ``(map_id, version)`` for ``ttl_s`` seconds
(``QUADLOC_MAP_CACHE_TTL_S``, default 1 s; 0 disables it). Writes through this process
invalidate the map at once; a write through another replica is seen within ``ttl_s``.
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

    def get(self, map_id: str, version: int | None = None) -> CompiledMap:
        """The compiled map (raises the store's ``MapNotFound``)."""
        key = (map_id, version)
        now = time.monotonic()
        if self.ttl_s > 0:
            with self._lock:
                hit = self._entries.get(key)
            if hit is not None and hit[0] > now:
                return hit[1]
        compiled = self.store.compiled(map_id, version)
        if self.ttl_s > 0:
            with self._lock:
                if len(self._entries) >= self.max_entries:
                    self._entries = {k: v for k, v in self._entries.items() if v[0] > now}
                    if len(self._entries) >= self.max_entries:
                        self._entries.clear()
                self._entries[key] = (now + self.ttl_s, compiled)
        return compiled

    def invalidate(self, map_id: str) -> None:
        """Forget every cached version of ``map_id`` (after a local write)."""
        with self._lock:
            self._entries = {k: v for k, v in self._entries.items() if k[0] != map_id}
