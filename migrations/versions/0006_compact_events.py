"""events.data as bytes: skinDeformedDetection packets packed as numbers; SQLite auto-vacuum

``wott_hub.history.codec`` stores a skin packet as ~70 B of numbers instead of ~700 B of
JSON, and gives back the identical text on read (SSE resume sends what was sent live);
every other payload is stored as its UTF-8 text. This revision changes the column's type
(PostgreSQL: ``bytea`` from the text's UTF-8; SQLite: the table rebuilt by Alembic's batch
mode, the text cast to a BLOB), then packs the existing skin packets in batches of rows
(not in offline ``--sql`` mode: rows left as UTF-8 text are read as well, only larger).

SQLite: a file made before has ``auto_vacuum = NONE``, which can only change with a
``VACUUM``: it is set to INCREMENTAL and the file vacuumed once, after the rows are
converted (their transaction is committed first: SQLite cannot VACUUM inside one; running
this revision again after a crash at that point is harmless, a packed row packs to
itself). The VACUUM needs free disk space about the size of the file, and time (~1 s per
100 MB). Retention can then give freed pages back to the file system
(``history/retention.py``).

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-24
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from wott_hub.events.record import Record
from wott_hub.history.codec import decode_many, encode_records

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

SKIN = "skinDeformedDetection"
_BATCH = 5000


def _convert(bind, pack: bool) -> None:
    """Re-store every skin packet: packed (``pack``) or as its UTF-8 text, in id order."""
    events = sa.table("events", sa.column("id", sa.BigInteger), sa.column("t_ns", sa.BigInteger),
                      sa.column("kind", sa.SmallInteger), sa.column("name", sa.String),
                      sa.column("data", sa.LargeBinary))
    last = -1
    while True:
        rows = bind.execute(sa.select(events.c.id, events.c.t_ns, events.c.data)
                            .where(events.c.name == SKIN, events.c.kind == 0, events.c.id > last)
                            .order_by(events.c.id).limit(_BATCH)).all()
        if not rows:
            return
        last = rows[-1][0]
        texts = decode_many([data for _, _, data in rows], [t_ns for _, t_ns, _ in rows])
        recs = [Record("", 0, 0, SKIN, t_ns, text) for (_, t_ns, _), text in zip(rows, texts, strict=True)]
        stored = encode_records(recs) if pack else [text.encode() for text in texts]
        out = [{"i": id_, "d": new} for (id_, _, data), new in zip(rows, stored, strict=True)
               if new != (data.encode() if isinstance(data, str) else bytes(data))]
        if out:
            bind.execute(sa.text("UPDATE events SET data = :d WHERE id = :i")
                         .bindparams(sa.bindparam("d", type_=sa.LargeBinary)), out)


def _vacuum_incremental(bind) -> None:
    if bind.exec_driver_sql("PRAGMA auto_vacuum").scalar() == 2:
        return
    raw = bind.connection.driver_connection
    raw.commit()  # VACUUM cannot run in a transaction
    raw.execute("PRAGMA auto_vacuum=INCREMENTAL")
    raw.execute("VACUUM")


def upgrade() -> None:
    bind = op.get_bind()
    if bind.dialect.name == "postgresql":
        op.execute("ALTER TABLE events ALTER COLUMN data TYPE bytea USING convert_to(data, 'UTF8')")
    else:
        with op.batch_alter_table("events") as batch:
            batch.alter_column("data", type_=sa.LargeBinary(), existing_type=sa.Text(),
                               existing_nullable=False)
    if op.get_context().as_sql:  # offline SQL: the rows stay UTF-8 text, which codec.decode reads as well
        return
    _convert(bind, pack=True)
    if bind.dialect.name == "sqlite":
        _vacuum_incremental(bind)


def downgrade() -> None:
    bind = op.get_bind()
    if not op.get_context().as_sql:
        _convert(bind, pack=False)
    if bind.dialect.name == "postgresql":
        op.execute("ALTER TABLE events ALTER COLUMN data TYPE text USING convert_from(data, 'UTF8')")
    else:
        with op.batch_alter_table("events") as batch:
            batch.alter_column("data", type_=sa.Text(), existing_type=sa.LargeBinary(),
                               existing_nullable=False)
