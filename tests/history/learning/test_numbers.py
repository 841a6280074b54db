"""Skin packets read as numbers (``history/numbers.py``) are the records read as text, and the export
that reads them so writes the values the text path writes (issue 46: the export's speed must not
change a value).

The session: a flat skin recording at 30 Hz what the hub records (skin packets from the pipeline's
arrays and displacement fields, both stored packed; contacts) and, among them, packets stored as text,
which the numbers path must hand to the text path: packets of a foreign driver (spaced JSON, an
intensity that is not a whole µm), a packet whose timeStamp is not its record's time (packed, but not
read as numbers), node ids the mesh does not have, and a displacement beyond ±65.535 mm.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from wott_hub.events.fields import FieldArrays, FieldRecord
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, SkinArrays, encode
from wott_hub.history.learning.export import DatasetRequest, export_dataset
from wott_hub.history.numbers import PackedRecord
from wott_hub.history.reader import HistoryReader

from .conftest import new_history, write_all

T0 = 1_700_000_000 * 10**9
FRAMES = 90
THING = "pad"


def _skin_text(t: int, ids: list[int], mm: list[float], spaced: bool = False) -> str:
    nodes = [{"deformedNodeID": i, "deformedNodeIntensity": v} for i, v in zip(ids, mm, strict=True)]
    packet = {"timeStamp": t, "numOfDeformedNodes": len(ids), "arrayOfDeformedNodes": nodes}
    return json.dumps(packet) if spaced else json.dumps(packet, separators=(",", ":"))


def _field_text(t: int, ids: list[int], mm: np.ndarray) -> str:
    nodes = [{"nodeID": i, "displacement": dict(zip("xyz", v.tolist(), strict=True))}
             for i, v in zip(ids, mm, strict=True)]
    return json.dumps({"timeStamp": t, "numOfDisplacedNodes": len(ids), "arrayOfDisplacedNodes": nodes})


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    from wott_hub.examples import example_device
    from wott_hub.runtime.payloads import skin_deformed_json
    from wott_hub.tactile.processing import FrameResult
    from wott_hub.td.builder import build_tactile_td, static_property_values

    db = tmp_path_factory.mktemp("numbers") / "hub.db"
    engine, w = new_history(db)
    desc = example_device("flat", THING)
    seq = w.register_thing(THING, title=THING, family="test", td=json.dumps(build_tactile_td(desc)),
                           static_values=encode(static_property_values(desc)))
    n_nodes = desc.mesh.n_nodes
    rng = np.random.default_rng(11)
    records: list[Record] = []
    for k in range(FRAMES):
        t = T0 + k * 10**9 // 30
        ids = np.sort(rng.choice(n_nodes, 8, replace=False)).astype(np.int64)
        mm = np.round(rng.uniform(0.001, 2.0, 8), 3)
        micro = np.round(rng.normal(0, 500, (8, 3))).astype(np.int64)
        seq += 1
        if k % 10 == 3:  # a foreign driver's packet: spaced JSON, a value that is not a whole µm
            skin = Record(THING, seq, KIND_EVENT, "skinDeformedDetection", t,
                          _skin_text(t, ids.tolist(), [*mm[:-1].tolist(), 0.0004]), )
        elif k % 10 == 5:  # the pipeline's text, its timeStamp not its record's time: packed, read as text
            skin = Record(THING, seq, KIND_EVENT, "skinDeformedDetection", t,
                          _skin_text(t - 1000, ids.tolist(), mm.tolist()))
        elif k % 10 == 7:  # ids the mesh does not have, among its own
            ids[-2:] = [n_nodes + 5, 9_000_000]
            skin = Record(THING, seq, KIND_EVENT, "skinDeformedDetection", t,
                          skin_deformed_json(FrameResult(t, ids, mm, False, [], [], True)),
                          skin=SkinArrays(ids, mm))
        else:
            skin = Record(THING, seq, KIND_EVENT, "skinDeformedDetection", t,
                          skin_deformed_json(FrameResult(t, ids, mm, False, [], [], True)),
                          skin=SkinArrays(ids, mm))
        seq += 1
        if k % 10 == 4:  # a foreign driver's displacement (spaced JSON): stored as text
            field: Record = Record(THING, seq, KIND_EVENT, "skinDisplacement", t,
                                   _field_text(t, ids.tolist(), micro / 1000))
        else:
            if k % 10 == 8:
                micro[0] = [70_000, -80_123, 5]  # beyond ±65.535 mm: its text by displacement_json
            field = FieldRecord(THING, seq, t, FieldArrays(ids, micro))
        seq += 1
        contact = Record(THING, seq, KIND_PROPERTY, "contactInformation", t, encode({
            "numOfContacts": 1, "contactLocations": [{"x": float(k), "y": 2.0, "z": 0.0}],
            "contactForces": [{"x": 0.0, "y": 0.0, "z": -float(mm.sum())}]}))
        records += [skin, field, contact]
    write_all(engine, w, records)
    return db


class _RowByRow(HistoryReader):
    """The reader on a database whose pages are read row by row (PostgreSQL's way)."""

    @property
    def _joins(self) -> bool:
        return False


class _TextOnly:
    """A reader that reads every page as text (``numbers`` not taken): the export's text path."""

    def __init__(self, reader: HistoryReader) -> None:
        self._reader = reader

    def __getattr__(self, name: str) -> object:
        return getattr(self._reader, name)

    def pages(self, *args: object, numbers: bool = False, **kwargs: object) -> object:
        return self._reader.pages(*args, **kwargs)  # type: ignore[arg-type]


def _stored(db: Path) -> dict[str, int]:
    """How many packets of each kind history stored packed (first byte 1 or 2) and as text."""
    import sqlite3

    with sqlite3.connect(db) as c:
        rows = c.execute("select name, substr(data, 1, 1) from events").fetchall()
    out: dict[str, int] = {}
    for name, first in rows:
        form = "packed" if first in (b"\x01", b"\x02") else "text"
        key = f"{name} {form}"
        out[key] = out.get(key, 0) + 1
    return out


@pytest.mark.parametrize("reader_class", [HistoryReader, _RowByRow])
def test_a_page_read_as_numbers_is_the_page_read_as_text(session, reader_of, reader_class):
    stored = _stored(session)
    assert stored["skinDeformedDetection text"] == FRAMES // 10  # the foreign ones
    assert stored["skinDeformedDetection packed"] == FRAMES - FRAMES // 10
    assert stored["skinDisplacement text"] == FRAMES // 10
    reader = reader_class(reader_of(session).engine)
    for page in (7, 20_000):
        text = [r for p in reader.pages(THING, page=page) for r in p]
        numbers = [r for p in reader.pages(THING, page=page, numbers=True) for r in p]
        def key(r: Record) -> tuple[int, int, int, str]:
            return r.seq, r.t_ns, r.kind, r.name

        assert list(map(key, numbers)) == list(map(key, text))
        assert [r.data for r in numbers] == [r.data for r in text]  # each text written when read
        packed = [r for r in numbers if isinstance(r, PackedRecord)]
        # every packed packet stamped at its record's time: all but the foreign ones and those of k % 10 == 5
        assert len(packed) == 2 * FRAMES - 3 * FRAMES // 10
        assert {r.name for r in packed} == {"skinDeformedDetection", "skinDisplacement"}


def test_the_export_reads_the_values_the_text_gives(session, reader_of, tmp_path):
    """The export with pages read as numbers and with pages read as text: every column and stat equal,
    the text-stored packets' frames included."""
    reader = reader_of(session)
    outs = []
    for name, r in (("numbers", reader), ("text", _TextOnly(reader))):
        out = tmp_path / name
        export_dataset(r, DatasetRequest("lerobot", out, [THING], fps=30))  # type: ignore[arg-type]
        outs.append(out)
    a, b = (pq.read_table(next(o.glob("data/*/*.parquet"))) for o in outs)
    assert a.column_names == b.column_names
    for column in a.column_names:
        assert a[column].equals(b[column]), column
    deformation = np.stack(a[f"observation.tactile.{THING}.deformation"].to_numpy(zero_copy_only=False))
    displacement = a[f"observation.tactile.{THING}.displacement"].to_pylist()
    assert len(deformation) >= FRAMES - 1 and (deformation > 0).sum(axis=1).min() >= 6  # nodes held
    assert np.abs(np.array(displacement)).max() == pytest.approx(80.123)  # the field beyond ±65.535 mm
    # the frames holding a foreign (text-stored) packet: its 0.0004 mm node is there
    assert np.isclose(deformation, 0.0004).sum() == FRAMES // 10
    stats = [json.loads((o / "meta/stats.json").read_text()) for o in outs]
    assert stats[0] == stats[1]


def test_the_skin_sources_decode_pages_of_numbers_as_pages_of_text(session, reader_of):
    """A block of samples from many pages (as a block that spans pages has), packed and text-stored
    mixed: the same arrays from the records read as numbers as from those read as text."""
    from wott_hub.history.learning.features import DeformationSource, DisplacementSource
    from wott_hub.history.learning.plan import plan

    reader = reader_of(session)
    (thing,) = plan(reader, [THING], T0 + 10**10).things
    sources = [s for s in thing.sources if isinstance(s, DeformationSource | DisplacementSource)]
    assert len(sources) == 2
    for source in sources:
        text = [r for p in reader.pages(THING, page=7, names=[source.name]) for r in p]
        numbers = [r for p in reader.pages(THING, page=7, names=[source.name], numbers=True) for r in p]
        assert len({id(r.packets) for r in numbers if isinstance(r, PackedRecord)}) > 10  # many pages
        for picked in (slice(None), slice(3, None, 4), slice(None, None, -1)):
            want, got = source.decode_many(text[picked])[0], source.decode_many(numbers[picked])[0]
            assert want.any() and np.array_equal(got, want), (source.name, picked)
