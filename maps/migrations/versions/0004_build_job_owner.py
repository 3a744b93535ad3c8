"""The owner of a map-building job: the sha256 of the API key that started it (NULL: started
without keys, or before this revision; such a job is seen only by an ``admin`` key when the
server has keys).

Revision ID: 0004_build_job_owner
Revises: 0003_map_calibrations
Create Date: 2026-11-27
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004_build_job_owner"
down_revision = "0003_map_calibrations"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("quadloc_build_jobs", sa.Column("owner", sa.String(64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("quadloc_build_jobs") as batch:  # (SQLite: table rebuilt)
        batch.drop_column("owner")
