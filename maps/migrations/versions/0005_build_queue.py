"""Builds leave the API process (issue 29): a job's input is stored with it, and on PostgreSQL
the job queue's own tables (procrastinate) are created.

* ``quadloc_build_jobs.payload``: the job's input (the recording, as the JSON the API validated)
  until the job ends (then NULL): any worker process can run the job from its row, and a job
  retried after its worker died starts again from it;
* PostgreSQL only: procrastinate's schema (its tables ``procrastinate_jobs``,
  ``procrastinate_workers``, ``procrastinate_events``, ..., its types and functions), the
  ``schema.sql`` of procrastinate 3.10.0 copied verbatim into
  ``maps/migrations/procrastinate-3.10.0-schema.sql`` (a migration never changes: upgrading
  procrastinate is a new revision that runs the upstream's migration files in between). SQLite
  runs builds in the API process and has no queue tables.

Revision ID: 0005_build_queue
Revises: 0004_build_job_owner
Create Date: 2026-11-27
"""

from __future__ import annotations

from pathlib import Path

import sqlalchemy as sa
from alembic import op

revision = "0005_build_queue"
down_revision = "0004_build_job_owner"
branch_labels = None
depends_on = None

#: procrastinate's schema, as shipped by the version this revision was written against.
PROCRASTINATE_SCHEMA = Path(__file__).resolve().parents[1] / "procrastinate-3.10.0-schema.sql"
#: Every object that schema creates, dropped (in this order) by :func:`downgrade`.
PROCRASTINATE_TABLES = ("procrastinate_events", "procrastinate_periodic_defers",
                        "procrastinate_jobs", "procrastinate_workers")


def upgrade() -> None:
    op.add_column("quadloc_build_jobs", sa.Column("payload", sa.Text, nullable=True))
    bind = op.get_bind()
    if bind.dialect.name == "postgresql":
        # the driver's own execute: the script has many statements and literal '%' signs
        bind.connection.driver_connection.execute(  # type: ignore[union-attr]
            PROCRASTINATE_SCHEMA.read_text())


def downgrade() -> None:
    bind = op.get_bind()
    if bind.dialect.name == "postgresql":
        functions = _functions(bind)
        if functions:  # (their triggers go with them)
            op.execute("DROP FUNCTION " + ", ".join(functions) + " CASCADE")
        for table in PROCRASTINATE_TABLES:
            op.execute(f"DROP TABLE IF EXISTS {table} CASCADE")
        op.execute("DROP TYPE IF EXISTS procrastinate_job_status, procrastinate_job_event_type, "
                   "procrastinate_job_to_defer_v1 CASCADE")
    with op.batch_alter_table("quadloc_build_jobs") as batch:  # (SQLite: table rebuilt)
        batch.drop_column("payload")


def _functions(bind: sa.Connection) -> list[str]:
    """The signatures of the ``procrastinate_*`` functions in the database."""
    rows = bind.execute(sa.text(
        "SELECT p.oid::regprocedure::text FROM pg_proc p "
        "JOIN pg_namespace n ON n.oid = p.pronamespace "
        "WHERE n.nspname = current_schema() AND p.proname LIKE 'procrastinate%'")).all()
    return [str(r[0]) for r in rows]
