"""Runs map-building jobs for the API: a bounded pool, a time budget, heartbeats in the store.

One :class:`BuildRunner` per app; beyond ``max_concurrent_builds + max_queued_builds`` jobs,
:class:`RunnerBusyError` (503 + ``Retry-After`` :data:`RETRY_AFTER_S`). A job ends
``succeeded`` or ``failed`` with a reason: ``invalid_recording``, ``time_budget_exceeded``,
``no_objects``, ``version_conflict``, ``map_exists``, ``map_not_found``, ``store_unavailable``,
``internal_error``. A job's steps: docs/design/service.md#map-building-jobs.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from sqlalchemy.exc import SQLAlchemyError

from quadloc.factors.budget import Deadline
from quadloc.maps.building.build import BuildTimeoutError, build_map
from quadloc.maps.building.jobs import JobStore
from quadloc.maps.building.recording import BuildLimits, Recording
from quadloc.maps.errors import MapAlreadyExists, MapNotFound, StoreUnavailable, VersionConflict
from quadloc.maps.model import MapValidationError
from quadloc.maps.store import MapStore

__all__ = ["HEARTBEAT_S", "RETRY_AFTER_S", "BuildRunner", "JobLostError", "RunnerBusyError",
           "build_limits", "install_map_building"]

log = logging.getLogger("quadloc.build")

#: Longest interval between two progress writes of a running job (s).
HEARTBEAT_S = 1.0


#: ``Retry-After`` (s) of the 503 answered when this replica's build queue is full.
RETRY_AFTER_S = 10


def build_limits(settings: Any) -> BuildLimits:
    """The recording limits of the settings (``QUADLOC_MAX_BUILD_*``, ``MAX_DETECTIONS``)."""
    return BuildLimits(max_frames=settings.max_build_frames,
                       max_detections_per_frame=settings.max_detections,
                       max_detections=settings.max_build_detections)


class RunnerBusyError(RuntimeError):
    """Too many builds queued on this replica."""


class JobLostError(RuntimeError):
    """The job's row is no longer active (marked failed, e.g. as stale): stop, store nothing."""


class BuildRunner:
    def __init__(self, store: MapStore, jobs: JobStore, *, max_concurrent: int, max_queued: int,
                 time_budget_s: float) -> None:
        self.store = store
        self.jobs = jobs
        self.time_budget_s = float(time_budget_s)
        self.max_pending = int(max_concurrent) + int(max_queued)
        self._pool = ThreadPoolExecutor(max_workers=int(max_concurrent),
                                        thread_name_prefix="quadloc-build")
        self._pending: set[str] = set()  # job ids queued or running here
        self._lock = threading.Lock()

    def submit(self, job_id: str, recording: Recording) -> None:
        """Queue the job, or :class:`RunnerBusyError` when ``max_concurrent + max_queued``
        jobs are already running or queued on this replica."""
        with self._lock:
            if len(self._pending) >= self.max_pending:
                raise RunnerBusyError(f"{len(self._pending)} builds running or queued on this "
                                      "replica")
            self._pending.add(job_id)
        try:
            self._pool.submit(self._run, job_id, recording)
        except RuntimeError:  # pool shut down
            with self._lock:
                self._pending.discard(job_id)
            raise

    def pending(self) -> list[str]:
        """Ids of the jobs running or queued on this replica."""
        with self._lock:
            return sorted(self._pending)

    def shutdown(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

    def _run(self, job_id: str, recording: Recording) -> None:
        try:
            self._build(job_id, recording)
        except JobLostError:
            log.warning("build job %s stopped: its row is no longer active (marked failed "
                        "meanwhile); nothing stored", job_id)
        except Exception as exc:
            log.exception("build job %s failed", job_id)
            try:
                self.jobs.fail(job_id, "internal_error", f"{type(exc).__name__}: {exc}")
            except Exception:
                log.exception("could not mark job %s failed", job_id)
        finally:
            with self._lock:
                self._pending.discard(job_id)

    def _build(self, job_id: str, recording: Recording) -> None:
        job = self.jobs.get(job_id)
        deadline = Deadline.wall_budget(self.time_budget_s)
        last = [0.0, ""]

        def progress(stage: str, percent: float, objects: int) -> None:
            now = time.monotonic()
            if stage != last[1] or now - last[0] >= HEARTBEAT_S:
                last[0], last[1] = now, stage
                if not self.jobs.progress(job_id, stage, percent, objects):
                    raise JobLostError(job_id)
                # the jobs waiting behind this one are alive too: their heartbeat
                waiting = [j for j in self.pending() if j != job_id]
                if waiting:
                    self.jobs.heartbeat(waiting)

        progress("associating", 0.0, 0)
        try:
            scene, report = build_map(recording, map_id=job.map_id, progress=progress,
                                      deadline=deadline)
        except BuildTimeoutError as exc:
            self.jobs.fail(job_id, "time_budget_exceeded",
                           f"{exc} (budget {self.time_budget_s:g} s); send fewer frames")
            return
        except MapValidationError as exc:
            self.jobs.fail(job_id, "invalid_map", str(exc))
            return
        if report["refinement"] is not None and report["refinement"]["stopped_early"]:
            report["warnings"] = ["time budget reached during refinement: the map holds the "
                                  "estimate at that point"]
        if not scene.objects:
            self.jobs.fail(job_id, "no_objects", "no object could be associated and "
                           "reconstructed from the recording (see the report)", report)
            return
        progress("saving", 95.0, len(scene.objects))
        if self.jobs.get(job_id).status != "running":
            raise JobLostError(job_id)
        try:
            if job.base_version is None:
                stored = self.store.create(scene)
            else:
                stored = self.store.update(job.map_id, scene,
                                           expected_version=job.base_version)
        except MapAlreadyExists:
            self.jobs.fail(job_id, "map_exists", f"map {job.map_id!r} was created meanwhile; "
                           "submit again with If-Match to add a version", report)
            return
        except VersionConflict as exc:
            self.jobs.fail(job_id, "version_conflict",
                           f"map {job.map_id!r} changed meanwhile (now version "
                           f"{exc.current_version}); nothing was overwritten", report)
            return
        except MapNotFound:
            self.jobs.fail(job_id, "map_not_found", f"map {job.map_id!r} was deleted meanwhile",
                           report)
            return
        except StoreUnavailable as exc:
            self.jobs.fail(job_id, "store_unavailable", str(exc), report)
            return
        self.jobs.succeed(job_id, stored.scene_map.version, report, len(scene.objects))


def install_map_building(app: Any, store: MapStore, settings: Any) -> None:
    """Wire map building into ``app``: the job store (jobs left running by a previous instance
    and silent for ``build_stale_after_s`` are marked failed now), the runner, the router."""
    from quadloc.service.api.routers import build

    jobs = JobStore(store.engine)
    try:
        stale = jobs.fail_stale(settings.build_stale_after_s)
    except SQLAlchemyError as exc:  # unmigrated / unreachable: the app still starts (503s)
        log.error("build jobs not swept at startup (%s): the database is unavailable or not "
                  "migrated; they are swept again before any job's status is answered",
                  type(exc).__name__)
    else:
        if stale:
            log.warning("marked %d build job(s) failed: their runner stopped reporting", stale)
    app.state.build_jobs = jobs
    app.state.build_runner = BuildRunner(
        store, jobs, max_concurrent=settings.max_concurrent_builds,
        max_queued=settings.max_queued_builds, time_budget_s=settings.build_time_budget_s)
    app.include_router(build.router)
