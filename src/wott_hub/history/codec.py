"""How a record's payload is stored: packed numbers for skin packets, UTF-8 text for the rest.

A ``skinDeformedDetection`` packet is most of what a hub records (~1,100 B of JSON for ~20
nodes). Its text is the one ``hub.skin_deformed_json`` writes, so it can be stored
as numbers and written back to the *identical* text on read: SSE resume and replay must
send exactly the bytes sent live. A packet is therefore packed only when unpacking it gives
back every byte; anything else (another affordance, a packet from a foreign driver, an
intensity that is not a whole number of µm) is stored as its UTF-8 text.

Packed form (``PACKED`` first; JSON text never starts with that byte):

    0x01, flags, varint n, [int64 timeStamp unless flag SAME_TIME], ids, n x uint16 µm

``SAME_TIME``: ``timeStamp`` equals the record's time. Ids: ascending ids as the first id
(uint32) and n-1 gaps of one byte (flag SMALL_GAPS), else n x uint32. Intensities: whole
µm (the processor rounds them to 3 decimals, ``intensity_decimals``) as uint16, written back
with Python's float repr of ``k / 1000``, which is what ``json`` wrote for the rounded
value (a correctly rounded division gives the same double as the decimal text).

Both directions work on batches (the writer's batch, a page of a replay or resume): the
numbers of every packet are packed, unpacked and written as text by a few NumPy operations
over all nodes of the batch at once, a few µs per packet instead of ~20 µs of Python. The
writer takes a packet's numbers from the arrays the pipeline computed it from
(``Record.skin``), else from its text; either way the packet is stored packed only if the
text rebuilt from the packed bytes (``decode_many``'s own code) equals the record's text, so
the contract never rests on where the numbers came from. ``encode`` and ``decode`` (one
payload) pay NumPy's fixed cost per call (~0.3-1 ms): whatever handles rows in numbers uses
the batch functions.

A ``skinDisplacement`` packet (the vectors of the same nodes) is packed as well, in a form of
its own that starts with ``field_codec.PACKED_FIELD`` (0x02): ``field_codec.py``.

Contract: ``decode(encode(kind, name, t_ns, data), t_ns) == data`` for every payload, and
``decode_many(encode_records(recs), ...) == [r.data for r in recs]`` whatever ``r.skin``
holds; ``decode`` also accepts a ``str`` (rows written before revision 0006 on a database
that kept its text) and plain UTF-8 bytes. Migrations import this module: its packed format
is part of the schema and may only be extended (a new first byte), never changed.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from wott_hub.events.record import KIND_EVENT, Record, SkinArrays

from .field_codec import PACKED_FIELD, PAD, encode_fields, field_texts, field_texts_at, join_spans

__all__ = ["PACKED", "PACKED_FIELD", "PAD", "SKIN_EVENT", "decode", "decode_at", "decode_joined",
           "decode_many", "encode", "encode_records", "joined_chunks", "skin_numbers_at", "skin_text"]

PACKED = 0x01
_MARK = bytes((PACKED,))
_FIELD_MARK = bytes((PACKED_FIELD,))
SKIN_EVENT = "skinDeformedDetection"
_SAME_TIME = 1
_SMALL_GAPS = 2
_MAX_NODES = 0x7FFF  # a two-byte varint
_MAX_ID = 0xFFFFFFFF
_MAX_MICRO = 0xFFFF

_NUMBERS = bytes(c if chr(c) in "0123456789." else 32 for c in range(256))  # the rest: spaces

_Int = npt.NDArray[np.int64]
Stored = bytes | memoryview | str


class _Packets(NamedTuple):
    """Skin packets of a batch as numbers: per packet its timeStamp and node count; per node
    (the packets' nodes one after the other) its id and intensity in µm."""

    ts: _Int
    n: _Int
    ids: _Int
    micro: _Int

    def node_index(self) -> tuple[_Int, _Int, _Int]:
        """(first node of each packet, packet of each node, index of each node in its packet)."""
        start = np.cumsum(self.n) - self.n
        packet = np.repeat(np.arange(len(self.n)), self.n)
        return start, packet, np.arange(len(packet)) - start[packet]


# --- numbers -> text ------------------------------------------------------------------------

_NODE_HEAD = b'{"deformedNodeID":'
_NODE_KEY = b',"deformedNodeIntensity":'
_HEAD_MARK, _KEY_MARK = b"\2", b"\3"
_HEADER = b'{"timeStamp":' + bytes(20) + b',"numOfDeformedNodes":' + bytes(6) + b',"arrayOfDeformedNodes":['
_TS_AT = _HEADER.index(bytes(20))  # 20 places: a sign and the 19 digits of an int64
_N_AT = _HEADER.index(bytes(6), _TS_AT + 20)  # 6 places: n <= _MAX_NODES
_FIXED = len(_HEADER) - 26 + 2  # a packet's text beyond its numbers and nodes (with "]}")
_SHORT_IDS = 10_000  # ids below: 4 places and digits by table (every mesh so far)
_ID_WIDTH = 10  # places of the largest uint32
_PAIRS = np.frombuffer(b"".join(b"%02d" % i for i in range(100)), "V2")
_TENS = np.uint64(10) ** np.arange(19, -1, -1, dtype=np.uint64)
_HUNDRED = np.uint64(100)


class _Layout(NamedTuple):
    """Rows of one width for a batch's text: a node's row ``head`` id ``key`` tail (NUL-padded,
    the keys as marker bytes expanded by ``bytes.replace``, which costs less than squeezing 43
    more bytes per node), a packet's header in ``heads`` rows, its footer ("]}") in one."""

    node: np.dtype[np.void]
    heads: int
    template: npt.NDArray[np.uint8]  # the header rows, then the footer row


@functools.cache
def _layout(id_width: int) -> _Layout:
    node = np.dtype([("head", "u1"), ("id", f"V{id_width}"), ("key", "u1"), ("tail", "<u8")])
    width = node.itemsize
    heads = -(-len(_HEADER) // width)
    template = _HEADER.ljust(heads * width, b"\0") + b"]}".ljust(width, b"\0")
    return _Layout(node, heads, np.frombuffer(template, np.uint8))


@functools.cache
def _tables() -> tuple[npt.NDArray[np.void], npt.NDArray[np.int64], npt.NDArray[np.uint64],
                       npt.NDArray[np.uint64], npt.NDArray[np.int64]]:
    """Digits of the ids below ``_SHORT_IDS`` and their lengths; ``repr(k / 1000) + "},"`` of
    every uint16 ``k`` (8 bytes at most: "65.535},"), the same without the ",", and its length;
    built on first use (~40 ms, 1.7 MB)."""
    ids = [str(i).encode() for i in range(_SHORT_IDS)]
    tails = [(repr(k / 1000) + "},").encode() for k in range(_MAX_MICRO + 1)]
    return (np.frombuffer(b"".join(i.rjust(4, b"\0") for i in ids), "V4"),
            np.fromiter(map(len, ids), np.int64, len(ids)),
            np.frombuffer(b"".join(t.ljust(8, b"\0") for t in tails), "<u8"),
            np.frombuffer(b"".join(t[:-1].ljust(8, b"\0") for t in tails), "<u8"),
            np.fromiter(map(len, tails), np.int64, len(tails)))


def _decimal(values: _Int, width: int) -> tuple[npt.NDArray[np.uint8], _Int]:
    """The values' decimal text, right-aligned in rows of ``width`` (even) NUL-padded bytes, a
    "-" in the first place for a negative value (the NULs go: "-\\0\\012" reads "-12"), and its
    length. Two digits per step, by table; divisions by a scalar, which NumPy multiplies."""
    mag = values.astype(np.uint64)
    neg = values < 0
    mag[neg] = np.negative(mag[neg])  # |int64 min| too: 2**63 fits a uint64
    pairs = np.empty((len(values), width // 2), np.intp)
    q = mag
    for k in range(width // 2 - 1, -1, -1):
        rest = q // _HUNDRED
        pairs[:, k] = q - rest * _HUNDRED
        q = rest
    digits = _PAIRS[pairs].view(np.uint8)
    lead = mag[:, None] < _TENS[-width:]
    lead[:, -1] = False  # 0 is "0"
    digits[lead] = 0
    digits[neg, 0] = ord("-")
    length: _Int = width - lead.sum(axis=1) + neg
    return digits, length


def _id_digits(ids: _Int) -> tuple[npt.NDArray[np.void], _Int]:
    """The ids' digits, ``V4`` (all below ``_SHORT_IDS``) or ``V10`` (uint32) rows, and their lengths."""
    table, lengths, *_ = _tables()
    if not len(ids) or ids.max() < _SHORT_IDS:
        return table[ids], lengths[ids]
    digits, length = _decimal(ids, _ID_WIDTH)
    return np.ascontiguousarray(digits).view(f"V{_ID_WIDTH}")[:, 0], length



def _texts(p: _Packets) -> list[str]:
    """The pipeline's text of each packet: every packet's header, nodes and footer written as
    NUL-padded rows by NumPy, put in order by one gather, squeezed by ``bytes.translate``,
    expanded by ``bytes.replace`` (C) and cut per packet at lengths NumPy adds up: no Python per
    packet but the cut, none per node."""
    count = len(p.n)
    if not count:
        return []
    _, _, tails, last_tails, tail_len = _tables()
    id_digits, id_len = _id_digits(p.ids)
    layout = _layout(id_digits.dtype.itemsize)
    heads = layout.heads * count
    rows = np.empty(heads + 1 + len(p.ids), f"V{layout.node.itemsize}")  # headers, a footer, nodes
    head = rows[:heads].view(np.uint8).reshape(count, -1)
    head[:] = layout.template[:head.shape[1]]
    head[:, _TS_AT:_TS_AT + 20], ts_len = _decimal(p.ts, 20)
    n_digits, n_len = _id_digits(p.n)  # by table: n < 10,000 (all but absurd packets)
    if n_digits.dtype.itemsize == 4:
        head[:, _N_AT + 2:_N_AT + 6] = n_digits.view(np.uint8).reshape(count, 4)
    else:
        head[:, _N_AT:_N_AT + 6], n_len = _decimal(p.n, 6)
    rows[heads] = layout.template[head.shape[1]:].view(rows.dtype)[0]
    nodes = rows[heads + 1:].view(layout.node)
    nodes["head"] = ord(_HEAD_MARK)
    nodes["id"] = id_digits
    nodes["key"] = ord(_KEY_MARK)
    nodes["tail"] = tails[p.micro]
    end = np.cumsum(p.n)
    last = end[p.n > 0] - 1
    nodes["tail"][last] = last_tails[p.micro[last]]
    # the output's rows, packet by packet: its header rows, its nodes, the footer
    start = end - p.n
    packet = np.arange(count)
    segments = np.empty((count, 3), np.int64)
    segments[:, 0] = layout.heads
    segments[:, 1] = p.n
    segments[:, 2] = 1
    shift = np.zeros((count, 3), np.int64)  # source row - output row, per segment
    shift[:, 0] = -packet - start
    shift[:, 1] = heads + 1 - (layout.heads + 1) * packet - layout.heads
    order = np.arange(heads + count + len(p.ids)) + np.repeat(shift.ravel(), segments.ravel())
    order[start + (layout.heads + 1) * packet + layout.heads + p.n] = heads  # the footers
    # each packet's length: fixed text, numbers, nodes (a comma less for the last)
    node_len = np.zeros(len(p.ids) + 1, np.int64)
    np.cumsum(len(_NODE_HEAD) + len(_NODE_KEY) + id_len + tail_len[p.micro], out=node_len[1:])
    size = _FIXED + ts_len + n_len + node_len[end] - node_len[start] - (p.n > 0)
    cut = np.zeros(count + 1, np.int64)
    np.cumsum(size, out=cut[1:])
    text = (rows[order].tobytes().translate(None, b"\0").replace(_HEAD_MARK, _NODE_HEAD)
            .replace(_KEY_MARK, _NODE_KEY).decode("ascii"))
    bounds = cut.tolist()
    if len(text) != bounds[-1]:  # never: the lengths are the rows' own; a guard, not a decision
        raise RuntimeError("skin packets decoded to a text of another length than computed")
    return [text[i:j] for i, j in zip(bounds, bounds[1:], strict=False)]  # n + 1 bounds: n texts


# --- numbers <-> packed bytes ---------------------------------------------------------------

def _le(values: _Int, dtype: str, width: int) -> npt.NDArray[np.uint8]:
    """Little-endian bytes of ``values``, one row each."""
    return values.astype(dtype).view(np.uint8).reshape(-1, width)


def _pack(p: _Packets, t_ns: _Int) -> list[bytes]:
    """The packed bytes of each packet (ids within uint32, µm within uint16, n <= _MAX_NODES)."""
    n = p.n
    start, packet, j = p.node_index()
    gaps = np.diff(p.ids, prepend=0)
    gaps[start[n > 0]] = 0
    bad_gap = np.bincount(packet[(gaps < 0) | (gaps > 0xFF)], minlength=len(n)) > 0
    small = (n > 0) & ~bad_gap
    same = p.ts == t_ns
    wide = n > 0x7F
    ids_len = np.where(small, 3 + n, 4 * n)
    pos = 3 + wide + 8 * ~same  # where the ids start, from the packet's first byte
    size = pos + ids_len + 2 * n
    off = np.cumsum(size) - size
    buf = np.zeros(int(size.sum()), np.uint8)
    buf[off] = PACKED
    buf[off + 1] = same * _SAME_TIME | small * _SMALL_GAPS
    buf[off + 2] = np.where(wide, n & 0x7F | 0x80, n)
    buf[off[wide] + 3] = n[wide] >> 7
    own = ~same
    buf[(off + 3 + wide)[own, None] + np.arange(8)] = _le(p.ts[own], "<i8", 8)
    pos += off
    buf[pos[small, None] + np.arange(4)] = _le(p.ids[start[small]], "<u4", 4)
    node_pos = pos[packet]
    gap = small[packet] & (j > 0)
    buf[node_pos[gap] + 3 + j[gap]] = gaps[gap]
    whole = ~small[packet]
    buf[(node_pos + 4 * j)[whole, None] + np.arange(4)] = _le(p.ids[whole], "<u4", 4)
    at = (pos + ids_len)[packet] + 2 * j
    buf[at] = p.micro & 0xFF
    buf[at + 1] = p.micro >> 8
    raw = buf.tobytes()
    return [raw[a:b] for a, b in zip(off.tolist(), (off + size).tolist(), strict=True)]


def _unpack(blobs: Sequence[bytes | memoryview], t_ns: list[int]) -> _Packets:
    """The numbers of packed payloads (ValueError for bytes that are not a whole packet)."""
    size = np.fromiter(map(len, blobs), np.int64, len(blobs))
    buf = np.frombuffer(b"".join([*blobs, PAD]), np.uint8)
    return _unpack_at(buf, np.cumsum(size) - size, size, np.array(t_ns, np.int64))


def _unpack_at(buf: npt.NDArray[np.uint8], off: _Int, size: _Int, t_ns: _Int) -> _Packets:
    """The numbers of the packets at ``off`` in ``buf`` (which ends with ``PAD``)."""
    flags = buf[off + 1]
    first = buf[off + 2].astype(np.int64)
    wide = first >= 0x80
    n = np.where(wide, first & 0x7F | buf[off + 3].astype(np.int64) << 7, first)
    same = (flags & _SAME_TIME) != 0
    small = (n > 0) & ((flags & _SMALL_GAPS) != 0)
    pos = off + 3 + wide + 8 * ~same
    ids_len = np.where(small, 3 + n, 4 * n)
    if ((size < 3) | (pos + ids_len + 2 * n != off + size)).any():
        raise ValueError("a stored skin packet is damaged: its length does not match its header")
    ts = t_ns.copy()
    own = ~same
    if own.any():
        ts[own] = buf[(off + 3 + wide)[own, None] + np.arange(8)].copy().view("<i8")[:, 0]
    micro = join_spans(buf, pos + ids_len, 2 * n).view("<u2").astype(np.int64)
    p = _Packets(ts, n, np.empty(0, np.int64), micro)
    if (small | (n == 0)).all():  # the first id, then a byte per gap: runs of n bytes from the
        has = n > 0               # first id's last byte (zeroed), added up
        start = (np.cumsum(n) - n)[has]
        gaps = join_spans(buf, pos + 3, n).astype(np.int64)
        gaps[start] = 0
        run = np.cumsum(gaps)
        return p._replace(ids=run + np.repeat(_words(buf, pos[has], "<u4") - run[start], n[has]))
    start, packet, j = p.node_index()
    node_pos = pos[packet]
    gaps = buf[node_pos + 3 + j].astype(np.int64)
    gaps[j == 0] = 0
    run = np.cumsum(gaps)
    ids = _words(buf, pos, "<u4")[packet] + run - run[start[packet]]
    whole = ~small[packet]  # the others: a uint32 per id
    ids[whole] = _words(buf, (node_pos + 4 * j)[whole], "<u4")
    return p._replace(ids=ids)


def _words(buf: npt.NDArray[np.uint8], at: _Int, dtype: str) -> _Int:
    """The little-endian unsigned integers at byte offsets ``at`` of ``buf``."""
    width = np.dtype(dtype).itemsize
    words: _Int = buf[at[:, None] + np.arange(width)].view(dtype)[:, 0].astype(np.int64)
    return words


# --- records -> packets ---------------------------------------------------------------------

_START = '{"timeStamp":'


def _time_stamp(data: str) -> int | None:
    """The timeStamp of a text that starts as the pipeline's (the rest is checked by rebuilding it)."""
    if not data.startswith(_START):
        return None
    digits = data[len(_START):data.find(",", len(_START), len(_START) + 20)]
    if not (digits.isascii() and digits.isdigit()):
        return None
    ts = int(digits)
    return ts if ts < 1 << 63 else None


def _usable(skin: SkinArrays) -> bool:
    """Arrays of the shape and kind the pipeline makes (what NumPy concatenates and converts
    without raising: the writer's batch must never fail on a record's arrays)."""
    ids, values = skin
    return (isinstance(ids, np.ndarray) and isinstance(values, np.ndarray) and ids.ndim == values.ndim == 1
            and ids.dtype.kind in "iu" and values.dtype.kind == "f" and len(ids) == len(values) <= _MAX_NODES)


def _from_arrays(recs: list[Record]) -> tuple[list[int], _Packets]:
    """The packets whose arrays (``Record.skin``) fit the packed form: their indexes, numbers."""
    idx: list[int] = []
    ts: list[int] = []
    skins: list[SkinArrays] = []
    for i, r in enumerate(recs):
        t = _time_stamp(r.data)
        if t is not None and r.skin is not None and _usable(r.skin):
            idx.append(i)
            ts.append(t)
            skins.append(r.skin)
    if not idx:
        return [], _Packets(*[np.empty(0, np.int64)] * 4)
    ids = np.concatenate([s.ids for s in skins]).astype(np.int64)
    mm = np.concatenate([s.intensity for s in skins]).astype(np.float64)
    micro = np.rint(mm * 1000)
    ok = (ids >= 0) & (ids <= _MAX_ID) & (micro >= 0) & (micro <= _MAX_MICRO) & (micro / 1000 == mm)
    return _keep(idx, np.array(ts, np.int64), np.array([len(s.ids) for s in skins], np.int64),
                 ids, np.where(ok, micro, 0).astype(np.int64), ok)


def _from_text(recs: list[Record]) -> tuple[list[int], _Packets]:
    """The packets whose text reads as numbers that fit the packed form: its tokens of digits
    and dots (the keys have none) are the timeStamp, the node count, then ids and intensities."""
    idx: list[int] = []
    ts: list[int] = []
    n: list[int] = []
    ids: list[int] = []
    values: list[float] = []
    for i, r in enumerate(recs):
        if not r.data.startswith(_START):
            continue
        tokens = r.data.encode().translate(_NUMBERS).split()
        try:
            t, k = int(tokens[0]), int(tokens[1])
            if len(tokens) != 2 + 2 * k or k > _MAX_NODES or t >= 1 << 63:
                continue
            nodes = list(map(int, tokens[2::2]))
            vals = list(map(float, tokens[3::2]))
        except (ValueError, IndexError):  # "1.5" as an id, "1.2.3", fewer than two tokens
            continue
        if nodes and max(nodes) > _MAX_ID:
            continue
        idx.append(i)
        ts.append(t)
        n.append(k)
        ids += nodes
        values += vals
    mm = np.array(values, np.float64) * 1000
    micro = np.rint(mm)
    ok = (micro >= 0) & (micro <= _MAX_MICRO)
    return _keep(idx, np.array(ts, np.int64), np.array(n, np.int64), np.array(ids, np.int64),
                 np.where(ok, micro, 0).astype(np.int64), ok)


def _time(t_ns: int) -> int:
    """A record time as int64: one beyond it (never in a database) as -1, which no timeStamp equals."""
    return t_ns if -1 << 63 <= t_ns < 1 << 63 else -1


def _keep(idx: list[int], ts: _Int, n: _Int, ids: _Int, micro: _Int,
          ok: npt.NDArray[np.bool_]) -> tuple[list[int], _Packets]:
    """The packets all of whose nodes are ``ok``."""
    p = _Packets(ts, n, ids, micro)
    _, packet, _ = p.node_index()
    good = np.bincount(packet[~ok], minlength=len(n)) == 0
    if good.all():
        return idx, p
    return [i for i, g in zip(idx, good.tolist(), strict=True) if g], \
        _Packets(ts[good], n[good], ids[good[packet]], micro[good[packet]])


def encode_records(recs: Sequence[Record]) -> list[bytes]:
    """The bytes stored for each record's payload (a batch: the writer's)."""
    out: list[bytes | None] = encode_fields(recs)  # skinDisplacement packets (field_codec.py)
    todo = [i for i, r in enumerate(recs) if r.kind == KIND_EVENT and r.name == SKIN_EVENT]
    for numbers in (_from_arrays, _from_text):  # what the arrays cannot give, the text may
        batch = [recs[i] for i in todo]
        idx, packets = numbers(batch)
        if idx:
            t_ns = np.array([_time(batch[i].t_ns) for i in idx], np.int64)
            packed = _pack(packets, t_ns)
            for i, blob, text in zip(idx, packed, _texts(_unpack(packed, t_ns.tolist())), strict=True):
                if text == batch[i].data:  # every byte comes back: else the text is stored
                    out[todo[i]] = blob
        todo = [i for i in todo if out[i] is None]
    return [r.data.encode() if b is None else b for r, b in zip(recs, out, strict=True)]


def encode(kind: int, name: str, t_ns: int, data: str) -> bytes:
    """The bytes stored for one payload (``encode_records`` of one record)."""
    return encode_records([Record("", 0, kind, name, t_ns, data)])[0]


_CHUNK = 2048
"""Rows decoded per NumPy pass. A pass's buffers (~1 MB of text for skin packets) stay in the
CPU's caches and in memory the allocator reuses; a replay page of 20,000 rows at once made
~10 MB buffers, fresh pages of the OS at every call, whose page faults cost a third of the time."""


def decode_many(stored: Sequence[Stored], t_ns: Sequence[int]) -> list[str]:
    """Each payload's text exactly as it was sent live (``t_ns``: the records' times, which a
    packet whose timeStamp equals it does not store again); packed ones decoded together."""
    if len(stored) <= _CHUNK:
        return _decode_chunk(stored, t_ns)
    out: list[str] = []
    for i in range(0, len(stored), _CHUNK):
        out += _decode_chunk(stored[i:i + _CHUNK], t_ns[i:i + _CHUNK])
    return out


def decode_joined(joined: bytes, size: _Int, t_ns: _Int) -> list[str]:
    """``decode_many`` of payloads given one after the other in ``joined``, which ends with 16
    NUL bytes (``size``: their lengths): a page read as one value, no bytes object per row."""
    out: list[str] = []
    for rows, lo, buf, off, chunk in joined_chunks(joined, size):
        out += decode_at(joined, lo, buf, off, chunk, t_ns[rows], None)
    return out


def joined_chunks(joined: bytes, size: _Int
                  ) -> Iterator[tuple[slice, int, npt.NDArray[np.uint8], _Int, _Int]]:
    """The chunks of at most ``_CHUNK`` payloads of ``joined`` (``decode_joined``'s input), each as (its
    rows, where its bytes start in ``joined``, those bytes and the 16 NULs after them, each payload's
    offset there, their lengths): masks of a chunk's length, never a page's."""
    buf = np.frombuffer(joined, np.uint8)
    if len(buf) != int(size.sum()) + len(PAD):
        raise ValueError("the joined payloads do not have the lengths given")
    ends = np.cumsum(size)
    lo = 0
    for i in range(0, len(size), _CHUNK):
        chunk = size[i:i + _CHUNK]
        hi = int(ends[i + len(chunk) - 1]) + len(PAD)
        yield slice(i, i + len(chunk)), lo, buf[lo:hi], ends[i:i + _CHUNK] - chunk - lo, chunk
        lo = hi - len(PAD)


def _decode_chunk(stored: Sequence[Stored], t_ns: Sequence[int]) -> list[str]:
    """``decode_many`` of at most ``_CHUNK`` rows: their bytes joined once, then ``decode_at``."""
    try:
        joined = b"".join([*stored, PAD])  # type: ignore[list-item]  # a str raises TypeError
    except TypeError:  # a str among them: a row written before 0006 on a database that kept its text
        return _decode_each(stored, t_ns)
    size = np.fromiter(map(len, stored), np.int64, len(stored))
    try:
        times = np.fromiter(t_ns, np.int64, len(stored))
    except OverflowError:
        times = np.fromiter(map(_time, t_ns), np.int64, len(stored))
    return decode_at(joined, 0, np.frombuffer(joined, np.uint8), np.cumsum(size) - size, size, times,
                      stored)  # type: ignore[arg-type]  # no str: the join took them all


def decode_at(joined: bytes, base: int, buf: npt.NDArray[np.uint8], off: _Int, size: _Int, t_ns: _Int,
               stored: Sequence[bytes | memoryview] | None) -> list[str]:
    """The texts of the payloads at ``off`` in ``buf``, which is ``joined[base:]`` (``stored``: the
    same payloads as objects, else sliced from ``joined``): the packets found and unpacked in
    place, the other payloads' UTF-8 decoded together; no Python per row but the slices."""
    packed = (buf[off] == PACKED) & (size > 0)
    where = np.flatnonzero(packed)
    if len(where) == len(off):
        return _texts(_unpack_at(buf, off, size, t_ns))
    fields = (buf[off] == PACKED_FIELD) & (size > 0)
    if fields.any():
        return _with_fields(joined, base, buf, off, size, t_ns, stored, fields)
    rest = np.flatnonzero(~packed).tolist()
    if stored is not None:
        items: Sequence[bytes | memoryview] = [stored[i] for i in rest]
    else:
        at = off[rest] + base
        items = [joined[i:j] for i, j in zip(at.tolist(), (at + size[rest]).tolist(), strict=True)]
    if not len(where):
        return _utf8(items)
    out = np.empty(len(off), object)
    out[where] = _texts(_unpack_at(buf, off[where], size[where], t_ns[where]))
    out[rest] = _utf8(items)
    result: list[str] = out.tolist()
    return result


def _with_fields(joined: bytes, base: int, buf: npt.NDArray[np.uint8], off: _Int, size: _Int, t_ns: _Int,
                 stored: Sequence[bytes | memoryview] | None, fields: npt.NDArray[np.bool_]) -> list[str]:
    """``decode_at`` of payloads some of which are packed displacement packets (``field_codec``): those
    written back by ``field_texts``, the others as ``decode_at`` writes them."""
    where = np.flatnonzero(fields)
    others = np.flatnonzero(~fields)
    texts = field_texts_at(buf, off[where], size[where], t_ns[where])
    if not len(others):
        return texts
    out = np.empty(len(off), object)
    out[where] = texts
    if len(others):
        rest = None if stored is None else [stored[i] for i in others.tolist()]
        out[others] = decode_at(joined, base, buf, off[others], size[others], t_ns[others], rest)
    result: list[str] = out.tolist()
    return result


def _utf8(items: Sequence[bytes | memoryview]) -> list[str]:
    """The items' UTF-8 text, decoded in one call: joined by NULs, which JSON text never holds
    (a text that does holds one more: then one by one)."""
    texts = b"\0".join(items).decode("utf-8").split("\0")
    if len(texts) != len(items):
        return [str(d, "utf-8") for d in items]
    return texts


def _decode_each(stored: Sequence[Stored], t_ns: Sequence[int]) -> list[str]:
    """``decode_many`` of rows some of which are ``str``: each row tested in Python."""
    where = [i for i, d in enumerate(stored) if d[:1] == _MARK]  # a str never starts with it
    out = [d if isinstance(d, str) else "" if d[:1] in (_MARK, _FIELD_MARK) else str(d, "utf-8")
           for d in stored]
    fields = [i for i, d in enumerate(stored) if d[:1] == _FIELD_MARK]
    if fields:
        for i, text in zip(fields, field_texts([stored[i] for i in fields],  # type: ignore[misc]  # no str
                                               [t_ns[i] for i in fields]), strict=True):
            out[i] = text
    if not where:
        return out
    times = [t_ns[i] for i in where]
    if not -1 << 63 <= min(times) <= max(times) < 1 << 63:
        times = list(map(_time, times))
    packets = _unpack([stored[i] for i in where], times)  # type: ignore[misc]  # no str starts with _MARK
    for i, text in zip(where, _texts(packets), strict=True):
        out[i] = text
    return out


def skin_numbers_at(buf: npt.NDArray[np.uint8], off: _Int, size: _Int, t_ns: _Int) -> tuple[_Int, _Int, _Int]:
    """(nodes per packet, every packet's ids one after the other, their intensities in µm) of the
    packed packets at ``off`` in ``buf`` (which ends with 16 NUL bytes): the numbers their texts
    are written from, for a reader that wants the numbers (``history.numbers``)."""
    p = _unpack_at(buf, off, size, t_ns)
    return p.n, p.ids, p.micro


def skin_text(t_ns: int, ids: _Int, micro: _Int) -> str:
    """The text of one packet of ``timeStamp`` ``t_ns`` (the text ``decode_many`` gives for it)."""
    return _texts(_Packets(np.array([t_ns], np.int64), np.array([len(ids)], np.int64),
                           ids.astype(np.int64, copy=False), micro.astype(np.int64, copy=False)))[0]


def decode(stored: Stored, t_ns: int) -> str:
    """One payload's text (``decode_many`` of one)."""
    return decode_many([stored], [t_ns])[0]
