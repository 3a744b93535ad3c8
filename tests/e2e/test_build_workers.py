"""Builds leave the API process (issue 29): the API (``quadloc serve``) and two ``quadloc
worker`` processes on loopback, over one PostgreSQL schema, as docker-compose.yml runs them.

One run checks, with the shipped 300-frame recording (docs/examples/room_recording.json.gz,
about 4 s a build here): two builds submitted together run on the two workers at once; a
worker killed (SIGKILL) in the middle of its build loses nothing: the API shows the job
``running`` -> ``queued`` (the other worker found it stalled) -> ``running`` -> ``succeeded``
on the other worker; a worker stopped by SIGTERM past its grace period releases its build,
which the other worker completes, and exits 0; a job cancelled through its row stops on its
worker and stores nothing; the workers' ``/healthz``. Skipped with the reason when PostgreSQL
does not answer.
"""

from __future__ import annotations

import gzip
import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
import sqlalchemy as sa

from quadloc.maps.building.jobs import JobStore
from tests.conftest import REPO_ROOT, _free_port, run_live_server
from tests.support.postgres import pg_schema_url, pg_unavailable_reason

pytestmark = [pytest.mark.postgres, pytest.mark.slow]

RECORDING = json.loads(gzip.decompress(
    (REPO_ROOT / "docs" / "examples" / "room_recording.json.gz").read_bytes()))
#: Liveness window of the workers (the smallest the settings allow): a killed worker's job is
#: found stalled this long after its last heartbeat.
STALE_AFTER_S = "5"
#: SIGTERM grace: 3 s - 2 s of margin = 1 s for the running build to finish, then released.
SHUTDOWN_GRACE_S = "3"


@contextmanager
def _worker(name: str, url: str, logs: Path) -> Iterator[tuple[subprocess.Popen[bytes], Path]]:
    """A ``quadloc worker`` process until exit (killed if still running); its log file."""
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    env.update({"QUADLOC_DATABASE_URL": url, "QUADLOC_DATA_DIR": str(logs),
                "QUADLOC_BUILD_STALE_AFTER_S": STALE_AFTER_S,
                "QUADLOC_SHUTDOWN_GRACE_S": SHUTDOWN_GRACE_S, "QUADLOC_LOG_LEVEL": "info",
                "PYTHONPATH": str(REPO_ROOT)})
    log_path = logs / f"{name}.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "quadloc.service", "worker", "--name", name,
             "--health-port", str(port)], cwd=REPO_ROOT, env=env, stdout=log,
            stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60
        while True:
            assert proc.poll() is None, log_path.read_text()[-3000:]
            try:
                health = httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1.0)
                if health.status_code == 200:
                    assert health.json() == {"status": "ok", "checks": {
                        "worker": "running", "database": "ok"}}
                    break
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline, log_path.read_text()[-3000:]
            time.sleep(0.1)
        yield proc, log_path
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)


def _runs_on(job_id: str, workers: dict[str, tuple[subprocess.Popen[bytes], Path]]) -> list[str]:
    """The workers whose log says they started the job (in the order of the dict)."""
    pattern = re.compile(rf"Starting job quadloc\.build\[\d+\]\(job_id='{job_id}'\)")
    return [name for name, (_, log) in workers.items() if pattern.search(log.read_text())]


def _follow(api: httpx.Client, job_id: str, timeout_s: float = 120.0) -> list[dict[str, Any]]:
    """Poll the job until it ends; every answer (each a 200)."""
    seen = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        r = api.get(f"/v1/build-jobs/{job_id}")
        assert r.status_code == 200, r.text
        seen.append(r.json())
        if seen[-1]["status"] in ("succeeded", "failed"):
            return seen
        time.sleep(0.1)
    raise AssertionError(f"job {job_id} did not end in {timeout_s} s: {seen[-1]}")


def _wait_running(api: httpx.Client, job_id: str) -> None:
    t0 = time.monotonic()
    while api.get(f"/v1/build-jobs/{job_id}").json()["status"] != "running":
        assert time.monotonic() - t0 < 60, f"job {job_id} never ran"
        time.sleep(0.05)


