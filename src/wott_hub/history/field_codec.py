"""How a ``skinDisplacement`` packet is stored: its numbers packed, its text written back on read.

A vector record is three numbers per node where a ``skinDeformedDetection`` packet has one:
~2,300 B of JSON for 20 nodes. Its text is a function of its µm integers
(``events.fields.displacement_json``), so it is stored as those integers and the identical text
is written back on read (SSE resume and replay send exactly the bytes sent live). A record is
packed when its numbers are known: a ``FieldRecord``'s own, or those of a text in exactly that
form (``field_of_text``: rebuilt and compared); anything else is stored as its UTF-8 text.

Packed form (``PACKED_FIELD`` first; JSON text never starts with that byte, nor does the skin
packets' ``0x01``)::

    0x02, flags, uint16 n, [int64 timeStamp unless flag SAME_TIME],
    n ids (uint16 if flag IDS16 else uint32), 3n components in µm (int16 if flag VALUES16 else int32)

little-endian, x, y, z per node in the packet's order: 4 + 2n + 6n = 164 B for 20 nodes
whose components stay within ±32.767 mm (``bench storage``). A packet beyond uint32 ids, int32
µm or 65,535 nodes is stored as text.

Reading works on batches: every packet's nodes are written as fixed-width rows by NumPy (id
digits and each component's text by table), squeezed and expanded by ``bytes.translate`` and
``bytes.replace`` (C), and cut per packet; Python per packet, not per node. A packet with an id
of 10,000 or more, or a component beyond ±65.535 mm, is written by ``displacement_json`` itself.
"""

from __future__ import annotations

import functools
import struct
import threading
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from wott_hub.events.fields import (
    SKIN_DISPLACEMENT,
    FieldArrays,
    FieldRecord,
    displacement_json,
    field_of_text,
)
from wott_hub.events.record import KIND_EVENT, Record

__all__ = ["PACKED_FIELD", "PAD", "encode_fields", "field_numbers_at", "field_texts", "field_texts_at",
           "join_spans"]

PACKED_FIELD = 0x02
_SAME_TIME, _IDS16, _VALUES16 = 1, 2, 4
_HEAD = struct.Struct("<BBH")
_TIME = struct.Struct("<q")
_MAX_NODES = 0xFFFF
_I32 = 2**31 - 1
_SHORT_IDS = 10_000  # ids below: digits by table
_TABLE_MICRO = 0xFFFF  # |component| in µm up to this: its text by table

# --- records -> bytes ----------------------------------------------------------------------------


def _time_stamp(data: str) -> int | None:
    start = '{"timeStamp":'
    if not data.startswith(start):
        return None
    digits = data[len(start):data.find(",", len(start))]
    return int(digits) if digits.isascii() and digits.lstrip("-").isdigit() else None


def _pack(ts: int, t_ns: int, field: FieldArrays) -> bytes | None:
    ids, micro = field.ids, field.micro
    n = len(ids)
    if n > _MAX_NODES or not -(1 << 63) <= ts < 1 << 63:
        return None
    flags = _SAME_TIME if ts == t_ns else 0
    if n:
        lo, hi = int(ids.min()), int(ids.max())
        top = int(np.abs(micro).max())
        if lo < 0 or hi > 0xFFFFFFFF or top > _I32:
            return None
        flags |= (_IDS16 if hi <= 0xFFFF else 0) | (_VALUES16 if top <= 0x7FFF else 0)
    parts = [_HEAD.pack(PACKED_FIELD, flags, n)]
    if not flags & _SAME_TIME:
        parts.append(_TIME.pack(ts))
    parts.append(ids.astype("<u2" if flags & _IDS16 else "<u4").tobytes())
    parts.append(micro.astype("<i2" if flags & _VALUES16 else "<i4").tobytes())
    return b"".join(parts)


