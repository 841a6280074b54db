"""Vector records in history (issue 29): ``skinDisplacement`` packets stored as their numbers and read
back to the exact text sent live, whatever the batch holds; ≤ 400 B for 20 nodes."""

from __future__ import annotations

import numpy as np
import pytest

from wott_hub.events.fields import SKIN_DISPLACEMENT, FieldArrays, FieldRecord, displacement_json
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record
from wott_hub.history.codec import PACKED, PACKED_FIELD, decode, decode_joined, decode_many, encode_records
from wott_hub.history.field_codec import field_texts

T0 = 1_763_000_000 * 10**9


def _mixed(n: int, seed: int) -> list[Record]:
    """Vector records made by the pipeline and as bare text, skin packets, properties, foreign texts;
    node ids beyond the tables' and components beyond ±65.535 mm and ±32.767 mm now and then."""
    rng = np.random.default_rng(seed)
    out: list[Record] = []
    for k in range(n):
        t = T0 + k * 8_333_333
        nodes = int(rng.integers(0, 40))
        ids = rng.choice(70_000 if k % 41 == 0 else 707, nodes, replace=False)
        scale = 120.0 if k % 29 == 0 else 40.0 if k % 31 == 0 else 2.0
        vec = rng.normal(0, scale, (nodes, 3)) * (0 if k % 17 == 0 else 1)
        field = FieldArrays.of(ids, vec)
        kind = k % 5
        if kind in (0, 1):
            out.append(FieldRecord("d", k, t, field))
        elif kind == 2:  # a replayed record, or one an embedding program published: text only
            text = displacement_json(t, field)
            out.append(Record("d", k, KIND_EVENT, SKIN_DISPLACEMENT, t + (k % 3), text))
        elif kind == 3:
            out.append(Record("d", k, KIND_PROPERTY, "contactInformation", t, '{"numOfContacts":0}'))
        else:  # the name, not the hub's form: stored as its text
            out.append(Record("d", k, KIND_EVENT, SKIN_DISPLACEMENT, t, '{"timeStamp":1,"note":"é"}'))
    return out


@pytest.mark.parametrize("seed", [1, 2])
def test_every_payload_comes_back_exactly_one_by_one_in_batches_and_joined(seed):
    recs = _mixed(1500, seed)
    stored = encode_records(recs)
    times = [r.t_ns for r in recs]
    assert decode_many(stored, times) == [r.data for r in recs]
    size = np.array([len(b) for b in stored], np.int64)
    joined = b"".join(stored) + bytes(16)
    assert decode_joined(joined, size, np.array(times, np.int64)) == [r.data for r in recs]
    assert all(decode(b, t) == r.data for b, t, r in zip(stored[:200], times, recs, strict=False))
    packed = [b for b, r in zip(stored, recs, strict=True)
              if r.name == SKIN_DISPLACEMENT and b[:1] == bytes((PACKED_FIELD,))]
    assert len(packed) >= 800 and all(b[:1] != bytes((PACKED,)) for b in packed)
    foreign = [b for b, r in zip(stored, recs, strict=True) if r.data.startswith('{"timeStamp":1,')]
    assert foreign and all(b[:1] == b"{" for b in foreign)  # stored as text


def test_a_20_node_record_is_packed_in_at_most_400_bytes():
    rng = np.random.default_rng(4)
    for scale in (1.0, 20.0):  # components in int16 µm, then beyond: int32
        field = FieldArrays.of(np.sort(rng.choice(707, 20, replace=False)), rng.normal(0, scale, (20, 3)))
        stored = encode_records([FieldRecord("d", 1, T0, field)])[0]
        assert stored[0] == PACKED_FIELD and len(stored) <= 400
    ones = FieldArrays.of(np.arange(20), np.ones((20, 3)))
    assert len(encode_records([FieldRecord("d", 1, T0, ones)])[0]) == 164  # 4 + 2 x 20 + 6 x 20


def test_a_packet_beyond_the_packed_form_is_stored_as_its_text():
    huge = FieldArrays.of([1], [[3e6, 0, 0]])  # 3 km: beyond int32 µm
    rec = FieldRecord("d", 1, T0, huge)
    stored = encode_records([rec])[0]
    assert stored == rec.data.encode() and decode(stored, T0) == rec.data


def test_damaged_packed_bytes_raise_instead_of_reading_garbage():
    good = encode_records([FieldRecord("d", 1, T0, FieldArrays.of(np.arange(5), np.ones((5, 3))))])[0]
    with pytest.raises(ValueError, match="damaged"):
        field_texts([good[:-3]], [T0])
    with pytest.raises(ValueError, match="damaged"):
        field_texts([good[:2]], [T0])


@pytest.mark.parametrize("outlier", [None, "id", "value", "empty"])
def test_a_batch_of_pipeline_records_packs_as_each_record_alone(outlier):
    """The batch path (``_pack_many``: one quantisation and one conversion for all the records the
    pipeline made) gives each record the bytes ``_pack`` gives it alone, and decodes to its text;
    one record beyond the 16-bit forms (or with no node) sends the batch one by one."""
    from wott_hub.history.field_codec import _pack, encode_fields

    rng = np.random.default_rng(7)
    recs, alone = [], []
    for k in range(300):
        ids = np.sort(rng.choice(700, int(rng.integers(1, 30)), replace=False))
        mm = rng.normal(0, 1.5, (len(ids), 3))
        if k == 150 and outlier == "id":
            ids[-1] = 70_000
        elif k == 150 and outlier == "value":
            mm[0, 0] = 40.0
        elif k == 150 and outlier == "empty":
            ids, mm = ids[:0], mm[:0]
        t = T0 + k * 8_333_333
        rec = FieldRecord("d", k + 1, t, rows=(ids, mm.copy()))  # as the pipeline hands it over
        if k % 7 == 0:
            rec.field  # noqa: B018 - quantised already (a subscriber read it first)
        recs.append(rec)
        alone.append(_pack(t, t, FieldArrays.of(ids, mm)))
    stored = encode_fields(recs)
    assert stored == alone
    assert decode_many(stored, [r.t_ns for r in recs]) == [r.data for r in recs]
