"""history: things and events

Revision ID: 0001
Revises:
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "things",
        sa.Column("key", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("id", sa.String(length=200), nullable=False),
        sa.Column("title", sa.String(length=200), nullable=False),
        sa.Column("family", sa.String(length=100), nullable=False),
        sa.Column("td", sa.Text(), nullable=True),
        sa.Column("static_values", sa.Text(), nullable=True),
        sa.Column("seq_reserved", sa.BigInteger(), nullable=False),
        sa.Column("updated_ns", sa.BigInteger(), nullable=False),
        sa.PrimaryKeyConstraint("key", name=op.f("pk_things")),
        sa.UniqueConstraint("id", name=op.f("uq_things_id")),
    )
    op.create_table(
        "events",
        sa.Column("id", sa.BigInteger().with_variant(sa.Integer(), "sqlite"), autoincrement=True,
                  nullable=False),
        sa.Column("thing_key", sa.Integer(), nullable=False),
        sa.Column("seq", sa.BigInteger(), nullable=False),
        sa.Column("t_ns", sa.BigInteger(), nullable=False),
        sa.Column("kind", sa.SmallInteger(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("data", sa.Text(), nullable=False),
        sa.ForeignKeyConstraint(["thing_key"], ["things.key"], ondelete="CASCADE",
                                name=op.f("fk_events_thing_key_things")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_events")),
        sa.UniqueConstraint("thing_key", "seq", name=op.f("uq_events_thing_key")),
    )
    op.create_index("ix_events_thing_time", "events", ["thing_key", "t_ns"], unique=False)


def downgrade() -> None:
    op.drop_index("ix_events_thing_time", table_name="events")
    op.drop_table("events")
    op.drop_table("things")
