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

Contract: ``decode(encode(kind, name, t_ns, data), t_ns) == data`` for every payload, and
``decode_many(encode_records(recs), ...) == [r.data for r in recs]`` whatever ``r.skin``
holds; ``decode`` also accepts a ``str`` (rows written before revision 0006 on a database
that kept its text) and plain UTF-8 bytes. Migrations import this module: its packed format
is part of the schema and may only be extended (a new first byte), never changed.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from wott_hub.events.record import KIND_EVENT, Record, SkinArrays

__all__ = ["PACKED", "SKIN_EVENT", "decode", "decode_many", "encode", "encode_records"]

PACKED = 0x01
_MARK = bytes((PACKED,))
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

_ID_TABLE = 8192  # ids below: digits by table (every mesh so far), above: computed
_ID_WIDTH = 10  # digits of the largest uint32
_NODE = np.dtype([("head", "u1"), ("id", "u1", (_ID_WIDTH,)), ("key", "u1"), ("tail", "<u8")])
"""One node's text, NUL-padded, with a marker byte for each key (expanded by ``bytes.replace``,
which costs less than squeezing 43 more bytes per node): ``head`` id ``key`` repr(µm / 1000) "},"."""
_HEAD_MARK, _KEY_MARK = 2, 3
_NODE_HEAD = b'{"deformedNodeID":'
_NODE_KEY = b',"deformedNodeIntensity":'
_NODE_FIXED = len(_NODE_HEAD) + len(_NODE_KEY)
_POW10 = 10 ** np.arange(_ID_WIDTH, dtype=np.int64)
_ID_LEN = 1 + (np.arange(_ID_TABLE)[:, None] >= _POW10[1:]).sum(axis=1)


@functools.cache
def _tables() -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint64], npt.NDArray[np.int64]]:
    """Digits of the ids below ``_ID_TABLE``, ``repr(k / 1000) + "},"`` of every uint16 ``k``
    (8 bytes at most: "65.535},") and its length; built on first use (~40 ms, 0.7 MB)."""
    ids = b"".join(str(i).encode().ljust(_ID_WIDTH, b"\0") for i in range(_ID_TABLE))
    tails = [(repr(k / 1000) + "},").encode() for k in range(_MAX_MICRO + 1)]
    packed = b"".join(t.ljust(8, b"\0") for t in tails)
    return (np.frombuffer(ids, np.uint8).reshape(-1, _ID_WIDTH), np.frombuffer(packed, "<u8"),
            np.fromiter(map(len, tails), np.int64, len(tails)))


def _id_digits(ids: _Int) -> tuple[npt.NDArray[np.uint8], _Int]:
    """The ids' digits (NUL-padded rows) and their numbers of digits."""
    if not len(ids) or ids.max() < _ID_TABLE:
        return _tables()[0][ids], _ID_LEN[ids]
    low = ids < _ID_TABLE
    out = np.zeros((len(ids), _ID_WIDTH), np.uint8)
    out[low] = _tables()[0][ids[low]]
    size = 1 + (ids[:, None] >= _POW10[1:]).sum(axis=1)
    big = ids[~low][:, None]
    exp = size[~low][:, None] - 1 - np.arange(_ID_WIDTH)  # the place of each digit
    digits = big // _POW10[np.maximum(exp, 0)] % 10 + ord("0")
    out[~low] = np.where(exp >= 0, digits, 0)
    return out, size


def _texts(p: _Packets) -> list[str]:
    """The pipeline's text of each packet: the nodes' texts of all packets written into one
    buffer by NumPy, squeezed and expanded by ``bytes`` methods (C), then cut per packet."""
    _, tails, tail_len = _tables()
    nodes = np.empty(len(p.ids), _NODE)
    nodes["head"] = _HEAD_MARK
    digits, id_len = _id_digits(p.ids)
    nodes["id"] = digits
    nodes["key"] = _KEY_MARK
    nodes["tail"] = tails[p.micro]
    text = (nodes.tobytes().translate(None, b"\0").replace(b"\2", _NODE_HEAD).replace(b"\3", _NODE_KEY)
            .decode("ascii"))
    ends = np.zeros(len(p.ids) + 1, np.int64)
    np.cumsum(_NODE_FIXED + id_len + tail_len[p.micro], out=ends[1:])
    start = np.cumsum(p.n) - p.n
    a = ends[start]
    b = ends[start + p.n] - (p.n > 0)  # without the "," after a packet's last node
    return [f'{{"timeStamp":{t},"numOfDeformedNodes":{k},"arrayOfDeformedNodes":[{text[i:j]}]}}'
            for t, k, i, j in zip(p.ts.tolist(), p.n.tolist(), a.tolist(), b.tolist(), strict=True)]


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
    buf = np.frombuffer(b"".join(blobs) + bytes(16), np.uint8)  # the padding: header reads stay inside
    off = np.cumsum(size) - size
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
    ts = np.array(t_ns, np.int64)
    own = ~same
    ts[own] = buf[(off + 3 + wide)[own, None] + np.arange(8)].copy().view("<i8")[:, 0]
    p = _Packets(ts, n, np.empty(0, np.int64), np.empty(0, np.int64))
    start, packet, j = p.node_index()
    node_pos = pos[packet]
    # small gaps: the first id, then a byte per gap (at j = 0 the first id's last byte: zeroed)
    gaps = buf[node_pos + 3 + j].astype(np.int64)
    gaps[j == 0] = 0
    run = np.cumsum(gaps)
    ids = _words(buf, pos, "<u4")[packet] + run - run[start[packet]]
    if not small.all():  # the others: a uint32 per id
        whole = ~small[packet]
        ids[whole] = _words(buf, (node_pos + 4 * j)[whole], "<u4")
    return p._replace(ids=ids, micro=_words(buf, (pos + ids_len)[packet] + 2 * j, "<u2"))


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
    out: list[bytes | None] = [None] * len(recs)
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


def decode_many(stored: Sequence[Stored], t_ns: Sequence[int]) -> list[str]:
    """Each payload's text exactly as it was sent live (``t_ns``: the records' times, which a
    packet whose timeStamp equals it does not store again); packed ones decoded together."""
    where = [i for i, d in enumerate(stored) if d[:1] == _MARK]  # a str never starts with it
    if not where:
        return [d if isinstance(d, str) else str(d, "utf-8") for d in stored]
    out = [d if isinstance(d, str) else "" if d[:1] == _MARK else str(d, "utf-8") for d in stored]
    times = [t_ns[i] for i in where]
    if not -1 << 63 <= min(times) <= max(times) < 1 << 63:
        times = list(map(_time, times))
    packets = _unpack([stored[i] for i in where], times)  # type: ignore[misc]  # no str starts with _MARK
    for i, text in zip(where, _texts(packets), strict=True):
        out[i] = text
    return out


def decode(stored: Stored, t_ns: int) -> str:
    """One payload's text (``decode_many`` of one)."""
    return decode_many([stored], [t_ns])[0]
