"""The map use cases: list, get, versions, create, import (Chess format), update, delete, the
demo map, readiness.

Concurrency (docs/design/maps.md): a map version is immutable and its ``content_hash`` is its
strong ETag (``"<sha256hex>"``). An update names the ETag of the latest version it edited
(``If-Match``): missing -> ``precondition-required``, stale -> ``precondition-failed`` (with the
current ETag), a lost race between the check and the write -> ``version-conflict``; never a
silent overwrite. ``If-Match: *`` follows RFC 9110 (13.1.1): it matches when the map exists
(the write replaces its latest version, still refused with ``version-conflict`` if another
write lands between the check and the write), and fails (``precondition-failed``) when it does
not; one rule for ``PUT`` and ``maps:build`` (:data:`ANY_ETAG`, :meth:`MapService.check_etag`).
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

from sqlalchemy.exc import SQLAlchemyError

from quadloc.maps.demo import DEMO_MAP_ID, load_demo_map
from quadloc.maps.errors import MapAlreadyExists, MapNotFound, StoreUnavailable, VersionConflict
from quadloc.maps.model import SceneMap, scene_map_from_chess, scene_map_from_dict
from quadloc.maps.store import MapStore, StoredMap
from quadloc.service.app.errors import AppError, log_database_error, map_not_found
from quadloc.service.schemas.maps import (
    MapListOut,
    MapOut,
    MapSummaryOut,
    MapVersionOut,
    MapVersionsOut,
    etag_of,
)
from quadloc.service.settings import Settings

__all__ = ["ANY_ETAG", "MapService", "parse_if_match", "seed_demo_map"]

log = logging.getLogger("quadloc.app")

#: ``If-Match: *``: matches any current version of an existing map (RFC 9110, 13.1.1).
ANY_ETAG = "*"


def parse_if_match(if_match: str | None, *, what: str = "the update") -> set[str]:
    """The entity tags of an ``If-Match`` value (:data:`ANY_ETAG` included: it matches any
    version of an existing map, :meth:`MapService.check_etag`); ``precondition-required`` when
    it is missing or blank. A weak tag (``W/"..."``) is kept as is and fails the strong
    comparison of :meth:`MapService.check_etag` (RFC 9110 13.1.1)."""
    if if_match is None or not if_match.strip():
        raise AppError("precondition-required",
                       f"{what} needs 'If-Match: \"<ETag>\"' with the ETag of the map's latest "
                       "version (GET /v1/maps/{map_id} returns it), or 'If-Match: *'",
                       field="header.if-match", message="missing")
    return {t.strip() for t in if_match.split(",") if t.strip()}


def _star_on_missing(map_id: str) -> AppError:
    """``If-Match: *`` on a map that does not exist: the precondition is false (412)."""
    return AppError("precondition-failed",
                    f"map {map_id!r} does not exist, so If-Match cannot match; omit it to "
                    "create the map", field="header.if-match", message="map does not exist")


def seed_demo_map(store: MapStore, map_id: str = DEMO_MAP_ID) -> bool:
    """Create the demo Chess map as ``map_id`` if absent. Returns True if it was created."""
    try:
        store.get(map_id)
        return False
    except MapNotFound:
        pass
    scene_map = load_demo_map()
    if map_id != scene_map.map_id:
        scene_map = SceneMap.from_dict({**scene_map.to_dict(), "map_id": map_id})
    try:
        store.create(scene_map)
    except MapAlreadyExists:  # another worker seeded it first
        return False
    return True


def _iso(when: Any) -> str | None:
    return when.isoformat() if when is not None else None


def map_out(stored: StoredMap) -> MapOut:
    """The wire form of a stored map version."""
    sm = stored.scene_map
    return MapOut(map_id=sm.map_id, version=sm.version, content_hash=stored.content_hash,
                  created_at=_iso(getattr(stored, "created_at", None)), map=sm.to_dict())


class MapService:
    """The map use cases over a :class:`MapStore` (limits and the default map from
    ``settings``). Methods returning a stored map also return it as wire (:class:`MapOut`); its
    ETag is :func:`etag_of` of ``content_hash``."""

    def __init__(self, store: MapStore, settings: Settings) -> None:
        self.store = store
        self.settings = settings

    # ------------------------------------------------------------------------------- reads

    def list(self) -> MapListOut:
        """Every map with its latest version."""
        return MapListOut(maps=[
            MapSummaryOut(map_id=s.map_id, name=s.name, version=s.latest_version,
                          content_hash=s.content_hash,
                          updated_at=_iso(getattr(s, "updated_at", None)))
            for s in self.store.list()])

    def get(self, map_id: str, version: int | None = None) -> MapOut:
        """A map version (latest by default); ``map-not-found``."""
        try:
            return map_out(self.store.get(map_id, version))
        except MapNotFound as exc:
            raise map_not_found(map_id, version) from exc

    def versions(self, map_id: str) -> MapVersionsOut:
        """Every stored version of ``map_id``, ascending."""
        try:
            history = self.store.version_history(map_id)
        except MapNotFound as exc:
            raise map_not_found(map_id) from exc
        return MapVersionsOut(map_id=map_id, versions=[
            MapVersionOut(version=h.version, content_hash=h.content_hash,
                          created_at=h.created_at.isoformat()) for h in history])

    def latest_version(self, map_id: str) -> int | None:
        """The latest version of ``map_id``, None when it does not exist."""
        try:
            return int(self.store.get(map_id).scene_map.version)
        except MapNotFound:
            return None

    # ------------------------------------------------------------------------------ writes

    def check_object_limit(self, document: Any) -> None:
        """``invalid-map`` when a map document has more objects than ``max_map_objects``
        (checked before the document is validated: a huge body fails fast)."""
        objs = document.get("objects") if isinstance(document, dict) else None
        limit = self.settings.max_map_objects
        if isinstance(objs, list) and len(objs) > limit:
            raise AppError("invalid-map", f"objects: at most {limit} objects",
                           field="objects", message=f"at most {limit} objects")

    def create(self, document: dict[str, Any]) -> MapOut:
        """Create a map (version 1) from its document (docs/maps.md); ``map-exists``; an
        invalid document raises ``MapValidationError`` naming every field."""
        self.check_object_limit(document)
        return self._created(scene_map_from_dict(document, version=1))

    def import_chess(self, document: dict[str, Any], map_id: str, name: str) -> MapOut:
        """Create a map from the Chess scene format."""
        self.check_object_limit(document)
        return self._created(scene_map_from_chess(document, map_id=map_id, name=name))

    def _created(self, scene_map: SceneMap) -> MapOut:
        try:
            return map_out(self.store.create(scene_map))
        except MapAlreadyExists as exc:
            raise AppError("map-exists", f"map {scene_map.map_id!r} already exists; use PUT "
                           "/v1/maps/{map_id} with If-Match to update it",
                           field="map_id", message="already exists") from exc

    def check_etag(self, map_id: str, tags: set[str], hint: str = "") -> int:
        """The latest version of ``map_id`` if its ETag is one of ``tags`` or ``tags`` holds
        :data:`ANY_ETAG`; else ``precondition-failed`` carrying the current ETag (``hint`` ends
        the detail). A missing map: ``precondition-failed`` for ``*`` (RFC 9110: ``*`` is false
        when there is no current representation), ``map-not-found`` otherwise."""
        try:
            current = self.store.get(map_id)
        except MapNotFound as exc:
            if ANY_ETAG in tags:
                raise _star_on_missing(map_id) from exc
            raise map_not_found(map_id) from exc
        etag = etag_of(current.content_hash)
        if etag not in tags and ANY_ETAG not in tags:
            raise AppError("precondition-failed",
                           f"map {map_id!r} is at version {current.scene_map.version} with ETag "
                           f"{etag}{hint}", field="header.if-match", message="stale ETag",
                           etag=etag)
        return int(current.scene_map.version)

    def update(self, map_id: str, document: dict[str, Any], if_match: str | None) -> MapOut:
        """Store ``document`` as the next version of ``map_id``. Checked in this order: the
        document (invalid -> ``invalid-map`` / ``MapValidationError``), ``If-Match`` (missing ->
        ``precondition-required``), the map (absent -> ``map-not-found``, or
        ``precondition-failed`` for ``*``), the ETag (stale -> ``precondition-failed``;
        ``*`` matches any); a lost race -> ``version-conflict``."""
        self.check_object_limit(document)
        if document.get("map_id", map_id) != map_id:
            raise AppError("invalid-map", "map_id in the body differs from the path",
                           field="map_id", message=f"must be {map_id!r}")
        # the body first: an invalid document is the client's error whatever If-Match says
        scene_map = scene_map_from_dict({**document, "map_id": map_id}, version=1)
        tags = parse_if_match(if_match, what="PUT")
        expected = self.check_etag(map_id, tags, "; fetch it, re-apply your change and retry")
        scene_map = dataclasses.replace(scene_map, version=expected + 1)
        try:
            stored = self.store.update(map_id, scene_map, expected_version=expected)
        except VersionConflict as exc:
            raise AppError("version-conflict",
                           f"map {map_id!r} changed concurrently (now version "
                           f"{exc.current_version}); fetch it and retry",
                           field="header.if-match", message="lost a race") from exc
        except MapNotFound as exc:
            raise map_not_found(map_id) from exc
        return map_out(stored)

    def delete(self, map_id: str) -> None:
        """Delete every version of ``map_id``; the server's default map is refused
        (``default-map``: the readiness probe needs it)."""
        if self.settings.default_map_id and map_id == self.settings.default_map_id:
            raise AppError("default-map",
                           f"map {map_id!r} is this server's default map "
                           "(QUADLOC_DEFAULT_MAP_ID): the readiness probe needs it, so "
                           "deleting it would make every replica unready; update it with PUT, "
                           "or configure another default map first",
                           field="path.map_id", message="is the default map")
        try:
            self.store.delete(map_id)
        except MapNotFound as exc:
            raise map_not_found(map_id) from exc

    # ---------------------------------------------------------------------------- operations

    def seed_demo(self) -> bool:
        """Create the demo Chess map as the default map id when configured and absent."""
        if not (self.settings.seed_demo_map and self.settings.default_map_id):
            return False
        return seed_demo_map(self.store, self.settings.default_map_id)

    def readiness(self) -> dict[str, str]:
        """The readiness checks (database answers, the default map compiles) by name;
        ``not-ready`` naming the failing check only (the driver's text goes to the log)."""
        checks: dict[str, str] = {}
        try:
            self.store.ping()
            checks["database"] = "ok"
            if self.settings.default_map_id:
                compiled = self.store.compiled(self.settings.default_map_id)
                checks["default_map"] = f"{compiled.map_id} v{compiled.version}"
        except MapNotFound as exc:
            raise AppError("not-ready", "default_map: not found",
                           field="default_map", message="not found") from exc
        except (StoreUnavailable, SQLAlchemyError) as exc:  # any driver error: not ready
            log_database_error("readiness: database unavailable", exc)
            raise AppError("not-ready", "database: unavailable",
                           field="database", message="unavailable") from exc
        except Exception as exc:  # the stored default map does not load (logged)
            log.exception("readiness: default map %r not loadable", self.settings.default_map_id)
            raise AppError("not-ready", "default_map: not loadable",
                           field="default_map", message="not loadable") from exc
        return checks
