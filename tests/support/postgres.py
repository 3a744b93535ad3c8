"""The test PostgreSQL server (127.0.0.1:5432, trust auth, user ``postgres``, database
``test``): whether it answers, throw-away schemas (each test's own ``search_path``, dropped
afterwards), and a build worker in a thread (the API on PostgreSQL only queues builds)."""

from __future__ import annotations

import asyncio
import threading
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import sqlalchemy as sa

from quadloc.service.app.context import App
from quadloc.service.settings import Settings

__all__ = ["PG_BASE", "pg_schema_url", "pg_unavailable_reason", "worker_thread"]

PG_BASE = "postgresql+psycopg://postgres@127.0.0.1:5432/test"

_state: dict[str, str | None] = {}


def pg_unavailable_reason() -> str | None:
    """None when the test server answers, else why not (a skip message); asked once."""
    if "reason" not in _state:
        try:
            import psycopg

            with psycopg.connect("host=127.0.0.1 port=5432 user=postgres dbname=test",
                                 connect_timeout=3) as conn:
                conn.execute("SELECT 1")
            _state["reason"] = None
        except Exception as exc:
            _state["reason"] = (f"PostgreSQL at 127.0.0.1:5432 (user postgres, db test) "
                                f"unreachable: {exc.__class__.__name__}: {exc}")
    return _state["reason"]


@contextmanager
def pg_schema_url(prefix: str = "quadloc_test") -> Iterator[str]:
    """The URL of a new, empty schema of the test database (its ``search_path``), dropped with
    everything in it on exit. Call :func:`pg_unavailable_reason` first."""
    schema = f"{prefix}_{uuid.uuid4().hex[:12]}"
    admin = sa.create_engine(PG_BASE)
    with admin.begin() as conn:
        conn.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
    try:
        yield f"{PG_BASE}?options=-csearch_path%3D{schema}"
    finally:
        with admin.begin() as conn:
            conn.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


@contextmanager
def worker_thread(url: str, **settings: object) -> Iterator[Any]:
    """A ``quadloc worker`` in a thread of this process (its own application on the database
    ``url``, as a worker process has), taking the queue's builds until exit; yields its
    application."""
    app = App.create(Settings(database_url=url, seed_demo_map=False,
                              **settings))  # type: ignore[arg-type]
    loop = asyncio.new_event_loop()
    task = loop.create_task(app.builds.run_worker(name="test-worker",
                                                  install_signal_handlers=False))

    def main() -> None:
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(task)
        except asyncio.CancelledError:
            pass
        finally:
            loop.close()

    thread = threading.Thread(target=main, name="test-worker", daemon=True)
    thread.start()
    try:
        yield app
    finally:
        loop.call_soon_threadsafe(task.cancel)
        thread.join(60)
        app.close()
