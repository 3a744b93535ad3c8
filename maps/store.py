"""Versioned map storage over SQLAlchemy 2: SQLite (WAL, the embedded default) or PostgreSQL.

``MapStore("sqlite:///path/quadloc.db")`` or ``MapStore("postgresql://user@host:5432/db")``
(driven by psycopg 3). The schema is created and upgraded by Alembic migrations
(``maps/migrations``), run by :meth:`MapStore.migrate` (automatically at construction unless
``migrate=False``; idempotent, serialised between replicas on PostgreSQL by an advisory lock).

Semantics (docs/design/maps.md, "Map store"): versions 1, 2, ... of a map are immutable;
``update`` succeeds only against the latest version (else :class:`VersionConflict`), each write
is one transaction, ``delete`` removes every version. ``content_hash`` is
:func:`quadloc.maps.model.content_hash` (the ETag). ``compiled`` answers from the store's
:class:`quadloc.maps.cache.CompiledMapCache` (THE compiled-map cache); writes through the store
invalidate it at once.
"""

from __future__ import annotations

import builtins
import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from functools import partialmethod
from pathlib import Path
from typing import Any

import sqlalchemy as sa
from sqlalchemy import event
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.exc import (
    IntegrityError,
    InterfaceError,
    OperationalError,
    ProgrammingError,
    SQLAlchemyError,
)
from sqlalchemy.pool import StaticPool

from quadloc.maps.cache import CompiledMapCache, MapKey
from quadloc.maps.compiled import CompiledMap, MapVersionView, compile_map
from quadloc.maps.errors import (
    MapAlreadyExists,
    MapNotFound,
    MapStoreError,
    SchemaNotMigrated,
    StoreUnavailable,
    VersionConflict,
)
from quadloc.maps.model import (
    MapValidationError,
    SceneMap,
    canonical_json,
    content_hash,
    scene_map_from_dict,
)

__all__ = [
    "MapAlreadyExists",
    "MapNotFound",
    "MapStore",
    "MapStoreError",
    "MapSummary",
    "MapVersionInfo",
    "SchemaNotMigrated",
    "StoreUnavailable",
    "StoredMap",
    "VersionConflict",
    "as_utc",
    "calibrations_table",
    "normalize_url",
    "utc_now",
]

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
#: Key of the PostgreSQL advisory lock taken while migrating (any constant 64-bit integer).
_PG_MIGRATION_LOCK = 0x51_4C_4F_43_4D_41_50  # "QLOCMAP"
#: SQLite busy timeout (seconds): how long a writer waits for another writer's lock.
SQLITE_BUSY_TIMEOUT_S = 30.0

