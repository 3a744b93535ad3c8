"""Loading a map version for a localization without exceeding the request's time budget:
:class:`MapLoader` compiles it in a background thread (single flight) and waits at most
``max_wait_s``; a request that gives up answers 503 ``map-loading``. Why:
docs/design/service.md#map-loader.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout

from quadloc.maps.compiled import CompiledMap
from quadloc.maps.store import MapStore

__all__ = ["MapLoader", "MapStillLoading"]


class MapStillLoading(Exception):  # noqa: N818 (a state, not a failure)
    """The map version is still being loaded after the request's wait."""


class MapLoader:
    """Single-flight, time-bounded ``store.compiled(map_id, version)`` (thread-safe)."""

    def __init__(self, store: MapStore, max_wait_s: float, workers: int = 2) -> None:
        self.store = store
        #: The store's cache of resolved versions (None for a store without one): a hit is
        #: answered in the calling thread, without a hand-off to the loader pool.
        self._cache = getattr(store, "cache", None)
        self.max_wait_s = max_wait_s
        self._workers = workers
        self._pool: ThreadPoolExecutor | None = self._new_pool()
        self._pending: dict[tuple[str, int | None], Future[CompiledMap]] = {}
        self._lock = threading.Lock()

    def get(self, map_id: str, version: int | None = None) -> CompiledMap:
        """The compiled map; raises the store's errors (``MapNotFound``...) or
        :class:`MapStillLoading` after ``max_wait_s``."""
        if self._cache is not None:
            hit = self._cache.resolution(map_id, version)  # what store.compiled checks first
            if hit is not None:
                return hit
        key = (map_id, version)
        with self._lock:
            future = self._pending.get(key)
            fresh = future is None
            if future is None:
                if self._pool is None:  # closed by an app shutdown, then used again (tests)
                    self._pool = self._new_pool()
                future = self._pool.submit(self.store.compiled, map_id, version)
                self._pending[key] = future
        if fresh:  # outside the lock: a future already done runs the callback right here
            future.add_done_callback(lambda f, k=key: self._forget(k, f))
        try:
            return future.result(timeout=self.max_wait_s)
        except FutureTimeout as exc:
            raise MapStillLoading(f"map {map_id!r} is being loaded") from exc

    def _forget(self, key: tuple[str, int | None], future: Future[CompiledMap]) -> None:
        with self._lock:
            if self._pending.get(key) is future:
                del self._pending[key]

    def _new_pool(self) -> ThreadPoolExecutor:
        return ThreadPoolExecutor(max_workers=self._workers, thread_name_prefix="map-load")

    def close(self) -> None:
        """Stop the loader threads (pending loads finish); a later ``get`` starts new ones."""
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
