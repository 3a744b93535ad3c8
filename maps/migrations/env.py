"""Alembic environment of the map store (``maps/migrations``).

Run programmatically by :meth:`quadloc.maps.store.MapStore.migrate`, which passes an open connection
in ``config.attributes["connection"]``. From a shell: ``alembic -c maps/migrations/alembic.ini
-x url=sqlite:///quadloc.db upgrade head``.
"""

from __future__ import annotations

from alembic import context
from sqlalchemy import Connection, create_engine

from quadloc.maps.store import normalize_url

VERSION_TABLE = "quadloc_alembic_version"

config = context.config


def _run(connection: Connection) -> None:
    context.configure(connection=connection, target_metadata=None,
                      version_table=VERSION_TABLE, render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()


def _url() -> str | None:
    """``-x url=...`` on the command line, else ``sqlalchemy.url`` of the ini file."""
    return context.get_x_argument(as_dictionary=True).get("url") or config.get_main_option(
        "sqlalchemy.url")


def run_migrations_offline() -> None:
    context.configure(url=_url(), literal_binds=True, version_table=VERSION_TABLE)
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _run(connection)
        return
    engine = create_engine(normalize_url(_url()))
    try:
        with engine.begin() as conn:
            _run(conn)
    finally:
        engine.dispose()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
