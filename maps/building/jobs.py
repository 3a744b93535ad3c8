"""Map-building jobs as rows of the map store's database (table ``quadloc_build_jobs``, created by
the Alembic migration ``0002_build_jobs``).

A job is ``queued`` -> ``running`` -> ``succeeded`` | ``failed`` (a job whose worker died is put
back to ``queued`` by :meth:`JobStore.requeue` when the job queue retries it); the row holds the
job's input (``payload``) until it ends. With the in-process runner (SQLite) an active job's row
is its heartbeat (``updated_at``), and :meth:`JobStore.fail_stale` fails the jobs whose
heartbeat is older than ``stale_after_s`` with ``runner_lost`` (docs/design/maps.md, "Build
jobs"). Times are UTC.
"""

from __future__ import annotations

import json
import logging
import uuid
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

import sqlalchemy as sa
from pydantic import ValidationError
from sqlalchemy.engine import Engine

from quadloc.factors.names import scrubbed_text
from quadloc.maps.building.report import BuildReport
from quadloc.maps.store import as_utc, utc_now

__all__ = ["BuildJob", "JobNotFoundError", "JobStore", "jobs_table"]

log = logging.getLogger("quadloc.build")

ACTIVE = ("queued", "running")

# The table's description for building queries ONLY: the schema belongs to the Alembic migrations
# ``0002_build_jobs`` and ``0004_build_job_owner`` (maps/migrations/versions/), which this
# mirrors, CHECK constraint included (tests/service/api/test_api_build.py compares the two).
#: The build jobs (migrations ``0002_build_jobs``, ``0004_build_job_owner``, ``0005_build_queue``).
jobs_table = sa.Table(
    "quadloc_build_jobs",
    sa.MetaData(),
    sa.Column("job_id", sa.String(36), primary_key=True),
    sa.Column("map_id", sa.String(128), nullable=False),
    sa.Column("base_version", sa.Integer, nullable=True),
    sa.Column("status", sa.String(16), nullable=False),
    sa.Column("stage", sa.String(32), nullable=False),
    sa.Column("percent", sa.Float, nullable=False),
    sa.Column("objects_found", sa.Integer, nullable=False),
    sa.Column("map_version", sa.Integer, nullable=True),
    sa.Column("error", sa.Text, nullable=True),
    sa.Column("report", sa.Text, nullable=True),
    sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
    # the sha256 of the API key that started the job (None: no keys, or before 0003)
    sa.Column("owner", sa.String(64), nullable=True),
    # the job's input (JSON text) while it is active; NULL once it ended (0005)
    sa.Column("payload", sa.Text, nullable=True),
    sa.CheckConstraint("status IN ('queued', 'running', 'succeeded', 'failed')",
                       name="ck_quadloc_build_jobs_status"),
)



def _scrubbed(value: Any) -> Any:
    """A JSON value with every string (keys included) passed through
    :func:`quadloc.factors.names.scrubbed_text`."""
    if isinstance(value, str):
        return scrubbed_text(value)
    if isinstance(value, list):
        return [_scrubbed(v) for v in value]
    if isinstance(value, dict):
        return {scrubbed_text(str(k)): _scrubbed(v) for k, v in value.items()}
    return value


def _stored_error(job_id: str, text: str | None) -> dict[str, Any] | None:
    """A job's stored ``error`` column as ``{reason, detail}``, whatever the row holds (a row
    written before intake checked its text, or by another version, never makes the job
    unreadable: lone surrogates become U+FFFD, an unreadable value a stated one)."""
    if not text:
        return None
    try:
        error = _scrubbed(json.loads(text))
    except ValueError:
        error = None
    if not isinstance(error, dict) or not isinstance(error.get("reason"), str):
        log.warning("build job %s: stored error unreadable; served as 'internal_error'", job_id)
        return {"reason": "internal_error", "detail": "the stored error could not be read"}
    return {"reason": error["reason"], "detail": str(error.get("detail", ""))}


def _stored_report(job_id: str, text: str | None) -> BuildReport | None:
    """A job's stored ``report`` column, scrubbed as :func:`_stored_error`; None (logged) when
    it is no report this version can read."""
    if not text:
        return None
    try:
        return BuildReport.model_validate(_scrubbed(json.loads(text)))
    except (ValueError, ValidationError):
        log.warning("build job %s: stored report unreadable; served without it", job_id)
        return None


class JobNotFoundError(KeyError):
    """No job with this id."""


@dataclass(frozen=True)
class BuildJob:
    job_id: str
    map_id: str
    base_version: int | None
    status: str
    stage: str
    percent: float
    objects_found: int
    map_version: int | None
    error: dict[str, Any] | None
    report: BuildReport | None
    created_at: datetime
    updated_at: datetime
    owner: str | None = None


