"""Compact storage (revision 0006): skin packets packed as numbers, the identical text read back
(SSE resume sends what was sent live), ≤ 200 B per record of ~20 nodes on SQLite, and the
migration converting a database made with revision 0005 on either engine."""

from __future__ import annotations

import json

import sqlalchemy as sa
from alembic import command

from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history import HistoryReader, create_engine, upgrade
from wott_hub.history.codec import PACKED, decode, encode
from wott_hub.history.db import _alembic_config, current_revision
from wott_hub.history.models import HEAD_REVISION
from wott_hub.history.retention import used_bytes

from .skin_records import register_device, skin_json, skin_records

SKIN = "skinDeformedDetection"


def _stored(engine, thing_key=None) -> list[tuple[str, bytes | str]]:
    with engine.connect() as conn:
        return [(n, d) for n, d in conn.exec_driver_sql("SELECT name, data FROM events ORDER BY id").all()]


def test_skin_packets_are_stored_packed_and_read_back_byte_for_byte(writer, reader):
    start, n = register_device(writer, "pad")
    recs = skin_records("pad", start, 400, n)
    odd = [  # not packable: stored as text, read back as is
        skin_json(recs[-1].t_ns + 1, [3, 1], [0.5, 0.25]),  # ids not ascending: still packed (4-byte ids)
        skin_json(recs[-1].t_ns + 2, [1, 2], [0.12345, 0.5]),  # not whole µm
        skin_json(recs[-1].t_ns + 3, [], []),
        '{"timeStamp":1,"numOfDeformedNodes":1,"arrayOfDeformedNodes":[{"deformedNodeIntensity":0.5,'
        '"deformedNodeID":3}]}',  # another key order
        '{"timeStamp": 1, "numOfDeformedNodes": 0, "arrayOfDeformedNodes": []}',  # spaces
        json.dumps({"ünïcode": "✓"}, ensure_ascii=False),
    ]
    seq = recs[-1].seq
    for i, d in enumerate(odd):
        seq += 1
        recs.append(Record("pad", seq, KIND_EVENT, SKIN, recs[-1].t_ns + 10 + i, d))
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    stored = [d for n, d in _stored(writer.storage.engine) if n == SKIN]
    packed = [bytes(d) for d in stored if bytes(d)[0] == PACKED]
    assert len(packed) == 400 + 2  # every packet of the pipeline's form, the empty one, the unsorted one
    assert max(len(p) for p in packed[:400]) < 120  # ~20 nodes: ~66 B instead of ~1,100 B of JSON
    # resume (the event plane's HistorySource) and ranges give back every byte sent live
    got, _ = reader.rows("pad", start, seq, (KIND_EVENT, SKIN), 10_000)
    assert [r.data for r in got] == [r.data for r in recs if r.name == SKIN]
    paged = [row.data for page in reader.pages("pad", names=[SKIN], page=97) for row in page]
    assert paged == [r.data for r in recs if r.name == SKIN]
    assert all(decode(encode(0, SKIN, r.t_ns, r.data), r.t_ns) == r.data for r in recs)


def test_a_skin_record_of_20_nodes_takes_at_most_200_bytes_on_sqlite(tmp_path):
    from wott_hub.history import HistoryWriter, database_url

    engine = create_engine(database_url(tmp_path / "size.db"))
    upgrade(engine)
    w = HistoryWriter(engine, interval_s=0.01)
    start, n = register_device(w, "barrel", shape="barrel")
    recs = [r for r in skin_records("barrel", start, 30_000, n, per_frame=20) if r.name == SKIN]
    with engine.connect() as conn:
        before = used_bytes(conn)
    w.start()
    for r in recs:
        w.submit(r)
    assert w.flush(120)
    w.stop()
    with engine.connect() as conn:
        per_record = (used_bytes(conn) - before) / len(recs)
    engine.dispose()
    assert 20 <= sum(1 for _ in recs[0].data.split("deformedNodeID")) - 1 <= 20
    assert per_record <= 200, per_record


