"""When retention runs (``retention.RetentionClock``, issue 48 item 8): at once, then every
``check_every_s``, and sooner once the database grew by a tenth of ``max_mb`` (at least 1 MB), on
a real SQLite file (its file and WAL) and a real PostgreSQL table (``pg_total_relation_size``)."""

from __future__ import annotations

import base64
import json
import os

from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history import retention as R


def _grow(writer, thing: str, mb: float) -> None:
    start = writer.register_thing(thing)
    writer.start()
    for i in range(int(mb * 1e6 / 4000)):  # random text: neither the codec nor TOAST shrinks it much
        blob = base64.b64encode(os.urandom(3000)).decode()
        writer.submit(Record(thing, start + i + 1, KIND_EVENT, "tick", 10**18 + i, json.dumps({"b": blob})))
    assert writer.flush(60)


def test_a_pass_is_due_at_once_then_by_time_or_by_growth(engine, writer, monkeypatch):
    clock = R.RetentionClock(R.Retention(max_mb=5.0), engine)  # a pass per 1 MB grown (1 MB > 10 %)
    assert clock.due()  # the first at once
    clock.done()
    assert not clock.due()  # neither the minute nor the bytes
    monkeypatch.setattr(R, "MIN_GAP_S", 0.0)
    monkeypatch.setattr(R, "PG_SIZE_EVERY_S", 0.0)
    _grow(writer, "small", 0.2)
    assert not clock.due()  # 0.2 MB: not yet
    _grow(writer, "big", 3.0)
    assert clock.due()  # 3 MB written: due before the minute is up
    clock.done()
    assert not clock.due()


def test_without_a_size_limit_only_time_says_when(engine, writer, monkeypatch):
    clock = R.RetentionClock(R.Retention(days=1.0), engine)
    assert clock.due()
    clock.done()
    monkeypatch.setattr(R, "MIN_GAP_S", 0.0)
    monkeypatch.setattr(R, "PG_SIZE_EVERY_S", 0.0)
    _grow(writer, "big", 3.0)
    assert not clock.due()
