"""hub_lease: the one row naming the process that writes this database

A second hub on the same history database would interleave its sequence
numbers into the same Things; the writer takes this row at its first Thing and
refreshes it, and a second writer refuses while the holder is alive
(``wott_hub.history.lease``). The row is created here with no holder.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-24
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    lease = op.create_table(
        "hub_lease",
        sa.Column("id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("holder", sa.String(length=100), nullable=True),
        sa.Column("pid", sa.Integer(), nullable=True),
        sa.Column("host", sa.String(length=255), nullable=True),
        sa.Column("acquired_ns", sa.BigInteger(), nullable=True),
        sa.Column("heartbeat_ns", sa.BigInteger(), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_hub_lease")),
    )
    op.bulk_insert(lease, [{"id": 1}])


def downgrade() -> None:
    op.drop_table("hub_lease")
