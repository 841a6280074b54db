"""Publishes every event and observable property change of the hub's Things to an MQTT broker.

Contract with the hub: the event loop's hot path pays one ``deque.append`` per
record, or, while nothing waits to be sent (``[mqtt] immediate``, the default), the
record's QoS 0 message written to the socket (a ``send``). Each served Thing gets
a tap on the event plane (the way the wotpy bridge is fed); the tap turns the
record into (topic, payload, QoS, retain) and writes or queues it; one task sends
the queue to the broker in batches (written to the socket at once, or handed to
paho and waited for: flow control per batch, not per message). A batch's QoS 0
messages are encoded here and written joined, before its QoS 1 and 2 ones: each
topic keeps its order (its QoS is fixed), MQTT orders nothing across QoS levels.

A slow or absent broker never blocks the hub: the queue is bounded
(``[mqtt] queue_max``); when full, the oldest message is dropped and counted
(fresh events are worth more than old ones after an outage; history and SSE
resume still have every one). Connection loss: reconnect with a backoff doubling
from 0.2 s to ``reconnect_max_s``; on each (re)connect the TDs and the last value
of each property are published again, retained (a broker restarted without
persistence has lost them). ``health()`` says all of this; the hub Thing reports it.

Retained state is never left stale (docs/reliability.md, "MQTT"):

- the hub Thing's ``health`` is retained like any observable property, and the hub
  publishes it at start and whenever its state changes (``hub.status``);
- every connection carries a last will on that topic, retained: ``{"state":
  "disconnected", ...}``. A hub killed (SIGKILL, power, a network cut longer than the
  keepalive) is marked so by the broker itself: the hub and the Things it serves are
  offline. The next connection publishes the real health again;
- a clean stop clears the hub's retained TDs and property values (an empty retained
  message), ``health`` included, then disconnects cleanly (no will), as a clean stop
  deletes its TDs from directories; the hub does it first thing in ``stop``
  (``withdraw``), before the slower parts stop;
- a broker that accepts a connection and never answers it (no CONNACK) is given up
  after ``CONNECT_TIMEOUT_S`` and tried again with the backoff; one that stops reading
  shows in health as ``stalled`` once nothing has been written for ``STALL_S`` while
  messages wait (paho's keepalive then drops the connection).

Topics, QoS and forms: ``wott_hub.td.mqtt``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import aiomqtt
import paho.mqtt.client as mqtt

from wott_hub.events.fields import FieldRecord
from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.servient import HUB_THING_ID

if TYPE_CHECKING:
    from wott_hub.events.plane import EventPlane
    from wott_hub.servient import ServedThing
    from wott_hub.td.mqtt import MqttLayout

    from .config import MqttConfig

__all__ = ["MqttPublisher"]

log = logging.getLogger("wott_hub.mqtt")

BATCH = 2000  # messages handed to paho before waiting for them to be sent
CHUNK = 64 * 1024  # bytes of QoS 0 messages joined into one write
FIRST_DELAY_S = 0.2
CLEAR_TIMEOUT_S = 2.0
CONNECT_TIMEOUT_S = 10.0
"""A broker that has not answered a connection (CONNACK) by then is given up on, and tried again."""
STALL_S = 5.0
"""Messages waiting and nothing written for this long: the broker is not reading (health ``stalled``)."""
KEEPALIVE_S = 30
WILL_REASON = ("the hub's connection to the broker ended without a clean stop (MQTT last will): "
               "the hub and every Thing it serves are offline")

Message = tuple[str, str | bytes, int, bool]  # topic, payload, qos, retain


def _remaining_length(out: bytearray, n: int) -> None:
    """MQTT's variable-length integer (7 bits a byte, the high bit: more follow)."""
    while n > 0x7F:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)


def _encode(out: bytearray, heads: dict[str, bytes], topic: str, payload: str | bytes, retain: bool) -> None:
    """One QoS 0 PUBLISH packet (MQTT 3.1.1, no properties) appended to ``out``; ``heads``: each
    topic's encoded length and name, made once."""
    head = heads.get(topic)
    if head is None:
        name = topic.encode()
        head = heads[topic] = len(name).to_bytes(2, "big") + name
    body = payload.encode() if isinstance(payload, str) else payload
    out.append(0x31 if retain else 0x30)
    _remaining_length(out, len(head) + len(body))
    out += head
    out += body