def test_the_migration_converts_a_database_made_with_revision_0005(database):
    engine = create_engine(database)
    cfg = _alembic_config()
    with engine.connect() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "0005")
        conn.commit()
    assert current_revision(engine) == "0005"
    recs = skin_records("old", 0, 300, 256, t0_ns=10**18)
    with engine.begin() as conn:
        key = conn.execute(sa.text("INSERT INTO things (id, title, family, seq_reserved, updated_ns) "
                                   "VALUES ('old', 'old', 'scene', 0, 0) RETURNING key")).scalar()
        conn.execute(sa.text("INSERT INTO events (thing_key, seq, t_ns, kind, name, data) "
                             "VALUES (:k, :s, :t, :kind, :n, :d)"),
                     [{"k": key, "s": r.seq, "t": r.t_ns, "kind": r.kind, "n": r.name, "d": r.data}
                      for r in recs])
    assert upgrade(engine) == HEAD_REVISION
    stored = _stored(engine)
    skins = [bytes(d) for n, d in stored if n == SKIN]
    assert skins and all(d[0] == PACKED for d in skins)
    others = [d for n, d in stored if n != SKIN]
    assert others and all(decode(d, 0)[0] == "{" for d in others)
    reader = HistoryReader(engine)
    assert [row.data for page in reader.pages("old") for row in page] == [r.data for r in recs]
    if engine.dialect.name == "sqlite":
        with engine.connect() as conn:  # the file was vacuumed into incremental auto-vacuum
            assert conn.exec_driver_sql("PRAGMA auto_vacuum").scalar() == 2
    # and back: revision 0005 stores the same texts again
    with engine.connect() as conn:
        cfg.attributes["connection"] = conn
        command.downgrade(cfg, "0005")
        conn.commit()
    with engine.connect() as conn:
        texts = [d for (d,) in conn.exec_driver_sql("SELECT data FROM events ORDER BY id").all()]
    assert texts == [r.data for r in recs]
    engine.dispose()


# --- the codec's fast paths (tables of canonical texts, cached formats): every payload, packed
# or not, comes back byte for byte; the pipeline's own packets are always packed

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_MICRO = st.one_of(st.integers(0, 8191), st.integers(8192, 0xFFFF))  # in the tables and beyond
_IDS = st.lists(st.one_of(st.integers(0, 8191), st.integers(8192, 2**32 + 5)), max_size=40)


@settings(max_examples=300, deadline=None)
@given(ids=_IDS, micro=st.data(), t=st.integers(0, 2**63 - 1), same_time=st.booleans(), sort=st.booleans())
def test_pipeline_packets_round_trip_through_every_codec_path(ids, micro, t, same_time, sort):
    if sort:
        ids = sorted(set(ids))
    um = micro.draw(st.lists(_MICRO, min_size=len(ids), max_size=len(ids)))
    text = skin_json(t, ids, [k / 1000 for k in um])
    t_ns = t if same_time else t + 1
    stored = encode(0, SKIN, t_ns, text)
    assert decode(stored, t_ns) == text
    if max(ids, default=0) <= 0xFFFFFFFF:
        assert stored[0] == PACKED  # the pipeline's form with ids that fit is always packed


_SKIN_20 = skin_json(10**18, list(range(100, 120)), [(k * 37 % 2500) / 1000 for k in range(20)])


@settings(max_examples=400, deadline=None)
@given(pos=st.integers(0, len(_SKIN_20) - 1), cut=st.integers(0, 3),
       insert=st.sampled_from(["", "0", "1", ".", " ", ",", "}", "=", ";", "05", "1.5", "-", "e3", "_"]))
def test_a_changed_packet_text_still_comes_back_byte_for_byte(pos, cut, insert):
    text = _SKIN_20[:pos] + insert + _SKIN_20[pos + cut:]
    assert decode(encode(0, SKIN, 10**18, text), 10**18) == text


def test_odd_packets_that_look_like_the_pipelines_come_back_exactly():
    head = '{"timeStamp":5,"numOfDeformedNodes":2,"arrayOfDeformedNodes":['
    i, v, j = '{"deformedNodeID":', ',"deformedNodeIntensity":', "},"
    odd = [
        head + i + "05" + v + "0.5" + j + i + "6" + v + "0.25}]}",  # leading zero
        head + i + "5" + v + "0.50" + j + i + "6" + v + "0.25}]}",  # not float repr
        head + i + "5" + v + "0.5" + v + "6" + j + i + "0.25}]}",  # separators swapped
        head + i + "5" + v + "0.5" + j + i + "1_0" + v + "0.25}]}",  # int() would take it
        head + i + " 5" + v + "0.5" + j + i + "6" + v + "0.25}]}",  # a space
        head + i + "8192" + v + "8.192" + j + i + "9000" + v + "65.535}]}",  # beyond the tables
    ]
    for text in odd:
        assert decode(encode(0, SKIN, 5, text), 5) == text
    assert encode(0, SKIN, 5, odd[-1])[0] == PACKED  # beyond the tables: computed, still packed


