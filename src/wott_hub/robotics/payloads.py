"""The hub's JSON payloads read into arrays, once per record, for both encodings.

Shapes are the Tactile vocabulary's (td/vocabulary.py): a ``skinDeformedDetection`` packet
``{timeStamp (ns), numOfDeformedNodes, arrayOfDeformedNodes: [{deformedNodeID,
deformedNodeIntensity (mm)}]}`` and ``contactInformation`` ``{numOfContacts, contactLocations
[{x,y,z} mm], contactForces [{x,y,z} N]}``. A payload of another shape (a foreign driver's) is
``InvalidInput``: the caller keeps the record on its raw channel only.
"""

from __future__ import annotations

import json
from typing import Any, NamedTuple

import msgspec
import numpy as np

from wott_hub.errors import InvalidInput

__all__ = ["Contacts", "SkinPacket", "action_text", "contacts", "load_json", "skin_packet"]


class SkinPacket(NamedTuple):
    t_ns: int
    ids: np.ndarray  # int64 node ids
    intensity_mm: np.ndarray  # float64, one per id


class Contacts(NamedTuple):
    locations_mm: np.ndarray  # N x 3
    forces_n: np.ndarray  # N x 3


def load_json(text: str) -> Any:
    """A payload's value: msgspec's decoder (~4x faster than ``json``'s: exports read a million payloads
    an hour), ``json``'s for what strict JSON refuses and Python reads (``NaN``, ``Infinity``)."""
    try:
        return msgspec.json.decode(text)
    except msgspec.DecodeError:
        pass
    try:
        return json.loads(text)
    except ValueError as e:
        raise InvalidInput(f"not JSON: {e}") from None


_load = load_json


def skin_packet(text: str, t_ns: int) -> SkinPacket:
    """A skin packet's nodes; its ``timeStamp`` if it has one, else the record's time ``t_ns``."""
    d = _load(text)
    try:
        nodes = d["arrayOfDeformedNodes"]
        ids = np.fromiter((n["deformedNodeID"] for n in nodes), dtype=np.int64, count=len(nodes))
        inten = np.fromiter((n["deformedNodeIntensity"] for n in nodes), dtype=np.float64, count=len(nodes))
        stamp = int(d.get("timeStamp", t_ns))
    except (KeyError, TypeError, ValueError) as e:
        raise InvalidInput(f"not a skinDeformedDetection packet ({e!r})") from None
    return SkinPacket(stamp, ids, inten)


def _xyz(items: Any) -> np.ndarray:
    return np.array([(p["x"], p["y"], p["z"]) for p in items], dtype=np.float64).reshape(-1, 3)


def contacts(text: str) -> Contacts:
    d = _load(text)
    try:
        loc, force = _xyz(d["contactLocations"]), _xyz(d["contactForces"])
    except (KeyError, TypeError, ValueError) as e:
        raise InvalidInput(f"not a contactInformation value ({e!r})") from None
    if len(force) == 0:  # a device whose signal gives no force (docs/skins.md): arrows of length 0
        force = np.zeros_like(loc)
    if len(loc) != len(force):
        raise InvalidInput(f"contactInformation: {len(loc)} locations but {len(force)} forces")
    return Contacts(loc, force)


def action_text(name: str, text: str) -> str:
    """One line for a log panel: ``press`` for an ``actionDetection``; for ``actionDetails`` the
    action, its confidence and evidence; any other event's value as its JSON text."""
    d = _load(text)
    if isinstance(d, str):
        return d
    if name == "actionDetails" and isinstance(d, dict) and "action" in d:
        ev = d.get("evidence")
        ev = ev if isinstance(ev, dict) else {}
        parts = ", ".join(f"{k} {v}" for k, v in ev.items())
        return f"{d['action']} (confidence {d.get('confidence')}{'; ' + parts if parts else ''})"
    return text
