"""The job queue: background work of the application (map builds today; a job kind + the id of
its row, so that another kind, e.g. calibration, can be added by registering it) run away from
the request that started it.

* PostgreSQL: :class:`ProcrastinateQueue`, procrastinate (docs/deployment.md, "Build workers":
  why this one) over the store's own database. The API defers a job (one row in
  ``procrastinate_jobs``, a ``NOTIFY``); ``quadloc worker`` processes, scaled apart from the
  API replicas, take jobs with procrastinate's own locking (``SELECT ... FOR UPDATE SKIP
  LOCKED``), run them, and heartbeat as workers (``procrastinate_workers``). A job of a worker
  that stopped heartbeating (killed, its machine gone) is a *stalled* job: every heartbeat a
  worker (one at a time: an advisory lock) looks for them and puts them back in the queue
  (procrastinate's ``get_stalled_jobs`` + ``retry_job``), at most :data:`MAX_ATTEMPTS` runs in
  all, then the kind's ``lost``. SIGTERM:
  the worker takes no new job, lets the running ones finish for the grace period, then asks them
  to stop: a job that stops unfinished raises :class:`JobReleased` and goes back to the queue.
* SQLite (the embedded default, ``make serve``): no queue tables, the jobs run in the API
  process, in the application's own runner (``quadloc.service.app.builds.BuildRunner``); it is
  one process, not several replicas.

A kind (:class:`JobKind`) owns its rows: ``run`` ends the job (succeeded / failed) or raises
:class:`JobReleased`; ``requeued`` is told that the job runs again (its row back to
``queued``); ``lost`` that it never will (its row ``failed``).
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Iterable
from typing import Any, Protocol

import procrastinate
import sqlalchemy as sa

__all__ = ["MAX_ATTEMPTS", "QUEUE", "JobKind", "JobReleased", "ProcrastinateQueue",
           "conninfo"]

log = logging.getLogger("quadloc.worker")

#: The procrastinate queue of QuadLoc's jobs.
QUEUE = "quadloc"
#: Runs of one job in all (the first and the retries after a worker died or stopped).
MAX_ATTEMPTS = 3


class JobReleased(RuntimeError):  # noqa: N818 (not an error: the job goes back to the queue)
    """Raised by :meth:`JobKind.run` when it stopped before the end because its worker is
    stopping: nothing was stored and the job is to run again."""


class JobKind(Protocol):
    """A kind of job (module docstring)."""

    #: The kind's name (the task ``quadloc.<name>``).
    name: str

    def run(self, job_id: str, stop: threading.Event) -> None:
        """Run the job of row ``job_id`` to its end; ``stop`` is set when the worker stops:
        then end soon, raising :class:`JobReleased` if unfinished."""

    def requeued(self, job_id: str) -> None:
        """The job is back in the queue (its worker stopped or died)."""

    def lost(self, job_id: str, detail: str) -> None:
        """The job will not run again (:data:`MAX_ATTEMPTS` runs, each stopped; or no task
        of the queue holds it)."""

    def silent(self, stale_after_s: float) -> list[str]:
        """Ids of the kind's unfinished jobs whose rows were not written for that long."""


def conninfo(database_url: str) -> str:
    """The libpq connection string of a SQLAlchemy PostgreSQL URL (``postgresql+psycopg://``
    -> ``postgresql://``), password included."""
    url = sa.engine.make_url(database_url)
    return url.set(drivername="postgresql").render_as_string(hide_password=False)


