"""hub_lease: one row per hub identity instead of one per database

Several hubs of a fleet (issue 13) may record into one database (PostgreSQL),
each its own Things; what must stay impossible is two processes writing as the
*same* hub. So the lease row is keyed by the hub's id (``hub_id``, unique): a
writer takes the row of its own hub id, creating it on first use. The row of
the default hub id (a hub configured without one) keeps id 1 and whatever
holder it had, so a hub running during the upgrade keeps its lease.

``things.hub_id`` names the hub that records each Thing: a hub of another id is refused
a Thing while its recorder holds its lease (two hubs of a fleet configured with the same
Thing ids must not interleave one sequence); NULL (rows from before) is anyone's.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-24
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

DEFAULT_HUB_ID = "wott-hub"  # wott_hub.history.lease.DEFAULT_HUB_ID when this was written
_HOLDER = ("holder", "pid", "host", "acquired_ns", "heartbeat_ns")


def _holder_columns() -> list[sa.Column]:
    return [
        sa.Column("holder", sa.String(length=100), nullable=True),
        sa.Column("pid", sa.Integer(), nullable=True),
        sa.Column("host", sa.String(length=255), nullable=True),
        sa.Column("acquired_ns", sa.BigInteger(), nullable=True),
        sa.Column("heartbeat_ns", sa.BigInteger(), nullable=True),
    ]


def _default_row() -> dict:
    """The holder of the old single row (none when rendering SQL offline: nothing to read)."""
    if op.get_context().as_sql:
        return dict.fromkeys(_HOLDER)
    row = op.get_bind().execute(sa.text(f"SELECT {', '.join(_HOLDER)} FROM hub_lease WHERE id = 1")).first()
    return dict(zip(_HOLDER, row, strict=True)) if row is not None else dict.fromkeys(_HOLDER)


def upgrade() -> None:
    held = _default_row()
    op.drop_table("hub_lease")
    lease = op.create_table(
        "hub_lease",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("hub_id", sa.String(length=200), nullable=False),
        *_holder_columns(),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_hub_lease")),
        sa.UniqueConstraint("hub_id", name=op.f("uq_hub_lease_hub_id")),
    )
    op.bulk_insert(lease, [{"hub_id": DEFAULT_HUB_ID, **held}])  # the first id: 1
    op.add_column("things", sa.Column("hub_id", sa.String(length=200), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("things") as things:
        things.drop_column("hub_id")
    held = _default_row()
    op.drop_table("hub_lease")
    lease = op.create_table(
        "hub_lease",
        sa.Column("id", sa.Integer(), autoincrement=False, nullable=False),
        *_holder_columns(),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_hub_lease")),
    )
    op.bulk_insert(lease, [{"id": 1, **held}])
