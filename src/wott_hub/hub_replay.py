"""The hub Thing's ``replay`` and ``stopReplay`` actions: replay history from any WoT client.

``wott-hub replay`` runs a replay in a process of its own; these actions start
and stop one inside the running hub, so a browser (the web twin) or any WoT
client can replay a device's recorded range with one POST declared in the hub
Thing's TD, and watch it as the replay Thing ``replay-<device>`` like a live
device. Only one replay per device: starting another replaces it.

The ``replay`` output carries ``after``, the replay Thing's sequence number
before its first record: subscribing with ``Last-Event-ID: <after>`` gets the
replay from its very first record, however late the subscription comes (within
the Thing's in-memory ring).
"""

from __future__ import annotations

import asyncio
import contextlib
import copy
import json
import math
from typing import TYPE_CHECKING, Any

import tornado.web

from wott_hub.drivers.base import DriverError
from wott_hub.history.times import parse_time
from wott_hub.servient import HUB_THING_ID
from wott_hub.servient.http import _Base

if TYPE_CHECKING:
    from wott_hub.hub import Hub

__all__ = ["ACTIONS", "install", "start_replay", "stop_replay"]

_TIME_TEXT = ("ISO 8601 (local unless it has an offset or Z), relative to now ('-30s', '-10m'), 'now', "
              "or a number: seconds since the epoch, nanoseconds when larger than 1e14.")
_TIME = {"oneOf": [{"type": "string"}, {"type": "number"}]}

ACTIONS: dict[str, dict[str, Any]] = {
    "replay": {
        "title": "replay",
        "description": "Re-emit a recorded device's range as live events of the Thing replay-<device> "
                       "(replaces a replay of that device already running).",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {
            "type": "object",
            "properties": {
                "device": {"type": "string", "description": "Recorded device id."},
                "from": {**_TIME, "description": "Start of the range (default: the first record). "
                                                 + _TIME_TEXT},
                "to": {**_TIME, "description": "End of the range (default: the last record). " + _TIME_TEXT},
                "speed": {"type": "number", "minimum": 0, "default": 1.0,
                          "description": "Time scale: 2 plays twice as fast; 0 as fast as possible."},
                "loop": {"type": "boolean", "default": False, "description": "Start again after the end."},
            },
            "required": ["device"],
        },
        "output": {
            "type": "object",
            "properties": {
                "thing": {"type": "string", "description": "Id of the replay Thing."},
                "td": {"type": "string", "format": "uri", "description": "URL of its TD."},
                "after": {"type": "integer",
                          "description": "Last-Event-ID that resumes from the replay's first record."},
                "from": {"type": "integer", "description": "Start, ns since the epoch (absent: first)."},
                "to": {"type": "integer", "description": "End, ns since the epoch (absent: last)."},
                "speed": {"type": "number"},
                "loop": {"type": "boolean"},
            },
        },
    },
    "stopReplay": {
        "title": "stopReplay",
        "description": "Stop a replay and stop serving its replay Thing.",
        "safe": False,
        "idempotent": True,
        "synchronous": True,
        "input": {
            "type": "object",
            "properties": {
                "thing": {"type": "string", "description": "Replay Thing id (replay-<device>)."},
                "device": {"type": "string", "description": "Or the recorded device id."},
            },
        },
        "output": {
            "type": "object",
            "properties": {"stopped": {"type": "boolean"}, "emitted": {"type": "integer"}},
        },
    },
}


def install(hub: Hub, td: dict[str, Any]) -> None:
    """Declare the actions in the hub Thing's TD (before it is served) and mount their handlers."""
    base = hub.server.layout.thing_url(HUB_THING_ID)
    actions = td.setdefault("actions", {})
    for name, affordance in ACTIONS.items():
        aff = copy.deepcopy(affordance)
        aff["forms"] = [{"href": f"{base}/actions/{name}", "op": ["invokeaction"], "htv:methodName": "POST",
                         "contentType": "application/json"}]
        actions[name] = aff
    prefix = f"/wot/{HUB_THING_ID}/actions"
    hub.server.add_handlers([
        (rf"{prefix}/replay", _ReplayHandler, {"hub": hub}),
        (rf"{prefix}/stopReplay", _StopReplayHandler, {"hub": hub}),
    ])


