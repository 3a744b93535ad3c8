"""Map calibrations: at most one per map version (``quadloc calibrate``), deleted with it.

Revision ID: 0003_map_calibrations
Revises: 0002_build_jobs
Create Date: 2026-11-27
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003_map_calibrations"
down_revision = "0002_build_jobs"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "quadloc_map_calibrations",
        sa.Column("map_id", sa.String(128), primary_key=True),
        sa.Column("version", sa.Integer, primary_key=True),
        sa.Column("content", sa.Text, nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["map_id", "version"],
                                ["quadloc_map_versions.map_id", "quadloc_map_versions.version"],
                                ondelete="CASCADE",
                                name="fk_quadloc_map_calibrations_version"),
    )


def downgrade() -> None:
    op.drop_table("quadloc_map_calibrations")
