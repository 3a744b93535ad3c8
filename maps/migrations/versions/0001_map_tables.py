"""Map tables: one row per map, one immutable row per map version.

Revision ID: 0001_map_tables
Revises:
Create Date: 2026-11-21
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001_map_tables"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "quadloc_maps",
        sa.Column("map_id", sa.String(128), primary_key=True),
        sa.Column("name", sa.String(256), nullable=False),
        sa.Column("latest_version", sa.Integer, nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.CheckConstraint("latest_version >= 1", name="ck_quadloc_maps_latest_version"),
    )
    op.create_table(
        "quadloc_map_versions",
        sa.Column("map_id", sa.String(128),
                  sa.ForeignKey("quadloc_maps.map_id", ondelete="CASCADE"), nullable=False),
        sa.Column("version", sa.Integer, nullable=False),
        sa.Column("content", sa.Text, nullable=False),
        sa.Column("content_hash", sa.String(64), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        # The unique (map_id, version) key is what makes concurrent updates safe.
        sa.PrimaryKeyConstraint("map_id", "version", name="pk_quadloc_map_versions"),
        sa.CheckConstraint("version >= 1", name="ck_quadloc_map_versions_version"),
    )


def downgrade() -> None:
    op.drop_table("quadloc_map_versions")
    op.drop_table("quadloc_maps")
