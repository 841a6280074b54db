"""The ``skinDisplacement`` packet: its numbers, its JSON text and its binary form, defined once.

A packet is the nodes of a ``skinDeformedDetection`` packet with their displacement vectors,
in whole µm (``FieldArrays.micro``): the pipeline quantises once, and every form is a function
of those integers, so the JSON text, the binary form and history's packed bytes all say the
same thing, and history gives back the exact text sent live (``history/field_codec.py``).

A ``FieldRecord`` carries the arrays and builds each form the first time a consumer asks for
it: a hub that records the event but has no subscriber never writes its JSON text (history
packs the arrays), a binary subscriber never makes the text, a JSON one never the bytes. Its
``data`` is a slot left empty until read (``Record.data`` is then found by ``__getattr__``, once);
every other record is unchanged.

JSON text (keys in this order, compact, µm as Python writes ``k / 1000``)::

    {"timeStamp":T,"numOfDisplacedNodes":n,"arrayOfDisplacedNodes":[
        {"nodeID":i,"displacement":{"x":X,"y":Y,"z":Z}},...]}

Binary form, ``CONTENT_TYPE`` (all little-endian; a packet is self-delimiting, so a stream of
them needs no further framing)::

    offset  size  field
    0       4     magic b"WTD1" (format version 1)
    4       4     uint32 n, the number of nodes
    8       8     uint64 seq, the record's event id (its SSE id; 0 if never numbered)
    16      8     int64 timeStamp, ns since the Unix epoch
    24      4n    uint32 nodeID of each node
    24+4n   12n   float32 x, y, z of each node, mm (the µm values, as float32)
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Sequence
from itertools import repeat
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from .record import KIND_EVENT, Record

if TYPE_CHECKING:
    import numpy.typing as npt

__all__ = ["CONTENT_TYPE", "HEADER", "MAGIC", "SKIN_DISPLACEMENT", "FieldArrays", "FieldRecord", "Wire",
           "displacement_json", "field_of_text", "packet_bytes"]

SKIN_DISPLACEMENT = "skinDisplacement"
CONTENT_TYPE = "application/vnd.wott.skin-displacement"
"""The binary form's media type (TD forms' ``contentType``)."""
MAGIC = b"WTD1"
HEADER = struct.Struct("<4sIQq")
"""magic, n, seq, timeStamp: the 24 bytes before the ids."""


class FieldArrays(NamedTuple):
    """A packet's numbers: ``ids`` (n,) int64 node ids in the packet's order, ``micro`` (n, 3) int64
    displacement in µm in the device's ``sensorCoordinateFrame``."""

    ids: npt.NDArray[np.int64]
    micro: npt.NDArray[np.int64]

    @classmethod
    def of(cls, ids: np.ndarray, displacement_mm: np.ndarray) -> FieldArrays:
        """Quantise ``displacement_mm`` (n, 3) to whole µm (round half to even, as ``np.rint``)."""
        micro = np.multiply(displacement_mm, 1000.0, dtype=np.float64)  # a new array: rounded in place
        np.rint(micro, out=micro)
        return cls(np.asarray(ids, np.int64), micro.astype(np.int64).reshape(-1, 3))

    def mm(self) -> npt.NDArray[np.float64]:
        """The vectors in mm, exactly the numbers the JSON text shows."""
        out: npt.NDArray[np.float64] = self.micro / 1000.0
        return out

    def to_wire(self) -> tuple[bytes, bytes]:
        """Raw bytes to cross a pipe (a worker's, the history process's)."""
        return (self.ids.astype(np.int64, copy=False).tobytes(),
                self.micro.astype(np.int64, copy=False).tobytes())

    @classmethod
    def from_wire(cls, wire: tuple[bytes, bytes]) -> FieldArrays:
        return cls(np.frombuffer(wire[0], np.int64), np.frombuffer(wire[1], np.int64).reshape(-1, 3))


_TABLE_MICRO = 16_383
"""Components within ±16.383 mm (nearly all) have their text by table (``_texts``), others by ``repr``."""


