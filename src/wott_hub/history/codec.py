"""How a record's payload is stored: packed numbers for skin packets, UTF-8 text for the rest.

A ``skinDeformedDetection`` packet is most of what a hub records (~716 B of JSON for ~20
nodes). Its text is the one ``hub.pipeline.skin_deformed_json`` writes, so it can be stored
as numbers and written back to the *identical* text on read: SSE resume and replay must
send exactly the bytes sent live. ``encode`` therefore packs a packet only when unpacking
it gives back every byte; anything else (another affordance, a packet from a foreign driver,
an intensity that is not a whole number of µm) is stored as its UTF-8 text.

Packed form (``PACKED`` first; JSON text never starts with that byte):

    0x01, flags, varint n, [int64 timeStamp unless flag SAME_TIME], ids, n x uint16 µm

``SAME_TIME``: ``timeStamp`` equals the record's time. Ids: ascending ids as the first id
(uint32) and n-1 gaps of one byte (flag SMALL_GAPS), else n x uint32. Intensities: whole
µm (the processor rounds them to 3 decimals, ``intensity_decimals``) as uint16, written back
with Python's float repr of ``k / 1000``, which is what ``json`` wrote for the rounded
value (a correctly rounded division gives the same double as the decimal text).

Contract: ``decode(encode(kind, name, t_ns, data), t_ns) == data`` for every payload;
``decode`` also accepts a ``str`` (rows written before revision 0006 on a database that
kept its text) and plain UTF-8 bytes. Migrations import this module: its packed format
is part of the schema and may only be extended (a new first byte), never changed.
"""

from __future__ import annotations

import functools
import itertools
import operator
import re
import struct

__all__ = ["PACKED", "SKIN_EVENT", "decode", "encode"]

PACKED = 0x01
SKIN_EVENT = "skinDeformedDetection"
_SAME_TIME = 1
_SMALL_GAPS = 2

_HEAD = re.compile(r'\{"timeStamp":(0|[1-9]\d*),"numOfDeformedNodes":(0|[1-9]\d*),"arrayOfDeformedNodes":\[')
_Q = struct.Struct("<q")
_I = struct.Struct("<I")
_K1 = '{"deformedNodeID":'
_K2 = ',"deformedNodeIntensity":'
_J = '},{"deformedNodeID":'
_TABLE = 8192  # µm values below 8.192 mm: text <-> number by table (most packets), the rest computed


class _Tables:
    """repr(k / 1000) for k < _TABLE, the reverse, ids and node texts; built on first use (~4 MB)."""

    text: list[str] = []
    micro: dict[str, int] = {}
    micro_b: dict[bytes, int] = {}
    # the hot paths look every token up instead of parsing it: a key is canonical text, so a
    # hit is also the proof of "no leading zero"; a miss falls back to the computed path
    id_b: dict[bytes, int] = {}
    node_head: list[str] = []  # '{"deformedNodeID":<id>,"deformedNodeIntensity":'
    node_tail: list[str] = []  # '<repr(k / 1000)>},'

    @classmethod
    def load(cls) -> None:
        if not cls.text:
            text = [repr(k / 1000) for k in range(_TABLE)]
            cls.micro = {t: k for k, t in enumerate(text)}
            cls.micro_b = {t.encode(): k for k, t in enumerate(text)}
            cls.id_b = {str(i).encode(): i for i in range(_TABLE)}
            cls.node_head = [f"{_K1}{i}{_K2}" for i in range(_TABLE)]
            cls.node_tail = [t + "}," for t in text]
            cls.text = text  # last: ``load`` is a no-op once this is set


def _micro_text(k: int) -> str:
    return _Tables.text[k] if k < _TABLE else repr(k / 1000)


def _micro_of(text: str) -> int | None:
    k = _Tables.micro.get(text)
    if k is not None:
        return k
    try:
        k = round(float(text) * 1000)
    except (ValueError, OverflowError):
        return None
    return k if 0 <= k <= 0xFFFF and repr(k / 1000) == text else None




_NUMBERS = bytes(c if chr(c) in "0123456789." else 32 for c in range(256))
_LEAD0 = re.compile(rb" 0[0-9]")
_K2B = _K2.encode()
_JB = _J.encode()