# --- packing from the pipeline's arrays (Record.skin): the same bytes as from the text, and the
# text back whatever the arrays hold

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from wott_hub.events.record import SkinArrays  # noqa: E402
from wott_hub.history.codec import decode_many, encode_records  # noqa: E402
from wott_hub.runtime.payloads import skin_deformed_json  # noqa: E402
from wott_hub.tactile.processing import FrameResult  # noqa: E402


def _pipeline_record(seq: int, t_ns: int, ids, intensity, *, same_time: bool = True) -> Record:
    """A skin record as the pipeline publishes it: the text of ``skin_deformed_json``, the arrays."""
    ids = np.asarray(ids, np.int64)
    intensity = np.asarray(intensity, np.float64)
    text = skin_deformed_json(FrameResult(t_ns, ids, intensity, False, [], [], True))
    return Record("pad", seq, KIND_EVENT, SKIN, t_ns if same_time else t_ns + 7, text,
                  skin=SkinArrays(ids, intensity))


_GAPPY_IDS = st.lists(st.one_of(st.integers(0, 300), st.integers(0, 2**32 + 9)), max_size=60,
                      unique=True).map(sorted)  # small gaps, gaps > 255, ids beyond uint32
_INTENSITY = st.one_of(
    st.integers(0, 3000).map(lambda k: round(k / 1000, 3)),  # the processor's µm, in the tables
    st.integers(65_000, 70_000).map(lambda k: round(k / 1000, 3)),  # 65.535 mm and beyond uint16
    st.floats(0, 100, allow_nan=False),  # not a whole number of µm
)


@settings(max_examples=200, deadline=None)
@given(packets=st.lists(st.tuples(_GAPPY_IDS, st.data(), st.integers(0, 2**63 - 8), st.booleans()),
                        max_size=12))
def test_packets_packed_from_arrays_come_back_exactly_and_as_packed_from_text(packets):
    recs = []
    for seq, (ids, data, t, same_time) in enumerate(packets):
        values = data.draw(st.lists(_INTENSITY, min_size=len(ids), max_size=len(ids)))
        recs.append(_pipeline_record(seq, t, ids, values, same_time=same_time))
    stored = encode_records(recs)
    assert decode_many(stored, [r.t_ns for r in recs]) == [r.data for r in recs]
    # the arrays give the bytes the text gives: one stored format, whichever the writer had
    assert stored == [encode(r.kind, r.name, r.t_ns, r.data) for r in recs]
    for r, s in zip(recs, stored, strict=True):
        fits = (not len(r.skin.ids) or r.skin.ids.max() <= 0xFFFFFFFF) and all(
            round(v * 1000) / 1000 == v <= 65.535 for v in r.skin.intensity.tolist())  # whole µm, uint16
        assert (s[0] == PACKED) == fits, r.data


def test_release_and_empty_packets_are_packed_from_their_arrays():
    recs = [_pipeline_record(1, 10**18, [], []),  # nothing deformed
            _pipeline_record(2, 10**18 + 1, [4, 5, 900], [0.0, 0.0, 0.0]),  # the final all-zero packet
            _pipeline_record(3, 10**18 + 2, list(range(40_000, 40_000 + 300, 3)), [65.535] * 100)]
    stored = encode_records(recs)
    assert [s[0] for s in stored] == [PACKED] * 3
    assert [decode(s, r.t_ns) for s, r in zip(stored, recs, strict=True)] == [r.data for r in recs]