def _statuses(seen: list[dict[str, Any]]) -> list[str]:
    """The successive distinct statuses of a job."""
    out: list[str] = []
    for job in seen:
        if not out or out[-1] != job["status"]:
            out.append(job["status"])
    return out


def test_two_workers_share_the_builds_and_lose_none(tmp_path: Path) -> None:
    reason = pg_unavailable_reason()
    if reason is not None:
        pytest.skip(reason)
    with ExitStack() as stack:
        url = stack.enter_context(pg_schema_url("quadloc_workers"))
        base = stack.enter_context(run_live_server(
            tmp_path / "api", {"QUADLOC_DATABASE_URL": url,
                               "QUADLOC_BUILD_STALE_AFTER_S": STALE_AFTER_S}))
        api = stack.enter_context(httpx.Client(base_url=base, timeout=30))
        workers = {name: stack.enter_context(_worker(name, url, tmp_path))
                   for name in ("worker-a", "worker-b")}

        def build(map_id: str) -> str:
            r = api.post("/v1/maps:build", params={"map_id": map_id}, json=RECORDING)
            assert r.status_code == 202, r.text
            assert r.json()["status"] == "queued"
            return str(r.json()["job_id"])

        # two builds at once: one on each worker (each takes one job at a time)
        first, second = build("room-1"), build("room-2")
        for job_id in (first, second):
            _wait_running(api, job_id)
        assert sorted(_runs_on(first, workers) + _runs_on(second, workers)) == sorted(workers)

        # the worker of the first build is killed in the middle of it
        [victim] = _runs_on(first, workers)
        [survivor] = [name for name in workers if name != victim]
        assert api.get(f"/v1/build-jobs/{first}").json()["percent"] < 95.0
        workers[victim][0].send_signal(signal.SIGKILL)
        seen = _follow(api, first)
        assert seen[-1]["status"] == "succeeded", seen[-1]
        statuses = _statuses(seen)
        assert statuses[0] == "running" and statuses[-1] == "succeeded", statuses
        assert set(statuses) <= {"running", "queued", "succeeded"}, statuses
        # put back in the queue by the survivor's search for stalled jobs; the row stays
        # `queued` only until a worker takes the job, too short for a poll to see it when the
        # survivor is idle
        assert re.search(rf"job {first} \(quadloc\.build\): its worker stopped reporting; "
                         "queued again", workers[survivor][1].read_text())
        assert _runs_on(first, workers) == sorted([victim, survivor])  # both started it
        assert _follow(api, second)[-1]["status"] == "succeeded"
        for map_id in ("room-1", "room-2"):
            assert api.get(f"/v1/maps/{map_id}").json()["version"] == 1
        done = api.get(f"/v1/build-jobs/{first}").json()
        assert done["map_version"] == 1 and done["objects_found"] == len(
            done["report"]["objects"]) > 0

        # a third worker; a worker stopped by SIGTERM releases its build to the other one
        workers["worker-c"] = stack.enter_context(_worker("worker-c", url, tmp_path))
        third = build("room-3")
        _wait_running(api, third)
        [stopping] = _runs_on(third, workers)
        proc = workers[stopping][0]
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 0  # finished or released within its grace, then exited
        seen = _follow(api, third)
        assert seen[-1]["status"] == "succeeded", seen[-1]
        # released (a 4 s build does not finish within the 1 s grace: back to the queue, the
        # row queued), then run again by the other worker
        assert re.search(rf"job_id='{third}'\) ended with status: .*to retry",
                         workers[stopping][1].read_text())
        assert len(_runs_on(third, workers)) == 2

        # cancel: the job's row marked failed while it runs stops it on its worker
        fourth = build("room-4")
        _wait_running(api, fourth)
        jobs = JobStore(sa.create_engine(url))
        try:
            assert jobs.fail(fourth, "cancelled", "cancelled by the test")
        finally:
            jobs.engine.dispose()
        end = _follow(api, fourth)[-1]
        assert end["status"] == "failed" and end["error"]["reason"] == "cancelled"
        time.sleep(2.0)  # the worker stops at its next progress report; nothing is stored
        assert api.get("/v1/maps/room-4").status_code == 404
        # the remaining worker goes on: one more build succeeds
        assert _follow(api, build("room-5"))[-1]["status"] == "succeeded"
