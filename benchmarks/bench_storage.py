"""History storage (issue 15): bytes per record, write rate, resume and replay of one hour,
before and after compaction; MCAP export of one hour of one device.

One 120 Hz device touched all the time for ``--minutes`` (60): per frame a
skinDeformedDetection packet of ~20 nodes in the pipeline's exact text (ids in a moving
window, intensities rounded to µm, ~720 B) and a contactInformation change. "before" is
the payload stored as its UTF-8 text (what revision 0005 stored: ``HistoryWriter(compact=
False)``), "after" the packed form of revision 0006 (``history/codec.py``). Each into a
new SQLite file (WAL, ``synchronous=NORMAL``, incremental auto-vacuum):

- write: records/s through ``HistoryWriter``'s batch path (encode, INSERT, COMMIT), the
  records submitted 100,000 at a time and written by ``flush`` in this thread;
- bytes/record: pages in use after the write (tables and indexes) / records; the skin
  packet alone from a second file of skin packets only;
- resume: records/s of ``HistoryReader.rows`` (the SSE resume backlog), 5,000 a page;
- replay: ``Replayer`` at speed 0 (as fast as possible) over the whole range, emitting
  into nothing: what the hub's replay costs beyond publishing;
- MCAP: ``export_mcap`` of the whole range with the Foxglove scene channels (30 Hz).

    uv run wott-hub bench storage [--minutes 60]
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
import time
from pathlib import Path

from report import markdown_table, write_section

__all__ = ["main"]

SKIN = "skinDeformedDetection"


def records(thing: str, frames: int, *, contacts: bool = True, seed: int = 7):
    import numpy as np

    from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, encode

    rng = np.random.default_rng(seed)
    t0 = 1_763_000_000 * 10**9
    seq = 0
    out = []
    centres = rng.integers(0, 700 - 40, frames).tolist()
    inten = np.round(rng.uniform(0.005, 2.5, (frames, 20)), 3).tolist()
    for k in range(frames):
        t = t0 + k * 1_000_000_000 // 120
        c = centres[k]
        ids = sorted(rng.choice(40, 20, replace=False).tolist())
        nodes = ",".join(f'{{"deformedNodeID":{c + i},"deformedNodeIntensity":{v!r}}}'
                         for i, v in zip(ids, inten[k], strict=True))
        seq += 1
        out.append(Record(thing, seq, KIND_EVENT, SKIN, t,
                          f'{{"timeStamp":{t},"numOfDeformedNodes":20,"arrayOfDeformedNodes":[{nodes}]}}'))
        if contacts:
            seq += 1
            out.append(Record(thing, seq, KIND_PROPERTY, "contactInformation", t, encode(
                {"numOfContacts": 1, "contactLocations": [{"x": round(c * 0.1, 3), "y": 2.25, "z": 4.0}],
                 "contactForces": [{"x": 0.01, "y": -0.02, "z": round(-0.3 - inten[k][0] * 0.01, 4)}]})))
    return out


def _writer(path: Path, compact: bool):
    import json

    from wott_hub.examples import example_device
    from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade
    from wott_hub.td.builder import build_tactile_td, static_property_values

    engine = create_engine(database_url(path))
    upgrade(engine)
    w = HistoryWriter(engine, compact=compact, integrity_check=False)
    desc = example_device("barrel", "dev")
    w.register_thing("dev", title="dev", family="bench", td=json.dumps(build_tactile_td(desc)),
                     static_values=json.dumps(static_property_values(desc)))
    return engine, w


def _write(engine, w, recs) -> float:
    t0 = time.perf_counter()
    for i in range(0, len(recs), 100_000):
        for r in recs[i:i + 100_000]:
            w.submit(r)
        assert w.flush(3600)
    dt = time.perf_counter() - t0
    assert w.written == len(recs) and w.dropped == 0
    return dt


def _used(engine) -> int:
    from wott_hub.history.retention import used_bytes

    with engine.connect() as conn:
        return used_bytes(conn)


def one_mode(tmp: Path, compact: bool, recs, skins) -> dict:
    from wott_hub.events.record import KIND_EVENT
    from wott_hub.history import HistoryReader, Replayer

    name = "after" if compact else "before"
    engine, w = _writer(tmp / f"{name}.db", compact)
    base = _used(engine)
    write_s = _write(engine, w, recs)
    w.stop()
    used = _used(engine) - base
    reader = HistoryReader(engine)
    # resume: the SSE backlog path, skin packets of the first 100,000 seqs
    t0 = time.perf_counter()
    after, n, top = 0, 0, min(100_000, len(recs))
    while after < top:
        got, after = reader.rows("dev", after, top, (KIND_EVENT, SKIN), 5000)
        n += len(got)
    resume_rate = top / (time.perf_counter() - t0)
    rp = Replayer(reader, "dev", speed=0)
    t0 = time.perf_counter()
    asyncio.run(rp.run(lambda k, nm, t, d: None))
    replay_s = time.perf_counter() - t0
    assert rp.emitted == len(recs)
    # the skin packet alone
    e2, w2 = _writer(tmp / f"{name}-skin.db", compact)
    b2 = _used(e2)
    _write(e2, w2, skins)
    w2.stop()
    skin_bytes = (_used(e2) - b2) / len(skins)
    e2.dispose()
    return {"mode": name, "write_rate": len(recs) / write_s, "bytes": used / len(recs),
            "skin_bytes": skin_bytes, "resume_rate": resume_rate, "replay_s": replay_s, "engine": engine,
            "reader": reader}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=60.0, help="Recorded time of the device (default 60).")
    ap.add_argument("--no-doc", action="store_true", help="Print only; leave docs/benchmarks.md alone.")
    args = ap.parse_args()
    frames = int(args.minutes * 60 * 120)
    scale = 60.0 / args.minutes
    recs = records("dev", frames)
    skins = records("dev", min(frames, 60_000), contacts=False, seed=8)
    avg_skin = sum(len(r.data) for r in recs if r.name == SKIN) / frames
    with tempfile.TemporaryDirectory(prefix="wott-bench-storage-") as d:
        tmp = Path(d)
        results = [one_mode(tmp, False, recs, skins), one_mode(tmp, True, recs, skins)]
        from wott_hub.history.mcap import export_mcap

        path = tmp / "hour.mcap"
        t0 = time.perf_counter()
        with path.open("wb") as f:
            summary = export_mcap(results[1]["reader"], f, ["dev"])
        mcap_s = time.perf_counter() - t0
        mcap_mb = path.stat().st_size / 1e6
        for r in results:
            r["engine"].dispose()
    hour = "one hour" if scale == 1 else f"{args.minutes:g} min (x{scale:g} = one hour)"
    rows = [[r["mode"], f"{r['skin_bytes']:.0f}", f"{r['bytes']:.0f}",
             f"{r['bytes'] * len(recs) * scale / 1e6:.0f}",
             f"{r['write_rate']:,.0f}", f"{r['resume_rate']:,.0f}", f"{r['replay_s'] * scale:.2f}"]
            for r in results]
    table = markdown_table(["storage", "B / skin record", "B / record (all)", "MB / hour",
                            "write (records/s)", "resume (records/s)", "replay of one hour (s)"], rows)
    before, after = results
    body = f"""
