"""A page read as numbers: packed skin and displacement packets as records carrying their numbers.

History stores those packets packed (``codec``, ``field_codec``) and writes their text back on read,
which a consumer of arrays (the learning export, ``learning/features.py``) then parses again: at
30 frames/s and three skins, writing and parsing those texts cost several times what reading the
packed numbers does. A page read with ``numbers`` (``StorageReader.pages``) gives the same records,
each ``data`` the same text once read, but a packed ``skinDeformedDetection`` or ``skinDisplacement``
packet stamped with its record's time (the flag SAME_TIME: every packet the hub's pipeline makes)
comes as a ``PackedRecord``: its text unwritten until ``data`` is read (``codec.skin_text``,
``events.fields.displacement_json``: the texts the codecs write back, by their contracts), its numbers
in its page's ``Packets`` (every packet's nodes of the page one after the other, unpacked by one
NumPy pass), which ``nodes_of`` gathers for many records at once.

Every other payload (a packet stored as text: a foreign driver's, one the writer could not pack,
rows from before the packed forms; a packet with a timeStamp of its own) is its text, exactly as
``codec.decode_joined`` gives it. A consumer that reads numbers from ``PackedRecord``s must read the
same values from the text of any other record: a faster path, never a second definition
(``tests/history/learning/test_numbers.py`` compares the two on a recorded session).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import repeat
from operator import attrgetter
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from wott_hub.events.fields import SKIN_DISPLACEMENT, FieldArrays, displacement_json
from wott_hub.events.record import KIND_EVENT, Record

from .codec import (
    PACKED,
    PAD,
    SKIN_EVENT,
    decode_at,
    decode_many,
    joined_chunks,
    skin_numbers_at,
    skin_text,
)
from .field_codec import PACKED_FIELD, field_numbers_at

__all__ = [
    "Numbered", "PackedRecord", "Packets", "nodes_of", "numbered_records", "numbers_joined", "numbers_many",
]

_Int = npt.NDArray[np.int64]
_Column = Sequence[int] | _Int
"""A page's column of integers: a NumPy array (``sqlite.JoinedPage``) or the driver's tuple."""
_SAME_TIME = 1  # both packed forms' flag (second byte): the packet's timeStamp is its record's time


class Packets(NamedTuple):
    """The packed packets of one name in a page: packet ``i``'s nodes are ``start[i]`` to
    ``start[i] + n[i]`` of ``ids`` (int64) and ``micro`` (int64 µm: one per node for a skin packet,
    x, y, z rows for a displacement)."""

    name: str
    start: _Int
    n: _Int
    ids: _Int
    micro: _Int


class PackedRecord(Record):
    """A packed packet read as its numbers (``packets``, its ``index`` there); its text is written the
    first time ``data`` is read (the slot stays empty until then, as ``FieldRecord``'s)."""

    __slots__ = ("index", "packets")

    def __init__(self, thing: str, seq: int, t_ns: int, packets: Packets, index: int) -> None:
        super().__init__(thing, seq, KIND_EVENT, packets.name, t_ns, "")
        del self.data
        self.packets = packets
        self.index = index

    def __getattr__(self, name: str) -> Any:
        if name == "data":
            p, i = self.packets, self.index
            a, b = int(p.start[i]), int(p.start[i] + p.n[i])
            text = self.data = (skin_text(self.t_ns, p.ids[a:b], p.micro[a:b]) if p.name == SKIN_EVENT
                                else displacement_json(self.t_ns, FieldArrays(p.ids[a:b], p.micro[a:b])))
            return text
        raise AttributeError(name)


def nodes_of(recs: Sequence[PackedRecord]) -> tuple[_Int, _Int, npt.NDArray[np.float64]]:
    """(the position in ``recs`` of each node, its id, its value in mm: ``k / 1000`` of the stored µm
    ``k``, the double its text reads as) of every node of ``recs``' packets, in their order; a few
    NumPy calls per page the records come from, none per record (their fields read by ``map``)."""
    index = np.fromiter(map(_INDEX, recs), np.int64, len(recs))
    of = list(map(_PACKETS, recs))
    pages = dict(zip(map(id, of), of, strict=True))
    if len(pages) == 1:
        return _nodes(next(iter(pages.values())), index, np.arange(len(recs)))
    page_id = np.fromiter(map(id, of), np.uint64, len(of))
    parts = [_nodes(p, index[at], at) for key, p in pages.items()
             if len(at := np.flatnonzero(page_id == key))]
    samples, ids, values = zip(*parts, strict=True)
    order = np.argsort(np.concatenate(samples), kind="stable")  # in the records' order, and their nodes'
    return np.concatenate(samples)[order], np.concatenate(ids)[order], np.concatenate(values)[order]


def _nodes(p: Packets, index: _Int, at: _Int) -> tuple[_Int, _Int, npt.NDArray[np.float64]]:
    """``nodes_of`` of the packets ``index`` of ``p``, the records at ``at``."""
    n = p.n[index]
    node = np.repeat(p.start[index] - (np.cumsum(n) - n), n) + np.arange(int(n.sum()))
    return np.repeat(at, n), p.ids[node], p.micro[node] / 1000.0


_INDEX = attrgetter("index")
_PACKETS = attrgetter("packets")


class Numbered(NamedTuple):
    """A page's payloads read as numbers: the texts of the rows at ``text_at``, and the rows at each
    ``positions`` the packets of its ``Packets``, in their order."""

    texts: list[str]
    text_at: _Int
    found: list[tuple[_Int, Packets]]


def numbers_joined(joined: bytes, size: _Int, t_ns: _Int, names: Sequence[str], kinds: _Int) -> Numbered:
    """``codec.decode_joined`` of a page, the packets this module's docstring names as numbers."""
    kinds = np.asarray(kinds)
    out = Numbered([], np.empty(0, np.int64), [])
    text_at = []
    for rows, lo, buf, off, chunk in joined_chunks(joined, size):
        part = _chunk(joined, lo, buf, off, chunk, t_ns[rows], names[rows], kinds[rows])
        out.texts.extend(part.texts)
        text_at.append(part.text_at + rows.start)
        out.found.extend((at + rows.start, packets) for at, packets in part.found)
    return out._replace(text_at=np.concatenate(text_at)) if text_at else out


def numbers_many(stored: Sequence[bytes | memoryview | str], t_ns: Sequence[int], names: Sequence[str],
                 kinds: Sequence[int]) -> Numbered:
    """``numbers_joined`` of rows as the driver gives them (``codec.decode_many``'s input)."""
    try:
        joined = b"".join([*stored, PAD])  # type: ignore[list-item]  # a str raises TypeError
        times = np.fromiter(t_ns, np.int64, len(stored))
    except (TypeError, OverflowError):  # a text row (before 0006), a time beyond int64: as text
        return Numbered(decode_many(stored, t_ns), np.arange(len(stored)), [])
    size = np.fromiter(map(len, stored), np.int64, len(stored))
    return numbers_joined(joined, size, times, names, np.fromiter(kinds, np.int64, len(stored)))


def _chunk(joined: bytes, base: int, buf: npt.NDArray[np.uint8], off: _Int, size: _Int, t_ns: _Int,
           names: Sequence[str], kinds: _Int) -> Numbered:
    """``numbers_joined`` of one of ``codec.joined_chunks``: the rows at ``off`` in ``buf``
    (``joined[base:]``)."""
    head = np.where(size > 0, buf[off], 0)
    same = (buf[off + 1] & _SAME_TIME) != 0  # the 16 NULs after the bytes: never read beyond them
    event = kinds == KIND_EVENT
    named = np.array(names, object)
    skin = (head == PACKED) & same & event & (named == SKIN_EVENT)
    field = (head == PACKED_FIELD) & same & event & (named == SKIN_DISPLACEMENT)
    text = ~(skin | field)
    if text.all():
        return Numbered(decode_at(joined, base, buf, off, size, t_ns, None), np.arange(len(off)), [])
    out = Numbered([], np.flatnonzero(text), [])
    if len(out.text_at):
        at = out.text_at
        out.texts.extend(decode_at(joined, base, buf, off[at], size[at], t_ns[at], None))
    if skin.any():
        at = np.flatnonzero(skin)
        n, ids, micro = skin_numbers_at(buf, off[at], size[at], t_ns[at])
        out.found.append((at, Packets(SKIN_EVENT, np.cumsum(n) - n, n, ids, micro)))
    if field.any():
        at = np.flatnonzero(field)
        numbers, n = field_numbers_at(buf, off[at], size[at], t_ns[at])
        out.found.append((at, Packets(SKIN_DISPLACEMENT, np.cumsum(n) - n, n, numbers.ids, numbers.micro)))
    return out


def numbered_records(thing: str, seqs: _Column, kinds: _Column, names: Sequence[str], times: _Column,
                     page: Numbered) -> list[Record]:
    """The records of a page read as numbers (``Columns.records`` of a page of texts): made by ``map``
    (C), no Python per record but their ``__init__``."""
    if not page.found:
        return list(map(Record, repeat(thing), _listed(seqs), _listed(kinds), names, _listed(times),
                        page.texts))
    seq_of, time_of = np.asarray(seqs), np.asarray(times)
    out = np.empty(len(seq_of), object)
    at = page.text_at
    if len(at):  # (np.fromiter: an object array of them without NumPy asking each for an array form)
        out[at] = np.fromiter(map(Record, repeat(thing), seq_of[at].tolist(), np.asarray(kinds)[at].tolist(),
                                  np.array(names, object)[at].tolist(), time_of[at].tolist(), page.texts),
                              object, len(at))
    for at, packets in page.found:
        out[at] = np.fromiter(map(PackedRecord, repeat(thing), seq_of[at].tolist(), time_of[at].tolist(),
                                  repeat(packets), range(len(at))), object, len(at))
    records: list[Record] = out.tolist()
    return records


def _listed(values: _Column) -> Sequence[int]:
    """Python ints of a column (a page's NumPy array, a driver's tuple as it is)."""
    return values.tolist() if isinstance(values, np.ndarray) else values