class ProcrastinateQueue:
    """The job queue over PostgreSQL (module docstring).

    Args:
        database_url: the store's URL (``postgresql://`` or ``postgresql+psycopg://``).
        kinds: the job kinds this process runs (a process that only defers needs none).
        heartbeat_s: interval of a worker's heartbeat and of its search for stalled jobs (s).
        stalled_after_s: a worker whose heartbeat is this old is gone: its jobs are retried.
        shutdown_grace_s: on SIGTERM, how long running jobs may go on before they are asked to
            stop (and then released).
    """

    def __init__(self, database_url: str, kinds: Iterable[JobKind] = (), *,
                 heartbeat_s: float = 5.0, stalled_after_s: float = 30.0,
                 shutdown_grace_s: float = 28.0, concurrency: int = 1) -> None:
        self.kinds = {kind.name: kind for kind in kinds}
        self.heartbeat_s = float(heartbeat_s)
        self.stalled_after_s = float(stalled_after_s)
        self.shutdown_grace_s = float(shutdown_grace_s)
        self.concurrency = int(concurrency)
        # connections: the jobs' own, plus the worker's listener, heartbeat and fetches
        self.app = procrastinate.App(connector=procrastinate.PsycopgConnector(
            conninfo=conninfo(database_url), min_size=1, max_size=self.concurrency + 3))
        self._opened = False
        self._lock = threading.Lock()
        for kind in self.kinds.values():
            self._register(kind)

    @staticmethod
    def task_name(kind: str) -> str:
        return f"quadloc.{kind}"

    def _register(self, kind: JobKind) -> None:
        def run(context: procrastinate.JobContext, job_id: str) -> None:
            try:
                kind.run(job_id, _AbortEvent(context))
            except JobReleased:  # procrastinate retries it, unless this was the last run
                if _last_run(context.job):
                    kind.lost(job_id, _LOST_DETAIL)
                else:
                    kind.requeued(job_id)
                raise

        self.app.task(name=self.task_name(kind.name), queue=QUEUE, pass_context=True,
                      retry=procrastinate.RetryStrategy(max_attempts=MAX_ATTEMPTS - 1,
                                                        retry_exceptions={JobReleased}))(run)

    # ------------------------------------------------------------------ the API side
    def defer(self, kind: str, job_id: str) -> None:
        """Queue the job ``job_id`` of ``kind`` (a row in ``procrastinate_jobs`` + NOTIFY);
        :class:`procrastinate.exceptions.ConnectorException` when the database refuses."""
        with self._lock:
            if not self._opened:
                self.app.open()
                self._opened = True
        self.app.configure_task(self.task_name(kind), queue=QUEUE).defer(job_id=job_id)

    def close(self) -> None:
        with self._lock:
            if self._opened:
                self.app.close()
                self._opened = False

    # ------------------------------------------------------------------ the worker side
    async def run_worker_async(self, *, name: str | None = None, wait: bool = True,
                               install_signal_handlers: bool = True) -> None:
        """Take and run up to ``concurrency`` jobs at once (threads) until SIGTERM / SIGINT
        (then as the module docstring says); ``wait`` False: until the queue is empty."""
        async with self.app.open_async():
            recovery = asyncio.create_task(self._recover_stalled_jobs(), name="stalled jobs")
            try:
                await self.app.run_worker_async(
                    queues=[QUEUE], concurrency=self.concurrency, name=name or "quadloc-worker",
                    update_heartbeat_interval=self.heartbeat_s,
                    stalled_worker_timeout=self.stalled_after_s,
                    shutdown_graceful_timeout=self.shutdown_grace_s,
                    fetch_job_polling_interval=self.heartbeat_s,
                    abort_job_polling_interval=self.heartbeat_s,
                    install_signal_handlers=install_signal_handlers, wait=wait,
                    delete_jobs="successful")
            finally:
                recovery.cancel()
                await asyncio.gather(recovery, return_exceptions=True)
        with self._lock:  # opening the async pool closed the connector of defer: reopen it
            self._opened = False

    async def _recover_stalled_jobs(self) -> None:
        """Every heartbeat: the jobs of workers silent for ``stalled_after_s`` back to the
        queue (or lost after :data:`MAX_ATTEMPTS` runs), and the orphaned rows ended
        (:meth:`recover_stalled_jobs`)."""
        while True:
            await asyncio.sleep(self.heartbeat_s)
            try:
                await self.recover_stalled_jobs()
            except Exception as exc:  # e.g. the database is away: the next beat retries
                log.warning("stalled jobs not checked (%s: %s)", type(exc).__name__, exc)

    async def recover_stalled_jobs(self) -> int:
        """One search for stalled jobs (see :meth:`_recover_stalled_jobs`); how many were put
        back in the queue or given up. One worker at a time searches (a PostgreSQL advisory
        lock; the others skip that beat): a job put back and taken again by a live worker is
        never taken for stalled by a search that read it before."""
        manager = self.app.job_manager
        done = 0
        async with self.app.connector.pool.connection() as conn:  # type: ignore[attr-defined]
            locked = await conn.execute("SELECT pg_try_advisory_lock(%s)", (_RECOVERY_LOCK,))
            if not (await locked.fetchone())[0]:
                return 0
            try:
                for job in await manager.get_stalled_jobs(
                        seconds_since_heartbeat=self.stalled_after_s):
                    kind = self.kinds.get(job.task_name.removeprefix("quadloc."))
                    job_id = str(job.task_kwargs.get("job_id", ""))
                    if kind is None or job.id is None:
                        continue
                    if _last_run(job):
                        await manager.finish_job_by_id_async(
                            job.id, procrastinate.jobs.Status.FAILED, delete_job=False)
                        await asyncio.to_thread(kind.lost, job_id, _LOST_DETAIL)
                    else:
                        # the row first: once retried, a live worker may take the job and mark
                        # it running at once, which a later `queued` would overwrite
                        await asyncio.to_thread(kind.requeued, job_id)
                        await manager.retry_job(job)
                    log.warning("job %s (%s): its worker stopped reporting; %s", job_id,
                                job.task_name, "given up" if _last_run(job) else "queued again")
                    done += 1
                done += await self._fail_orphans(conn)
            finally:
                await conn.execute("SELECT pg_advisory_unlock(%s)", (_RECOVERY_LOCK,))
        return done


    async def _fail_orphans(self, conn: Any) -> int:
        """The unfinished jobs (rows) silent for ``stalled_after_s`` that no task of the queue
        holds (``todo`` / ``doing``) end as lost: e.g. a worker's database write that failed
        when it ended its job, or a row whose task could not be queued. How many."""
        done = 0
        for name, kind in self.kinds.items():
            silent = await asyncio.to_thread(kind.silent, self.stalled_after_s)
            if not silent:
                continue
            cursor = await conn.execute(
                "SELECT args->>'job_id' FROM procrastinate_jobs WHERE task_name = %s AND "
                "status IN ('todo', 'doing') AND args->>'job_id' = ANY(%s)",
                (self.task_name(name), silent))
            held = {row[0] for row in await cursor.fetchall()}
            for job_id in sorted(set(silent) - held):
                await asyncio.to_thread(kind.lost, job_id, _ORPHAN_DETAIL)
                log.warning("job %s (%s): no task of the queue holds it; given up", job_id,
                            self.task_name(name))
                done += 1
        return done


#: Key of the advisory lock of the search for stalled jobs (any constant 64-bit integer).
_RECOVERY_LOCK = 0x51_4C_4F_43_4A_4F_42  # "QLOCJOB"
_LOST_DETAIL = (f"the job was run {MAX_ATTEMPTS} times and each time its worker stopped "
                "before the end (killed, or its machine gone); submit the recording again")


_ORPHAN_DETAIL = ("the job was left unfinished and no worker holds it (a database write "
                  "failed when it ended); submit the recording again")


def _last_run(job: procrastinate.jobs.Job) -> bool:
    """Whether this run of ``job`` is its last (:data:`MAX_ATTEMPTS` in all)."""
    return job.attempts + 1 >= MAX_ATTEMPTS


class _AbortEvent(threading.Event):
    """The stop event handed to a job: set as soon as it is read while procrastinate asks the
    job to abort (the worker's shutdown past its grace period)."""

    def __init__(self, context: procrastinate.JobContext) -> None:
        super().__init__()
        self._context = context

    def is_set(self) -> bool:
        if not super().is_set() and self._context.should_abort():
            self.set()
        return super().is_set()