def _write(paho: mqtt.Client, sock: socket.socket | None, data: bytearray) -> mqtt.MQTTMessageInfo | None:
    """Joined PUBLISH packets to the socket at once while paho has nothing to write (``sock``: a plain
    TCP socket, else None), and what the socket does not take on paho's output queue
    (``_packet_queue``, what ``publish`` ends in), written in order after paho's own packets. None
    when all went at once, else the message info to wait for."""
    sent = 0
    if sock is not None and not paho.want_write():
        try:
            sent = sock.send(data)
        except OSError:  # full, or broken: paho's writer waits for the socket or reports the loss
            sent = 0
        if sent == len(data):
            return None
    info = mqtt.MQTTMessageInfo(0)
    paho._packet_queue(mqtt.PUBLISH, data[sent:], 0, 0, info)  # noqa: SLF001 - see MqttPublisher._send
    return info


def _queue_chunk(paho: mqtt.Client, sock: socket.socket | None, chunk: bytearray, held: list[Message],
                 queue: deque[Message], later: list[Message]) -> mqtt.MQTTMessageInfo | None:
    """``_write`` a batch's chunk. Not connected: the chunk's messages and the batch's QoS 1 and 2
    ones so far go back to the queue's front."""
    if not paho.is_connected():
        queue.extendleft(reversed(later))
        queue.extendleft(reversed(held))
        raise aiomqtt.MqttError("connection lost while sending")
    return _write(paho, sock, chunk)


def _drop(client: aiomqtt.Client) -> None:
    """Close a connection aiomqtt did not finish opening (or closing): its socket and reader go."""
    paho = client._client  # noqa: SLF001 - aiomqtt's paho client (a documented escape hatch)
    with contextlib.suppress(Exception):
        paho._sock_close()  # noqa: SLF001 - paho's own way to drop a socket (on_socket_close: the reader)


async def _dropped_after(client: aiomqtt.Client) -> None:
    """Pushed after aiomqtt's exit: when that exit did not close the socket (cancelled while a broker
    that does not read holds the DISCONNECT), close it here."""
    if client._client.socket() is not None:  # noqa: SLF001 - see _drop
        _drop(client)


class _Tap:
    """The event plane's tap of one Thing: topic lookups cached, one append per record."""

    __slots__ = ("_binary", "_events", "_layout", "_props", "_publisher", "_thing")

    def __init__(self, publisher: MqttPublisher, thing: str) -> None:
        self._publisher = publisher
        self._thing = thing
        self._layout = publisher.layout
        self._events: dict[str, tuple[str, int]] = {}
        self._props: dict[str, tuple[str, int]] = {}
        self._binary: dict[str, str] = {}  # event name -> the topic of its binary form

    @property
    def active(self) -> bool:
        return self._publisher.running

    def __call__(self, rec: Record) -> None:
        layout = self._layout
        if rec.kind == KIND_EVENT:
            route = self._events.get(rec.name)
            if route is None:
                route = self._events[rec.name] = (layout.event_topic(self._thing, rec.name),
                                                  layout.qos("event", rec.name))
            self._publisher.put((route[0], rec.data, route[1], False))
            if type(rec) is FieldRecord:  # skinDisplacement: its binary form on a topic of its own
                topic = self._binary.get(rec.name)
                if topic is None:
                    topic = self._binary[rec.name] = layout.binary_topic(self._thing, rec.name)
                self._publisher.put((topic, rec.binary(), route[1], False))
        else:
            route = self._props.get(rec.name)
            if route is None:
                route = self._props[rec.name] = (layout.property_topic(self._thing, rec.name),
                                                 layout.qos("property", rec.name))
            self._publisher.retained[route[0]] = (rec.data, route[1])
            self._publisher.put((route[0], rec.data, route[1], True))


