"""``quadloc worker``: run the map builds of the job queue (PostgreSQL) in this process, apart
from the API replicas (docs/deployment.md, "Build workers"). SIGTERM / SIGINT: no new job, the
running builds finish within ``QUADLOC_SHUTDOWN_GRACE_S`` - 2 s or are released (queued again
for another worker), then the process exits 0.

Health: ``GET /healthz`` on ``QUADLOC_HOST``:``QUADLOC_WORKER_HEALTH_PORT`` (0: none) answers
200 ``{"status": "ok", ...}`` while the worker runs and its database answers, else 503 (a
plain asyncio server: the worker serves nothing else).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys

from quadloc.service.app.context import App
from quadloc.service.cli.common import CliError, settings

__all__ = ["cmd_worker"]

log = logging.getLogger("quadloc.worker")


def cmd_worker(args: argparse.Namespace) -> int:
    config = settings(args)
    logging.basicConfig(level=config.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    app = App.create(config)
    try:
        if app.builds.queue is None:
            raise CliError("quadloc worker runs the builds of the job queue, which needs "
                           "PostgreSQL (QUADLOC_DATABASE_URL=postgresql://...); with "
                           f"{app.store.dialect} builds run in the API process (quadloc serve)")
        app.warm_up()
        port = config.worker_health_port if args.health_port is None else args.health_port
        asyncio.run(_work(app, config.host, port, args.name))
    finally:
        app.close()
    return 0


async def _work(app: App, host: str, port: int, name: str | None) -> None:
    worker = asyncio.create_task(app.builds.run_worker(name=name), name="worker")
    server = None
    if port:
        server = await asyncio.start_server(
            lambda r, w: _health(app, worker, r, w), host=host, port=port)
        print(f"quadloc worker: health on http://{host}:{port}/healthz", file=sys.stderr)
    try:
        await worker
    finally:
        if server is not None:
            server.close()
            await server.wait_closed()


async def _health(app: App, worker: asyncio.Task[None], reader: asyncio.StreamReader,
                  writer: asyncio.StreamWriter) -> None:
    """Answer one HTTP request: 200 on ``GET /healthz`` while the worker runs and the database
    answers, 503 otherwise; 404 for any other path."""
    try:
        line = (await asyncio.wait_for(reader.readline(), 5.0)).decode("latin-1").split()
        body: dict[str, object]
        if len(line) < 2 or line[0] != "GET" or line[1] != "/healthz":
            status, body = "404 Not Found", {"status": "not found"}
        else:
            checks = {"worker": "running" if not worker.done() else "stopped"}
            try:
                await asyncio.to_thread(app.store.ping)
                checks["database"] = "ok"
            except Exception:
                checks["database"] = "unavailable"
            ok = checks == {"worker": "running", "database": "ok"}
            status = "200 OK" if ok else "503 Service Unavailable"
            body = {"status": "ok" if ok else "unavailable", "checks": checks}
        data = json.dumps(body).encode()
        writer.write(f"HTTP/1.0 {status}\r\nContent-Type: application/json\r\n"
                     f"Content-Length: {len(data)}\r\nConnection: close\r\n\r\n".encode() + data)
        await writer.drain()
    except (TimeoutError, ConnectionError):
        pass
    finally:
        writer.close()
