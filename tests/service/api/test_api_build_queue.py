"""The build job's life cycle on both stores (issue 29: builds leave the API process).

PostgreSQL (``QUADLOC_BUILD_RUNNER`` auto = queue): the API only queues the job (its row holds
the recording, procrastinate's ``procrastinate_jobs`` the task); a worker in this process
(``BuildService.run_worker``, ``wait=False``) runs it; a job whose worker stopped heartbeating
goes back to ``queued`` (then, after ``MAX_ATTEMPTS`` runs, ``runner_lost``); a released job
goes back to the queue; a job whose row was marked failed (cancelled) stops and stores nothing.
SQLite: builds stay in the API process (``test_api_build.py`` runs them), and a worker or the
queue are refused with the reason. Real worker processes: tests/e2e/test_build_workers.py.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

import quadloc.service.app.builds as builds_module
from quadloc.maps.building.build import BuildTimeoutError
from quadloc.maps.store import MapStore
from quadloc.service.api.app import create_app
from quadloc.service.app.job_queue import MAX_ATTEMPTS, JobReleased
from quadloc.service.cli.main import main as cli_main
from quadloc.service.settings import Settings
from tests.conftest import make_test_app
from tests.service.api.test_api_build import _recording
from tests.support.postgres import pg_schema_url, pg_unavailable_reason


@pytest.fixture
def pg_app(tmp_path: Path) -> Iterator[Any]:
    reason = pg_unavailable_reason()
    if reason is not None:
        pytest.skip(reason)
    with pg_schema_url("quadloc_queue") as url:
        app = create_app(Settings(data_dir=tmp_path, build_stale_after_s=5.0),
                         store=MapStore(url))
        try:
            yield app
        finally:
            app.state.services.close()


def _queue_rows(app: Any) -> list[dict[str, Any]]:
    with app.state.services.store.engine.connect() as conn:
        rows = conn.execute(sa.text(
            "SELECT id, status::text AS status, attempts, args FROM procrastinate_jobs "
            "WHERE task_name = 'quadloc.build' ORDER BY id")).mappings().all()
    return [dict(r) for r in rows]


def _drain(app: Any) -> None:
    """Run the queued jobs in this process until the queue is empty (a worker, wait=False)."""
    asyncio.run(app.state.services.builds.run_worker(name="test-worker", wait=False,
                                                     install_signal_handlers=False))


@pytest.mark.postgres
def test_the_api_queues_the_build_and_a_worker_runs_it(pg_app: Any) -> None:
    builds = pg_app.state.services.builds
    assert builds.queue is not None and builds.runner is None
    rec, _ = _recording()
    with TestClient(pg_app) as c:
        r = c.post("/v1/maps:build", params={"map_id": "room"}, json=rec)
        assert r.status_code == 202, r.text
        job_id = r.json()["job_id"]
        time.sleep(0.3)  # no runner in the API process: it stays queued
        queued = c.get(r.headers["Location"]).json()
        assert (queued["status"], queued["stage"], queued["percent"]) == ("queued", "queued", 0)
        assert builds.jobs.payload(job_id) is not None  # the recording, for any worker
        [task] = _queue_rows(pg_app)
        assert task["status"] == "todo" and task["args"] == {"job_id": job_id}
        _drain(pg_app)
        job = c.get(r.headers["Location"]).json()
        assert job["status"] == "succeeded", job
        assert (job["stage"], job["percent"], job["map_version"]) == ("done", 100.0, 1)
        assert job["objects_found"] == len(job["report"]["objects"]) > 0
        assert c.get("/v1/maps/room").json()["version"] == 1
        assert builds.jobs.payload(job_id) is None  # the input is dropped when the job ends
        assert _queue_rows(pg_app) == []  # procrastinate's row is deleted once succeeded


def _take_as_dead_worker(app: Any) -> int:
    """Fetch the next queued task as a worker whose last heartbeat was an hour ago (a worker
    that was killed while running it); its job row is marked running, as the build would."""
    with app.state.services.store.engine.begin() as conn:
        worker = conn.execute(sa.text(
            "INSERT INTO procrastinate_workers (last_heartbeat) VALUES (now() - interval "
            "'1 hour') RETURNING id")).scalar_one()
        task = conn.execute(sa.text("SELECT * FROM procrastinate_fetch_job_v2(:q, :w)"),
                            {"q": ["quadloc"], "w": worker}).mappings().one()
    assert task["id"] is not None
    job_id = task["args"]["job_id"]
    assert app.state.services.builds.jobs.progress(job_id, "refining", 60.0, 4)
    return int(task["id"])


def _recover(app: Any) -> int:
    """One search for stalled jobs, as every worker makes every heartbeat."""
    queue = app.state.services.builds.queue

    async def recover() -> int:
        async with queue.app.open_async():
            return int(await queue.recover_stalled_jobs())

    return asyncio.run(recover())


@pytest.mark.postgres
def test_a_job_whose_worker_died_is_queued_again_then_given_up(pg_app: Any) -> None:
    builds = pg_app.state.services.builds
    job_id = builds.start(_recording(6)[0], "room", None).job_id
    for attempt in range(MAX_ATTEMPTS):
        _take_as_dead_worker(pg_app)
        assert builds.jobs.get(job_id).status == "running"
        assert _recover(pg_app) == 1
        assert _recover(pg_app) == 0  # nothing more to recover: the job was handled once
        job = builds.jobs.get(job_id)
        [task] = _queue_rows(pg_app)
        if attempt < MAX_ATTEMPTS - 1:  # back in the queue, progress reset
            assert (job.status, job.stage, job.percent, job.objects_found) == (
                "queued", "queued", 0.0, 0)
            assert (task["status"], task["attempts"]) == ("todo", attempt + 1)
            assert builds.jobs.payload(job_id) is not None
        else:  # the last run: given up
            assert job.status == "failed" and job.error is not None
            assert job.error["reason"] == "runner_lost"
            assert str(MAX_ATTEMPTS) in job.error["detail"]
            assert task["status"] == "failed"
            assert builds.jobs.payload(job_id) is None


@pytest.mark.postgres
def test_an_unfinished_job_no_task_holds_is_given_up(pg_app: Any) -> None:
    """A row left running (its worker's final write failed) once silent for the window."""
    builds = pg_app.state.services.builds
    held = builds.start(_recording(6)[0], "held", None).job_id  # queued: its task holds it
    orphan = builds.jobs.create("orphan", None, payload="{}").job_id  # no task
    assert builds.jobs.progress(orphan, "refining", 60.0, 3)
    assert _recover(pg_app) == 0  # not silent yet
    with pg_app.state.services.store.engine.begin() as conn:
        conn.execute(sa.text("UPDATE quadloc_build_jobs SET updated_at = updated_at - "
                             "interval '1 hour'"))
    assert _recover(pg_app) == 1
    job = builds.jobs.get(orphan)
    assert job.status == "failed" and job.error is not None
    assert job.error["reason"] == "runner_lost"
    assert builds.jobs.get(held).status == "queued"  # waiting in the queue: left alone


@pytest.mark.postgres
def test_a_released_build_goes_back_to_the_queue_and_runs_again(pg_app: Any) -> None:
    builds = pg_app.state.services.builds
    job_id = builds.start(_recording()[0], "room", None).job_id
    stop = threading.Event()
    stop.set()  # the worker is stopping: the build stops at its first deadline check
    with pytest.raises(JobReleased):
        builds.kind.run(job_id, stop)
    assert "room" not in {m.map_id for m in pg_app.state.services.store.list()}  # nothing stored
    builds.kind.requeued(job_id)
    job = builds.jobs.get(job_id)
    assert (job.status, job.stage, job.percent) == ("queued", "queued", 0.0)
    _drain(pg_app)  # the queue's task was never taken: it runs now
    assert builds.jobs.get(job_id).status == "succeeded"


@pytest.mark.postgres
@pytest.mark.parametrize("attempts", [0, MAX_ATTEMPTS - 1])
def test_a_build_released_on_its_last_run_is_given_up(pg_app: Any, attempts: int) -> None:
    """The queue's task itself (what a worker calls), asked to abort on its first run and on
    its last one (:data:`MAX_ATTEMPTS` runs in all)."""
    builds = pg_app.state.services.builds
    job_id = builds.start(_recording()[0], "room", None).job_id
    task = builds.queue.app.tasks["quadloc.build"]
    context = SimpleNamespace(job=SimpleNamespace(attempts=attempts), should_abort=lambda: True)
    with pytest.raises(JobReleased):
        task.func(context, job_id=job_id)
    job = builds.jobs.get(job_id)
    if attempts == 0:
        assert job.status == "queued"
    else:
        assert job.status == "failed" and job.error is not None
        assert job.error["reason"] == "runner_lost"
    assert "room" not in {m.map_id for m in pg_app.state.services.store.list()}


class _ProgressUntilReleased:
    """Stands in for ``build_map``: reports progress until the test releases it, then fails
    the build cleanly (no map)."""

    def __init__(self) -> None:
        self.started = threading.Event()
        self.release = threading.Event()

    def __call__(self, recording: Any, *, map_id: str, progress: Any, deadline: Any) -> Any:
        self.started.set()
        while not self.release.wait(0.01):
            progress("associating", 10.0, 0)
        raise BuildTimeoutError("released by the test")


@pytest.mark.postgres
def test_a_cancelled_job_stops_on_its_worker_and_stores_nothing(
        pg_app: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    fake = _ProgressUntilReleased()
    monkeypatch.setattr(builds_module, "build_map", fake)
    monkeypatch.setattr(builds_module, "HEARTBEAT_S", 0.0)
    builds = pg_app.state.services.builds
    first = builds.start(_recording(6)[0], "one", None).job_id
    worker = threading.Thread(target=_drain, args=(pg_app,))
    worker.start()
    try:
        assert fake.started.wait(30)
        assert builds.jobs.fail(first, "cancelled", "cancelled by the test")  # the row only
        worker.join(30)
        assert not worker.is_alive()  # the build stopped at its next progress report
    finally:
        fake.release.set()
        worker.join(30)
    job = builds.jobs.get(first)
    assert job.status == "failed" and job.error == {"reason": "cancelled",
                                                    "detail": "cancelled by the test"}
    assert "one" not in {m.map_id for m in pg_app.state.services.store.list()}
    assert _queue_rows(pg_app) == []  # the task ended (as succeeded: nothing to retry)


def test_sqlite_builds_in_process_and_refuses_the_queue(tmp_path: Path) -> None:
    app = make_test_app(tmp_path)
    builds = app.state.services.builds
    assert builds.runner is not None and builds.queue is None
    with pytest.raises(ValueError, match="a worker needs the job queue"):
        asyncio.run(builds.run_worker(wait=False))
    app.state.services.close()
    with pytest.raises(ValueError, match="QUADLOC_BUILD_RUNNER=queue needs PostgreSQL"):
        make_test_app(tmp_path / "queue", build_runner="queue")


def test_the_worker_command_refuses_sqlite_with_the_reason(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("QUADLOC_DATA_DIR", str(tmp_path))
    status = cli_main(["worker", "--database-url", f"sqlite:///{tmp_path / 'q.db'}",
                       "--health-port", "0"])
    assert status == 2
    err = capsys.readouterr().err
    assert "needs PostgreSQL" in err and "quadloc serve" in err


@pytest.mark.postgres
def test_the_queue_holds_at_most_max_active_build_jobs(tmp_path: Path) -> None:
    reason = pg_unavailable_reason()
    if reason is not None:
        pytest.skip(reason)
    rec = _recording(6)[0]
    with pg_schema_url("quadloc_queue") as url:
        app = create_app(Settings(data_dir=tmp_path, max_active_build_jobs=1),
                         store=MapStore(url))
        with TestClient(app) as c:
            assert c.post("/v1/maps:build", params={"map_id": "one"}, json=rec).status_code == 202
            full = c.post("/v1/maps:build", params={"map_id": "two"}, json=rec)
            assert full.status_code == 503 and full.json()["type"].endswith("busy")
            assert int(full.headers["Retry-After"]) == builds_module.BUSY_RETRY_AFTER_S
            builds = app.state.services.builds
            assert builds.jobs.count_active() == 1 and len(_queue_rows(app)) == 1  # no row
            _drain(app)  # the worker ends the first: room again
            assert c.post("/v1/maps:build", params={"map_id": "two"}, json=rec).status_code == 202