def encode_fields(recs: Sequence[Record]) -> list[bytes | None]:
    """The packed bytes of each ``skinDisplacement`` record that packs (None: store its text).
    A batch's ``FieldRecord``s are packed together (``_pack_many``)."""
    out: list[bytes | None] = [None] * len(recs)
    made: list[tuple[int, FieldRecord]] = []
    for i, r in enumerate(recs):
        if r.kind == KIND_EVENT and r.name == SKIN_DISPLACEMENT:
            if isinstance(r, FieldRecord):  # its text is displacement_json of these numbers
                made.append((i, r))
            else:
                ts = _time_stamp(r.data)
                field = field_of_text(r.data) if ts is not None else None
                if field is not None and ts is not None:
                    out[i] = _pack(ts, r.t_ns, field)
    if made:
        for (i, _), blob in zip(made, _pack_many([r for _, r in made]), strict=True):
            out[i] = blob
    return out


def _pack_many(recs: Sequence[FieldRecord]) -> list[bytes | None]:
    """``_pack`` of each record's own numbers (its timeStamp is its time): for the usual batch, whose
    every id fits 16 bits and every component ±32.767 mm, the ids and the components of all
    records are converted by two NumPy calls and cut per record (Python per record, not NumPy
    calls: 1.5 against 8 µs a record at 21 nodes); else one by one."""
    ids, micro, counts = FieldRecord.quantise_all(recs)
    t_ns = [r.t_ns for r in recs]
    usual = bool(len(ids) and min(counts) and max(counts) <= _MAX_NODES and int(ids.min()) >= 0
             and int(ids.max()) <= 0xFFFF and int(np.abs(micro).max()) <= 0x7FFF
             and -(1 << 63) <= min(t_ns) and max(t_ns) < 1 << 63)
    if not usual:
        return [_pack(r.t_ns, r.t_ns, r.field) for r in recs]
    id_bytes, value_bytes = ids.astype("<u2").tobytes(), micro.astype("<i2").tobytes()
    flags = _SAME_TIME | _IDS16 | _VALUES16
    out: list[bytes | None] = []
    at = 0
    for n in counts:
        out.append(b"".join((_HEAD.pack(PACKED_FIELD, flags, n), id_bytes[2 * at:2 * (at + n)],
                             value_bytes[6 * at:6 * (at + n)])))
        at += n
    return out


# --- bytes -> text -------------------------------------------------------------------------------

_ROW = np.dtype([("head", "V10"), ("id", "V4"), ("kx", "V21"), ("sx", "u1"), ("x", "V6"), ("ky", "V5"),
                 ("sy", "u1"), ("y", "V6"), ("kz", "V5"), ("sz", "u1"), ("z", "V6"), ("end", "V3")])
"""A node's text as a fixed-width row: the keys as they are, each number NUL-padded (the NULs go)."""
_KEYS = {"head": b'{"nodeID":', "kx": b',"displacement":{"x":', "ky": b',"y":', "kz": b',"z":'}
_NEXT, _LAST = b"}},", b"}}\1"  # a node's end; the last of its packet's, with the mark to cut at


@functools.cache
def _tables() -> tuple[npt.NDArray[np.void], npt.NDArray[np.void]]:
    """Digits of the ids below ``_SHORT_IDS``; ``repr(k / 1000)`` of every k up to ``_TABLE_MICRO``
    (6 bytes at most: "65.535"), NUL-padded; built on first use."""
    ids = b"".join(str(i).encode().rjust(4, b"\0") for i in range(_SHORT_IDS))
    tails = b"".join(repr(k / 1000).encode().ljust(6, b"\0") for k in range(_TABLE_MICRO + 1))
    return np.frombuffer(ids, "V4"), np.frombuffer(tails, "V6")


PAD = bytes(16)
"""After a batch's bytes, so that reading a header never goes past the end."""


def _le(buf: npt.NDArray[np.uint8], at: npt.NDArray[np.int64], width: npt.NDArray[np.int64],
        signed: bool) -> npt.NDArray[np.int64]:
    """The little-endian integers of ``width`` (2 or 4) bytes at ``at`` in ``buf`` (which ends with
    ``PAD``: reading 4 bytes never runs past it)."""
    value = buf[at].astype(np.int64) | buf[at + 1].astype(np.int64) << 8
    wide = width == 4
    value[wide] |= buf[at[wide] + 2].astype(np.int64) << 16 | buf[at[wide] + 3].astype(np.int64) << 24
    if signed:
        half = np.where(wide, 1 << 31, 1 << 15)
        value = (value ^ half) - half
    return value


