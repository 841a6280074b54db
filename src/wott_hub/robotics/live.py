"""The live Foxglove endpoint: the Foxglove WebSocket protocol, served by ``foxglove-sdk``.

Contract (docs/robotics.md):
- the same channels, schemas and bytes as the MCAP export (``mapping``, profile ``foxglove``):
  each served Thing's raw channels (its events and observable properties, JSON, the TD's
  schemas) and, for a skin, its mesh, deformation and contact scenes and its log; ``/tf`` places
  every skin's frame. Channels are advertised when a Thing is served and removed with it;
- nothing is built for nobody: a Thing's tap on the event plane (``EventPlane.add_tap``) is active
  only while a client subscribes to one of its channels, and only the subscribed channels'
  messages are made. The mesh and ``/tf`` are sent when a client subscribes to them (the protocol
  has no latching), and the mesh again every ``MESH_EVERY_S``; static data is encoded once (the
  mesh's bytes are kept per Thing) and sent at most once per ``STATIC_MIN_S`` per topic however
  many clients subscribe (issue 48: every subscribe rebuilt and resent the whole barrel mesh to
  every subscriber, 986 MB in 30 s from one client subscribing in a loop);
- scenes at most ``scene_hz`` per device, the latest state drawn when its slot comes (a timer on
  the hub's loop); raw channels carry every record, as the hub published it;
- the hub is never slowed or stopped by a client: the SDK runs in a process of its own
  (``relay.py``: its ``Channel.log`` copies a message once per client holding the GIL, which in the
  hub's process every device's pipeline waited for). The hub encodes each message once and writes it
  once to the relay's socket (``relay_link``: one ``sendmsg`` on the loop; what the socket does not
  take waits, bounded in bytes, ``RELAY_BYTES``; beyond, a message is not sent and counted), whatever
  the number of viewers. There each client has
  its own queue (``backlog`` messages; a slow client loses its oldest, alone), and
  ``guard.FoxgloveGuard`` bounds it in bytes: a client that stops reading is cut, so are clients
  beyond ``MAX_CLIENTS`` and one that sends invalid messages (whose log lines are sampled);
  a client's bad request (garbage, an unknown channel) gets an error status from the SDK and
  changes nothing for the others; a mapping error is logged and counted, never raised into the
  plane's publish.

The SDK speaks the protocol under its current name, subprotocol ``foxglove.sdk.v1`` (the
``foxglove.websocket.v1`` messages, renamed): Foxglove and ``@foxglove/ws-protocol``'s client
(given a socket offering it) connect; a client offering only ``foxglove.websocket.v1`` is refused
at the handshake (docs/robotics.md).
"""

from __future__ import annotations

import asyncio
import logging
import subprocess
import time
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record

from . import relay_wire as W
from .channel import Channel, Out
from .mapping import CONTACTS, LOG_EVENTS, FleetMapping
from .names import TF_TOPIC
from .raw_signals import DISPLACEMENT_EVENT, ImageFrame, TaxelGrid
from .relay_link import RELAY_BYTES, RelayLink

if TYPE_CHECKING:
    from wott_hub.events.plane import EventPlane
    from wott_hub.servient import ServedThing

    from .config import FoxgloveConfig

__all__ = ["RELAY_BYTES", "STATIC_MIN_S", "FoxgloveLive"]

log = logging.getLogger("wott_hub.foxglove")

STATIC_MIN_S = 1.0
"""A topic's static data (a mesh, ``/tf``) is sent at most this often, however many subscribe."""


class _Tap:
    """One Thing's tap on the event plane: active while a client subscribes to one of its channels."""

    __slots__ = ("live", "thing")

    def __init__(self, live: FoxgloveLive, thing: str) -> None:
        self.live = live
        self.thing = thing

    @property
    def active(self) -> bool:
        return self.live.active.get(self.thing, 0) > 0

    def __call__(self, rec: Record) -> None:
        self.live.record(rec)