def _time(value: Any, field: str) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, str | int | float):
        raise ValueError(f"'{field}' must be a string or a number, got {value!r}")
    if isinstance(value, int | float):
        if not math.isfinite(value):
            raise ValueError(f"'{field}' must be finite")
        return int(value) if value > 1e14 else int(value * 1e9)
    return parse_time(value)


async def start_replay(hub: Hub, device: str, *, t_from: Any = None, t_to: Any = None, speed: Any = 1.0,
                       loop: Any = False) -> dict[str, Any]:
    """Start (or restart) the replay of ``device``; ValueError for bad input, DriverError for no history."""
    if not isinstance(device, str) or not device:
        raise ValueError("'device' (a recorded device id) is required")
    number = isinstance(speed, int | float) and not isinstance(speed, bool)
    if not (number and math.isfinite(speed) and speed >= 0):
        raise ValueError(f"'speed' must be a number >= 0, got {speed!r}")
    if not isinstance(loop, bool):
        raise ValueError(f"'loop' must be true or false, got {loop!r}")
    lo, hi = _time(t_from, "from"), _time(t_to, "to")
    if lo is not None and hi is not None and lo > hi:
        raise ValueError("'from' is after 'to'")
    tid = f"replay-{device}"
    await stop_replay(hub, tid)
    rt = await hub.add_replay(device, t_from_ns=lo, t_to_ns=hi, speed=float(speed), loop=loop, thing_id=tid)
    after = hub.plane.stream(tid).seq
    hub.start_replay(rt)
    out = {"thing": tid, "td": hub.td_url(tid), "after": after, "speed": float(speed), "loop": loop}
    out.update({k: v for k, v in (("from", lo), ("to", hi)) if v is not None})
    return out


async def stop_replay(hub: Hub, thing_id: str) -> dict[str, Any]:
    """Stop the replay Thing ``thing_id`` and stop serving it; a no-op if there is none."""
    rt = hub.replays.pop(thing_id, None)
    if rt is None:
        return {"stopped": False, "emitted": 0}
    if rt.task is not None:
        rt.task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await rt.task
    hub._unserve(thing_id)
    return {"stopped": True, "emitted": rt.replayer.emitted}


class _ActionHandler(_Base):
    """The hub's CORS headers and problem+json errors, for POSTs to the hub Thing's actions."""

    def initialize(self, hub: Hub) -> None:  # type: ignore[override]
        self.hub = hub

    def options(self, *_args) -> None:
        self.set_header("Access-Control-Allow-Methods", "POST, OPTIONS")
        self.set_header("Access-Control-Allow-Headers", "Content-Type, Accept")
        self.set_status(204)

    def input(self) -> dict[str, Any]:
        body = self.request.body or b"{}"
        try:
            value = json.loads(body)
        except ValueError as e:
            raise tornado.web.HTTPError(400, reason=f"the body is not JSON: {e}") from None
        if not isinstance(value, dict):
            raise tornado.web.HTTPError(400, reason="the input must be a JSON object")
        return value

    def reply(self, value: dict[str, Any]) -> None:
        self.write_json_text(json.dumps(value))


class _ReplayHandler(_ActionHandler):
    async def post(self) -> None:
        x = self.input()
        try:
            out = await start_replay(self.hub, x.get("device"), t_from=x.get("from"), t_to=x.get("to"),
                                     speed=x.get("speed", 1.0), loop=x.get("loop", False))
        except ValueError as e:
            raise tornado.web.HTTPError(400, reason=str(e)) from None
        except DriverError as e:  # no history, or nothing recorded for that device
            raise tornado.web.HTTPError(404, reason=str(e)) from None
        self.reply(out)


class _StopReplayHandler(_ActionHandler):
    async def post(self) -> None:
        x = self.input()
        thing, device = x.get("thing"), x.get("device")
        if not isinstance(thing, str) or not thing:
            if not isinstance(device, str) or not device:
                raise tornado.web.HTTPError(400, reason="give 'thing' (replay Thing id) or 'device'")
            thing = f"replay-{device}"
        self.reply(await stop_replay(self.hub, thing))
