"""``skinDisplacement`` packets as NumPy arrays: the binary form decoded without JSON, the JSON too.

The binary form (``application/vnd.wott.skin-displacement``, docs/tactile-td.md of wott-hub)
is little-endian: magic ``b"WTD1"``, uint32 n, uint64 seq, int64 timeStamp (ns), n uint32
node ids, n x 3 float32 (mm). A packet says its own length, so a stream is packets back to
back; ``PacketParser`` cuts whatever chunks a socket hands it and views each packet's arrays
in place (``np.frombuffer``: no copy, no Python per node).
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ._frames import ProtocolError

__all__ = ["CONTENT_TYPE", "Displacement", "PacketParser", "displacement_of_json", "displacement_of_text"]

CONTENT_TYPE = "application/vnd.wott.skin-displacement"
MAGIC = b"WTD1"
_HEADER = struct.Struct("<4sIQq")


@dataclass(frozen=True, slots=True)
class Displacement:
    """One ``skinDisplacement`` packet: the displaced nodes' vectors in the device's frame.

    ``ids`` (n,) are node ids as the TD's ``skinNodes`` names them, ``vectors`` (n, 3) float32 mm
    (x, y, z); a release packet lists the previously displaced nodes with zero vectors. Nodes
    absent from a packet are at rest. ``dense(mesh)`` gives the whole field."""

    thing: str
    event_id: str | None  # its seq (SSE id), the resume key
    timestamp_ns: int
    ids: npt.NDArray[np.uint32] = field(repr=False)
    vectors: npt.NDArray[np.float32] = field(repr=False)

    def norms(self) -> npt.NDArray[np.float32]:
        """Each node's displacement norm (the packet's ``skinDeformedDetection`` intensity, to 1 µm)."""
        out: npt.NDArray[np.float32] = np.sqrt(np.einsum("ij,ij->i", self.vectors, self.vectors))
        return out

    def dense(self, n_nodes: int, rows: npt.NDArray[np.intp] | None = None) -> npt.NDArray[np.float32]:
        """The (n_nodes, 3) field, zero where the packet is silent. ``rows``: each id's row in the mesh
        (``Mesh.rows_of``), when node ids are not simply rows."""
        out = np.zeros((n_nodes, 3), np.float32)
        out[self.ids if rows is None else rows] = self.vectors
        return out


class PacketParser:
    """Feed it the bytes of a binary stream as they arrive; it returns the complete packets."""

    __slots__ = ("_buf", "thing")

    def __init__(self, thing: str = "") -> None:
        self.thing = thing
        self._buf = b""

    def feed(self, chunk: bytes) -> list[Displacement]:
        buf = self._buf + chunk if self._buf else chunk
        out: list[Displacement] = []
        at, size = 0, len(buf)
        unpack, header = _HEADER.unpack_from, _HEADER.size
        thing = self.thing
        while size - at >= header:
            magic, n, seq, ts = unpack(buf, at)
            if magic != MAGIC:
                raise ProtocolError(f"{thing}: not a skinDisplacement packet at byte {at} (magic {magic!r})")
            end = at + header + 16 * n
            if end > size:
                break
            ids = np.frombuffer(buf, "<u4", n, at + header)
            vectors = np.frombuffer(buf, "<f4", 3 * n, at + header + 4 * n).reshape(n, 3)
            out.append(Displacement(thing, str(seq), ts, ids, vectors))
            at = end
        self._buf = buf[at:] if at < size else b""
        return out


def displacement_of_json(thing: str, event_id: str | None, value: Any) -> Displacement:
    """A packet's JSON value (SSE, WebSocket, history) as the same arrays the binary form gives."""
    try:
        nodes = value["arrayOfDisplacedNodes"]
        ids = np.array([d["nodeID"] for d in nodes], np.uint32)
        vectors = np.array([[d["displacement"]["x"], d["displacement"]["y"], d["displacement"]["z"]]
                            for d in nodes], np.float32).reshape(-1, 3)
        return Displacement(thing, event_id, int(value["timeStamp"]), ids, vectors)
    except (KeyError, TypeError, ValueError) as e:
        raise ProtocolError(f"{thing}: skinDisplacement message {event_id}: {e!r}") from None


def displacement_of_text(thing: str, event_id: str | None, data: bytes | str) -> Displacement:
    try:
        value = json.loads(data)
    except ValueError as e:
        raise ProtocolError(f"{thing}: skinDisplacement message {event_id}: {e}") from None
    return displacement_of_json(thing, event_id, value)
