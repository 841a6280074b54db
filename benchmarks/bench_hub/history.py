"""History group: events/s written by the batched writer, and replay of one hour of one device.

One 120 Hz device touched all the time (skinDeformedDetection + contactInformation per
frame); the anchor is one INSERT + COMMIT per event, as a naive recorder does.
"""

from __future__ import annotations

import time
from pathlib import Path

from .common import payload

__all__ = ["history_bench", "run"]


def _hour_records(thing: str, frames: int):
    """Records as the pipeline publishes them: a skin packet (its text and its arrays,
    ``SkinArrays``, which history packs) and a contactInformation change per frame."""
    import numpy as np

    from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, SkinArrays, encode

    t0 = time.time_ns()
    contact = encode({"numOfContacts": 1, "contactLocations": [{"x": 1.5, "y": 2.25, "z": 4.0}],
                      "contactForces": [{"x": 0.01, "y": -0.02, "z": -0.35}]})
    nodes = payload(20, 0)["arrayOfDeformedNodes"]
    skin = SkinArrays(np.array([n["deformedNodeID"] for n in nodes]),
                      np.array([n["deformedNodeIntensity"] for n in nodes]))
    seq = 0
    for k in range(frames):
        t = t0 + int(k * 1e9 / 120)
        seq += 1
        yield Record(thing, seq, KIND_EVENT, "skinDeformedDetection", t, encode(payload(20, t)), skin=skin)
        seq += 1
        yield Record(thing, seq, KIND_PROPERTY, "contactInformation", t, contact)


async def history_bench(tmp: Path, frames: int) -> dict:
    import sqlalchemy as sa

    from wott_hub.history import HistoryReader, HistoryWriter, Replayer, create_engine, database_url, upgrade
    from wott_hub.history.models import EventRow

    from ._hub_internals import EventPlane

    engine = create_engine(database_url(tmp / "history.db"))
    upgrade(engine)
    writer = HistoryWriter(engine)
    writer.register_thing("dev", title="dev", family="bench")
    records = list(_hour_records("dev", frames))
    writer.start()
    t0 = time.perf_counter()
    for i in range(0, len(records), 10_000):  # a producer faster than the disk, kept within the queue
        while writer.queue_depth > 200_000:
            time.sleep(0.001)
        for r in records[i:i + 10_000]:
            writer.submit(r)
    assert writer.flush(600)
    write_s = time.perf_counter() - t0
    writer.stop()
    assert writer.dropped == 0 and writer.written == len(records)
    rate = writer.written / write_s

    # anchor: one INSERT + COMMIT per event (what a naive recorder does), for 1.5 s
    naive_engine = create_engine(database_url(tmp / "naive.db"))
    upgrade(naive_engine)
    HistoryWriter(naive_engine).register_thing("dev")
    ins = EventRow.__table__.insert()
    t0 = time.perf_counter()
    n = 0
    with naive_engine.connect() as conn:
        while time.perf_counter() - t0 < 1.5:
            r = records[n]
            conn.execute(ins, {"thing_key": 1, "seq": r.seq, "t_ns": r.t_ns, "kind": r.kind, "name": r.name,
                               "data": r.data.encode()})  # text, as revision 0006 stores it
            conn.commit()
            n += 1
    naive_rate = n / (time.perf_counter() - t0)

    # replay the whole range as fast as possible through the event plane (no subscriber)
    reader = HistoryReader(engine)
    plane = EventPlane()
    plane.add_stream("replay-dev", record=False)
    count = 0

    def emit(r):
        nonlocal count
        plane.publish("replay-dev", r.kind, r.name, r.t_ns, r.data)
        count += 1

    t0 = time.perf_counter()
    await Replayer(reader, "dev", speed=0).run(emit)
    replay_s = time.perf_counter() - t0
    with engine.connect() as conn:
        stored = conn.execute(sa.select(sa.func.count()).select_from(EventRow.__table__)).scalar()
    size_mb = (tmp / "history.db").stat().st_size / 1e6
    engine.dispose()
    naive_engine.dispose()
    return {"records": len(records), "frames": frames, "write_rate": rate, "naive_rate": naive_rate,
            "replayed": count, "replay_s": replay_s, "stored": stored, "size_mb": size_mb}


async def run(tmp: Path, *, quick: bool) -> dict:
    """One hour of records (ten minutes when quick)."""
    frames = 120 * (600 if quick else 3600)
    print(f"history: {frames} frames ...", flush=True)
    r = await history_bench(tmp, frames)
    print(r, flush=True)
    return {"result": r, "span": "10 minutes" if quick else "one hour"}