# Table descriptions for building queries ONLY (the map store's; the build jobs' are in
# quadloc.maps.building.jobs). The schema
# itself belongs to the Alembic migrations (maps/migrations/versions/); these declarations mirror
# it, CHECK constraints included, and are never used to create tables (no metadata.create_all).
# A schema change is a new migration plus the matching edit here (tests/maps/test_maps_store.py and
# tests/service/api/test_api_build.py compare the two).
_metadata = sa.MetaData()
maps_table = sa.Table(
    "quadloc_maps",
    _metadata,
    sa.Column("map_id", sa.String(128), primary_key=True),
    sa.Column("name", sa.String(256), nullable=False),
    sa.Column("latest_version", sa.Integer, nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("latest_version >= 1", name="ck_quadloc_maps_latest_version"),
)
versions_table = sa.Table(
    "quadloc_map_versions",
    _metadata,
    sa.Column("map_id", sa.String(128), sa.ForeignKey("quadloc_maps.map_id", ondelete="CASCADE"),
              primary_key=True),
    sa.Column("version", sa.Integer, primary_key=True),
    sa.Column("content", sa.Text, nullable=False),
    sa.Column("content_hash", sa.String(64), nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("version >= 1", name="ck_quadloc_map_versions_version"),
)


#: A map version's own calibration (``quadloc calibrate``): an opaque JSON document written and
#: read by ``quadloc.service.app.calibrations``; deleted with its version.
calibrations_table = sa.Table(
    "quadloc_map_calibrations",
    _metadata,
    sa.Column("map_id", sa.String(128), primary_key=True),
    sa.Column("version", sa.Integer, primary_key=True),
    sa.Column("content", sa.Text, nullable=False),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(["map_id", "version"],
                            ["quadloc_map_versions.map_id", "quadloc_map_versions.version"],
                            ondelete="CASCADE", name="fk_quadloc_map_calibrations_version"),
)


@dataclass(frozen=True)
class StoredMap(MapVersionView):
    """One stored version: the map (with its ``version``), its content hash, creation time (UTC)."""

    scene_map: SceneMap
    content_hash: str
    created_at: datetime


@dataclass(frozen=True)
class MapSummary:
    """A map in :meth:`MapStore.list`: its latest version, that version's hash, times (UTC)."""

    map_id: str
    name: str
    latest_version: int
    content_hash: str
    updated_at: datetime
    created_at: datetime


@dataclass(frozen=True)
class MapVersionInfo:
    """One stored version in :meth:`MapStore.version_history`: number, content hash, creation
    time (UTC)."""

    version: int
    content_hash: str
    created_at: datetime


def normalize_url(url: str | None) -> str:
    """SQLAlchemy URL with the psycopg 3 driver for PostgreSQL (``postgresql://`` or
    ``postgres://`` -> ``postgresql+psycopg://``); other URLs unchanged."""
    if not isinstance(url, str) or not url:
        raise ValueError("database url must be a non-empty string, e.g. sqlite:///quadloc.db")
    for prefix in ("postgresql://", "postgres://"):
        if url.startswith(prefix):
            return "postgresql+psycopg://" + url[len(prefix):]
    return url


def as_utc(value: datetime) -> datetime:
    """A datetime read from the database as UTC (they come back naive from SQLite: they are
    stored in UTC)."""
    return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


def utc_now() -> datetime:
    """The current time, UTC (what the store writes)."""
    return datetime.now(UTC)


class MapStore:
    """Versioned map store. Thread-safe; one instance per process is enough (it pools).

    Database failures (unreachable server, SQLite busy beyond its timeout) raise
    :class:`StoreUnavailable`, also from the constructor when it migrates.

    Args:
        url: ``sqlite:///path`` (file; WAL mode), ``sqlite://`` (in-memory, one connection;
            for tests and one-shot tools, not for concurrent use), or ``postgresql://...`` / ``postgresql+psycopg://...``.
        migrate: run the Alembic migrations up to head at construction (default True).
        engine_options: extra keyword arguments for :func:`sqlalchemy.create_engine`.
    """

    def __init__(self, url: str, *, migrate: bool = True,
                 engine_options: dict[str, Any] | None = None,
                 cache: CompiledMapCache | None = None) -> None:
        self.url = normalize_url(url)
        parsed = sa.engine.make_url(self.url)
        self.dialect = parsed.get_backend_name()
        if self.dialect not in ("sqlite", "postgresql"):
            raise ValueError(f"database url: unsupported backend {self.dialect!r} "
                             f"(use sqlite:/// or postgresql://)")
        options: dict[str, Any] = dict(engine_options or {})
        if self.dialect == "sqlite":
            in_memory = parsed.database in (None, "", ":memory:")
            connect_args = {"timeout": SQLITE_BUSY_TIMEOUT_S, "check_same_thread": False}
            options.setdefault("connect_args", {}).update(connect_args)
            if in_memory:
                options.setdefault("poolclass", StaticPool)
            elif parsed.database:
                Path(parsed.database).expanduser().parent.mkdir(parents=True, exist_ok=True)
        else:
            options.setdefault("pool_pre_ping", True)
        self.engine: Engine = sa.create_engine(self.url, **options)
        if self.dialect == "sqlite":
            _configure_sqlite(self.engine, wal=not in_memory)
        #: THE compiled-map cache of this store (module docstring).
        self.cache = CompiledMapCache() if cache is None else cache
        #: (map_id, version) -> (expiry on the cache's clock, calibration document or None)
        self._calibrations: dict[tuple[str, int], tuple[float, dict[str, Any] | None]] = {}
        if migrate:
            self.migrate()

    # ------------------------------------------------------------------ lifecycle
    def migrate(self) -> None:
        """Upgrade the schema to the newest Alembic revision (idempotent)."""
        from alembic import command
        from alembic.config import Config

        cfg = Config()
        cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
        with self._write() as conn:
            if self.dialect == "postgresql":
                conn.execute(sa.text("SELECT pg_advisory_xact_lock(:k)"),
                             {"k": _PG_MIGRATION_LOCK})
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")

    def close(self) -> None:
        """Release the connection pool."""
        self.engine.dispose()

    def __enter__(self) -> MapStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def ping(self) -> None:
        """Raise :class:`StoreUnavailable` if the database cannot be queried."""
        try:
            with self.engine.connect() as conn:
                conn.execute(sa.text("SELECT 1")).scalar_one()
        except SQLAlchemyError as exc:
            raise _unavailable(exc) from exc

    # ------------------------------------------------------------------ transactions
    @contextmanager
    def _transaction(self, write: bool) -> Iterator[Connection]:
        """A transaction (a write one on SQLite: ``BEGIN IMMEDIATE``, taking the write lock up
        front). Connection-level database failures become :class:`StoreUnavailable`."""
        try:
            with (self.engine.connect().execution_options(quadloc_write=write) as conn,
                  conn.begin()):
                yield conn
        except (OperationalError, InterfaceError) as exc:
            raise _unavailable(exc) from exc
        except ProgrammingError as exc:
            if _schema_missing(exc):
                raise _unavailable(exc) from exc
            raise

    _read = partialmethod(_transaction, False)
    _write = partialmethod(_transaction, True)

    # ------------------------------------------------------------------ writes
    def create(self, scene_map: SceneMap) -> StoredMap:
        """Store ``scene_map`` as version 1 of a new map (its ``version`` field is ignored).

        Raises :class:`MapAlreadyExists` if the id is taken.
        """
        _check_scene_map(scene_map)
        stored = replace(scene_map, version=1)
        text = canonical_json(stored)
        digest = content_hash(stored)
        now = utc_now()
        try:
            with self._write() as conn:
                exists = conn.execute(sa.select(maps_table.c.map_id).where(
                    maps_table.c.map_id == stored.map_id)).first()
                if exists is not None:
                    raise MapAlreadyExists(stored.map_id)
                conn.execute(maps_table.insert().values(
                    map_id=stored.map_id, name=stored.name, latest_version=1,
                    created_at=now, updated_at=now))
                self._insert_version(conn, stored.map_id, 1, text, digest, now)
        except IntegrityError as exc:  # a concurrent create won the race
            raise MapAlreadyExists(stored.map_id) from exc
        finally:  # after the write, so that no reader re-caches what it read before
            self.cache.invalidate(stored.map_id)
        return StoredMap(stored, digest, now)

    def update(self, map_id: str, scene_map: SceneMap, expected_version: int) -> StoredMap:
        """Store ``scene_map`` as version ``expected_version + 1`` of ``map_id``.

        Raises :class:`MapNotFound`, :class:`VersionConflict` if ``expected_version`` is not the
        latest version, :class:`MapValidationError` if ``scene_map.map_id != map_id``,
        ``ValueError`` naming ``expected_version`` unless it is an integer >= 1 (no version
        below 1 ever exists).
        """
        _check_scene_map(scene_map)
        if scene_map.map_id != map_id:
            raise MapValidationError([{"field": "map_id", "message":
                                       f"must be {map_id!r} (the map being updated), got "
                                       f"{scene_map.map_id!r}"}])
        _check_version(expected_version, "expected_version")
        new_version = expected_version + 1
        stored = replace(scene_map, version=new_version)
        text = canonical_json(stored)
        digest = content_hash(stored)
        now = utc_now()
        try:
            with self._write() as conn:
                result = conn.execute(
                    maps_table.update()
                    .where(maps_table.c.map_id == map_id,
                           maps_table.c.latest_version == expected_version)
                    .values(latest_version=new_version, name=stored.name, updated_at=now))
                if result.rowcount != 1:
                    raise _refusal(conn, map_id, expected_version)
                self._insert_version(conn, map_id, new_version, text, digest, now)
        except IntegrityError as exc:  # (map_id, version) taken: another writer won
            with self._read() as conn:
                raise _refusal(conn, map_id, expected_version) from exc
        finally:  # also on a conflict: the map changed (maybe through another replica)
            self.cache.invalidate(map_id)
        return StoredMap(stored, digest, now)

    def _insert_version(self, conn: Connection, map_id: str, version: int, content: str,
                        digest: str, now: datetime) -> None:
        """Insert one immutable version row (inside the caller's transaction)."""
        conn.execute(versions_table.insert().values(
            map_id=map_id, version=version, content=content, content_hash=digest,
            created_at=now))

    def delete(self, map_id: str) -> None:
        """Delete the map and all its versions. Raises :class:`MapNotFound`."""
        try:
            with self._write() as conn:
                conn.execute(versions_table.delete().where(versions_table.c.map_id == map_id))
                result = conn.execute(maps_table.delete().where(maps_table.c.map_id == map_id))
                if result.rowcount != 1:
                    raise MapNotFound(map_id)
        finally:
            self.cache.forget(map_id)

    # ------------------------------------------------------------------ reads
    def _version_query(self, map_id: str, version: int | None, *columns: Any) -> Any:
        if version is None:
            return (sa.select(*columns)
                    .select_from(versions_table.join(
                        maps_table, sa.and_(maps_table.c.map_id == versions_table.c.map_id,
                                            maps_table.c.latest_version
                                            == versions_table.c.version)))
                    .where(versions_table.c.map_id == map_id))
        return sa.select(*columns).where(versions_table.c.map_id == map_id,
                                         versions_table.c.version == version)

    def _load(self, map_id: str, version: int | None
              ) -> tuple[MapKey, CompiledMap, datetime] | None:
        """Resolve ``version`` (latest if None; :class:`MapNotFound`) and return its key, its
        compiled map (from the cache, else parsed, compiled and cached) and its creation time;
        None if the version was deleted (and maybe re-created) between the two reads."""
        v = versions_table.c
        with self._read() as conn:
            row = conn.execute(self._version_query(
                map_id, version, v.version, v.content_hash, v.created_at)).first()
        if row is None:
            raise MapNotFound(map_id, version)
        key = (map_id, int(row.version), str(row.content_hash))
        compiled = self.cache.get(key)  # versions are immutable: reuse the parsed map
        if compiled is None:  # (parsing 10,000 objects takes ~3 s)
            with self._read() as conn:
                content = conn.execute(self._version_query(map_id, key[1], v.content,
                                                           v.content_hash)).first()
            if content is None or content.content_hash != key[2]:
                return None
            compiled = compile_map(scene_map_from_dict(json.loads(content.content),
                                                       version=key[1]))
            self.cache.put(key, compiled)
        return key, compiled, as_utc(row.created_at)

    def get(self, map_id: str, version: int | None = None) -> StoredMap:
        """The given version of a map (the latest if ``version`` is None). :class:`MapNotFound`."""
        _check_version(version)
        loaded = self._load(map_id, version)
        if loaded is None:
            raise MapNotFound(map_id, version)
        key, compiled, created_at = loaded
        return StoredMap(compiled.scene_map, key[2], created_at)

    def versions(self, map_id: str) -> builtins.list[int]:
        """All stored version numbers of a map, ascending. :class:`MapNotFound`."""
        return [info.version for info in self.version_history(map_id)]

    def version_history(self, map_id: str) -> builtins.list[MapVersionInfo]:
        """Every stored version of a map with its content hash and creation time, ascending.
        :class:`MapNotFound`."""
        v = versions_table.c
        with self._read() as conn:
            rows = conn.execute(sa.select(v.version, v.content_hash, v.created_at)
                                .where(v.map_id == map_id).order_by(v.version)).all()
        if not rows:
            raise MapNotFound(map_id)
        return [MapVersionInfo(int(r.version), r.content_hash, as_utc(r.created_at)) for r in rows]

    def list(self) -> builtins.list[MapSummary]:
        """Every map with its latest version, ordered by ``map_id``."""
        m, v = maps_table.c, versions_table.c
        query = (sa.select(m.map_id, m.name, m.latest_version, v.content_hash, m.updated_at,
                           m.created_at)
                 .select_from(maps_table.join(versions_table, sa.and_(
                     v.map_id == m.map_id, v.version == m.latest_version)))
                 .order_by(m.map_id))
        with self._read() as conn:
            rows = conn.execute(query).all()
        return [MapSummary(r.map_id, r.name, int(r.latest_version), r.content_hash,
                           as_utc(r.updated_at), as_utc(r.created_at)) for r in rows]

    def set_calibration(self, map_id: str, version: int, document: dict[str, Any]) -> None:
        """Store (or replace) the calibration document of a map version (JSON-serialisable).
        :class:`MapNotFound` when the version does not exist. Other replicas see it once their
        cached copy expires (``calibration``)."""
        _check_version(version)
        content = json.dumps(document, allow_nan=False)
        c = calibrations_table.c
        with self._write() as conn:
            exists = conn.execute(self._version_query(map_id, version,
                                                      versions_table.c.version)).first()
            if exists is None:
                raise MapNotFound(map_id, version)
            conn.execute(calibrations_table.delete().where(c.map_id == map_id,
                                                           c.version == version))
            conn.execute(calibrations_table.insert().values(
                map_id=map_id, version=version, content=content, created_at=utc_now()))
        self._calibrations.pop((map_id, version), None)

    def calibration(self, map_id: str, version: int) -> dict[str, Any] | None:
        """The calibration document of a map version, or None (none stored, or the version
        does not exist). Remembered per process for the cache's ``resolve_ttl_s`` (a
        calibration stored through another replica is seen after that)."""
        key = (map_id, int(version))
        now = self.cache.clock()
        hit = self._calibrations.get(key)
        if hit is not None and hit[0] > now:
            return hit[1]
        c = calibrations_table.c
        with self._read() as conn:
            row = conn.execute(sa.select(c.content).where(c.map_id == map_id,
                                                          c.version == version)).first()
        doc: dict[str, Any] | None = None if row is None else json.loads(row.content)
        if self.cache.resolve_ttl_s > 0:
            self._calibrations[key] = (now + self.cache.resolve_ttl_s, doc)
        return doc

    def compiled(self, map_id: str, version: int | None = None) -> CompiledMap:
        """Solver arrays of a map version (latest if None), cached per process.

        Raises :class:`MapNotFound`.
        """
        _check_version(version)
        hit = self.cache.resolution(map_id, version)
        if hit is not None:
            return hit
        generation = self.cache.generation(map_id)
        for _attempt in range(3):  # a None: deleted between the two reads, resolve again
            loaded = self._load(map_id, version)
            if loaded is not None:
                self.cache.resolved_as(map_id, version, loaded[0], generation)
                return loaded[1]
        raise MapStoreError(f"map {map_id!r} kept changing while being loaded")


def _schema_missing(exc: Exception) -> bool:
    """A missing table or column: PostgreSQL SQLSTATE 42P01 / 42703, SQLite "no such ..."."""
    code = getattr(getattr(exc, "orig", None), "sqlstate", None)
    return code in ("42P01", "42703") or "no such table" in str(exc) \
        or "no such column" in str(exc)


def _unavailable(exc: Exception) -> StoreUnavailable:
    first = str(exc).splitlines()[0] if str(exc) else ""
    if _schema_missing(exc):
        return SchemaNotMigrated(f"database schema not migrated: {exc.__class__.__name__}: "
                                 f"{first}")
    return StoreUnavailable(f"database unreachable or busy: {exc.__class__.__name__}: {first}")


def _refusal(conn: Connection, map_id: str, expected_version: int) -> MapStoreError:
    """Why an update of ``map_id`` from ``expected_version`` was refused: :class:`MapNotFound`,
    or :class:`VersionConflict` naming the latest version."""
    current = conn.execute(sa.select(maps_table.c.latest_version).where(
        maps_table.c.map_id == map_id)).scalar_one_or_none()
    return (MapNotFound(map_id) if current is None
            else VersionConflict(map_id, expected_version, int(current)))


def _check_version(version: int | None, name: str = "version") -> None:
    """``ValueError`` naming ``name`` unless ``version`` is None (the latest; not for
    ``expected_version``) or an integer >= 1 (no version below 1 ever exists)."""
    if (version is None and name == "version") or (
            not isinstance(version, bool) and isinstance(version, int) and version >= 1):
        return
    raise ValueError(f"{name} must be an integer >= 1 (versions start at 1), got {version!r}")


def _check_scene_map(scene_map: object) -> None:
    if not isinstance(scene_map, SceneMap):
        raise MapValidationError([{"field": "$", "message":
                                   f"expected a SceneMap, got {type(scene_map).__name__}"}])


def _configure_sqlite(engine: Engine, *, wal: bool) -> None:
    """Pragmas on every new connection; explicit BEGIN (IMMEDIATE for writes).

    pysqlite's own transaction handling is turned off (``isolation_level = None``) so that
    SQLAlchemy's ``begin`` emits our BEGIN: writers take the write lock when the transaction
    starts, so two writers queue on the busy timeout instead of failing with a lock upgrade
    error; readers never block in WAL mode.
    """

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.isolation_level = None
        cur = dbapi_connection.cursor()
        try:
            if wal:
                cur.execute("PRAGMA journal_mode=WAL")
                cur.execute("PRAGMA synchronous=NORMAL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute(f"PRAGMA busy_timeout={int(SQLITE_BUSY_TIMEOUT_S * 1000)}")
        finally:
            cur.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn: Connection) -> None:
        if conn.get_execution_options().get("quadloc_write"):
            conn.exec_driver_sql("BEGIN IMMEDIATE")
        else:
            conn.exec_driver_sql("BEGIN")
