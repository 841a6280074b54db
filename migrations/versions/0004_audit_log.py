"""audit_log: every write, action and refused credential (issue 17, wott_hub.security.audit)

Who (a token's name, never the token), what (method and path, without the query:
a token given as ``?access_token=`` is never stored), when, from which address,
and the status answered. Read with ``wott-hub history audit``.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-24
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "audit_log",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("t_ns", sa.BigInteger(), nullable=False),
        sa.Column("who", sa.String(length=64), nullable=False),
        sa.Column("action", sa.String(length=16), nullable=False),
        sa.Column("target", sa.Text(), nullable=False),
        sa.Column("address", sa.String(length=64), nullable=False),
        sa.Column("status", sa.Integer(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_audit_log")),
    )
    op.create_index(op.f("ix_audit_log_t_ns"), "audit_log", ["t_ns"], unique=False)


def downgrade() -> None:
    op.drop_index(op.f("ix_audit_log_t_ns"), table_name="audit_log")
    op.drop_table("audit_log")
