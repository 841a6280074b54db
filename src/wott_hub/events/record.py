"""One entry of the event plane: an event or a property change of one Thing.

The payload is JSON-encoded once, when the record is made; history stores that
text, SSE and WebSocket subscribers send it as is. Each SSE frame is built the
first time an SSE subscriber needs it and then shared by all of them.

SSE framing: a stream of one affordance (one event, one observed property)
carries unnamed messages (``id:`` + ``data:``), because the WoT clients users
have (node-wot, any page using ``EventSource.onmessage``) only see those; a
stream multiplexing several affordances (``subscribeallevents``) names each
message with ``event: <affordance>`` so that its reader can tell them apart.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any, NamedTuple

if TYPE_CHECKING:
    import numpy as np

__all__ = ["KIND_EVENT", "KIND_NAMES", "KIND_PROPERTY", "OBJECT_BYTES", "Record", "SkinArrays", "encode",
           "record_bytes"]

KIND_EVENT = 0
KIND_PROPERTY = 1
KIND_NAMES = {KIND_EVENT: "event", KIND_PROPERTY: "property"}
"""A kind's name in the export/JSON Lines form of a record."""

_encoder = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False, check_circular=False,
                            allow_nan=False)
encode = _encoder.encode
"""Compact JSON text of a payload (the one encoding every consumer shares). NaN and infinities
raise ValueError: JSON has no such numbers, and a record carrying them would be invalid JSON in
SSE, WebSocket and history alike (the frame pump counts it as a frame error)."""


class SkinArrays(NamedTuple):
    """A skin packet as the pipeline computed it, riding along its JSON text: history packs
    these arrays instead of parsing the text back (``history.codec``). ``intensity`` holds the
    values the text shows (mm, rounded); ``ids`` the node ids, ascending."""

    ids: np.ndarray
    intensity: np.ndarray

    def to_wire(self) -> tuple[bytes, bytes]:
        """The arrays as raw bytes, to cross a pipe (pickling two ndarrays costs ~4x more on each side)."""
        import numpy as np

        return (self.ids.astype(np.int64, copy=False).tobytes(),
                self.intensity.astype(np.float64, copy=False).tobytes())

    @classmethod
    def from_wire(cls, wire: tuple[bytes, bytes]) -> SkinArrays:
        import numpy as np

        return cls(np.frombuffer(wire[0], np.int64), np.frombuffer(wire[1], np.float64))


class Record:
    """``seq`` is per Thing, strictly increasing, never reused (see EventPlane).

    ``trace`` is None unless latency tracing is on (benchmarks): then it holds
    perf_counter_ns stamps of the pipeline stages. ``skin``: see ``SkinArrays`` (None: the
    text is all there is).
    """

    __slots__ = ("_sse", "_sse_named", "data", "kind", "name", "seq", "skin", "t_ns", "thing", "trace")

    def __init__(self, thing: str, seq: int, kind: int, name: str, t_ns: int, data: str,
                 trace: dict[str, int] | None = None, skin: SkinArrays | None = None) -> None:
        self.thing = thing
        self.seq = seq
        self.kind = kind
        self.name = name
        self.t_ns = t_ns
        self.data = data
        self.trace = trace
        self.skin = skin
        self._sse: bytes | None = None
        self._sse_named: bytes | None = None

    def sse(self, named: bool = False) -> bytes:
        """The Server-Sent Events frame: ``id`` is the sequence number (resume key); ``named``
        adds ``event: <name>``, for streams that carry several affordances."""
        # JSON text has no raw newlines (json escapes them), so one data line is enough
        if named:
            frame = self._sse_named
            if frame is None:
                frame = f"id: {self.seq}\nevent: {self.name}\ndata: {self.data}\n\n".encode()
                self._sse_named = frame
            return frame
        frame = self._sse
        if frame is None:
            frame = self._sse = f"id: {self.seq}\ndata: {self.data}\n\n".encode()
        return frame

    def __reduce__(self) -> tuple[Any, ...]:
        """Across a pipe (a worker's records, a batch for the history process): the fields only,
        the skin arrays as raw bytes (``SkinArrays.to_wire``), never the SSE frames cached here.
        A record not yet numbered by the plane carries ``seq`` 0."""
        skin = None if self.skin is None else self.skin.to_wire()
        return (_revive, (self.thing, self.seq, self.kind, self.name, self.t_ns, self.data, self.trace, skin))

    def to_dict(self) -> dict[str, Any]:
        """The export/JSON Lines form of the record."""
        return {"thing": self.thing, "seq": self.seq, "t_ns": self.t_ns,
                "kind": KIND_NAMES.get(self.kind, "event"),
                "name": self.name, "data": json.loads(self.data)}

    def __repr__(self) -> str:
        return f"Record({self.thing!r}, seq={self.seq}, {self.name!r}, t_ns={self.t_ns})"


def _revive(thing: str, seq: int, kind: int, name: str, t_ns: int, data: str,
            trace: dict[str, int] | None, skin: tuple[bytes, bytes] | None) -> Record:
    arrays = None if skin is None else SkinArrays.from_wire(skin)
    return Record(thing, seq, kind, name, t_ns, data, trace, arrays)


OBJECT_BYTES = 200
"""What a record held in a queue costs beyond its payload: the Record and its text objects, the slot."""


def record_bytes(rec: Record) -> int:
    """The memory a queued record holds, estimated (the same every time it is asked): its text, a skin
    packet's arrays, ``OBJECT_BYTES``. What the writer's queue and the plane's held queue count."""
    n = len(rec.data) + OBJECT_BYTES
    skin = rec.skin
    if skin is not None:
        n += skin.ids.nbytes + skin.intensity.nbytes
    return n
