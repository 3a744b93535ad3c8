"""Map-building jobs: one row per ``POST /v1/maps:build`` job.

Revision ID: 0002_build_jobs
Revises: 0001_map_tables
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002_build_jobs"
down_revision = "0001_map_tables"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "quadloc_build_jobs",
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
        sa.CheckConstraint("status IN ('queued', 'running', 'succeeded', 'failed')",
                           name="ck_quadloc_build_jobs_status"),
    )
    op.create_index("ix_quadloc_build_jobs_status", "quadloc_build_jobs", ["status"])


def downgrade() -> None:
    op.drop_index("ix_quadloc_build_jobs_status", "quadloc_build_jobs")
    op.drop_table("quadloc_build_jobs")