@functools.cache
def _texts() -> list[str]:
    """``repr(k / 1000)`` of every k in [-_TABLE_MICRO, _TABLE_MICRO], k + _TABLE_MICRO its index (~2 MB, on
    first use): a lookup costs a fifth of a float's repr, and a packet has three per node."""
    return [repr(k / 1000) for k in range(-_TABLE_MICRO, _TABLE_MICRO + 1)]


_HEADS: list[str] = []
"""Node ``i``'s ``{"nodeID":<i>,"displacement":{"x":``, made once per id (as ``runtime.payloads`` does)."""


def _head(i: int) -> str:
    return f'{{"nodeID":{i},"displacement":{{"x":'


def displacement_json(t_ns: int, field: FieldArrays) -> str:
    """The packet's JSON text (the module docstring's form): each component as Python writes
    ``k / 1000`` for its whole number of µm ``k``."""
    ids = field.ids.tolist()
    n = len(ids)
    if not n:
        return f'{{"timeStamp":{t_ns},"numOfDisplacedNodes":0,"arrayOfDisplacedNodes":[]}}'
    keys = (field.micro + _TABLE_MICRO).ravel().tolist()
    texts = _texts()
    if min(keys) < 0 or max(keys) >= len(texts):  # beyond ±16 mm: written one by one
        values = list(map(float.__repr__, (field.micro / 1000.0).ravel().tolist()))
    else:
        values = list(map(texts.__getitem__, keys))
    heads, top = _HEADS, max(ids)
    if len(heads) <= top < 1 << 16:
        heads += map(_head, range(len(heads), top + 1))
    head = heads.__getitem__ if top < len(heads) and min(ids) >= 0 else _head
    nodes = "}},".join(map("".join, zip(map(head, ids), values[0::3], repeat(',"y":'), values[1::3],
                                        repeat(',"z":'), values[2::3])))
    return f'{{"timeStamp":{t_ns},"numOfDisplacedNodes":{n},"arrayOfDisplacedNodes":[{nodes}}}}}]}}'


def packet_bytes(seq: int, t_ns: int, field: FieldArrays) -> bytes:
    """The packet's binary form (the module docstring's layout)."""
    n = len(field.ids)
    return b"".join((HEADER.pack(MAGIC, n, seq, t_ns), field.ids.astype("<u4").tobytes(),
                     (field.micro / 1000.0).astype("<f4").tobytes()))


def field_of_text(data: str) -> FieldArrays | None:
    """The numbers of a packet's JSON text, if it is one in exactly the form ``displacement_json``
    writes (a packet an embedding program published, a replay's decoded text); else None."""
    import json

    try:
        value = json.loads(data)
        nodes = value["arrayOfDisplacedNodes"]
        ids = np.array([d["nodeID"] for d in nodes], np.int64)
        mm = np.array([[d["displacement"][a] for a in "xyz"] for d in nodes], np.float64).reshape(-1, 3)
        with np.errstate(over="ignore", invalid="ignore"):  # absurd numbers: the text check refuses them
            field = FieldArrays(ids, np.rint(mm * 1000.0).astype(np.int64))
        if displacement_json(int(value["timeStamp"]), field) != data:
            return None
    except (ValueError, KeyError, TypeError, OverflowError, RecursionError):
        return None
    return field


Wire = tuple[str, bytes, bytes]
"""A record's numbers across a pipe: ``("mm", ids, float64 mm)`` as the pipeline made them, or
``("um", ids, int64 µm)`` once quantised."""


