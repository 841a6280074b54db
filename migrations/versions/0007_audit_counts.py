"""audit_log.count and last_ns: identical audited requests are one row (issue 33)

An unauthenticated flood of the same refused request wrote one row per request (600 requests
with a 60,000-character path: +38 MB), and retention then deleted the devices' events to make
room. ``wott_hub.security.audit`` now merges identical entries (who, action, target, address,
status) into one row: ``count`` requests, the first at ``t_ns``, the last at ``last_ns``. Rows
written before stand for one request each (``count`` 1, ``last_ns`` NULL).

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-27
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("audit_log") as batch:
        batch.add_column(sa.Column("count", sa.Integer(), nullable=False, server_default="1"))
        batch.add_column(sa.Column("last_ns", sa.BigInteger(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("audit_log") as batch:
        batch.drop_column("last_ns")
        batch.drop_column("count")
