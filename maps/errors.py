"""Errors of the map store. All derive from :class:`MapStoreError`.

Validation problems of a map's *content* are :class:`quadloc.maps.model.MapValidationError` (a
``ValueError``), re-exported here for convenience.
"""

from __future__ import annotations

from quadloc.maps.model import MapValidationError

__all__ = [
    "MapAlreadyExists",
    "MapNotFound",
    "MapStoreError",
    "MapValidationError",
    "StoreUnavailable",
    "VersionConflict",
]


class MapStoreError(Exception):
    """Base class of every storage error."""


class MapNotFound(MapStoreError, LookupError):  # noqa: N818 (names fixed by the API contract)
    """No map with this id (or no such version of it)."""

    def __init__(self, map_id: str, version: int | None = None) -> None:
        self.map_id = map_id
        self.version = version
        what = f"map {map_id!r}" if version is None else f"version {version} of map {map_id!r}"
        super().__init__(f"{what} not found")


class MapAlreadyExists(MapStoreError):  # noqa: N818 (names fixed by the API contract)
    """``create`` was called with a map id that is already taken."""

    def __init__(self, map_id: str) -> None:
        self.map_id = map_id
        super().__init__(f"map {map_id!r} already exists")


class VersionConflict(MapStoreError):  # noqa: N818 (names fixed by the API contract)
    """``update`` named a version that is not the latest (optimistic concurrency).

    ``current_version`` is the latest version at the time of the refusal.
    """

    def __init__(self, map_id: str, expected_version: int, current_version: int) -> None:
        self.map_id = map_id
        self.expected_version = expected_version
        self.current_version = current_version
        super().__init__(
            f"map {map_id!r}: expected version {expected_version} but the latest is "
            f"{current_version}"
        )


class StoreUnavailable(MapStoreError):  # noqa: N818 (names fixed by the API contract)
    """The database cannot be reached or failed (connection, timeout, lock, disk).

    Raised by every ``MapStore`` operation that touches the database (``create``, ``update``,
    ``delete``, ``get``, ``versions``, ``list``, ``compiled``, ``migrate``), not only by
    ``MapStore.ping``: callers map it to HTTP 503.
    """


class SchemaNotMigrated(StoreUnavailable):
    """The database answers but lacks the map tables or columns (schema not migrated to this
    version): an operator must run the migrations (the service runs them at start)."""