def join_spans(buf: npt.NDArray[np.uint8], at: npt.NDArray[np.int64],
               length: npt.NDArray[np.int64]) -> npt.NDArray[np.uint8]:
    """The bytes of ``buf`` in the spans [at, at + length), which follow one another, joined:
    one mask made by ``np.repeat`` (what lies between the spans, the spans alternately). Both
    codecs (this one and ``codec``) read their packed columns with it."""
    runs = np.empty(2 * len(at) + 1, np.int64)
    end = at + length
    runs[0:-1:2] = at
    runs[2:-1:2] -= end[:-1]
    runs[1::2] = length
    runs[-1] = len(buf) - (end[-1] if len(at) else 0)
    keep = np.zeros(len(runs), bool)
    keep[1::2] = True
    spans: npt.NDArray[np.uint8] = buf[np.repeat(keep, runs)]
    return spans


def _unpack(buf: npt.NDArray[np.uint8], off: npt.NDArray[np.int64], size: npt.NDArray[np.int64],
            t_ns: npt.NDArray[np.int64]) -> tuple[list[int], FieldArrays, npt.NDArray[np.int64]]:
    """(timeStamps, the numbers of every packet one after the other, nodes per packet) of the packed
    packets at ``off`` in ``buf`` (which ends with ``PAD``), their headers read together
    (ValueError: bytes that are not whole packets)."""
    if (size < _HEAD.size).any():
        raise ValueError("a stored displacement packet is damaged: shorter than its header")
    flags = buf[off + 1]
    n = buf[off + 2].astype(np.int64) | buf[off + 3].astype(np.int64) << 8
    same = (flags & _SAME_TIME) != 0
    pos = off + _HEAD.size + 8 * ~same
    id_width = np.where(flags & _IDS16, 2, 4).astype(np.int64)
    value_width = np.where(flags & _VALUES16, 2, 4).astype(np.int64)
    values_at = pos + n * id_width
    if (values_at + 3 * n * value_width != off + size).any():
        raise ValueError("a stored displacement packet is damaged: its length does not match its header")
    ts = np.array(t_ns, np.int64)  # a copy: the timeStamps stored are written in
    own = ~same
    if own.any():
        ts[own] = buf[(off + _HEAD.size)[own, None] + np.arange(8)].copy().view("<i8")[:, 0]
    if (id_width == 2).all() and (value_width == 2).all():  # the usual: every packet's numbers in 16 bits
        ids = join_spans(buf, pos, 2 * n).view("<u2").astype(np.int64)
        micro = join_spans(buf, values_at, 6 * n).view("<i2").astype(np.int64).reshape(-1, 3)
        return ts.tolist(), FieldArrays(ids, micro), n
    packet = np.repeat(np.arange(len(n)), n)
    j = np.arange(len(packet)) - (np.cumsum(n) - n)[packet]
    ids = _le(buf, pos[packet] + j * id_width[packet], id_width[packet], signed=False)
    pv = np.repeat(packet, 3)
    k = np.arange(len(pv)) - (3 * (np.cumsum(n) - n))[pv]
    micro = _le(buf, values_at[pv] + k * value_width[pv], value_width[pv], signed=True).reshape(-1, 3)
    return ts.tolist(), FieldArrays(ids, micro), n


def field_numbers_at(buf: npt.NDArray[np.uint8], off: npt.NDArray[np.int64], size: npt.NDArray[np.int64],
                     t_ns: npt.NDArray[np.int64]) -> tuple[FieldArrays, npt.NDArray[np.int64]]:
    """(the numbers of every packet one after the other, nodes per packet) of the packed packets at
    ``off`` in ``buf`` (which ends with 16 NUL bytes): what their texts are written from, for a
    reader that wants the numbers (``history.numbers``)."""
    _, numbers, n = _unpack(buf, off, size, t_ns)
    return numbers, n


