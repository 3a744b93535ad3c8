"""Shared fixtures: a real Uvicorn server on a free loopback port with a temporary SQLite DB.

``live_server`` (module scope) yields the base URL (``http://127.0.0.1:<port>``) of an open
server (no API keys) with the demo Chess map seeded as ``chess``. ``live_server_factory``
(function scope) starts servers with extra ``QUADLOC_*`` environment variables, e.g.
``live_server_factory({"QUADLOC_API_KEYS": "<sha256>:read"})``; they are stopped at teardown.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile the solvers' numeric kernels (or load them from numba's cache) once, before any
    test, as a server does at start (``App.warm_up``): on a fresh checkout the compilation
    (~13 s) would otherwise land inside the time budget of whichever test localizes first."""
    from quadloc.service.app.context import App

    App.warm_up()


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def run_live_server(data_dir: Path, env: dict[str, str] | None = None,
                    startup_timeout_s: float = 60.0,
                    on_start: Callable[[subprocess.Popen[bytes]], None] | None = None
                    ) -> Iterator[str]:
    """Run ``quadloc serve`` (``python -m quadloc.service serve``: Uvicorn with the connection
    limits of service/api/server.py) on a free loopback port (log level warning unless ``env``
    says).

    The database is ``sqlite:///<data_dir>/quadloc.db`` unless ``env`` sets
    ``QUADLOC_DATABASE_URL``. Yields the base URL; terminates the process on exit.
    ``on_start`` receives the process (e.g. to signal it).
    """
    data_dir.mkdir(parents=True, exist_ok=True)
    port = _free_port()
    full_env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    full_env.update({"QUADLOC_DATA_DIR": str(data_dir),
                     "QUADLOC_DATABASE_URL": f"sqlite:///{data_dir / 'quadloc.db'}",
                     "QUADLOC_LOG_LEVEL": "warning", "PYTHONPATH": str(REPO_ROOT)})
    full_env.update(env or {})
    log_path = data_dir / f"uvicorn-{port}.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "quadloc.service", "serve", "--host", "127.0.0.1", "--port",
             str(port)],
            cwd=REPO_ROOT, env=full_env, stdout=log, stderr=subprocess.STDOUT)
    if on_start is not None:
        on_start(proc)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + startup_timeout_s
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"uvicorn exited with {proc.returncode}:\n"
                                   f"{log_path.read_text()[-3000:]}")
            try:
                if httpx.get(f"{base}/healthz", timeout=1.0).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"uvicorn did not start in {startup_timeout_s} s:\n"
                                   f"{log_path.read_text()[-3000:]}")
            time.sleep(0.1)
        yield base
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:  # pragma: no cover
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def live_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """Base URL of a real open Uvicorn server (temp SQLite, demo map ``chess``)."""
    with run_live_server(tmp_path_factory.mktemp("live_server")) as base:
        yield base


@pytest.fixture
def live_server_factory(tmp_path: Path) -> Iterator[Callable[..., str]]:
    """Start servers with extra ``QUADLOC_*`` env vars: ``live_server_factory(env) -> URL``."""
    stack: list = []

    def start(env: dict[str, str] | None = None) -> str:
        cm = run_live_server(tmp_path / f"server{len(stack)}", env)
        base = cm.__enter__()
        stack.append(cm)
        return base

    yield start
    for cm in reversed(stack):
        cm.__exit__(None, None, None)


def make_test_app(data_dir: Path, **settings: object) -> Any:
    """An in-process app on a temp SQLite DB (demo map seeded) for TestClient tests."""
    from quadloc.service.api.app import create_app
    from quadloc.service.settings import Settings

    return create_app(Settings(data_dir=data_dir,
                               database_url=f"sqlite:///{data_dir / 'quadloc.db'}",
                               **settings))  # type: ignore[arg-type]
