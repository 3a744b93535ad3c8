"""MapStore on SQLite (tmp file, WAL) and on the real PostgreSQL at 127.0.0.1:5432.

Every test runs on both backends. PostgreSQL: trust auth, user ``postgres``, database ``test``;
each test gets its own schema (``search_path``), dropped afterwards. Skipped with a message when
the server is unreachable.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import sqlalchemy as sa

from quadloc.factors.camera import Ellipsoid
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.demo import load_demo_map
from quadloc.maps.errors import MapAlreadyExists, MapNotFound, StoreUnavailable, VersionConflict
from quadloc.maps.model import MapObject, MapValidationError, SceneMap
from quadloc.maps.store import MapStore, normalize_url, versions_table
from tests.support.postgres import pg_schema_url, pg_unavailable_reason

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'maps.db'}"
        return
    reason = pg_unavailable_reason()
    if reason is not None:
        pytest.skip(reason)
    with pg_schema_url() as url:
        yield url


@pytest.fixture
def store(store_url: str) -> Iterator[MapStore]:
    s = MapStore(store_url)
    try:
        yield s
    finally:
        s.close()


def _small_map(map_id: str = "office", name: str = "Office", shift: float = 0.0) -> SceneMap:
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    return SceneMap(
        map_id=map_id, name=name, up_axis=(0.0, 0.0, 1.0), categories=("chair", "tv"),
        objects=(
            MapObject("c1", "chair", Ellipsoid(np.array([1.0 + shift, 2.0, 0.4]),
                                               np.array([0.3, 0.25, 0.45]), rot)),
            MapObject("t1", "tv", Ellipsoid(np.array([0.0, 3.0, 1.2]),
                                            np.array([0.5, 0.05, 0.3]))),
        ),
        metadata={"site": "test"},
    )


def _independent_hash(scene_map: SceneMap) -> str:
    """sha256 of the exported document, geometric numbers rounded to 12 decimals (the documented
    hashed form, quadloc.maps.model.HASH_DECIMALS), written independently of quadloc.maps.model."""
    doc = scene_map.to_dict()

    def r12(values: list[float]) -> list[float]:
        return [float(f"{v:.12f}") + 0.0 for v in values]

    doc["up_axis"] = r12(doc["up_axis"])
    for o in doc["objects"]:
        o["center"], o["axes"] = r12(o["center"]), r12(o["axes"])
        o["quaternion_wxyz"] = r12(o["quaternion_wxyz"])
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"),
                      ensure_ascii=False, allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def _count_versions(store: MapStore, map_id: str) -> int:
    with store.engine.connect() as conn:
        return int(conn.execute(sa.select(sa.func.count()).select_from(versions_table)
                                .where(versions_table.c.map_id == map_id)).scalar_one())


def _content(scene_map: SceneMap) -> dict:
    d = scene_map.to_dict()
    d.pop("version")
    return d


# --------------------------------------------------------------------------- basic semantics


def test_create_get_roundtrip_and_hash(store: MapStore) -> None:
    demo = load_demo_map()
    stored = store.create(replace(demo, version=7))  # the given version is ignored
    assert stored.version == 1
    assert stored.content_hash == _independent_hash(stored.scene_map)
    got = store.get("chess")
    assert got.version == 1
    assert got.content_hash == stored.content_hash
    assert _independent_hash(got.scene_map) == stored.content_hash  # exact round trip
    assert _content(got.scene_map) == _content(demo)
    for a, b in zip(got.scene_map.objects, demo.objects, strict=True):
        np.testing.assert_allclose(a.ellipsoid.rotation, b.ellipsoid.rotation, atol=1e-15)
        np.testing.assert_array_equal(a.ellipsoid.axes, b.ellipsoid.axes)
    assert got.created_at.tzinfo is not None
    assert abs((got.created_at - stored.created_at).total_seconds()) < 1e-3


def test_create_twice_is_refused(store: MapStore) -> None:
    store.create(_small_map())
    with pytest.raises(MapAlreadyExists) as exc:
        store.create(_small_map(name="Other"))
    assert exc.value.map_id == "office"
    assert store.get("office").scene_map.name == "Office"
    assert _count_versions(store, "office") == 1


def test_versions_are_immutable_and_readable(store: MapStore) -> None:
    v1 = store.create(_small_map())
    v2 = store.update("office", _small_map(name="Office v2", shift=0.5), expected_version=1)
    v3 = store.update("office", _small_map(name="Office v3", shift=1.0), expected_version=2)
    assert (v1.version, v2.version, v3.version) == (1, 2, 3)
    assert len({v1.content_hash, v2.content_hash, v3.content_hash}) == 3
    assert store.versions("office") == [1, 2, 3]
    assert store.get("office").version == 3
    for old in (v1, v2, v3):
        got = store.get("office", old.version)
        assert got.content_hash == old.content_hash == _independent_hash(got.scene_map)
        assert got.scene_map.name == old.scene_map.name
    np.testing.assert_allclose(store.get("office", 2).scene_map.objects[0].ellipsoid.center,
                               [1.5, 2.0, 0.4])
    summaries = store.list()
    assert [s.map_id for s in summaries] == ["office"]
    s = summaries[0]
    assert (s.name, s.latest_version, s.content_hash) == ("Office v3", 3, v3.content_hash)
    assert s.updated_at >= s.created_at


def test_identical_content_in_two_versions_has_distinct_hashes(store: MapStore) -> None:
    a = store.create(_small_map())
    b = store.update("office", _small_map(), expected_version=1)
    assert a.content_hash != b.content_hash  # the version is part of the hashed document
    assert _content(store.get("office", 1).scene_map) == _content(store.get("office", 2).scene_map)


def test_stale_update_is_a_conflict_and_changes_nothing(store: MapStore) -> None:
    store.create(_small_map())
    store.update("office", _small_map(name="v2"), expected_version=1)
    for stale in (1, 5):
        with pytest.raises(VersionConflict) as exc:
            store.update("office", _small_map(name="lost"), expected_version=stale)
        assert exc.value.current_version == 2
        assert exc.value.expected_version == stale
    assert store.get("office").scene_map.name == "v2"
    assert _count_versions(store, "office") == 2


def test_missing_maps_and_versions(store: MapStore) -> None:
    with pytest.raises(MapNotFound):
        store.get("nope")
    with pytest.raises(MapNotFound):
        store.update("nope", _small_map("nope"), expected_version=1)
    with pytest.raises(MapNotFound):
        store.delete("nope")
    with pytest.raises(MapNotFound):
        store.compiled("nope")
    store.create(_small_map())
    with pytest.raises(MapNotFound) as exc:
        store.get("office", 2)
    assert exc.value.version == 2
    with pytest.raises(ValueError, match="version"):
        store.get("office", 0)


def test_update_must_keep_the_map_id(store: MapStore) -> None:
    store.create(_small_map())
    with pytest.raises(MapValidationError) as exc:
        store.update("office", _small_map("elsewhere"), expected_version=1)
    assert exc.value.errors[0]["field"] == "map_id"


def test_delete_removes_every_version(store: MapStore) -> None:
    store.create(_small_map())
    store.update("office", _small_map(shift=0.3), expected_version=1)
    first = store.compiled("office", 1)
    store.delete("office")
    assert _count_versions(store, "office") == 0
    assert store.list() == []
    for v in (None, 1, 2):
        with pytest.raises(MapNotFound):
            store.get("office", v)
    # Re-creating starts at version 1 again, and the compiled cache is not stale.
    store.create(_small_map(shift=2.0))
    again = store.compiled("office", 1)
    assert again is not first
    np.testing.assert_allclose(again.centers[0], [3.0, 2.0, 0.4])


# --------------------------------------------------------------------------- compiled cache


def test_compiled_is_cached_and_follows_updates_from_other_replicas(store_url: str) -> None:
    a, b = MapStore(store_url), MapStore(store_url, migrate=False)
    try:
        a.create(load_demo_map())
        c1 = a.compiled("chess")
        assert isinstance(c1, CompiledMap) and c1.version == 1
        assert a.compiled("chess") is c1
        assert a.compiled("chess", 1) is c1
        demo = load_demo_map()
        moved = replace(demo, objects=demo.objects[:-1])
        b.update("chess", moved, expected_version=1)  # another replica writes
        c2 = a.compiled("chess")
        assert c2.version == 2 and len(c2.object_ids) == 10
        assert a.compiled("chess", 1) is c1  # old version still cached and valid
        # The cached arrays are the map's: Q* from the Ellipsoid of each object.
        for i, e in enumerate(c2.ellipsoids):
            np.testing.assert_allclose(c2.dual_quadrics[i], e.dual_quadric(), atol=1e-12)
    finally:
        a.close()
        b.close()


# --------------------------------------------------------------------------- concurrency


def test_concurrent_updates_exactly_one_wins(store: MapStore) -> None:
    store.create(_small_map())
    n = 6
    barrier = threading.Barrier(n)
    outcomes: list[object] = [None] * n

    def writer(i: int) -> None:
        barrier.wait()
        try:
            outcomes[i] = store.update("office", _small_map(name=f"w{i}"), expected_version=1)
        except Exception as exc:
            outcomes[i] = exc

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    winners = [o for o in outcomes if not isinstance(o, Exception)]
    losers = [o for o in outcomes if isinstance(o, Exception)]
    assert len(winners) == 1, outcomes
    assert all(isinstance(o, VersionConflict) and o.current_version == 2 for o in losers), losers
    latest = store.get("office")
    assert latest.version == 2
    assert latest.content_hash == winners[0].content_hash
    assert _count_versions(store, "office") == 2


def test_concurrent_creates_exactly_one_wins(store: MapStore) -> None:
    n = 5
    barrier = threading.Barrier(n)
    outcomes: list[object] = [None] * n

    def creator(i: int) -> None:
        barrier.wait()
        try:
            outcomes[i] = store.create(_small_map(name=f"c{i}"))
        except Exception as exc:
            outcomes[i] = exc

    threads = [threading.Thread(target=creator, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert sum(not isinstance(o, Exception) for o in outcomes) == 1, outcomes
    assert all(isinstance(o, MapAlreadyExists) for o in outcomes if isinstance(o, Exception))
    assert _count_versions(store, "office") == 1


# --------------------------------------------------------------------------- crashes


def test_exception_between_inserts_leaves_nothing(store: MapStore,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    original = MapStore._insert_version

    def insert_then_fail(self: MapStore, *args: object, **kwargs: object) -> None:
        original(self, *args, **kwargs)  # the row is written inside the transaction ...
        raise RuntimeError("injected crash")  # ... which then dies before commit

    store.create(_small_map())
    monkeypatch.setattr(MapStore, "_insert_version", insert_then_fail)
    with pytest.raises(RuntimeError, match="injected"):
        store.update("office", _small_map(name="half"), expected_version=1)
    with pytest.raises(RuntimeError, match="injected"):
        store.create(_small_map("other"))
    monkeypatch.setattr(MapStore, "_insert_version", original)
    assert store.get("office").version == 1
    assert store.list()[0].latest_version == 1
    assert _count_versions(store, "office") == 1
    with pytest.raises(MapNotFound):
        store.get("other")
    assert _count_versions(store, "other") == 0
    assert store.update("office", _small_map(name="ok"), expected_version=1).version == 2


_CRASH_CHILD = r"""
import os, sys, time
from quadloc.maps.store import MapStore
from quadloc.maps.model import SceneMap
url, doc = sys.argv[1], sys.stdin.read()
store = MapStore(url, migrate=False)
original = MapStore._insert_version
def insert_then_hang(self, *args, **kwargs):
    original(self, *args, **kwargs)
    print("inserted", flush=True)
    time.sleep(120)  # killed here, mid-transaction