def field_texts(stored: Sequence[bytes | memoryview], t_ns: Sequence[int]) -> list[str]:
    """Each packed packet's text exactly as ``displacement_json`` wrote it (``t_ns``: the records'
    times, which a packet whose timeStamp equals it does not store again)."""
    size = np.fromiter(map(len, stored), np.int64, len(stored))
    buf = np.frombuffer(b"".join([*stored, PAD]), np.uint8)
    return field_texts_at(buf, np.cumsum(size) - size, size, np.array(t_ns, np.int64))


def field_texts_at(buf: npt.NDArray[np.uint8], off: npt.NDArray[np.int64], size: npt.NDArray[np.int64],
                   t_ns: npt.NDArray[np.int64]) -> list[str]:
    """``field_texts`` of the packets at ``off`` in ``buf`` (which ends with 16 NUL bytes): the
    codec's pages, read in place."""
    if not len(off):
        return []
    ts, numbers, n = _unpack(buf, off, size, t_ns)
    ids, micro = numbers
    packet = np.repeat(np.arange(len(n)), n)
    slow = np.zeros(len(n), bool)  # written one by one: an id or a component beyond the tables
    if len(ids):
        beyond = (ids >= _SHORT_IDS) | (np.abs(micro) > _TABLE_MICRO).any(axis=1)
        slow[packet[beyond]] = True
    fast = ~slow[packet]
    listed = n * ~slow  # the nodes each packet has in the rows
    pieces = _node_texts(ids[fast], micro[fast], listed)
    counts = n.tolist()
    if listed.all():
        bodies = pieces
    else:
        it = iter(pieces)
        bodies = [next(it) if k else "" for k in listed.tolist()]
    texts = [f'{{"timeStamp":{t},"numOfDisplacedNodes":{k},"arrayOfDisplacedNodes":[{b}]}}'
             for t, k, b in zip(ts, counts, bodies, strict=False)]
    if slow.any():
        start = np.cumsum(n) - n
        for i in np.flatnonzero(slow).tolist():
            a, k = int(start[i]), counts[i]
            texts[i] = displacement_json(ts[i], FieldArrays(ids[a:a + k], micro[a:a + k]))
    return texts


_BUFFERS = threading.local()
"""Each thread's rows, holding the keys and a node's end: the numbers are written over them (the
codec runs in the writer's thread and in readers' threads at once)."""


def _rows(n: int) -> npt.NDArray[np.void]:
    rows: npt.NDArray[np.void] | None = getattr(_BUFFERS, "rows", None)
    if rows is None or len(rows) < n:
        rows = np.zeros(max(n, 4096), _ROW)
        for key, text in _KEYS.items():
            rows[key] = np.frombuffer(text, f"V{len(text)}")[0]
        rows["end"] = np.frombuffer(_NEXT, "V3")[0]
        _BUFFERS.rows = rows
    return rows[:n]


def _node_texts(ids: npt.NDArray[np.int64], micro: npt.NDArray[np.int64],
                n: npt.NDArray[np.int64]) -> list[str]:
    """The node texts of each packet with nodes (``n``: nodes per packet, 0 ones skipped), all written
    as rows at once and squeezed by one ``bytes.translate``; the last node of each packet ends with a
    \\1 to cut at."""
    id_table, tails = _tables()
    rows = _rows(len(ids))  # the keys are there; every other byte is written below
    rows["id"] = id_table[ids]
    sign = (micro < 0).view(np.uint8) * np.uint8(ord("-"))
    magnitude = np.abs(micro)
    for axis, k in (("x", 0), ("y", 1), ("z", 2)):
        rows[f"s{axis}"] = sign[:, k]
        rows[axis] = tails[magnitude[:, k]]
    last = np.cumsum(n[n > 0]) - 1
    rows["end"][last] = np.frombuffer(_LAST, "V3")[0]
    text = rows.tobytes()
    rows["end"][last] = np.frombuffer(_NEXT, "V3")[0]  # the buffer as it was, for the next call
    pieces = text.translate(None, b"\0").decode("ascii").split("\1")
    pieces.pop()  # what follows the last packet's mark: nothing
    return pieces
