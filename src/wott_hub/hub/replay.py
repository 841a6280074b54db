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

``Replays`` keeps the replays a hub runs (started by these actions or by
``wott-hub replay`` through ``Hub.add_replay``/``Hub.start_replay``).
"""
from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from wott_hub.errors import Conflict, InvalidInput, NotFound, WottHubError
from wott_hub.events.record import KIND_PROPERTY, Record
from wott_hub.history.times import MAX_NS, parse_time
from wott_hub.runtime.pipeline import CONTACTS, NO_CONTACTS, NO_UNAVAILABLE, UNAVAILABLE
from wott_hub.servient import ServedThing, with_forms

from .actions import install as install_actions

if TYPE_CHECKING:
    from wott_hub.config import HubConfig
    from wott_hub.events.plane import EventPlane
    from wott_hub.history.replay import Replayer

    from .recording import HubHistory
    from .things import Things

__all__ = ["ACTIONS", "MAX_OFFSET_S", "MAX_SPEED", "MIN_SPEED", "TIME_TEXT", "ReplayRuntime", "Replays",
           "time_field"]

MAX_OFFSET_S = MAX_NS / 1e9
"""An offset past this many seconds is past anything history can hold (2262)."""
MIN_SPEED, MAX_SPEED = 1e-6, 1e6
"""A speed other than 0 (as fast as possible) lies in [MIN_SPEED, MAX_SPEED]: below, a record would be
due after the year 2262 (an infinite wait); above, it is as fast as possible anyway."""

TIME_TEXT = ("ISO 8601 (local unless it has an offset or Z), relative to now ('-30s', '-10m'), 'now', "
              "or a number as text: seconds since the epoch, nanoseconds when larger than 1e14 "
              "(a JSON number is accepted too).")
# one declared type: wotpy cannot consume a schema without one (docs/interop.md); numbers still parse
_TIME = {"type": "string"}

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
                                                 + TIME_TEXT},
                "to": {**_TIME, "description": "End of the range (default: the last record). " + TIME_TEXT},
                "speed": {"type": "number", "minimum": 0, "maximum": MAX_SPEED, "default": 1.0,
                          "description": "Time scale: 2 plays twice as fast; 0 as fast as possible; else "
                                         f"at least {MIN_SPEED:g}."},
                "loop": {"type": "boolean", "default": False, "description": "Start again after the end."},
                "withDevices": {"type": "array", "items": {"type": "string"},
                                "description": "More recorded device ids replayed together with 'device' on "
                                               "one time base, each as its own replay-<device> Thing."},
                "names": {"type": "array", "items": {"type": "string"},
                          "description": "Only these affordances (event or property names), like a topic "
                                         "filter; absent or empty: all."},
                "offset": {"type": "number", "minimum": 0, "maximum": MAX_OFFSET_S, "default": 0,
                           "description": "Start this many seconds into the range (each loop starts there)."},
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
                "things": {"type": "array", "items": {"type": "string"},
                           "description": "Every replay Thing of this replay (several with 'withDevices')."},
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



@dataclass(eq=False)
class ReplayRuntime:
    """One replay Thing: what it replays, the replayer that plays it, the last contacts it emitted."""

    id: str
    source: str
    thing: ServedThing
    replayer: Replayer
    contacts_json: str = NO_CONTACTS
    unavailable_json: str = NO_UNAVAILABLE  # the recorded device's unavailableNodes, as replayed
    group: list[ReplayRuntime] = field(default_factory=list, repr=False)
    """Every replay Thing one replayer drives (itself first); stopping one stops them all."""

    @property
    def task(self) -> asyncio.Task[None] | None:
        return self.replayer.task

    @property
    def state(self) -> str:
        return self.replayer.state


class Replays:
    def __init__(self, config: HubConfig, plane: EventPlane, things: Things, history: HubHistory) -> None:
        self.config = config
        self.plane = plane
        self.things = things
        self.history = history
        self.running: dict[str, ReplayRuntime] = {}

    async def add(self, device_id: str, *, t_from_ns: int | None = None, t_to_ns: int | None = None,
                  speed: float = 1.0, loop: bool = False, thing_id: str | None = None,
                  names: list[str] | None = None, offset_s: float = 0.0,
                  with_devices: list[str] | None = None) -> ReplayRuntime:
        """Expose a replay Thing re-emitting ``device_id``'s recorded range as live records.

        The replay Thing has the recorded device's TD (title "... (replay)", id
        ``replay-<device>``) and static values; its records get their own
        sequence and are not recorded again. ``NotFound`` without history or without
        that recorded device; ``InvalidInput`` when the replay Thing's id is taken.
        ``with_devices`` are replayed together with it on one time base (``Replayer``), each
        as its own ``replay-<device>`` Thing; ``names`` and ``offset_s`` as ``Replayer``'s.
        """
        from wott_hub.history import Replayer

        reader = self.history.reader
        if reader is None:
            raise NotFound("replay needs the history database (history = true)")
        devices = [device_id, *[d for d in with_devices or [] if d != device_id]]
        replayer = Replayer(reader, devices, t_from_ns=t_from_ns, t_to_ns=t_to_ns, speed=speed,
                            loop=loop, names=names, offset_s=offset_s)
        group: list[ReplayRuntime] = []
        try:
            for i, device in enumerate(devices):
                rt = await self._add_one(device, thing_id if i == 0 else None, speed, replayer)
                group.append(rt)
                rt.group = group
        except BaseException:
            for rt in group:
                self.running.pop(rt.id, None)
                self.things.unserve(rt.id)
            raise
        return group[0]

    async def _add_one(self, device_id: str, thing_id: str | None, speed: float,
                       replayer: Replayer) -> ReplayRuntime:
        reader = replayer.reader
        info = await asyncio.to_thread(reader.thing_info, device_id)
        if info is None or info["td"] is None:
            raise NotFound(f"no recorded device {device_id!r} in {self.config.database}")
        tid = thing_id or f"replay-{device_id}"
        td = with_forms(info["td"], tid, self.things.server.layout)
        td.pop("actions", None)  # a replay cannot tare or restart the recorded device (device_actions.py)
        td["id"] = self.things.identity.replay_id(device_id)
        td["title"] = f"{info['title']} (replay)"
        td["description"] = f"Replay of the recorded device {device_id!r} at {speed:g}x."
        static = {k: v for k, v in info["static_values"].items() if k not in (CONTACTS, UNAVAILABLE)}
        served = ServedThing.create(tid, td, static, record=False)
        rt = ReplayRuntime(tid, device_id, served, replayer)
        served.dynamic[CONTACTS] = lambda: rt.contacts_json
        served.dynamic[UNAVAILABLE] = lambda: rt.unavailable_json
        try:
            self.things.serve(served)
        except Conflict as e:  # the replay Thing id given is taken: bad input (400 from the action)
            raise InvalidInput(str(e)) from None
        self.running[tid] = rt
        return rt

    def start(self, rt: ReplayRuntime) -> asyncio.Task[None]:
        """Start the replayer of ``rt`` (and of every replay Thing of its group): each record goes to
        the replay Thing of the device it was recorded for."""
        plane = self.plane
        by_source = {g.source: g for g in rt.group or [rt]}

        def emit(rec: Record) -> None:
            target = by_source[rec.thing]
            if rec.kind == KIND_PROPERTY:
                if rec.name == CONTACTS:
                    target.contacts_json = rec.data
                elif rec.name == UNAVAILABLE:
                    target.unavailable_json = rec.data
            plane.publish(target.id, rec.kind, rec.name, rec.t_ns, rec.data)

        return rt.replayer.start(emit, name=f"replay:{rt.id}")

    async def replay(self, device: Any, *, t_from: Any = None, t_to: Any = None, speed: Any = 1.0,
                     loop: Any = False, with_devices: Any = None, names: Any = None,
                     offset: Any = 0) -> dict[str, Any]:
        """The ``replay`` action: start (or restart) the replay of ``device``; ``InvalidInput`` for bad
        input, ``NotFound`` for no history."""
        if not isinstance(device, str) or not device:
            raise InvalidInput("'device' (a recorded device id) is required")
        number = isinstance(speed, int | float) and not isinstance(speed, bool)
        if not (number and math.isfinite(speed) and (speed == 0 or MIN_SPEED <= speed <= MAX_SPEED)):
            raise InvalidInput(f"'speed' must be 0 (as fast as possible) or a number in [{MIN_SPEED:g}, "
                               f"{MAX_SPEED:g}], got {speed!r}")
        if not isinstance(loop, bool):
            raise InvalidInput(f"'loop' must be true or false, got {loop!r}")
        lo, hi = time_field(t_from, "from"), time_field(t_to, "to")
        if lo is not None and hi is not None and lo > hi:
            raise InvalidInput("'from' is after 'to'")
        more = _strings(with_devices, "withDevices")
        only = _strings(names, "names")
        number = isinstance(offset, int | float) and not isinstance(offset, bool)
        if not (number and math.isfinite(offset) and 0 <= offset <= MAX_OFFSET_S):
            raise InvalidInput(f"'offset' must be a number of seconds in [0, {MAX_OFFSET_S:.4g}], "
                               f"got {offset!r}")
        tid = f"replay-{device}"
        for d in (device, *more):
            await self.stop(f"replay-{d}")
        rt = await self.add(device, t_from_ns=lo, t_to_ns=hi, speed=float(speed), loop=loop, thing_id=tid,
                            names=only or None, offset_s=float(offset), with_devices=more)
        after = self.plane.stream(tid).seq
        self.start(rt)
        out = {"thing": tid, "td": self.things.server.td_url(tid), "after": after, "speed": float(speed),
               "loop": loop, "things": [g.id for g in rt.group]}
        out.update({k: v for k, v in (("from", lo), ("to", hi)) if v is not None})
        return out

    async def stop(self, thing_id: str) -> dict[str, Any]:
        """The ``stopReplay`` action: stop the replay Thing ``thing_id`` and stop serving it; a no-op
        if there is none."""
        rt = self.running.get(thing_id)
        if rt is None:
            return {"stopped": False, "emitted": 0}
        await rt.replayer.stop()
        for g in rt.group or [rt]:  # one replayer drives the group: it stops as a whole
            if self.running.pop(g.id, None) is not None:
                self.things.unserve(g.id)
        return {"stopped": True, "emitted": rt.replayer.emitted}

    def cancel_all(self) -> None:
        for rt in self.running.values():
            if rt.task is not None:
                rt.task.cancel()

    def install(self, td: dict[str, Any]) -> None:
        """Declare the actions in the hub Thing's TD (before it is served) and mount their handlers."""
        invokes = {"replay": self._replay_action, "stopReplay": self._stop_action}
        install_actions(td, self.things.server, {name: (aff, invokes[name]) for name, aff in ACTIONS.items()})

    async def _replay_action(self, x: dict[str, Any]) -> dict[str, Any]:
        try:
            return await self.replay(x.get("device"), t_from=x.get("from"), t_to=x.get("to"),
                                     speed=x.get("speed", 1.0), loop=x.get("loop", False),
                                     with_devices=x.get("withDevices"), names=x.get("names"),
                                     offset=x.get("offset", 0))
        except WottHubError:  # bad input (the id taken too) 400, no history 404
            raise
        except ValueError as e:  # a time parse_time refuses
            raise InvalidInput(str(e)) from None

    async def _stop_action(self, x: dict[str, Any]) -> dict[str, Any]:
        thing, device = x.get("thing"), x.get("device")
        if not isinstance(thing, str) or not thing:
            if not isinstance(device, str) or not device:
                raise InvalidInput("give 'thing' (replay Thing id) or 'device'")
            thing = f"replay-{device}"
        return await self.stop(thing)


