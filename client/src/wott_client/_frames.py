"""What a stream yields, and how a message becomes one.

A ``skinDeformedDetection`` packet lists only the nodes above the device's ε,
so the dense field is zero everywhere else, and a release packet (intensities 0)
brings the listed nodes back to zero: each ``Frame`` is the whole field at that
instant, not a delta. The decoder does the least Python work it can: one
``json.loads``, two list comprehensions over the packet, one fancy assignment.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._errors import ClientError
from ._td import Mesh, _NodeIndex

__all__ = ["Action", "ActionDetails", "Contacts", "Decoder", "Frame", "Item", "ProtocolError"]


class ProtocolError(ClientError):
    """A message that does not match its TD (not JSON, a node the mesh lacks)."""


@dataclass(frozen=True, slots=True)
class Frame:
    """One ``skinDeformedDetection`` packet as the displacement-intensity field over the mesh."""

    thing: str  # the Thing's id
    event_id: str | None
    timestamp_ns: int  # the packet's timeStamp (the server's clock)
    intensity: np.ndarray = field(repr=False)  # (N,) float64 mm by rows of Mesh.nodes; 0: not in the packet
    indices: np.ndarray = field(repr=False)  # (n,) rows the packet listed (a release lists its nodes with 0)


@dataclass(frozen=True, slots=True)
class Contacts:
    """A ``contactInformation`` change."""

    thing: str
    event_id: str | None
    locations: np.ndarray  # (k, 3) float64, mm
    forces: np.ndarray  # (k, 3) float64, N


@dataclass(frozen=True, slots=True)
class Action:
    """An ``actionDetection`` event: touch, release, press, slip, pat, pinch or collision."""

    thing: str
    event_id: str | None
    action: str


@dataclass(frozen=True, slots=True)
class ActionDetails:
    """An ``actionDetails`` event (newer TDs): the evidence behind the ``Action`` of the same order."""

    thing: str
    event_id: str | None
    action: str
    confidence: float  # in [0.5, 1]
    evidence: dict[str, Any]  # contacts, durationS, speedMmPerS, moveMm, approachMm


Item = Frame | Contacts | Action | ActionDetails

_XYZ = ("x", "y", "z")


def _points(items: Any) -> np.ndarray:
    return np.array([[p[a] for a in _XYZ] for p in items or ()], dtype=np.float64).reshape(-1, 3)


class Decoder:
    """Messages of one Thing -> items; ``decode`` returns None for affordances the client does not map."""

    __slots__ = ("_index", "n", "thing")

    def __init__(self, thing: str, mesh: Mesh) -> None:
        self.thing = thing
        self.n = len(mesh)
        self._index = _NodeIndex(mesh.node_ids)

    def decode(self, name: str, event_id: str | None, data: bytes) -> Item | None:
        try:
            value = json.loads(data)
            if name == "skinDeformedDetection":
                return self.frame(event_id, value)
            if name == "contactInformation":
                return Contacts(self.thing, event_id, _points(value.get("contactLocations")),
                                _points(value.get("contactForces")))
            if name == "actionDetection":
                return Action(self.thing, event_id, str(value))
            if name == "actionDetails":
                return ActionDetails(self.thing, event_id, str(value["action"]), float(value["confidence"]),
                                     dict(value.get("evidence") or {}))
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            raise ProtocolError(f"{self.thing}: {name} message {event_id}: {e}") from None
        return None

    def frame(self, event_id: str | None, packet: dict[str, Any]) -> Frame:
        nodes = packet["arrayOfDeformedNodes"]
        dense = np.zeros(self.n)
        ids = [d["deformedNodeID"] for d in nodes]
        index = self._index
        if index.identity and (not ids or min(ids) >= 0):  # ids are rows: numpy checks the upper bound
            rows = np.array(ids, dtype=np.intp)
        else:
            rows = index.rows(ids)
        try:
            dense[rows] = [d["deformedNodeIntensity"] for d in nodes]
        except IndexError:
            raise ValueError(f"a node id above {self.n - 1} is not in the mesh") from None
        return Frame(self.thing, event_id, int(packet.get("timeStamp", 0)), dense, rows)
