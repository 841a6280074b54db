"""History storage (issue 15): bytes per record, write rate, resume and replay of one hour,
before and after compaction; MCAP export of one hour of one device.

One 120 Hz device touched all the time for ``--minutes`` (60): per frame a
skinDeformedDetection packet of 20 nodes as the pipeline publishes it (the text of
``skin_deformed_json``, ids in a moving window, intensities rounded to µm, ~1,100 B, and
its arrays in ``Record.skin``) and a contactInformation change. "before" is the payload
stored as its UTF-8 text (what revision 0005 stored: ``HistoryWriter(compact=False)``),
"after" the packed form of revision 0006 (``history/codec.py``), packed from the arrays;
"after, text only" the same records without their arrays (a replayed or foreign record:
packed from the text), write only. Each into a new SQLite file (WAL, ``synchronous=NORMAL``,
incremental auto-vacuum):

- write: records/s through ``HistoryWriter``'s batch path (encode, INSERT, COMMIT), the
  records submitted 100,000 at a time and written by ``flush`` in this thread;
- bytes/record: pages in use after the write (tables and indexes) / records; the skin
  packet alone from a second file of skin packets only;
- resume: records/s of ``HistoryReader.rows`` (the SSE resume backlog), 5,000 a page;
- replay: ``Replayer`` at speed 0 (as fast as possible) over the whole range, emitting
  into nothing: what the hub's replay costs beyond publishing (the median of 3 runs);
- MCAP: ``export_mcap`` of the whole range with the Foxglove scene channels (30 Hz);
- vector records (issue 29): the skin packets again as ``skinDisplacement`` records (the same
  nodes, a vector each, as the pipeline makes them: ``FieldRecord``, packed by
  ``history/field_codec.py``) against the intensity packets alone, in files of their own, runs
  alternated (intensity, vectors, three times): bytes per record, write and replay rates.

    uv run wott-hub bench storage [--minutes 60]
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import os
import statistics
import tempfile
import time
from pathlib import Path

from report import markdown_table, write_section

__all__ = ["main"]

SKIN = "skinDeformedDetection"


def records(thing: str, frames: int, *, contacts: bool = True, seed: int = 7, arrays: bool = True):
    """The records a hub makes: each skin packet's text is ``skin_deformed_json`` of a real
    ``FrameResult`` and (``arrays``) carries that result's arrays (``Record.skin``), as the
    pipeline publishes it; ``arrays=False``: the text alone (a replayed or foreign record)."""
    import numpy as np

    from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, SkinArrays, encode
    from wott_hub.runtime.payloads import skin_deformed_json
    from wott_hub.tactile.processing import FrameResult

    rng = np.random.default_rng(seed)
    t0 = 1_763_000_000 * 10**9
    seq = 0
    out = []
    centres = rng.integers(0, 700 - 40, frames).tolist()
    inten = np.round(rng.uniform(0.005, 2.5, (frames, 20)), 3)
    for k in range(frames):
        t = t0 + k * 1_000_000_000 // 120
        c = centres[k]
        ids = c + np.sort(rng.choice(40, 20, replace=False))
        res = FrameResult(t, ids, inten[k], False, [], [], True)
        seq += 1
        out.append(Record(thing, seq, KIND_EVENT, SKIN, t, skin_deformed_json(res),
                          skin=SkinArrays(ids, inten[k]) if arrays else None))
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


def text_only(tmp: Path, recs) -> dict:
    """The write rate of the "after" path for records without arrays (packed from their text)."""
    from wott_hub.events.record import Record

    bare = [Record(r.thing, r.seq, r.kind, r.name, r.t_ns, r.data) for r in recs]
    engine, w = _writer(tmp / "text.db", True)
    write_s = _write(engine, w, bare)
    w.stop()
    engine.dispose()
    return {"mode": "after, text only", "write_rate": len(recs) / write_s}


def vector_records(skins) -> list:
    """The ``skinDisplacement`` records of the intensity packets ``skins``: the same frames and nodes,
    a vector per node whose norm is the node's intensity (random directions, some shear)."""
    import numpy as np

    from wott_hub.events.fields import FieldArrays, FieldRecord

    rng = np.random.default_rng(11)
    out = []
    for r in skins:
        ids, inten = r.skin
        d = rng.normal(0, 1, (len(ids), 3))
        d *= (np.asarray(inten) / np.linalg.norm(d, axis=1))[:, None]
        out.append(FieldRecord(r.thing, r.seq, r.t_ns, FieldArrays.of(ids, d)))
    return out


