"""The hub Thing's history actions: what is recorded, a range of records, an MCAP export.

Declared in the hub Thing's TD as actions (POST with a JSON object, like ``replay``), so
any WoT client that reads the TD can ask for "barrel-1, 10:02-10:05" without the CLI or
the hub's machine. The choice of actions over properties with URI variables: the inputs
(a list of affordance names, a range, paging) are objects that URI variables flatten badly,
and the answers are streams (JSON Lines, MCAP), not a property value.

- ``historyDevices``: every recorded device with its record count and time range (JSON).
- ``historyRecords``: one device's records in [from, to], optionally only some affordances,
  at most ``limit`` (default 1000, up to 100000), after the seq ``after``: JSON Lines
  (``application/x-ndjson``), one ``{"thing","seq","t_ns","kind","name","data"}`` per line,
  ``data`` the payload as subscribers got it. A page shorter than ``limit`` is the last;
  else ask again with ``after`` = the last line's ``seq``.
- ``historyExport``: devices' records as an MCAP file (``application/x-mcap``,
  ``history/mcap.py``), the same as ``wott-hub history export --format mcap``.

Errors are problem+json with the offending field named: 400 for bad input (a JSON number
out of range included: ``from``/``to`` as ``replay.time_field`` checks them, ``sceneHz`` in
[0.01, 1000]), 404 for an unknown device or a hub without history (``errors.http_status``), 503
when ``exports.MAX_EXPORTS`` exports run already.

Reads run in threads of their own (``exports.py``): pages in a small pool, each export in a
thread of its own, streamed, cancelled when its client leaves or the hub stops; the event loop's
default executor (which devices use) is never theirs. ``historyExport`` needs the ``control``
scope, though it is ``safe``: it costs a thread and a core (``security.policy.CONTROL_ACTIONS``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import AsyncGenerator
from typing import TYPE_CHECKING, Any

from wott_hub.errors import InvalidInput, NotFound

from .actions import Stream
from .actions import install as install_actions
from .replay import TIME_TEXT, time_field

if TYPE_CHECKING:
    from typing import IO

    from wott_hub.history import HistoryReader
    from wott_hub.servient.server import HubServer

    from .exports import Export
    from .recording import HubHistory

__all__ = ["ACTIONS", "MAX_LIMIT", "MAX_SCENE_HZ", "MIN_SCENE_HZ", "install"]

MAX_LIMIT = 100_000
MIN_SCENE_HZ, MAX_SCENE_HZ = 0.01, 1000.0
JSONL = "application/x-ndjson"
MCAP = "application/x-mcap"

_TIME = {"type": "string"}
_NAMES = {"type": "array", "items": {"type": "string"},
          "description": "Only these affordances (event or property names); absent or empty: all."}
_RANGE = {
    "from": {**_TIME, "description": "Start of the range (default: the first record). " + TIME_TEXT},
    "to": {**_TIME, "description": "End of the range (default: the last record). " + TIME_TEXT},
    "names": _NAMES,
}

ACTIONS: dict[str, dict[str, Any]] = {
    "historyDevices": {
        "title": "historyDevices",
        "description": "Every recorded device: record count, first and last time and seq.",
        "safe": True, "idempotent": True, "synchronous": True,
        "input": {"type": "object", "properties": {}},
        "output": {"type": "array", "items": {"type": "object", "properties": {
            "id": {"type": "string"}, "title": {"type": "string"}, "family": {"type": "string"},
            "count": {"type": "integer"},
            "firstSeq": {"type": "integer"}, "lastSeq": {"type": "integer"},
            "from": {"type": "integer", "description": "First record, ns since the epoch."},
            "to": {"type": "integer", "description": "Last record, ns since the epoch."},
        }}},
    },
    "historyRecords": {
        "title": "historyRecords",
        "description": "One device's records in a range as JSON Lines ({thing, seq, t_ns, kind, name, data} "
                       "per line), at most 'limit'; a full page means more: ask again with 'after' = the "
                       "last seq.",
        "safe": True, "idempotent": True, "synchronous": True,
        "input": {
            "type": "object",
            "properties": {
                "device": {"type": "string", "description": "Recorded device id (see historyDevices)."},
                **_RANGE,
                "after": {"type": "integer", "minimum": 0, "default": 0,
                          "description": "Only records with a seq above this one (paging)."},
                "limit": {"type": "integer", "minimum": 1, "maximum": MAX_LIMIT, "default": 1000,
                          "description": "At most this many records."},
            },
            "required": ["device"],
        },
        "output": {"type": "string", "contentMediaType": JSONL, "description": "JSON Lines."},
        "response": JSONL,
    },
    "historyExport": {
        "title": "historyExport",
        "description": "Devices' records in a range as one MCAP file (one channel per Thing and "
                       "affordance, Foxglove scene channels for the skins; docs/history.md).",
        "safe": True, "idempotent": True, "synchronous": True,
        "input": {
            "type": "object",
            "properties": {
                "devices": {"type": "array", "items": {"type": "string"}, "minItems": 1,
                            "description": "Recorded device ids, replayed on one time base."},
                **_RANGE,
                "scene": {"type": "boolean", "default": True,
                          "description": "Foxglove scene channels (mesh and deformation)."},
                "sceneHz": {"type": "number", "minimum": MIN_SCENE_HZ, "maximum": MAX_SCENE_HZ, "default": 30,
                            "description": "Deformation scenes per second at most."},
            },
            "required": ["devices"],
        },
        "output": {"type": "string", "contentMediaType": MCAP, "description": "The MCAP file."},
        "response": MCAP,
    },
}


def _names(value: Any) -> list[str] | None:
    if value is None:
        return None
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise InvalidInput(f"'names' must be a list of affordance names, got {value!r}")
    return value or None


def _int(value: Any, field: str, default: int, lo: int, hi: int) -> int:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise InvalidInput(f"'{field}' must be an integer in [{lo}, {hi}], got {value!r}")
    return value


def _range(x: dict[str, Any]) -> tuple[int | None, int | None]:
    lo, hi = time_field(x.get("from"), "from"), time_field(x.get("to"), "to")
    if lo is not None and hi is not None and lo > hi:
        raise InvalidInput("'from' is after 'to'")
    return lo, hi


def _reader(history: HubHistory) -> HistoryReader:
    reader = history.reader
    if reader is None:
        raise NotFound("this hub records no history (history = false)")
    return reader


async def _devices(history: HubHistory, x: dict[str, Any]) -> list[dict[str, Any]]:
    things = await history.exports.read(_reader(history).things)
    out = []
    for t in things:
        d: dict[str, Any] = {"id": t.id, "title": t.title, "family": t.family, "count": t.count}
        for k, v in (("firstSeq", t.first_seq), ("lastSeq", t.last_seq), ("from", t.first_t_ns),
                     ("to", t.last_t_ns)):
            if v is not None:
                d[k] = v
        out.append(d)
    return out


async def _records(history: HubHistory, x: dict[str, Any]) -> Stream:
    from wott_hub.history.export import jsonl

    device = x.get("device")
    if not isinstance(device, str) or not device:
        raise InvalidInput("'device' (a recorded device id) is required")
    lo, hi = _range(x)
    names = _names(x.get("names"))
    after = _int(x.get("after"), "after", 0, 0, (1 << 63) - 1)
    limit = _int(x.get("limit"), "limit", 1000, 1, MAX_LIMIT)
    reader = _reader(history)

    async def pages(after: int) -> AsyncGenerator[str, None]:
        left = limit
        while left > 0:
            records = await history.exports.read(reader.record_page, device, t_from_ns=lo, t_to_ns=hi,
                                                 names=names, after=after, limit=min(left, 5000))
            if not records:
                break
            yield jsonl(records)
            left -= len(records)
            after = records[-1].seq
            if len(records) < 5000:
                break

    return Stream(JSONL, pages(after))


async def _export(history: HubHistory, x: dict[str, Any]) -> Stream:
    from wott_hub.history.mcap import export_mcap

    devices = x.get("devices")
    if not isinstance(devices, list) or not devices or not all(isinstance(d, str) and d for d in devices):
        raise InvalidInput(f"'devices' must be a non-empty list of recorded device ids, got {devices!r}")
    lo, hi = _range(x)
    names = _names(x.get("names"))
    scene = x.get("scene", True)
    if not isinstance(scene, bool):
        raise InvalidInput(f"'scene' must be true or false, got {scene!r}")
    hz = x.get("sceneHz", 30)
    number = isinstance(hz, int | float) and not isinstance(hz, bool)
    if not (number and math.isfinite(hz) and MIN_SCENE_HZ <= hz <= MAX_SCENE_HZ):
        raise InvalidInput(f"'sceneHz' must be a number in [{MIN_SCENE_HZ:g}, {MAX_SCENE_HZ:g}], got {hz!r}")
    reader = _reader(history)

    def write(out: IO[bytes], job: Export) -> None:
        export_mcap(reader, out, devices, t_from_ns=lo, t_to_ns=hi, names=names, scene=scene,
                    scene_hz=float(hz), check=job.check)

    return Stream(MCAP, history.exports.stream(write))  # Busy (503) when as many run as allowed


_INVOKES = {"historyDevices": _devices, "historyRecords": _records, "historyExport": _export}


def install(td: dict[str, Any], server: HubServer, history: HubHistory) -> None:
    """Declare the actions in the hub Thing's TD (before it is served) and mount their handlers."""
    install_actions(td, server, {name: (aff, functools.partial(_INVOKES[name], history))
                                 for name, aff in ACTIONS.items()})