def _strings(value: Any, name: str) -> list[str]:
    if value is None:
        return []
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise InvalidInput(f"'{name}' must be a list of non-empty strings, got {value!r}")
    return value


def time_field(value: Any, field: str) -> int | None:
    """A time input field in ns (None: absent); ``InvalidInput`` naming ``field``. A JSON number is
    checked as its text would be (``parse_time``): seconds, or ns above 1e14, within 1970-2262 (what
    history's 64-bit column holds): ``1e300``, ``-1e300``, ``1e20`` are 400s, never an overflow."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, str | int | float):
        raise InvalidInput(f"'{field}' must be a string or a number, got {value!r}")
    if isinstance(value, str):
        try:
            return parse_time(value)
        except InvalidInput as e:
            raise InvalidInput(f"'{field}': {e}") from None
    if isinstance(value, float) and not math.isfinite(value):
        raise InvalidInput(f"'{field}' must be finite")
    if isinstance(value, int):  # exact, whatever its size (10**400 * 1e9 would overflow a float)
        ns: int | float = value if value > 10**14 else value * 10**9
    else:
        ns = value if value > 1e14 else value * 1e9  # no OverflowError: at worst inf
    if not 0 <= ns <= MAX_NS:
        raise InvalidInput(f"'{field}' is out of range: {value!r} (seconds, or ns above 1e14, between "
                           "1970-01-01 and 2262-04-11)")
    return int(ns)