def vectors_against_intensity(tmp: Path, skins, vecs) -> list[list[str]]:
    """Rows: per kind, bytes per record, write and replay rates (medians of three alternated runs)."""
    from wott_hub.history import HistoryReader, Replayer

    runs: dict[str, dict[str, list[float]]] = {}
    for k in range(3):
        for kind, recs in (("skinDeformedDetection (intensity)", skins),
                           ("skinDisplacement (vectors)", vecs)):
            engine, w = _writer(tmp / f"vec-{k}-{kind[:8]}.db", True)
            base = _used(engine)
            write_s = _write(engine, w, recs)
            w.stop()
            used = (_used(engine) - base) / len(recs)
            rp = Replayer(HistoryReader(engine), "dev", speed=0)
            t0 = time.perf_counter()
            asyncio.run(rp.run(lambda r: None))
            replay_s = time.perf_counter() - t0
            assert rp.emitted == len(recs)
            engine.dispose()
            got = runs.setdefault(kind, {"bytes": [], "write": [], "replay": []})
            got["bytes"].append(used)
            got["write"].append(len(recs) / write_s)
            got["replay"].append(len(recs) / replay_s)
    med = statistics.median
    return [[kind, f"{med(r['bytes']):.0f}", f"{med(r['write']):,.0f}", f"{med(r['replay']):,.0f}"]
            for kind, r in runs.items()]


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
    replays = []
    for _ in range(3):
        rp = Replayer(reader, "dev", speed=0)
        t0 = time.perf_counter()
        asyncio.run(rp.run(lambda r: None))
        replays.append(time.perf_counter() - t0)
        assert rp.emitted == len(recs)
    replay_s = statistics.median(replays)
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
    # the run's records out of the garbage collector's scans: a hub does not hold an hour of
    # records in memory, and every full collection would walk them all (before and after alike)
    gc.freeze()
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="wott-bench-storage-") as d:
        tmp = Path(d)
        results = [one_mode(tmp, False, recs, skins), one_mode(tmp, True, recs, skins)]
        texts = text_only(tmp, recs)
        from wott_hub.history.mcap import export_mcap

        path = tmp / "hour.mcap"
        t0 = time.perf_counter()
        with path.open("wb") as f:
            summary = export_mcap(results[1]["reader"], f, ["dev"])
        mcap_s = time.perf_counter() - t0
        mcap_mb = path.stat().st_size / 1e6
        for r in results:
            r["engine"].dispose()
        vec_rows = vectors_against_intensity(tmp, skins, vector_records(skins))
    load_after = os.getloadavg()[0]
    hour = "one hour" if scale == 1 else f"{args.minutes:g} min (x{scale:g} = one hour)"
    rows = [[r["mode"], f"{r['skin_bytes']:.0f}", f"{r['bytes']:.0f}",
             f"{r['bytes'] * len(recs) * scale / 1e6:.0f}",
             f"{r['write_rate']:,.0f}", f"{r['resume_rate']:,.0f}", f"{r['replay_s'] * scale:.2f}"]
            for r in results]
    rows.append([texts["mode"], "=", "=", "=", f"{texts['write_rate']:,.0f}", "=", "="])
    table = markdown_table(["storage", "B / skin record", "B / record (all)", "MB / hour",
                            "write (records/s)", "resume (records/s)", "replay of one hour (s)"], rows)
    before, after = results
    body = f"""
One 120 Hz device, {frames:,} frames ({hour}): {len(recs):,} records, a skinDeformedDetection
packet of 20 nodes ({avg_skin:.0f} B of JSON, with its arrays as the pipeline publishes it) and a
contactInformation change per frame. "before": payloads stored as their text (revision 0005);
"after": skin packets packed from their arrays (revision 0006, `history/codec.py`), read back to
the identical text; "after, text only": the same records without arrays (a replayed or foreign
record: packed from its text; "=": stored and read as "after"). Targets: ≤ 200 B per skin
record, ≥ 50,000 records/s written, one hour replayed in ≤ 5 s.

{table}

Skin record: {before['skin_bytes']:.0f} B → {after['skin_bytes']:.0f} B
({before['skin_bytes'] / after['skin_bytes']:.1f}x smaller, row and both indexes included).
MB / hour and replay time are {"measured on one hour" if scale == 1 else "the run scaled to one hour"}.
Rates are wall-clock: load average {load_before:.2f} before, {load_after:.2f} after (the machine's
cores shared with other jobs make them vary by up to ~2x from run to run).

MCAP export of the same {hour} (`export_mcap`, every record plus the Foxglove scene channels
at 30 Hz: {summary.scene_messages:,} SceneUpdate messages, zstd chunks):
{mcap_s * scale:.1f} s, {mcap_mb * scale:.0f} MB{" (scaled)" if scale != 1 else ""}.

Vector records (issue 29): {len(skins):,} skin packets of 20 nodes, as intensity packets and as
`skinDisplacement` packets (the same nodes with their vectors, ~2,300 B of JSON each, packed by
`history/field_codec.py` and read back to the identical text), each kind in a file of its own
(row and indexes included), three runs alternated, medians. Target: ≤ 400 B per 20-node vector
record, the same write and replay rates as the intensity records.

{markdown_table(["records", "B / record", "write (records/s)", "replay (records/s)"], vec_rows)}
"""
    print(body)
    if not args.no_doc:
        write_section("storage", "History storage: compaction, replay, MCAP export (issue 15)", body,
                      f"uv run wott-hub bench storage{'' if scale == 1 else f' --minutes {args.minutes:g}'}")


if __name__ == "__main__":
    main()
