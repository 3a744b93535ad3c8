"""The map-building use cases: start a build job from a recording, follow it, run it (in a
``quadloc worker`` or in this process), and build in this process without a job (the CLI
without a server).

A job is a row of the map store's database (``quadloc.maps.building.jobs.JobStore``):
``queued`` -> ``running`` -> ``succeeded`` | ``failed``, holding its recording until it ends.
:class:`BuildJobs` runs one job from its row (the job kind ``build`` of
:mod:`quadloc.service.app.job_queue`); where it runs is ``QUADLOC_BUILD_RUNNER``:

* ``queue`` (the default on PostgreSQL): the API only queues the job
  (:class:`~quadloc.service.app.job_queue.ProcrastinateQueue`); ``quadloc worker`` processes run
  it (:meth:`BuildService.run_worker`). A worker that dies loses nothing: its job goes back to
  ``queued`` and runs again on another worker (at most ``MAX_ATTEMPTS`` runs, then
  ``runner_lost``). A worker stopped by SIGTERM finishes its build within the grace period or
  releases it (back to ``queued``).
* ``in-process`` (the default on SQLite, ``make serve``): one :class:`BuildRunner` per process
  runs at most ``max_concurrent_builds`` builds (threads) and queues ``max_queued_builds``
  more (beyond: ``busy``, retry after 10 s). While it has jobs, the runner's own heartbeat
  thread refreshes their rows every :func:`beat_interval_s` whatever the builds report, so a
  stage that runs longer than ``build_stale_after_s`` without progress is not taken for a lost
  runner; a job whose process stopped is marked ``runner_lost`` by the next sweep. One process,
  not several replicas.

Each build has a time budget and its recording size limits (``QUADLOC_BUILD_TIME_BUDGET_S``,
``QUADLOC_MAX_BUILD_*``; unset: the runner's defaults, small in-process, building-scale in the
workers: ``quadloc.service.settings.BUILD_LIMIT_DEFAULTS``). A job ends ``succeeded`` (a new map or
version) or ``failed`` with a reason: ``time_budget_exceeded``, ``invalid_map``,
``no_objects``, ``version_conflict``, ``map_exists``, ``map_not_found``, ``store_unavailable``,
``busy``, ``runner_lost``, ``internal_error``. A job whose row was marked failed meanwhile
stops at its next progress report and stores nothing. A job's steps:
docs/design/service.md#map-building-jobs.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Literal

from procrastinate.exceptions import ConnectorException
from pydantic import TypeAdapter, ValidationError
from sqlalchemy.exc import SQLAlchemyError

from quadloc.factors.budget import Deadline
from quadloc.maps.building.build import BuildTimeoutError, build_map
from quadloc.maps.building.jobs import BuildJob, JobNotFoundError, JobStore
from quadloc.maps.building.recording import BuildLimits, Recording
from quadloc.maps.building.report import BuildReport
from quadloc.maps.errors import MapAlreadyExists, MapNotFound, StoreUnavailable, VersionConflict
from quadloc.maps.model import MapValidationError, SceneMap
from quadloc.maps.store import MapStore, StoredMap
from quadloc.service.app.conversions import RecordingInputError, recording_from_wire
from quadloc.service.app.errors import AppError
from quadloc.service.app.job_queue import JobReleased, ProcrastinateQueue
from quadloc.service.app.maps import MapService, parse_if_match
from quadloc.service.app.ownership import INTERNAL, Caller
from quadloc.service.schemas.builds import BuildErrorOut, BuildJobOut
from quadloc.service.schemas.common import field_path
from quadloc.service.schemas.recording import LegacyRecordingIn, RecordingBody, RecordingIn
from quadloc.service.settings import SHUTDOWN_CANCEL_MARGIN_S, Settings

__all__ = [
    "BUSY_RETRY_AFTER_S",
    "HEARTBEAT_S",
    "RUNNER_BEAT_S",
    "BuildJobs",
    "BuildRunner",
    "BuildService",
    "LocalBuild",
    "beat_interval_s",
    "build_limits",
    "recording_of",
    "resolved_runner",
    "validate_recording",
]

log = logging.getLogger("quadloc.build")

#: Longest interval between two progress writes of a running job (s).
HEARTBEAT_S = 1.0
#: Longest interval between two beats of the runner's heartbeat thread (s): the rows of the
#: jobs running or queued on this replica are refreshed that often, progress or not.
RUNNER_BEAT_S = 5.0
#: ``Retry-After`` (s) when this process's build queue is full.
BUSY_RETRY_AFTER_S = 10.0

#: ``progress(stage, percent, objects_found)``, as :func:`build_map` reports it.
Progress = Callable[[str, float, int], None]
#: Where builds run (``QUADLOC_BUILD_RUNNER`` resolved).
Runner = Literal["in-process", "queue"]


def beat_interval_s(stale_after_s: float) -> float:
    """The runner's beat interval for a liveness window of ``stale_after_s``: at most
    :data:`RUNNER_BEAT_S` and a quarter of the window (three beats may be late or lost, e.g. to
    a busy database or a long GIL hold, before a sweep takes the job for lost)."""
    return min(RUNNER_BEAT_S, float(stale_after_s) / 4.0)


def build_limits(settings: Settings, runner: Runner = "in-process") -> BuildLimits:
    """The recording limits of the settings where builds run on ``runner``
    (``QUADLOC_MAX_BUILD_*`` or the runner's defaults: :meth:`Settings.build_limits_for`;
    ``QUADLOC_MAX_DETECTIONS`` per frame)."""
    limits = settings.build_limits_for(runner)
    return BuildLimits(max_frames=limits.max_frames,
                       max_detections_per_frame=settings.max_detections,
                       max_detections=limits.max_detections)


def resolved_runner(settings: Settings, dialect: str) -> Runner:
    """Where builds run: ``QUADLOC_BUILD_RUNNER``, ``auto`` being the job queue on PostgreSQL
    (the store's ``dialect``) and in-process otherwise."""
    if settings.build_runner != "auto":
        return settings.build_runner
    return "queue" if dialect == "postgresql" else "in-process"


_RECORDING = TypeAdapter[RecordingIn | LegacyRecordingIn](RecordingBody)


def validate_recording(document: Any) -> RecordingIn | LegacyRecordingIn:
    """A recording document (parsed JSON) as its wire model (either form);
    ``validation-error`` naming every invalid or unknown field."""
    if isinstance(document, RecordingIn | LegacyRecordingIn):
        return document
    try:
        return _RECORDING.validate_python(document)
    except ValidationError as exc:
        errors = [{"field": field_path(("body", *e["loc"])), "message": e["msg"]}
                  for e in exc.errors()]
        raise AppError("validation-error", f"invalid recording: {errors[0]['field']}: "
                       f"{errors[0]['message']}", errors=errors) from exc


def recording_of(document: Any, limits: BuildLimits | None = None) -> Recording:
    """The :class:`Recording` to build from a recording document (parsed JSON or its wire
    model; held-out frames left out), checked against ``limits``; ``validation-error`` naming
    every invalid field."""
    try:
        return recording_from_wire(validate_recording(document), limits)
    except RecordingInputError as exc:
        raise AppError("validation-error", f"invalid recording: {exc}",
                       errors=exc.errors) from exc


class _RunnerBusyError(RuntimeError):
    """Too many builds queued on this replica."""


class _JobLostError(RuntimeError):
    """The job's row is no longer active (marked failed, e.g. as stale): stop, store nothing."""


#: Why a released job stored nothing, when it cannot run again (in-process runner).
STOPPED_DETAIL = "the replica stopped during the build; nothing was stored"


class BuildJobs:
    """The job kind ``build`` (:class:`quadloc.service.app.job_queue.JobKind`): runs one job
    from its row, whichever runner called it (a ``quadloc worker`` or :class:`BuildRunner`)."""

    name = "build"

    def __init__(self, store: MapStore, jobs: JobStore, time_budget_s: float) -> None:
        self.store = store
        self.jobs = jobs
        self.time_budget_s = float(time_budget_s)

    def run(self, job_id: str, stop: threading.Event) -> None:
        """Build the job's recording and store the map, ending the job; stops soon after
        ``stop`` is set, raising :class:`JobReleased` (nothing stored). A job that is no
        longer active (ended, or marked failed meanwhile) is left as it is."""
        try:
            self._build(job_id, stop)
        except _JobLostError:
            log.warning("build job %s stopped: its row is no longer active (marked failed "
                        "meanwhile); nothing stored", job_id)
        except JobReleased:
            raise
        except Exception as exc:
            log.exception("build job %s failed", job_id)
            try:
                self.jobs.fail(job_id, "internal_error", f"{type(exc).__name__}: {exc}")
            except Exception:
                log.exception("could not mark job %s failed", job_id)

    def requeued(self, job_id: str) -> None:
        if self.jobs.requeue(job_id):
            log.warning("build job %s is queued again: its worker stopped", job_id)

    def lost(self, job_id: str, detail: str) -> None:
        self.jobs.fail(job_id, "runner_lost", detail)

    def silent(self, stale_after_s: float) -> list[str]:
        return self.jobs.silent(stale_after_s)

    def _progress(self, job_id: str) -> Progress:
        """The build's progress callback: writes the job's progress at every stage change and
        at most every :data:`HEARTBEAT_S`; raises ``_JobLostError`` when the row is no longer
        active."""
        last_time, last_stage = 0.0, ""

        def progress(stage: str, percent: float, objects: int) -> None:
            nonlocal last_time, last_stage
            now = time.monotonic()
            if stage != last_stage or now - last_time >= HEARTBEAT_S:
                last_time, last_stage = now, stage
                if not self.jobs.progress(job_id, stage, percent, objects):
                    raise _JobLostError(job_id)

        return progress

    def _build(self, job_id: str, stop: threading.Event) -> None:
        payload = self.jobs.payload(job_id)
        if payload is None:
            raise _JobLostError(job_id)
        job = self.jobs.get(job_id)
        recording = recording_of(json.loads(payload))  # the limits were checked at intake
        progress = self._progress(job_id)
        progress("associating", 0.0, 0)
        try:
            scene, report = build_map(recording, map_id=job.map_id, progress=progress,
                                      deadline=Deadline.wall_budget(self.time_budget_s)
                                      .cancelled_by(stop))
        except BuildTimeoutError as exc:
            if stop.is_set():
                raise JobReleased(job_id) from exc
            self.jobs.fail(job_id, "time_budget_exceeded",
                           f"{exc} (budget {self.time_budget_s:g} s); send fewer frames")
            return
        except MapValidationError as exc:
            self.jobs.fail(job_id, "invalid_map", str(exc))
            return
        if not scene.objects:
            self.jobs.fail(job_id, "no_objects", "no object could be associated and "
                           "reconstructed from the recording (see the report)", report)
            return
        if stop.is_set():
            raise JobReleased(job_id)
        progress("saving", 95.0, len(scene.objects))
        if self.jobs.get(job_id).status != "running":
            raise _JobLostError(job_id)
        try:
            stored = _store_build(self.store, scene, job.base_version)
        except AppError as exc:
            self.jobs.fail(job_id, _FAILURE_OF[exc.code], exc.detail, report)
            return
        self.jobs.succeed(job_id, stored.scene_map.version, report, len(scene.objects))


class BuildRunner:
    """The in-process runner: the process's build threads (see the module docstring)."""

    def __init__(self, kind: BuildJobs, *, max_concurrent: int, max_queued: int,
                 beat_s: float = RUNNER_BEAT_S) -> None:
        self.kind = kind
        self.jobs = kind.jobs
        self.max_pending = int(max_concurrent) + int(max_queued)
        self.beat_s = float(beat_s)
        self._pool = ThreadPoolExecutor(max_workers=int(max_concurrent),
                                        thread_name_prefix="quadloc-build")
        self._pending: set[str] = set()  # job ids queued or running here
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._stopped = threading.Event()
        self._beat_thread: threading.Thread | None = None

    def submit(self, job_id: str) -> None:
        """Queue the job; ``_RunnerBusyError`` when ``max_concurrent + max_queued`` jobs are
        already running or queued here, ``RuntimeError`` after :meth:`shutdown`."""
        with self._lock:
            if len(self._pending) >= self.max_pending:
                raise _RunnerBusyError(f"{len(self._pending)} builds running or queued on "
                                       "this replica")
            self._pending.add(job_id)
            if self._beat_thread is None or not self._beat_thread.is_alive():
                self._beat_thread = threading.Thread(target=self._beat, daemon=True,
                                                     name="quadloc-build-heartbeat")
                self._beat_thread.start()
        try:
            self._pool.submit(self._run, job_id)
        except RuntimeError:  # pool shut down
            with self._lock:
                self._pending.discard(job_id)
            raise

    def pending(self) -> list[str]:
        """Ids of the jobs running or queued on this replica."""
        with self._lock:
            return sorted(self._pending)

    def shutdown(self) -> None:
        """Stop taking jobs; queued ones are dropped (their rows go stale: ``runner_lost``)."""
        self._stopped.set()
        self._pool.shutdown(wait=False, cancel_futures=True)

    def stop_running(self, stop: bool = True) -> None:
        """The process is stopping (``stop``; False: it serves again): a running build stops
        at its next progress check and is marked failed ``runner_lost``, storing nothing."""
        if stop:
            self._stopping.set()
        else:
            self._stopping.clear()

    def _beat(self) -> None:
        """The heartbeat thread: every ``beat_s`` refresh the rows of the jobs running or
        queued here (independent of the builds' progress); ends when none is left (the next
        :meth:`submit` starts it again) or at :meth:`shutdown`. A failed write is logged and
        retried at the next beat."""
        while not self._stopped.wait(self.beat_s):
            with self._lock:
                ids = sorted(self._pending)
                if not ids:
                    self._beat_thread = None
                    return
            try:
                self.jobs.heartbeat(ids)
            except Exception as exc:  # database unavailable: the next beat retries
                log.warning("build heartbeat not written (%s: %s)", type(exc).__name__, exc)

    def _run(self, job_id: str) -> None:
        try:
            self.kind.run(job_id, self._stopping)
        except JobReleased:  # one process: nobody runs it again
            try:
                self.jobs.fail(job_id, "runner_lost", STOPPED_DETAIL)
            except Exception:
                log.exception("could not mark job %s failed", job_id)
        finally:
            with self._lock:
                self._pending.discard(job_id)


#: A job's failure reason for each refusal of :func:`_store_build`.
_FAILURE_OF = {"map-exists": "map_exists", "version-conflict": "version_conflict",
               "map-not-found": "map_not_found", "database-unavailable": "store_unavailable"}


def _store_build(store: MapStore, scene: SceneMap, base_version: int | None) -> StoredMap:
    """Store a built map: a new map (``base_version`` None) or the version after
    ``base_version``; refusals as :class:`AppError` (``map-exists``, ``version-conflict``,
    ``map-not-found``, ``database-unavailable``), nothing overwritten."""
    map_id = scene.map_id
    try:
        if base_version is None:
            return store.create(scene)
        return store.update(map_id, scene, expected_version=base_version)
    except MapAlreadyExists as exc:
        raise AppError("map-exists", f"map {map_id!r} was created meanwhile; build again "
                       "with If-Match to add a version") from exc
    except VersionConflict as exc:
        raise AppError("version-conflict", f"map {map_id!r} changed meanwhile (now version "
                       f"{exc.current_version}); nothing was overwritten") from exc
    except MapNotFound as exc:
        raise AppError("map-not-found", f"map {map_id!r} was deleted meanwhile") from exc
    except StoreUnavailable as exc:
        raise AppError("database-unavailable", str(exc)) from exc


def job_out(job: BuildJob) -> BuildJobOut:
    """The wire form of a job (times as ISO 8601 text)."""
    return BuildJobOut(
        job_id=job.job_id, map_id=job.map_id, status=job.status,  # type: ignore[arg-type]
        stage=job.stage, percent=job.percent, objects_found=job.objects_found,
        base_version=job.base_version, map_version=job.map_version,
        error=None if job.error is None else BuildErrorOut(**job.error),
        report=job.report, created_at=job.created_at.isoformat(),
        updated_at=job.updated_at.isoformat())


@dataclass(frozen=True)
class LocalBuild:
    """A build run in this process: the stored map and the report, or (``stored`` None) the
    reason no map came of it (``failure``: ``time_budget_exceeded`` or ``no_objects``, as a
    job's, with ``detail``; the report when the build got that far)."""

    stored: StoredMap | None
    report: BuildReport | None
    failure: str | None = None
    detail: str = ""


class BuildService:
    """The map-building use cases of a process (see the module docstring)."""

    def __init__(self, store: MapStore, maps: MapService, settings: Settings) -> None:
        self.store = store
        self.maps = maps
        self.settings = settings
        self.jobs = JobStore(store.engine)
        runner = resolved_runner(settings, store.dialect)
        #: The build limits in force (recording size at intake, time of each build, request
        #: body of ``POST /v1/maps:build``): the settings', else the runner's defaults.
        self.limits = settings.build_limits_for(runner)
        self.kind = BuildJobs(store, self.jobs, self.limits.time_budget_s)
        #: The job queue (``QUADLOC_BUILD_RUNNER`` queue), or None: the in-process runner.
        self.queue: ProcrastinateQueue | None = None
        #: The in-process runner, or None: the job queue.
        self.runner: BuildRunner | None = None
        self.runner_kind: Runner = runner
        if runner == "queue":
            if store.dialect != "postgresql":
                raise ValueError("QUADLOC_BUILD_RUNNER=queue needs PostgreSQL "
                                 "(QUADLOC_DATABASE_URL=postgresql://...); on SQLite builds "
                                 "run in-process")
            self.queue = ProcrastinateQueue(
                store.url, [self.kind], heartbeat_s=beat_interval_s(settings.build_stale_after_s),
                stalled_after_s=settings.build_stale_after_s,
                shutdown_grace_s=max(0.0, settings.shutdown_grace_s - SHUTDOWN_CANCEL_MARGIN_S),
                concurrency=settings.max_concurrent_builds)
        else:
            self.runner = BuildRunner(
                self.kind, max_concurrent=settings.max_concurrent_builds,
                max_queued=settings.max_queued_builds,
                beat_s=beat_interval_s(settings.build_stale_after_s))

    def sweep_stale(self) -> int:
        """Mark failed (``runner_lost``) the jobs silent for ``build_stale_after_s`` (their
        replica stopped; with the job queue only the jobs no queue holds: queued by an
        in-process runner before the queue); returns how many. At start-up a database that is
        unreachable or not migrated is logged, not raised: the app still starts (its requests
        answer 503)."""
        try:
            stale = self.jobs.fail_stale(self.settings.build_stale_after_s,
                                         without_payload=self.queue is not None)
        except SQLAlchemyError as exc:
            log.error("build jobs not swept (%s): the database is unavailable or not "
                      "migrated; they are swept again before any job's status is answered",
                      type(exc).__name__)
            return 0
        if stale:
            log.warning("marked %d build job(s) failed: their runner stopped reporting", stale)
        return stale

    def stop_running(self, stop: bool = True) -> None:
        """The process is stopping (``stop``; False: it serves again): in-process builds stop
        at their next progress check (``runner_lost``, nothing stored); the queue's
        connections close (the workers' jobs are theirs)."""
        if self.runner is not None:
            self.runner.stop_running(stop)
        elif self.queue is not None and stop:
            self.queue.close()

    async def run_worker(self, name: str | None = None, *, wait: bool = True,
                         install_signal_handlers: bool = True) -> None:
        """Run the queue's build jobs in this process (``quadloc worker``) until SIGTERM /
        SIGINT: finish the running builds within ``shutdown_grace_s`` - 2 s, else release
        them (queued again); ``wait`` False: until the queue is empty. ``ValueError`` when
        builds run in-process (SQLite)."""
        if self.queue is None:
            raise ValueError("builds run in the API process here (SQLite, or "
                             "QUADLOC_BUILD_RUNNER=in-process): a worker needs the job queue "
                             "(PostgreSQL)")
        await self.queue.run_worker_async(name=name, wait=wait,
                                          install_signal_handlers=install_signal_handlers)

    def parse(self, document: Any) -> Recording:
        """A recording (parsed JSON or its wire model) checked against the limits, without its
        held-out frames; ``validation-error`` naming every invalid field."""
        return recording_of(document, build_limits(self.settings, self.runner_kind))

    def base_version(self, map_id: str, if_match: str | None) -> int | None:
        """The version a build of ``map_id`` replaces: None for a new map (then ``If-Match``
        must be absent: ``precondition-failed``, ``*`` included); for an existing map
        ``If-Match`` must name its latest ETag or be ``*`` (``precondition-required`` /
        ``precondition-failed``; the rule of :meth:`MapService.check_etag`)."""
        if self.maps.latest_version(map_id) is None:
            if if_match is not None:  # no current version: no tag matches, not even '*'
                raise AppError("precondition-failed",
                               f"map {map_id!r} does not exist, so If-Match cannot match; omit "
                               "it to build a new map",
                               field="header.if-match", message="map does not exist")
            return None
        tags = parse_if_match(if_match, what=f"map {map_id!r} exists: building a new version")
        return self.maps.check_etag(map_id, tags)

    def start(self, document: Any, map_id: str, if_match: str | None,
              caller: Caller = INTERNAL) -> BuildJobOut:
        """Start a build job of ``caller``: its row (with the recording) queued for the
        workers (``busy`` at ``max_active_build_jobs`` jobs queued or running), or for this
        process's runner (``busy`` when its queue is full);
        ``database-unavailable`` when the job queue cannot be reached (the job failed
        ``store_unavailable``)."""
        wire = validate_recording(document)
        self.parse(wire)
        base = self.base_version(map_id, if_match)
        if self.queue is not None and (
                active := self.jobs.count_active()) >= self.settings.max_active_build_jobs:
            raise AppError("busy", f"{active} map builds are queued or running (at most "
                           f"QUADLOC_MAX_ACTIVE_BUILD_JOBS={self.settings.max_active_build_jobs})"
                           "; retry later", retry_after_s=BUSY_RETRY_AFTER_S)
        job = self.jobs.create(map_id, base, caller.owner,
                               payload=wire.model_dump_json(exclude_unset=True))
        try:
            if self.queue is not None:
                self.queue.defer(self.kind.name, job.job_id)
            else:
                assert self.runner is not None
                self.runner.submit(job.job_id)
        except ConnectorException as exc:
            self.jobs.fail(job.job_id, "store_unavailable", f"the job queue refused the job: "
                           f"{type(exc).__name__}")
            raise AppError("database-unavailable", "the build job could not be queued; retry "
                           "later", retry_after_s=BUSY_RETRY_AFTER_S) from exc
        except RuntimeError as exc:  # the queue is full, or the runner stopped
            self.jobs.fail(job.job_id, "busy", str(exc))
            raise AppError("busy", f"too many map builds on this replica ({exc}); retry later",
                           retry_after_s=BUSY_RETRY_AFTER_S) from exc
        return job_out(self.jobs.get(job.job_id))

    def get(self, job_id: str, caller: Caller = INTERNAL) -> BuildJobOut:
        """A job (with the in-process runner, stale ones marked failed first); ``not-found``,
        also for a job of another key (:mod:`quadloc.service.app.ownership`: the same answer
        as an unknown id)."""
        if self.runner is not None:
            self.jobs.fail_stale(self.settings.build_stale_after_s)
        try:
            job = self.jobs.get(job_id)
        except JobNotFoundError:
            job = None
        if job is None or not caller.may_access(job.owner):
            raise AppError("not-found", f"no build job {job_id!r}",
                           field="path.job_id", message="not found")
        return job_out(job)

    def build_now(self, document: Any, map_id: str, *, update: bool,
                  progress: Progress | None = None) -> LocalBuild:
        """Build in this process (no job row) and store the map: a new map, or with
        ``update`` the next version of an existing one (refused if it changed meanwhile).
        Refusals: ``validation-error``, ``map-exists`` (the map exists and not ``update``), the
        store's (``version-conflict``...); a build that gives no map is a :class:`LocalBuild`
        with its ``failure``."""
        recording = self.parse(document)
        base = self.maps.latest_version(map_id)
        if base is not None and not update:
            raise AppError("map-exists", f"map {map_id!r} exists; build its next version "
                           "with update (CLI: --update)", field="map_id",
                           message="already exists")
        try:
            scene, report = build_map(
                recording, map_id=map_id, progress=progress,
                deadline=Deadline.wall_budget(self.limits.time_budget_s))
        except BuildTimeoutError as exc:
            return LocalBuild(None, None, "time_budget_exceeded",
                              f"{exc} (QUADLOC_BUILD_TIME_BUDGET_S="
                              f"{self.limits.time_budget_s:g})")
        if not scene.objects:
            return LocalBuild(None, report, "no_objects", "no object could be associated and "
                              "reconstructed (see the report)")
        return LocalBuild(_store_build(self.store, scene, base), report)
