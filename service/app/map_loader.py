"""Loading a map version for a request without exceeding its time budget: :class:`MapLoader`
compiles it in a background thread (single flight) and waits at most ``max_wait_s``; a request
that gives up is refused with ``map-loading`` (503, retry after 2 s). Every use case that needs
a compiled map (localize, batches, tracking sessions) gets it here. Why:
docs/design/service.md#map-loader.
"""

from __future__ import annotations

import functools
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout

from quadloc.maps.compiled import CompiledMap
from quadloc.maps.errors import MapNotFound
from quadloc.maps.store import MapStore
from quadloc.service.app.errors import AppError, map_not_found

__all__ = ["MAP_LOADING_RETRY_AFTER_S", "MapLoader"]

#: ``Retry-After`` (s) of a request that gave up waiting for its map version to load.
MAP_LOADING_RETRY_AFTER_S = 2.0


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
        """The compiled map (latest version, or ``version``). Refusals: :class:`AppError`
        ``map-not-found``, or ``map-loading`` after ``max_wait_s`` (the load goes on; the next
        request finds it); the store's availability errors pass through."""
        if self._cache is not None:
            hit: CompiledMap | None = self._cache.resolution(map_id, version)
            if hit is not None:  # (what store.compiled checks first)
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
            future.add_done_callback(functools.partial(self._forget, key))
        try:
            return future.result(timeout=self.max_wait_s)
        except MapNotFound as exc:
            raise map_not_found(map_id, version) from exc
        except FutureTimeout as exc:  # a new version's first use on this replica
            raise AppError("map-loading", f"map {map_id!r} is being loaded on this server "
                           "(first use of this version); retry shortly",
                           retry_after_s=MAP_LOADING_RETRY_AFTER_S) from exc

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