MapStore._insert_version = insert_then_hang
store.update("office", SceneMap.from_json(doc), expected_version=1)
"""


def test_killed_writer_leaves_nothing_visible(store: MapStore, store_url: str) -> None:
    store.create(_small_map())
    doc = _small_map(name="never committed").to_json()
    child = subprocess.Popen([sys.executable, "-c", _CRASH_CHILD, store_url], cwd=REPO_ROOT,
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        child.stdin.write(doc)  # type: ignore[union-attr]
        child.stdin.close()  # type: ignore[union-attr]
        line = child.stdout.readline()  # type: ignore[union-attr]
        assert line.strip() == "inserted", child.stderr.read()  # type: ignore[union-attr]
        # Mid-transaction: readers see only the committed state.
        assert store.get("office").version == 1
        child.kill()
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert store.get("office").scene_map.name == "Office"
    assert store.versions("office") == [1]
    assert _count_versions(store, "office") == 1
    # The lock died with the writer: the next update goes through.
    assert store.update("office", _small_map(name="after crash"), expected_version=1).version == 2


# --------------------------------------------------------------------------- engine, migrations


def test_migrations_are_idempotent_and_recorded(store: MapStore) -> None:
    store.migrate()
    store.migrate()
    with store.engine.connect() as conn:
        rev = conn.execute(sa.text("SELECT version_num FROM quadloc_alembic_version")).scalar_one()
        tables = set(sa.inspect(conn).get_table_names())
    assert rev == "0005_build_queue"
    assert {"quadloc_maps", "quadloc_map_versions"} <= tables
    # the job queue's tables on PostgreSQL only (SQLite builds in-process)
    queue_tables = {"procrastinate_jobs", "procrastinate_workers", "procrastinate_events",
                    "procrastinate_periodic_defers"}
    assert (queue_tables <= tables) == (store.dialect == "postgresql")
    assert not any(t.startswith("procrastinate") for t in tables - queue_tables)
    store.ping()


def test_the_queue_migration_downgrades_and_upgrades_again(store: MapStore) -> None:
    from alembic import command
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(REPO_ROOT / "maps" / "migrations"))

    def tables() -> set[str]:
        with store.engine.connect() as conn:
            return set(sa.inspect(conn).get_table_names())

    for target in ("0004_build_job_owner", "head"):
        with store.engine.begin() as conn:
            cfg.attributes["connection"] = conn
            if target == "head":
                command.upgrade(cfg, target)
            else:
                command.downgrade(cfg, target)
        with store.engine.connect() as conn:
            columns = {c["name"] for c in sa.inspect(conn).get_columns("quadloc_build_jobs")}
            if target == "head":
                assert "payload" in columns
            else:
                assert "payload" not in columns
                assert not any(t.startswith("procrastinate") for t in tables())
                routines = (conn.execute(sa.text(
                    "SELECT count(*) FROM pg_proc p JOIN pg_namespace n ON n.oid = "
                    "p.pronamespace WHERE n.nspname = current_schema() AND p.proname LIKE "
                    "'procrastinate%'")).scalar_one() if store.dialect == "postgresql" else 0)
                assert routines == 0
    assert ("procrastinate_jobs" in tables()) == (store.dialect == "postgresql")


def test_sqlite_uses_wal(tmp_path: Path) -> None:
    with MapStore(f"sqlite:///{tmp_path / 'wal.db'}") as s, s.engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1


def test_in_memory_sqlite_works(tmp_path: Path) -> None:
    with MapStore("sqlite://") as s:
        s.create(_small_map())
        assert s.get("office").version == 1


def test_unreachable_database_is_store_unavailable() -> None:
    url = "postgresql://postgres@127.0.0.1:1/none?connect_timeout=2"
    s = MapStore(url, migrate=False)
    with pytest.raises(StoreUnavailable, match="unreachable"):
        s.ping()
    with pytest.raises(StoreUnavailable):
        s.get("chess")
    with pytest.raises(StoreUnavailable):
        s.create(_small_map())
    s.close()
    with pytest.raises(StoreUnavailable):
        MapStore(url)  # migrating at construction


def test_urls() -> None:
    assert normalize_url("postgresql://u@h/db") == "postgresql+psycopg://u@h/db"
    assert normalize_url("postgres://u@h/db") == "postgresql+psycopg://u@h/db"
    assert normalize_url("sqlite:///x.db") == "sqlite:///x.db"
    with pytest.raises(ValueError, match="unsupported backend"):
        MapStore("mysql://u@h/db", migrate=False)
    with pytest.raises(ValueError, match="url"):
        normalize_url("")


@pytest.mark.parametrize("bad", [0, -3])
def test_update_rejects_impossible_expected_versions_by_name(store: MapStore, bad: int) -> None:
    """Before: -3 reached ``replace(scene_map, version=-2)`` and raised a MapValidationError
    naming the map's ``version`` field, which the caller never set."""
    store.create(_small_map())
    with pytest.raises(ValueError, match="expected_version") as exc:
        store.update("office", _small_map(name="v2"), expected_version=bad)
    assert not isinstance(exc.value, MapValidationError)
    assert _count_versions(store, "office") == 1