class FoxgloveLive:
    def __init__(self, cfg: FoxgloveConfig, plane: EventPlane, *, name: str = "wott-hub",
                 tls: tuple[bytes, bytes] | None = None) -> None:
        self.cfg = cfg
        self.plane = plane
        self.name = name
        self.tls = tls
        self.mapping = FleetMapping("foxglove", scene_hz=cfg.scene_hz, color_max_mm=cfg.color_max_mm)
        self.link: RelayLink | None = None
        self._next_id = 0
        self.channels: dict[str, int] = {}  # topic -> its id with the relay
        self.owner: dict[str, str] = {}  # topic -> its Thing ("" for /tf)
        self.subscribers: dict[str, int] = {}  # topic -> clients subscribed
        self.active: dict[str, int] = {}  # Thing -> subscriptions to its channels
        self.sent = 0
        self.bytes = 0  # logged to the endpoint (what a stalled client's queue can hold at most)
        self.errors = 0
        self._meshes: dict[str, bytes] = {}  # Thing -> its mesh scene, encoded once
        self._static_last: dict[str, float] = {}  # topic -> when its static data was last sent
        self._static_due: set[str] = set()  # topics whose static data is scheduled
        self._loop: asyncio.AbstractEventLoop | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at = 0

    # --- lifecycle ----------------------------------------------------------------------------

    def start(self) -> None:
        """Start the relay process and its server (the port is known after this: ``port``)."""
        self._loop = asyncio.get_running_loop()
        self.link = RelayLink(self._loop, self.subscribed, self._relay_ended)
        self.link.start({"name": self.name, "host": self.cfg.host, "port": self.cfg.port,
                         "backlog": self.cfg.backlog, "tls": self.tls,
                         "level": logging.getLogger("wott_hub").getEffectiveLevel()},
                        f"the Foxglove endpoint on {self.cfg.host}:{self.cfg.port}",
                        "(choose another with --foxglove-port or [foxglove] port)")
        self._channel(self._tf_channel(), "")

    def _relay_ended(self) -> None:
        self.subscribers.clear()
        self.active.clear()

    def stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self.link is not None:
            self.link.stop()
        self.channels.clear()
        self.owner.clear()

    @property
    def relay(self) -> subprocess.Popen[bytes] | None:
        """The relay process (None before ``start`` and after ``stop``)."""
        return self.link.process if self.link is not None else None

    @property
    def port(self) -> int | None:
        return self.link.port if self.link is not None else None

    @property
    def url(self) -> str | None:
        if self.port is None:
            return None
        host = self.cfg.host if self.cfg.host not in ("0.0.0.0", "::") else "127.0.0.1"
        return f"{'wss' if self.tls else 'ws'}://{host}:{self.port}"

    # --- following the served Things ------------------------------------------------------------

    def exposed(self, served: ServedThing) -> None:
        """Map a newly served Thing, advertise its channels, tap its records."""
        import json

        static = {}
        for prop in ("skinNodes", "skinCells", "sensorCoordinateFrame"):
            text = served.static.get(prop)
            if text is not None:
                static[prop] = json.loads(text)
        m = self.mapping.add(served.id, served.td, static)
        for ch in self._channels_of(served, m.enc):
            self._channel(ch, served.id)
        self.plane.add_tap(served.id, _Tap(self, served.id))
        if m.geom is not None and self.subscribers.get(TF_TOPIC):
            self._send_transforms()

    def removed(self, served: ServedThing) -> None:
        self.mapping.remove(served.id)
        self._meshes.pop(served.id, None)
        for topic in [t for t, owner in self.owner.items() if owner == served.id]:
            cid = self.channels.pop(topic)
            if self.link is not None:
                self.link.put(W.control(W.CLOSE, cid), droppable=False)
            del self.owner[topic]
            self.subscribers.pop(topic, None)
        self.active.pop(served.id, None)

    def _channels_of(self, served: ServedThing, enc: Any) -> Iterable[Channel]:
        td = served.td
        events = td.get("events") or {}
        props = td.get("properties") or {}
        for name in events:
            yield self.mapping.raw_channel(served.id, KIND_EVENT, name)
        for name, aff in props.items():
            if isinstance(aff, dict) and aff.get("observable"):
                yield self.mapping.raw_channel(served.id, KIND_PROPERTY, name)
        kinds = []
        if enc.geom is not None:
            kinds += ["mesh", "deformation"]
            if DISPLACEMENT_EVENT in events:
                kinds.append("displacement")
        if CONTACTS in props:
            kinds.append("contacts")
        if any(n in events for n in LOG_EVENTS):
            kinds.append("log")
        for kind in kinds:
            ch = enc.channel(kind)
            if ch is not None:
                yield ch

    def _tf_channel(self) -> Channel:
        from .foxglove_msgs import FoxgloveEncoder

        return FoxgloveEncoder.tf_channel()

    def _channel(self, ch: Channel, owner: str) -> int:
        found = self.channels.get(ch.topic)
        if found is None:
            self._next_id += 1
            found = self.channels[ch.topic] = self._next_id
            self.owner[ch.topic] = owner
            if self.link is not None:
                self.link.put(W.control(W.CHANNEL, (
                    found, ch.topic, ch.schema_name, ch.schema_encoding, ch.schema, ch.encoding,
                    dict(ch.metadata))), droppable=False)
        return found

    def _log(self, cid: int, payload: bytes, t_ns: int) -> None:
        """One message to the relay, once, whatever the number of viewers (they are the relay's)."""
        link = self.link
        if link is not None and link.put(W.log_frame(cid, t_ns, payload)):
            self.sent += 1
            self.bytes += len(payload)

    # --- subscriptions (on the hub's loop) ------------------------------------------------------

    def subscribed(self, topic: str, change: int) -> None:
        owner = self.owner.get(topic)
        if owner is None:
            return
        n = self.subscribers[topic] = max(0, self.subscribers.get(topic, 0) + change)
        if owner:
            self.active[owner] = max(0, self.active.get(owner, 0) + change)
        if change > 0 and n and (topic == TF_TOPIC or self._mesh_topic(owner) == topic):
            self._static_soon(topic)

    def _mesh_topic(self, owner: str) -> str | None:
        m = self.mapping.things.get(owner)
        mesh = m.enc.channel("mesh") if m is not None else None
        return mesh.topic if mesh is not None else None

    def _static_soon(self, topic: str) -> None:
        """Send ``topic``'s static data now, or at its next slot (``STATIC_MIN_S``): one send for every
        subscribe meanwhile (each send goes to every subscriber: the protocol has no per-client send)."""
        if topic in self._static_due or self._loop is None:
            return
        self._static_due.add(topic)
        wait = max(0.0, self._static_last.get(topic, -STATIC_MIN_S) + STATIC_MIN_S - time.monotonic())
        self._loop.call_later(wait, self._send_static, topic)

    def _send_static(self, topic: str) -> None:
        self._static_due.discard(topic)
        if not self.wanted(topic):
            return
        self._static_last[topic] = time.monotonic()
        if topic == TF_TOPIC:
            self._send_transforms()
            return
        owner = self.owner.get(topic)
        m = self.mapping.things.get(owner) if owner else None
        if m is None or owner is None:
            return
        now = time.time_ns()
        encoded = self._meshes.get(owner)
        if encoded is None:
            outs = m.mesh(now)  # built and encoded once; the periodic resend (MESH_EVERY_S) builds anew
            if not outs:
                return
            encoded = self._meshes[owner] = outs[0].payload
        cid = self.channels.get(topic)
        if cid is not None:
            self._log(cid, encoded, now)

    def wanted(self, topic: str) -> bool:
        return self.subscribers.get(topic, 0) > 0

    # --- sending --------------------------------------------------------------------------------

    def _send(self, outs: list[Out]) -> None:
        for o in outs:
            cid = self.channels.get(o.channel.topic)
            if cid is None:  # a channel first met now (a camera's): advertised from now on
                self._channel(o.channel, dict(o.channel.metadata).get("thing", ""))
                continue  # nobody can be subscribed to it yet
            self._log(cid, o.payload, o.t_ns)

    def _send_transforms(self) -> None:
        tf = self.mapping.transforms(time.time_ns())
        if tf is not None:
            self._send([tf])

    def record(self, rec: Record) -> None:
        """The tap: what the subscribed channels need of ``rec``, sent; a pending scene timed."""
        try:
            self._send(self.mapping.record(rec, self.wanted))
        except Exception:  # never into the plane's publish: the device's pipeline goes on
            self.errors += 1
            if self.errors == 1 or self.errors % 1000 == 0:
                log.exception("Foxglove: mapping a record of %s failed (%d so far)", rec.thing, self.errors)
            return
        self._arm()

    def image(self, thing: str, img: ImageFrame) -> None:
        """A camera image of ``thing`` (issue 29's raw signal) to the clients subscribed to its camera."""
        m = self.mapping.things.get(thing)
        if m is not None:
            self._send(m.image(img))

    def taxels(self, thing: str, grid: TaxelGrid) -> None:
        m = self.mapping.things.get(thing)
        if m is not None:
            self._send(m.taxels(grid))

    def _arm(self) -> None:
        """A timer at the earliest pending scene's slot (none while one is set)."""
        if self._timer is not None or self._loop is None:
            return
        at = min(self.mapping.deadlines(), default=None)
        if at is None:
            return
        # deadlines are in the records' time: a device whose clock is off by more than a slot is
        # still drawn a slot later at most
        self._timer_at = at
        delay = min(1.0 / self.cfg.scene_hz, max(0.0, (at - time.time_ns()) / 1e9))
        self._timer = self._loop.call_later(delay, self._flush)

    def _flush(self) -> None:
        self._timer = None
        try:
            self._send(self.mapping.due(max(time.time_ns(), self._timer_at)))
        except Exception:
            self.errors += 1
            log.exception("Foxglove: drawing a pending scene failed")
        self._arm()

    def health(self) -> dict[str, Any]:
        """The hub's counters, and the relay's (its guard's, every ``TICK_S``: ``clients``, ``closedSlow``...;
        ``relaySent``: messages it logged to the SDK). ``notSent``: refused past ``RELAY_BYTES``."""
        link = self.link
        relay = dict(link.health) if link is not None else {}
        relay["relaySent"] = relay.pop("sent", 0)
        relay.pop("bytes", None)
        outbox = link.outbox if link is not None else None
        return {"url": self.url, "channels": len(self.channels),
                "subscriptions": sum(self.subscribers.values()), "sent": self.sent, "errors": self.errors,
                "queuedBytes": outbox.bytes if outbox is not None else 0,
                "notSent": outbox.refused if outbox is not None else 0,
                "relayPid": self.relay.pid if self.relay is not None else None,
                "clients": 0, "closedSlow": 0, "closedOverLimit": 0, "closedInvalid": 0, "invalidMessages": 0,
                **relay}
