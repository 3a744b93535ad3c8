"""Fixtures of the API tests: clients of apps on either store (SQLite file, PostgreSQL schema).

``store_clients`` is parametrized over both stores (the PostgreSQL case is marked ``postgres``
and skipped with the reason when the server at 127.0.0.1:5432 does not answer); it yields a
factory ``make(**settings) -> TestClient`` of apps sharing that one database (so that two apps
are two replicas of one deployment), each started and stopped by the fixture.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from quadloc.maps.store import MapStore
from quadloc.service.api.app import create_app
from quadloc.service.settings import Settings
from tests.maps.test_maps_store import PG_BASE, _pg_unavailable_reason

ClientFactory = Callable[..., TestClient]


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def store_clients(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ClientFactory]:
    """``make(**settings)``: a started TestClient (server exceptions answered as 500, as a
    real server would) of a new app on this test's database (see the module docstring)."""
    with ExitStack() as stack:
        if request.param == "sqlite":
            url = f"sqlite:///{tmp_path / 'quadloc.db'}"
        else:
            reason = _pg_unavailable_reason()
            if reason is not None:
                pytest.skip(reason)
            schema = f"quadloc_api_{uuid.uuid4().hex[:12]}"
            admin = sa.create_engine(PG_BASE)
            with admin.begin() as conn:
                conn.execute(sa.text(f'CREATE SCHEMA "{schema}"'))

            def drop() -> None:
                with admin.begin() as conn:
                    conn.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))
                admin.dispose()

            stack.callback(drop)
            url = f"{PG_BASE}?options=-csearch_path%3D{schema}"

        def make(**settings: Any) -> TestClient:
            store = MapStore(url)
            stack.callback(store.close)
            app = create_app(Settings(data_dir=tmp_path, **settings), store=store)
            return stack.enter_context(TestClient(app, raise_server_exceptions=False))

        yield make
