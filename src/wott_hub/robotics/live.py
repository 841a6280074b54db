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
  once to the relay's socket (``_Outbox``: one ``sendmsg`` on the loop; what the socket does not take
  waits, bounded in bytes, ``RELAY_BYTES``; beyond, a message is not sent and counted), whatever the
  number of viewers. There each client has
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
import socket
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record

from . import relay_wire as W
from .channel import Channel, Out
from .guard import CLIENT_MAX_BYTES
from .mapping import CONTACTS, LOG_EVENTS, FleetMapping
from .names import TF_TOPIC
from .raw_signals import DISPLACEMENT_EVENT, ImageFrame, TaxelGrid

if TYPE_CHECKING:
    from wott_hub.events.plane import EventPlane
    from wott_hub.servient import ServedThing

    from .config import FoxgloveConfig

__all__ = ["RELAY_BYTES", "STATIC_MIN_S", "FoxgloveLive"]

log = logging.getLogger("wott_hub.foxglove")

STATIC_MIN_S = 1.0
"""A topic's static data (a mesh, ``/tf``) is sent at most this often, however many subscribe."""
RELAY_BYTES = CLIENT_MAX_BYTES
"""What waits for the relay's socket at most (the relay fell behind: a loaded machine); beyond, a
message is not sent to the viewers, and counted (``notSent``): the sensors never wait for it."""
START_S = 30.0  # the relay's server bound, at most (a Python start and the SDK's import: ~0.5 s)
STOP_S = 5.0  # the relay's end after STOP, at most; then it is killed