def test_query_tables_mirror_the_migrated_schema(store: MapStore) -> None:
    """The Table declarations used for queries carry the migration's CHECK constraints."""
    from quadloc.maps.store import calibrations_table, maps_table

    inspector = sa.inspect(store.engine)
    for table in (maps_table, versions_table):
        migrated = {c["name"] for c in inspector.get_check_constraints(table.name)}
        declared = {c.name for c in table.constraints if isinstance(c, sa.CheckConstraint)}
        assert declared and declared == migrated, table.name
        assert {c["name"] for c in inspector.get_columns(table.name)} == set(table.c.keys())
    assert {c["name"] for c in inspector.get_columns(calibrations_table.name)} == set(
        calibrations_table.c.keys())
    fks = inspector.get_foreign_keys(calibrations_table.name)
    assert [(f["constrained_columns"], f["referred_table"]) for f in fks] == [
        (["map_id", "version"], "quadloc_map_versions")]


def test_calibration_is_stored_per_version_and_deleted_with_the_map(store: MapStore) -> None:
    from quadloc.maps.errors import MapNotFound

    store.create(_small_map())
    store.update("office", _small_map(shift=0.1), expected_version=1)
    assert store.calibration("office", 1) is None
    store.set_calibration("office", 1, {"k": 1.5})
    store.set_calibration("office", 1, {"k": 2.5})  # replaced
    assert store.calibration("office", 1) == {"k": 2.5}
    assert store.calibration("office", 2) is None  # each version its own
    with pytest.raises(MapNotFound):
        store.set_calibration("office", 3, {"k": 1.0})
    with pytest.raises(MapNotFound):
        store.set_calibration("nowhere", 1, {"k": 1.0})
    store.delete("office")
    with store.engine.connect() as conn:
        left = conn.execute(sa.text("SELECT count(*) FROM quadloc_map_calibrations")).scalar_one()
    assert left == 0