One 120 Hz device, {frames:,} frames ({hour}): {len(recs):,} records, a skinDeformedDetection
packet of 20 nodes ({avg_skin:.0f} B of JSON) and a contactInformation change per frame. "before":
payloads stored as their text (revision 0005); "after": skin packets packed (revision 0006,
`history/codec.py`), read back to the identical text. Targets: ≤ 200 B per skin record,
≥ 50,000 records/s written, one hour replayed in ≤ 5 s.

{table}

Skin record: {before['skin_bytes']:.0f} B → {after['skin_bytes']:.0f} B
({before['skin_bytes'] / after['skin_bytes']:.1f}x smaller, row and both indexes included).
MB / hour and replay time are {"measured on one hour" if scale == 1 else "the run scaled to one hour"}.

MCAP export of the same {hour} (`export_mcap`, every record plus the Foxglove scene channels
at 30 Hz: {summary.scene_messages:,} SceneUpdate messages, zstd chunks):
{mcap_s * scale:.1f} s, {mcap_mb * scale:.0f} MB{" (scaled)" if scale != 1 else ""}.
"""
    print(body)
    if not args.no_doc:
        write_section("storage", "History storage: compaction, replay, MCAP export (issue 15)", body,
                      f"uv run wott-hub bench storage{'' if scale == 1 else f' --minutes {args.minutes:g}'}")


if __name__ == "__main__":
    main()