class MqttPublisher:
    def __init__(self, cfg: MqttConfig, layout: MqttLayout, plane: EventPlane, *, client_id: str) -> None:
        self.cfg = cfg
        self.layout = layout
        self.plane = plane
        self.client_id = client_id
        self.host, self.port = cfg.host_port()
        self.queue: deque[Message] = deque()
        self.retained: dict[str, tuple[str | bytes, int]] = {}  # topic -> last retained payload, qos
        self.running = False
        self.connected = False
        self.published = 0
        self.dropped = 0
        self.connects = 0
        self.last_error = ""
        self._wake = asyncio.Event()
        self.idle = False  # everything handed over is on the socket, the publisher waits for more
        self._direct: Callable[[Message], bool] | None = None  # set while the publisher waits, if immediate
        self._immediate = cfg.immediate  # off after a failure, until the next connection
        self._task: asyncio.Task[None] | None = None
        self._client: aiomqtt.Client | None = None
        self._progress_at = time.monotonic()  # when the broker last took what was waiting (or none waited)
        self.withdrawn = False

    @property
    def health_topic(self) -> str:
        """The hub Thing's ``health`` property topic: the last will's, so killed means offline."""
        return self.layout.property_topic(HUB_THING_ID, "health")

    def _will(self) -> aiomqtt.Will:
        payload = json.dumps({"state": "disconnected", "reason": WILL_REASON, "devices": {}})
        return aiomqtt.Will(self.health_topic, payload, qos=1, retain=True)

    # --- following the served Things -----------------------------------------------------

    def exposed(self, served: ServedThing) -> None:
        self.plane.add_tap(served.id, _Tap(self, served.id))
        topic = self.layout.td_topic(served.id)
        td = served.td_bytes()
        self.retained[topic] = (td, 1)
        self.put((topic, td, 1, True))

    def removed(self, served: ServedThing) -> None:
        prefix = f"{self.layout.prefix}/{served.id}/"
        for topic in [t for t in self.retained if t.startswith(prefix)]:
            del self.retained[topic]
            self.put((topic, b"", 1, True))  # an empty retained message deletes the retained one

    def put(self, msg: Message) -> None:
        queue = self.queue
        if not queue and self._direct is not None and not msg[2]:
            try:  # inside the event plane's publish: nothing of paho's may reach the device's pipeline
                if self._direct(msg):
                    self.published += 1
                    return
            except Exception:
                log.exception("MQTT: writing a message at once failed; batches only until reconnected")
                self._direct, self._immediate = None, False
        if len(queue) >= self.cfg.queue_max:
            queue.popleft()
            self.dropped += 1
        queue.append(msg)
        if not self._wake.is_set():
            self._wake.set()

    # --- lifecycle ------------------------------------------------------------------------

    def start(self) -> None:
        self.running = True
        self.withdrawn = False
        self._task = asyncio.create_task(self._run(), name="mqtt-publisher")

    async def withdraw(self) -> None:
        """The first step of a clean stop: publish nothing more, send what is queued and clear the
        retained TDs and values (``CLEAR_TIMEOUT_S`` at most). The connection stays until ``stop``."""
        if self._task is None or self.withdrawn:
            return
        self.running = False
        self.withdrawn = True
        if self.connected:
            for topic in {*self.retained, self.health_topic}:  # health: what the will would say
                self.put((topic, b"", 1, True))
            self.retained.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._flushed(), CLEAR_TIMEOUT_S)

    async def stop(self) -> None:
        """``withdraw`` (if not done yet), then disconnect cleanly (the will is not published)."""
        if self._task is None:
            return
        await self.withdraw()
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task
        self._task = None
        self.connected = False

    async def _flushed(self) -> None:
        while (self.queue or not self.idle) and self.connected:
            await asyncio.sleep(0.01)

    async def _run(self) -> None:
        delay = FIRST_DELAY_S
        while True:
            try:
                client = aiomqtt.Client(self.host, self.port, identifier=self.client_id,
                                        keepalive=KEEPALIVE_S, timeout=10, max_inflight_messages=0,
                                        protocol=aiomqtt.ProtocolVersion.V311, will=self._will())
                async with contextlib.AsyncExitStack() as stack:
                    stack.push_async_callback(_dropped_after, client)  # last: if the clean exit is cut short
                    try:
                        await asyncio.wait_for(stack.enter_async_context(client), CONNECT_TIMEOUT_S)
                    except TimeoutError:
                        _drop(client)
                        raise aiomqtt.MqttError(f"the broker accepted the connection but did not answer it "
                                                f"(no CONNACK) within {CONNECT_TIMEOUT_S:g} s") from None
                    self._client = client
                    self.connected = True
                    self.connects += 1
                    self.last_error = ""
                    self._progress_at = time.monotonic()
                    delay = FIRST_DELAY_S
                    log.info("MQTT: connected to %s:%d", self.host, self.port)
                    self._requeue_retained()
                    await self._send(client)
            except aiomqtt.MqttError as e:
                if self.connected:
                    log.warning("MQTT: lost %s:%d (%s); reconnecting", self.host, self.port, e)
                self.last_error = str(e)
            except Exception as e:  # never let the publisher die quietly: log, back off, try again
                log.exception("MQTT: publisher failed; reconnecting")
                self.last_error = f"{type(e).__name__}: {e}"
            finally:
                self.connected = self.idle = False
                self._direct = None
                self._client = None
            await asyncio.sleep(delay)
            delay = min(delay * 2, self.cfg.reconnect_max_s)

    def _requeue_retained(self) -> None:
        """After a (re)connect, the retained TDs and values first: the broker may have lost them."""
        pending = list(self.queue)
        self.queue.clear()
        for topic, (payload, qos) in self.retained.items():
            self.queue.append((topic, payload, qos, True))
        for msg in pending:
            if not (msg[3] and msg[0] in self.retained):  # retained ones were just re-queued, latest
                self.put(msg)

    async def _send(self, client: aiomqtt.Client) -> None:
        """Hand the queue to paho batch by batch, then wait until the batch is on the socket (its
        last QoS 0 write done, its last QoS 1 or 2 message acknowledged) before the next one: flow
        control without a future or a callback per message, and at most a batch unacknowledged.

        QoS 0 messages (the high-rate events) are encoded here and joined, up to ``CHUNK`` bytes,
        and sent at once while paho has nothing to write (else, and what the socket does not
        take, as one packet of paho's output queue): one socket write per chunk instead of paho's
        ``publish`` per message (its locks, a ``threading.Condition`` and a write each), and no
        loop turn for paho's writer callback, nor a wait for it (32 devices: p50 / p99 2.5-5.2 /
        13-16 ms against 11-27 / 36-45, docs/scale-out.md). They go first; the batch's QoS 1 and 2
        messages follow through ``publish`` (paho keeps them until acknowledged). A topic's QoS
        never changes, so each topic keeps its order; MQTT orders nothing across QoS levels.
        paho's own limit of 20 messages in flight is off (``max_inflight_messages=0``): the batch
        is the limit.

        aiomqtt keeps the connection (its socket callbacks on this loop, keepalive, disconnects);
        paho's ``on_publish``, which aiomqtt sets and which builds two MQTT 5 objects per message
        sent, is switched off (the hub never awaits ``Client.publish``)."""
        queue, wake = self.queue, self._wake
        paho = client._client  # noqa: SLF001 - aiomqtt's paho client (a documented escape hatch)
        paho.on_publish = None
        sock = paho.socket()
        if isinstance(sock, socket.socket):  # one small message per event: Nagle would hold them up
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # to 40 ms+ (delayed ACKs)
        plain = sock if type(sock) is socket.socket else None  # TLS: paho writes every record
        self._immediate = self.cfg.immediate
        heads: dict[str, bytes] = {}  # topic -> its encoded length and name (MQTT 3.1.1: no properties)

        def direct(msg: Message) -> bool:  # ``put``, while nothing waits: the message written at once
            if plain is None or paho.want_write() or not paho.is_connected():
                return False
            packet = bytearray()
            _encode(packet, heads, msg[0], msg[1], msg[3])
            _write(paho, plain, packet)
            return True

        while True:
            if not queue:
                wake.clear()
                self.idle = True  # everything handed over is on the socket
                self._progress_at = time.monotonic()
                self._direct = direct if self._immediate else None
                await wake.wait()
                self._direct = None
                self.idle = False
                continue
            n = min(len(queue), BATCH)
            written = acked = None
            chunk = bytearray()
            held: list[Message] = []  # the chunk's messages, back to the queue if it cannot be sent
            later: list[Message] = []  # QoS 1 and 2, after the chunks
            for _ in range(n):
                msg = queue.popleft()
                topic, payload, qos, retain = msg
                if qos:
                    later.append(msg)
                    continue
                _encode(chunk, heads, topic, payload, retain)
                held.append(msg)
                if len(chunk) >= CHUNK:
                    written = _queue_chunk(paho, plain, chunk, held, queue, later)
                    chunk, held = bytearray(), []
            if chunk:
                written = _queue_chunk(paho, plain, chunk, held, queue, later)
            for i, msg in enumerate(later):
                acked = paho.publish(*msg)
                if acked.rc:
                    queue.extendleft(reversed(later[i:]))
                    raise aiomqtt.MqttCodeError(acked.rc, "could not publish")
            spins = 0
            while not all(info.is_published() for info in (written, acked) if info is not None):
                if not paho.is_connected():
                    raise aiomqtt.MqttError("connection lost while sending")
                spins += 1
                await asyncio.sleep(0 if spins < 100 else 0.001)
            self.published += n
            self._progress_at = time.monotonic()

    # --- what the hub Thing reports -------------------------------------------------------

    def stalled_s(self) -> float:
        """How long messages have waited with nothing written (0: the broker keeps up)."""
        if not self.connected or (self.idle and not self.queue):
            return 0.0
        return max(0.0, time.monotonic() - self._progress_at)

    def health(self) -> dict[str, Any]:
        stalled = self.stalled_s()
        state = "disconnected" if not self.connected else "stalled" if stalled >= STALL_S else "ok"
        error = self.last_error
        if state == "stalled":
            error = (f"the broker has taken nothing for {stalled:.0f} s ({len(self.queue)} messages "
                     "waiting): it accepts the connection but does not read")
        return {"state": state, "broker": f"mqtt://{self.host}:{self.port}", "prefix": self.layout.prefix,
                "published": self.published, "dropped": self.dropped, "queued": len(self.queue),
                "connects": self.connects, "error": error}