class FieldRecord(Record):
    """A ``skinDisplacement`` record made from its numbers: ``data`` (the JSON text) and ``binary()``
    are written on first use and kept (the plane's ring, every subscriber and history share them).

    The pipeline hands over the vectors as it has them (``rows``: node ids and their mm rows, a
    copy): quantising them to µm (``field``) is left to whoever needs the numbers first, so a
    record that only goes to history is quantised in the history process, off the hub's loop."""

    __slots__ = ("_bin", "_field", "_rows")

    def __init__(self, thing: str, seq: int, t_ns: int, field: FieldArrays | None = None,
                 trace: dict[str, int] | None = None, data: str | None = None, *,
                 rows: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        super().__init__(thing, seq, KIND_EVENT, SKIN_DISPLACEMENT, t_ns, "", trace)
        if (field is None) == (rows is None):
            raise ValueError("a FieldRecord is made from its field or from its rows, one of them")
        self._field = field
        self._rows = rows
        self._bin: bytes | None = None
        if data is None:
            del self.data  # written by ``__getattr__`` when first read
        else:
            self.data = data

    @property
    def field(self) -> FieldArrays:
        """The packet's numbers in µm (quantised here the first time they are needed)."""
        # _rows is read first: whoever quantises sets _field, then clears _rows (here, or the history
        # writer's thread for a batch: ``quantise_all``), so a reader never finds both empty
        rows = self._rows
        field = self._field
        if field is None:
            assert rows is not None  # one of the two is always set
            field = self._field = FieldArrays.of(*rows)
            self._rows = None
        return field

    def __getattr__(self, name: str) -> Any:
        if name == "data":  # the slot is empty until the text is first read
            text = self.data = displacement_json(self.t_ns, self.field)
            return text
        raise AttributeError(name)

    @property
    def text_built(self) -> bool:
        """Has anyone read the JSON text yet (else a pipe carries the numbers only)?"""
        try:
            object.__getattribute__(self, "data")
        except AttributeError:
            return False
        return True

    @staticmethod
    def quantise_all(records: Sequence[FieldRecord]) -> tuple[np.ndarray, np.ndarray, list[int]]:
        """Every record's numbers, one after the other: (ids (N,), µm (N, 3), nodes per record).
        Those not yet quantised are quantised together, one NumPy pass for a batch where ``field``
        would take four calls per record (history's packing: ``history.field_codec``); the same
        numbers ``FieldArrays.of`` gives, kept in each record."""
        pending = [(r, r._rows) for r in records if r._rows is not None]  # not yet quantised
        if pending:
            counts = [len(ids) for _, (ids, _mm) in pending]
            field = FieldArrays.of(np.concatenate([ids for _, (ids, _mm) in pending]),
                                   np.concatenate([mm.reshape(-1, 3) for _, (_ids, mm) in pending]))
            at = 0
            for (r, _), n in zip(pending, counts, strict=True):
                r._field, r._rows = FieldArrays(field.ids[at:at + n], field.micro[at:at + n]), None
                at += n
            if len(pending) == len(records):
                return field.ids, field.micro, counts
        fields = [r.field for r in records]
        return (np.concatenate([f.ids for f in fields]), np.concatenate([f.micro for f in fields]),
                [len(f.ids) for f in fields])

    def binary(self) -> bytes:
        """The binary form (seq as numbered by the plane)."""
        out = self._bin
        if out is None or self.seq != int.from_bytes(out[8:16], "little"):
            out = self._bin = packet_bytes(self.seq, self.t_ns, self.field)
        return out

    def wire(self) -> Wire:
        """The numbers as raw bytes, to cross a pipe (pickling arrays costs ~4x more on each side)."""
        rows = self._rows
        if rows is not None:
            return ("mm", np.asarray(rows[0], np.int64).tobytes(), np.asarray(rows[1], np.float64).tobytes())
        return ("um", *self.field.to_wire())

    @classmethod
    def revive(cls, thing: str, seq: int, t_ns: int, wire: Wire, trace: dict[str, int] | None = None,
               data: str | None = None) -> FieldRecord:
        """The record ``wire()`` describes (its text too, if it had been written)."""
        kind, ids, values = wire
        if kind == "mm":
            rows = (np.frombuffer(ids, np.int64), np.frombuffer(values, np.float64).reshape(-1, 3))
            return cls(thing, seq, t_ns, None, trace, data, rows=rows)
        return cls(thing, seq, t_ns, FieldArrays.from_wire((ids, values)), trace, data)

    def __reduce__(self) -> tuple[Any, ...]:
        data = self.data if self.text_built else None
        return (FieldRecord.revive, (self.thing, self.seq, self.t_ns, self.wire(), self.trace, data))
