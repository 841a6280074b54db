"""directory: tdd_things and tdd_events of the embedded Thing Description Directory

The hub's TDD (package wott-directory) keeps its TDs and lifecycle events in the
hub's database; the hub creates its tables here, with the history's, and the
directory only checks they exist (``Directory(..., create_tables=False)``).
The columns are those of ``wott_directory.models`` (tests/history/test_schema.py
compares both metadata with the migrated database).

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "tdd_things",
        sa.Column("id", sa.String(length=2048), nullable=False),
        sa.Column("td", sa.Text(), nullable=False),
        sa.Column("anonymous", sa.Boolean(), nullable=False),
        sa.Column("own", sa.Boolean(), nullable=False),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("modified", sa.DateTime(timezone=True), nullable=False),
        sa.Column("expires", sa.DateTime(timezone=True), nullable=True),
        sa.PrimaryKeyConstraint("id"),
    )
    op.create_index("ix_tdd_things_expires", "tdd_things", ["expires"], unique=False)
    op.create_table(
        "tdd_events",
        sa.Column("id", sa.BigInteger(), autoincrement=False, nullable=False),
        sa.Column("type", sa.String(length=16), nullable=False),
        sa.Column("thing_id", sa.String(length=2048), nullable=False),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("data", sa.Text(), nullable=True),
        sa.PrimaryKeyConstraint("id"),
    )


def downgrade() -> None:
    op.drop_table("tdd_events")
    op.drop_index("ix_tdd_things_expires", table_name="tdd_things")
    op.drop_table("tdd_things")