class _Outbox:
    """Frames for the relay, written on the hub's loop to a non-blocking socket: a message costs the loop
    one ``sendmsg`` (the kernel copies it once), whatever the number of viewers. What the socket does not
    take waits here and goes when it is writable (``add_writer``), bounded in bytes: a ``LOG`` frame
    that would take it past ``RELAY_BYTES`` is refused and counted; control frames always go. (A thread
    writing a blocking socket cost more: every message woke it, and each wake-up took the GIL from the
    devices' pipelines on a busy machine.)"""

    def __init__(self, sock: socket.socket, loop: asyncio.AbstractEventLoop) -> None:
        sock.setblocking(False)
        self.sock = sock
        self.loop = loop
        self.pending: deque[bytes | memoryview] = deque()
        self.bytes = 0  # pending
        self.refused = 0
        self.failed = ""

    def put(self, frame: tuple[bytes, bytes], *, droppable: bool = True) -> bool:
        head, body = frame
        if self.failed:
            return False
        total = len(head) + len(body)
        if self.pending:  # behind what waits: in order, or not at all
            if droppable and self.bytes + total > RELAY_BYTES:
                self.refused += 1
                return False
            self.pending += (head, body)
            self.bytes += total
            return True
        try:
            sent = self.sock.sendmsg([head, body])
        except BlockingIOError:
            sent = 0
        except OSError as e:  # the relay is gone: the reader says so
            self.failed = str(e)
            return False
        if sent == total:
            return True
        if sent < len(head):  # a frame begun is finished whatever the bound
            self.pending += (memoryview(head)[sent:], body)
        else:
            self.pending.append(memoryview(body)[sent - len(head):])
        self.bytes += total - sent
        self.loop.add_writer(self.sock.fileno(), self._flush)
        return True

    def _flush(self) -> None:
        pending = self.pending
        while pending:
            try:
                sent = self.sock.sendmsg([pending[i] for i in range(min(len(pending), 64))])
            except BlockingIOError:
                return
            except OSError as e:
                self.failed = str(e)
                pending.clear()
                self.bytes = 0
                break
            self.bytes -= sent
            while sent:
                n = len(pending[0])
                if sent >= n:
                    pending.popleft()
                    sent -= n
                else:
                    pending[0] = memoryview(pending[0])[sent:]
                    sent = 0
        self.loop.remove_writer(self.sock.fileno())

    def close(self, timeout: float) -> None:
        """What waits, written within ``timeout`` (the hub stops: the loop no longer writes it)."""
        if self.pending:
            self.loop.remove_writer(self.sock.fileno())
        if self.failed:
            return
        self.sock.settimeout(timeout)
        try:
            for part in self.pending:
                self.sock.sendall(part)
        except OSError as e:
            self.failed = str(e)
        self.pending.clear()
        self.bytes = 0


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
        self.relay: subprocess.Popen[bytes] | None = None
        self._socks: list[socket.socket] = []
        self._outbox: _Outbox | None = None
        self._port: int | None = None
        self._relay_health: dict[str, Any] = {}
        self._stopping = False
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
        # two socket pairs: the hub writes "down" without blocking (its loop), reads "up" in a thread
        down, down_theirs = socket.socketpair()
        up, up_theirs = socket.socketpair()
        fds = (down_theirs.fileno(), up_theirs.fileno())
        self.relay = subprocess.Popen([sys.executable, "-m", "wott_hub.robotics.relay", *map(str, fds)],
                                      pass_fds=fds, stdin=subprocess.DEVNULL)
        down_theirs.close()
        up_theirs.close()
        self._socks = [down, up]
        W.send(down, W.control(W.INIT, {
            "name": self.name, "host": self.cfg.host, "port": self.cfg.port, "backlog": self.cfg.backlog,
            "tls": self.tls, "level": logging.getLogger("wott_hub").getEffectiveLevel()}))
        up.settimeout(START_S)
        try:
            ready = self._ready(up)
        except (OSError, TimeoutError) as e:
            ready = {"error": f"the relay process did not start: {e}"}
        up.settimeout(None)
        if "error" in ready:
            import errno

            self._end_relay()
            text = ready["error"]
            code = errno.EADDRINUSE if "in use" in text else errno.EADDRNOTAVAIL
            raise OSError(code, f"the Foxglove endpoint on {self.cfg.host}:{self.cfg.port}: {text} "
                                "(choose another with --foxglove-port or [foxglove] port)")
        self._port = int(ready["port"])
        if not ready["nagle"]:
            log.warning("Foxglove: the listener on port %s was not found to turn Nagle's algorithm off "
                        "(not Linux?): messages may wait up to 40 ms for the client's ACK", self._port)
        self._outbox = _Outbox(down, self._loop)
        threading.Thread(target=self._read, args=(up,), name="foxglove-relay", daemon=True).start()
        self._channel(self._tf_channel(), "")

    @staticmethod
    def _ready(sock: socket.socket) -> dict[str, Any]:
        """The relay's ``READY`` (its log lines before it are written as they come)."""
        while True:
            frame = W.recv(sock)
            if frame is None:
                return {"error": "the relay process ended before its server started"}
            kind, body = frame
            if kind == W.READY:
                return dict(body)
            if kind == W.LOGREC:
                level, name, text = body
                logging.getLogger(name).log(level, "%s", text)

    def _read(self, sock: socket.socket) -> None:
        """The relay's frames (a thread): subscriptions to the hub's loop, health kept, log lines written."""
        while True:
            try:
                frame = W.recv(sock)
            except OSError:
                frame = None
            if frame is None:
                self.call_soon(self._relay_ended)
                return
            kind, body = frame
            if kind == W.SUB:
                self.call_soon(self.subscribed, *body)
            elif kind == W.HEALTH:
                self._relay_health = body
            elif kind == W.LOGREC:
                level, name, text = body
                logging.getLogger(name).log(level, "%s", text)

    def _relay_ended(self) -> None:
        if self._stopping:
            return
        code = self.relay.poll() if self.relay is not None else None
        log.error("Foxglove: the relay process ended (exit code %s): the endpoint is down until the hub "
                  "restarts", code)
        self._relay_health = {**self._relay_health, "relay": "ended"}
        self.subscribers.clear()
        self.active.clear()

    def stop(self) -> None:
        self._stopping = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._outbox is not None:
            self._outbox.put(W.control(W.STOP, None), droppable=False)
            self._outbox.close(STOP_S)
            self._outbox = None
        self._end_relay()
        self.channels.clear()
        self.owner.clear()
        self._port = None

    def _end_relay(self) -> None:
        relay, self.relay = self.relay, None
        if relay is not None:
            try:
                relay.wait(STOP_S)
            except subprocess.TimeoutExpired:
                log.warning("Foxglove: the relay process did not end in %.0f s; killed", STOP_S)
                relay.kill()
                relay.wait(STOP_S)
        for sock in self._socks:
            sock.close()
        self._socks = []

    @property
    def port(self) -> int | None:
        return self._port

    @property
    def url(self) -> str | None:
        if self.port is None:
            return None
        host = self.cfg.host if self.cfg.host not in ("0.0.0.0", "::") else "127.0.0.1"
        return f"{'wss' if self.tls else 'ws'}://{host}:{self.port}"

    def call_soon(self, fn: Any, *args: Any) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(fn, *args)

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
            if self._outbox is not None:
                self._outbox.put(W.control(W.CLOSE, cid), droppable=False)
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
            if self._outbox is not None:
                self._outbox.put(W.control(W.CHANNEL, (
                    found, ch.topic, ch.schema_name, ch.schema_encoding, ch.schema, ch.encoding,
                    dict(ch.metadata))), droppable=False)
        return found

    def _log(self, cid: int, payload: bytes, t_ns: int) -> None:
        """One message to the relay, once, whatever the number of viewers (they are the relay's)."""
        outbox = self._outbox
        if outbox is not None and outbox.put(W.log_frame(cid, t_ns, payload)):
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
        relay = dict(self._relay_health)
        relay["relaySent"] = relay.pop("sent", 0)
        relay.pop("bytes", None)
        outbox = self._outbox
        return {"url": self.url, "channels": len(self.channels),
                "subscriptions": sum(self.subscribers.values()), "sent": self.sent, "errors": self.errors,
                "queuedBytes": outbox.bytes if outbox is not None else 0,
                "notSent": outbox.refused if outbox is not None else 0,
                "relayPid": self.relay.pid if self.relay is not None else None,
                "clients": 0, "closedSlow": 0, "closedOverLimit": 0, "closedInvalid": 0, "invalidMessages": 0,
                **relay}