@functools.cache
def _seps_b(n_tokens: int) -> list[bytes]:
    """The woven list for ``n_tokens`` tokens with the separators in place (copied, then filled)."""
    out = [b""] * (2 * n_tokens - 1)
    out[1::2] = ([_K2B, _JB] * (n_tokens // 2 + 1))[:n_tokens - 1]
    return out


def _weave_b(tokens: list[bytes]) -> bytes:
    out = _seps_b(len(tokens)).copy()
    out[::2] = tokens
    return b"".join(out)


def _weave(tokens: list[str]) -> str:
    """id0 K2 v0 J id1 K2 v1 ... (tokens: ids and intensity texts alternating), by C-level joins."""
    seps = [_K2, _J] * (len(tokens) // 2)
    out = [""] * (2 * len(tokens) - 1)
    out[::2] = tokens
    out[1::2] = seps[:len(tokens) - 1]
    return "".join(out)


def _text(ts: int, ids: list[int], micro: list[int]) -> str:
    n = len(ids)
    if not n:
        return f'{{"timeStamp":{ts},"numOfDeformedNodes":0,"arrayOfDeformedNodes":[]}}'
    table = _Tables.text
    tokens = [""] * (2 * n)
    tokens[::2] = map(str, ids)
    if max(micro) < _TABLE:
        tokens[1::2] = map(table.__getitem__, micro)
    else:
        tokens[1::2] = [table[k] if k < _TABLE else repr(k / 1000) for k in micro]
    return f'{{"timeStamp":{ts},"numOfDeformedNodes":{n},"arrayOfDeformedNodes":[{_K1}{_weave(tokens)}}}]}}'


def _nodes(inner: bytes, n: int) -> tuple[list[int], list[int]] | None:
    """Ids and µm of a packet's nodes parsed token by token (ids or µm beyond the tables)."""
    tokens = inner.translate(_NUMBERS).split()  # every byte but 0-9 and "." is a space
    if len(tokens) != 2 * n:
        return None
    micro = list(map(_Tables.micro_b.get, tokens[1::2]))
    if None in micro:
        micro = [_micro_of(v.decode()) for v in tokens[1::2]]
        if None in micro:
            return None
    id_tokens = tokens[::2]
    ids = list(map(_Tables.id_b.get, id_tokens))  # a hit: canonical digits below _TABLE
    if None in ids:
        try:
            ids = list(map(int, id_tokens))  # digits only here: "1.5" fails
        except ValueError:
            return None
        if _LEAD0.search(b" " + b" ".join(id_tokens)):  # "05" would not come back
            return None
    # every byte given back, or the text is stored: the pieces in this order with exactly
    # the separators between them
    if _weave_b(tokens) != inner:
        return None
    return ids, micro  # type: ignore[return-value]  # no None left


def _pack_skin(t_ns: int, data: str) -> bytes | None:
    head = _HEAD.match(data)
    if head is None or not data.isascii():
        return None
    ts, n = int(head.group(1)), int(head.group(2))
    if n > 0x7FFF or ts >= 1 << 63:
        return None
    body = data[head.end():]
    if not n:
        if body != "]}":
            return None
        ids: list[int] = []
        micro: list[int] = []
    else:
        if not (body.startswith(_K1) and body.endswith("}]}")):
            return None
        inner = body[len(_K1):-3].encode()  # ASCII: bytes work in C at every step below
        _Tables.load()
        nodes = _nodes(inner, n)
        if nodes is None:
            return None
        ids, micro = nodes
    flags = 0
    out = bytearray((PACKED, 0))
    out += bytes((n & 0x7F | 0x80, n >> 7)) if n > 0x7F else bytes((n,))
    if ts == t_ns:
        flags |= _SAME_TIME
    else:
        out += _Q.pack(ts)
    if n:  # ids are >= 0 here (canonical digits)
        try:
            gaps = bytes(map(operator.sub, ids[1:], ids))  # ValueError: a gap outside 0..255
        except ValueError:
            gaps = None
        if gaps is not None and ids[0] <= 0xFFFFFFFF:
            flags |= _SMALL_GAPS
            out += _I.pack(ids[0])
            out += gaps
        elif max(ids) <= 0xFFFFFFFF:
            out += struct.pack(f"<{n}I", *ids)
        else:
            return None
    out += _unpack_h(n).pack(*micro)
    out[1] = flags
    return bytes(out)


def encode(kind: int, name: str, t_ns: int, data: str) -> bytes:
    """The bytes stored for a record's payload."""
    if name == SKIN_EVENT and kind == 0:
        packed = _pack_skin(t_ns, data)
        if packed is not None:
            return packed
    return data.encode()


def decode(stored: bytes | memoryview | str, t_ns: int) -> str:
    """The payload text exactly as it was sent live (``t_ns``: the record's time, which a packet
    whose timeStamp equals it does not store again)."""
    if isinstance(stored, str):
        return stored
    if not stored or stored[0] != PACKED:
        return bytes(stored).decode()
    b = bytes(stored)
    flags = b[1]
    n = b[2]
    pos = 3
    if n & 0x80:
        n = (n & 0x7F) | (b[3] << 7)
        pos = 4
    if flags & _SAME_TIME:
        ts = t_ns
    else:
        ts = _Q.unpack_from(b, pos)[0]
        pos += 8
    if flags & _SMALL_GAPS:
        first = _I.unpack_from(b, pos)[0]
        pos += 4
        ids = list(itertools.accumulate(b[pos:pos + n - 1], initial=first))
        pos += n - 1
    else:
        ids = list(struct.unpack_from(f"<{n}I", b, pos))
        pos += 4 * n
    micro = _unpack_h(n).unpack_from(b, pos)
    tables = _Tables
    tables.load()
    if not n or max(micro) >= _TABLE or max(ids) >= _TABLE:
        return _text(ts, ids, list(micro))
    # the common case: one join of precomputed pieces (node head by id, intensity text + "},")
    parts = _parts(n).copy()
    parts[1] = str(ts)
    parts[3:-1:2] = map(tables.node_head.__getitem__, ids)
    parts[4:-1:2] = map(tables.node_tail.__getitem__, micro)
    parts[-2] = tables.text[micro[-1]]  # the last node ends in "}]}", not "},"
    return "".join(parts)


@functools.cache
def _unpack_h(n: int) -> struct.Struct:
    return struct.Struct(f"<{n}H")


@functools.cache
def _parts(n: int) -> list[str]:
    """['{"timeStamp":', ts, ',"numOfDeformedNodes":n,"arrayOfDeformedNodes":[', head, tail, ...]."""
    middle = f',"numOfDeformedNodes":{n},"arrayOfDeformedNodes":['
    return ['{"timeStamp":', "", middle, *[""] * (2 * n), "}]}"]
