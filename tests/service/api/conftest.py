"""Fixtures of the API tests: clients of apps on either store (SQLite file, PostgreSQL schema).

``store_clients`` is parametrized over both stores (the PostgreSQL case is marked ``postgres``
and skipped with the reason when the server at 127.0.0.1:5432 does not answer); it yields a
factory ``make(**settings) -> TestClient`` of apps sharing that one database (so that two apps
are two replicas of one deployment), each started and stopped by the fixture. On PostgreSQL a
build worker runs in a thread (the API only queues builds there).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from quadloc.maps.store import MapStore
from quadloc.service.api.app import create_app
from quadloc.service.settings import Settings
from tests.support.postgres import pg_schema_url, pg_unavailable_reason, worker_thread

ClientFactory = Callable[..., TestClient]


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def store_clients(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ClientFactory]:
    """``make(**settings)``: a started TestClient (server exceptions answered as 500, as a
    real server would) of a new app on this test's database (see the module docstring)."""
    with ExitStack() as stack:
        if request.param == "sqlite":
            url = f"sqlite:///{tmp_path / 'quadloc.db'}"
        else:
            reason = pg_unavailable_reason()
            if reason is not None:
                pytest.skip(reason)
            url = stack.enter_context(pg_schema_url("quadloc_api"))
            # the API queues the builds: a worker runs them (as in a deployment)
            stack.enter_context(worker_thread(url, build_stale_after_s=5.0))

        def make(**settings: Any) -> TestClient:
            store = MapStore(url)
            stack.callback(store.close)
            app = create_app(Settings(data_dir=tmp_path, **settings), store=store)
            return stack.enter_context(TestClient(app, raise_server_exceptions=False))

        yield make