def test_arrays_that_do_not_give_the_text_back_fall_back_to_the_text():
    good = _pipeline_record(1, 10**18, [1, 2, 3], [0.5, 0.25, 1.0])
    other = [
        SkinArrays(np.array([1, 2, 4]), np.array([0.5, 0.25, 1.0])),  # another id
        SkinArrays(np.array([1, 2, 3]), np.array([0.5, 0.25, 1.001])),  # another intensity
        SkinArrays(np.array([1, 2]), np.array([0.5, 0.25])),  # fewer nodes
        SkinArrays(np.array([1, 2, 3]), np.array([0.5, np.nan, 1.0])),
        SkinArrays(np.array([-1, 2, 3]), np.array([0.5, 0.25, 1.0])),
        SkinArrays(np.array([[1, 2, 3]] * 3), np.array([[0.5, 0.25, 1.0]] * 3)),  # not what NumPy can join
        SkinArrays(np.array([1, 2, 3], dtype=object), np.array([0.5, 0.25, 1.0])),
        SkinArrays([1, 2, 3], [0.5, 0.25, 1.0]),  # type: ignore[arg-type]  # lists, not arrays
    ]
    recs = [Record("pad", i, KIND_EVENT, SKIN, good.t_ns, good.data, skin=s) for i, s in enumerate(other)]
    foreign = '{"timeStamp":1,"numOfDeformedNodes":1,"arrayOfDeformedNodes":[{"deformedNodeID":3,' \
              '"deformedNodeIntensity":0.1234}]}'  # arrays of a text the pipeline could not have made
    recs.append(Record("pad", 9, KIND_EVENT, SKIN, 1, foreign,
                       skin=SkinArrays(np.array([3]), np.array([0.123]))))
    stored = encode_records(recs)
    # the text parser packs what the arrays could not (same bytes as the good record), or the text is kept
    assert stored[:-1] == [encode_records([good])[0]] * len(other)
    assert stored[-1] == foreign.encode()
    assert decode_many(stored, [r.t_ns for r in recs]) == [r.data for r in recs]


def test_decode_many_reads_every_stored_form_and_refuses_a_damaged_packet():
    rec = _pipeline_record(1, 10**18, [7, 8], [0.5, 2.0])
    packed = encode_records([rec])[0]
    stored = [packed, memoryview(packed), rec.data, rec.data.encode(), memoryview(b'{"a":1}'), b""]
    assert decode_many(stored, [rec.t_ns] * 6) == [rec.data] * 4 + ['{"a":1}', ""]
    for damaged in (packed[:-1], packed + b"\0", packed[:2]):
        with pytest.raises(ValueError, match="damaged"):
            decode_many([damaged], [rec.t_ns])


def test_the_writer_packs_the_pipelines_records_from_their_arrays(writer, reader):
    start, n = register_device(writer, "pad")
    rng = np.random.default_rng(3)
    recs = []
    for i in range(300):
        ids = np.sort(rng.choice(n, size=int(rng.integers(0, 30)), replace=False))
        recs.append(_pipeline_record(start + 1 + i, 10**18 + i * 8_333_333, ids,
                                     np.round(rng.uniform(0.001, 3.0, len(ids)), 3)))
        recs[-1].thing = "pad"
    recs[5].skin = SkinArrays(recs[5].skin.ids + 1, recs[5].skin.intensity)  # wrong arrays: the text decides
    writer.start()
    for r in recs:
        writer.submit(r)
    assert writer.flush()
    stored = [bytes(d) for _, d in _stored(writer.storage.engine)]
    assert all(d[0] == PACKED for d in stored)
    assert stored == [encode(r.kind, r.name, r.t_ns, r.data) for r in recs]
    got, _ = reader.rows("pad", start, recs[-1].seq, (KIND_EVENT, SKIN), 10_000)
    assert [r.data for r in got] == [r.data for r in recs]


def test_a_batch_longer_than_a_chunk_and_joined_payloads_decode_as_one_by_one():
    """``decode_many`` works in chunks of rows and ``decode_joined`` (a page SQLite joined into one
    value) slices the same payloads out of one buffer: both give each row's own text, in order."""
    from wott_hub.history.codec import _CHUNK, decode_joined

    rng = np.random.default_rng(5)
    recs = []
    for i in range(2 * _CHUNK + 77):
        t = 10**18 + i * 8_333_333
        if i % 3 == 2:  # text rows between the packets, some not ASCII, some empty
            text = ["", '{"é":1}', '{"a":2}'][i % 2 + (i % 5 == 0)]
            recs.append(Record("pad", i, KIND_EVENT, "note", t, text))
            continue
        ids = np.sort(rng.choice(12_000 if i % 7 == 0 else 700, size=int(rng.integers(0, 25)), replace=False))
        values = np.round(rng.uniform(0, 3, len(ids)), 3)
        recs.append(_pipeline_record(i, t, ids, values, same_time=i % 4 != 1))
    stored = encode_records(recs)
    assert sum(s[:1] == bytes((PACKED,)) for s in stored) > _CHUNK
    times = [r.t_ns for r in recs]
    assert decode_many(stored, times) == [r.data for r in recs]
    joined = b"".join(stored) + bytes(16)
    sizes = np.array([len(s) for s in stored], np.int64)
    assert decode_joined(joined, sizes, np.array(times, np.int64)) == [r.data for r in recs]
    with pytest.raises(ValueError, match="lengths"):
        decode_joined(joined[:-1], sizes, np.array(times, np.int64))