class JobStore:
    """Build-job rows over the map store's engine (``MapStore.engine``)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def create(self, map_id: str, base_version: int | None,
               owner: str | None = None, payload: str | None = None) -> BuildJob:
        """A new ``queued`` job of ``owner`` (the sha256 of the API key starting it) with its
        input ``payload`` (JSON text, kept until the job ends)."""
        now = utc_now()
        job_id = str(uuid.uuid4())
        with self.engine.begin() as conn:
            conn.execute(jobs_table.insert().values(
                job_id=job_id, map_id=map_id, base_version=base_version, status="queued",
                stage="queued", percent=0.0, objects_found=0, created_at=now, updated_at=now,
                owner=owner, payload=payload))
        return self.get(job_id)

    def count_active(self) -> int:
        """How many jobs are queued or running."""
        with self.engine.connect() as conn:
            return int(conn.execute(sa.select(sa.func.count()).select_from(jobs_table)
                                    .where(jobs_table.c.status.in_(ACTIVE))).scalar_one())

    def silent(self, stale_after_s: float) -> list[str]:
        """Ids of the queued/running jobs whose row was not written for ``stale_after_s``."""
        cutoff = utc_now() - timedelta(seconds=stale_after_s)
        with self.engine.connect() as conn:
            return [r.job_id for r in conn.execute(
                sa.select(jobs_table.c.job_id).where(jobs_table.c.status.in_(ACTIVE),
                                                     jobs_table.c.updated_at < cutoff))]

    def payload(self, job_id: str) -> str | None:
        """The input of an active job (None once it ended); :class:`JobNotFoundError`."""
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(jobs_table.c.status, jobs_table.c.payload)
                               .where(jobs_table.c.job_id == job_id)).first()
        if row is None:
            raise JobNotFoundError(job_id)
        return row.payload if row.status in ACTIVE else None

    def get(self, job_id: str) -> BuildJob:
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(jobs_table).where(jobs_table.c.job_id == job_id)).first()
        if row is None:
            raise JobNotFoundError(job_id)
        m = row._mapping
        return BuildJob(
            job_id=m["job_id"], map_id=m["map_id"], base_version=m["base_version"],
            status=m["status"], stage=m["stage"], percent=float(m["percent"]),
            objects_found=int(m["objects_found"]), map_version=m["map_version"],
            error=_stored_error(m["job_id"], m["error"]),
            report=_stored_report(m["job_id"], m["report"]),
            created_at=as_utc(m["created_at"]), updated_at=as_utc(m["updated_at"]),
            owner=m["owner"])

    def _update(self, *where: Any, **values: Any) -> int:
        """Set ``values`` (and the heartbeat ``updated_at``) on the ACTIVE jobs matching
        ``where``; returns how many."""
        with self.engine.begin() as conn:
            return conn.execute(jobs_table.update().where(jobs_table.c.status.in_(ACTIVE), *where)
                                .values(updated_at=utc_now(), **values)).rowcount

    def progress(self, job_id: str, stage: str, percent: float, objects_found: int) -> bool:
        """Heartbeat + progress of a running job; False if the job is no longer active (e.g.
        marked failed as stale): the runner should stop."""
        return self._update(jobs_table.c.job_id == job_id, status="running", stage=stage,
                            percent=float(min(100.0, max(0.0, percent))),
                            objects_found=int(objects_found)) == 1

    def heartbeat(self, job_ids: list[str]) -> int:
        """Refresh the heartbeat (``updated_at``) of the listed jobs that are still active
        (e.g. queued behind a running build on the same replica); returns how many."""
        return self._update(jobs_table.c.job_id.in_(job_ids)) if job_ids else 0

    def requeue(self, job_id: str) -> bool:
        """An active job back to ``queued`` (its progress reset): its worker stopped and the
        job queue runs it again. False if the job is no longer active."""
        return self._update(jobs_table.c.job_id == job_id, status="queued", stage="queued",
                            percent=0.0, objects_found=0) == 1

    def succeed(self, job_id: str, map_version: int, report: BuildReport,
                objects_found: int) -> bool:
        return self._update(jobs_table.c.job_id == job_id, status="succeeded", stage="done",
                            percent=100.0, map_version=map_version, objects_found=objects_found,
                            report=report.model_dump_json(), payload=None) == 1

    def fail(self, job_id: str, reason: str, detail: str,
             report: BuildReport | None = None) -> bool:
        return self._update(jobs_table.c.job_id == job_id, status="failed", stage="failed",
                            error=json.dumps({"reason": reason, "detail": detail}), payload=None,
                            report=None if report is None else report.model_dump_json()) == 1

    def fail_stale(self, stale_after_s: float, *, without_payload: bool = False) -> int:
        """Mark queued/running jobs without a heartbeat for ``stale_after_s`` as failed
        (``without_payload``: only those whose row holds no input, i.e. no worker can run
        them: started before migration ``0005_build_queue``)."""
        cutoff = utc_now() - timedelta(seconds=stale_after_s)
        err = json.dumps({"reason": "runner_lost",
                          "detail": f"no progress for {stale_after_s:g} s: the replica running "
                                    f"the job restarted or died; submit the recording again"})
        where = [jobs_table.c.updated_at < cutoff]
        if without_payload:
            where.append(jobs_table.c.payload.is_(None))
        return self._update(*where, status="failed", stage="failed", error=err, payload=None)
