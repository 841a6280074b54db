"""Records written by the publisher itself (``events/subscriber.py``) over real sockets.

An SSE client and a WebSocket client stop reading while the hub publishes
megabytes: their sockets back up, the hub keeps running, what follows is
queued; once they read again each gets every record once, in order. The SSE
bytes the hub sends to the socket itself (``servient/sending.py``) are framed as
tornado frames the response: chunks for HTTP/1.1, the bare stream for HTTP/1.0.
"""

from __future__ import annotations

import asyncio
import json
import re
import socket
import time

import pytest
from tornado.websocket import websocket_connect

from wott_hub.config import HubConfig
from wott_hub.events.record import KIND_EVENT

EVENT = "actionDetection"  # declared by the device, published by it only now and then
PADDING = "x" * 1000
ROUNDS, PER_ROUND = 200, 100  # at most 20 MB: well past what loopback buffers hold


@pytest.fixture(scope="module")
def hub(hub_thread, press_scene):
    ht = hub_thread(HubConfig(http_port=0, ws_port=0, history=False, devices=(press_scene("pad"),))).start()
    yield ht
    ht.stop()


def _flood(ht) -> tuple[list[int], bool]:
    """Publish on the hub's loop, in rounds, until a subscriber of EVENT has records queued behind
    its backed-up socket (or ROUNDS are spent): the seqs published, and whether one was queued."""
    plane = ht.hub._plane

    async def run() -> tuple[list[int], bool]:
        seqs: list[int] = []
        for _ in range(ROUNDS):
            seqs += [plane.publish("pad", KIND_EVENT, EVENT, time.time_ns(),
                                   json.dumps({"i": len(seqs) + k, "padding": PADDING})).seq
                     for k in range(PER_ROUND)]
            await asyncio.sleep(0.002)  # the consumers write what was queued, until the socket is full
            if any(s.pending for s in plane.stream("pad").subs.get((KIND_EVENT, EVENT), ())):
                return seqs, True
        return seqs, False

    return ht.call(run, timeout=60)


def _subscribers(ht) -> int:
    return ht.call(lambda: len(ht.hub._plane.stream("pad").subs.get((KIND_EVENT, EVENT), ())))


def test_an_sse_client_that_stops_reading_backs_up_then_gets_every_record_once_in_order(hub):
    sock = socket.create_connection(("127.0.0.1", hub.hub._server.http_port), timeout=10)
    try:
        sock.sendall(f"GET /wot/pad/events/{EVENT} HTTP/1.1\r\nHost: x\r\nAccept: text/event-stream\r\n\r\n"
                     .encode())
        got = sock.recv(65536)
        assert got.startswith(b"HTTP/1.1 200"), got[:200]
        deadline = time.monotonic() + 10
        while _subscribers(hub) < 1:
            assert time.monotonic() < deadline, "the stream was not subscribed"
            time.sleep(0.01)
        seqs, queued = _flood(hub)
        assert queued, f"{len(seqs)} records of 1 kB never backed the socket up"
        buf = bytearray(got)
        ids: list[int] = []
        while not ids or ids[-1] < seqs[-1]:
            chunk = sock.recv(1 << 20)
            assert chunk, "the hub closed the stream"
            buf += chunk
            end = buf.rfind(b"\n\n")  # whole SSE messages only (a chunk ends with one)
            if end > 0:
                ids += [int(m) for m in re.findall(rb"^id: (\d+)$", bytes(buf[:end]), re.M)]
                del buf[:end + 2]
        assert ids == sorted(set(ids)), "a record came twice or out of order"
        assert set(seqs) <= set(ids), f"{len(set(seqs) - set(ids))} records lost"
    finally:
        sock.close()


def test_a_websocket_client_that_stops_reading_backs_up_then_gets_every_record_once_in_order(hub):
    async def main() -> None:
        ws = await websocket_connect(f"ws://127.0.0.1:{hub.hub._server.ws_port}/pad", connect_timeout=5)
        try:
            await ws.write_message(json.dumps({"jsonrpc": "2.0", "method": "on_event",
                                               "params": {"name": EVENT}, "id": 1}))
            sid = json.loads(await asyncio.wait_for(ws.read_message(), 5))["result"]
            while _subscribers(hub) < 1:
                await asyncio.sleep(0.01)
            # tornado's client stops reading the socket while a message waits to be read
            seqs, queued = await asyncio.to_thread(_flood, hub)
            assert queued, f"{len(seqs)} records of 1 kB never backed the socket up"
            order: list[int] = []
            while len(order) < len(seqs):
                msg = json.loads(await asyncio.wait_for(ws.read_message(), 10))
                assert msg.get("subscription") == sid, msg
                if isinstance(msg["data"], dict):  # not one of the device's own actions
                    order.append(msg["data"]["i"])
            assert order == list(range(len(seqs))), "a record lost, repeated or out of order"
        finally:
            ws.close()

    asyncio.run(main())


def _read_until(sock: socket.socket, buf: bytearray, done) -> bytes:
    while not done(bytes(buf)):
        got = sock.recv(65536)
        assert got, f"the hub closed the stream after {bytes(buf)[-200:]!r}"
        buf += got
    return bytes(buf)


def _dechunk(body: bytes) -> tuple[bytes, bytes]:
    """Whole chunks of ``body`` joined, and what follows them (a chunk not yet complete)."""
    out = bytearray()
    while (eol := body.find(b"\r\n")) > 0:
        size = int(body[:eol], 16)  # a framing error fails here
        if len(body) < eol + 2 + size + 2:
            break
        assert body[eol + 2 + size:eol + 4 + size] == b"\r\n", body[:eol + 6 + size]
        out += body[eol + 2:eol + 2 + size]
        body = body[eol + 4 + size:]
    return bytes(out), body


def _without_the_devices_own(stream: bytes) -> bytes:
    """``stream`` less the messages the pad published itself meanwhile (their data is a JSON string)."""
    head, _, body = stream.partition(b"\n")
    kept = [m for m in body.split(b"\n\n")[:-1] if not m.split(b"\ndata: ", 1)[1].startswith(b'"')]
    return head + b"\n" + b"".join(m + b"\n\n" for m in kept)


@pytest.mark.parametrize("version", ["HTTP/1.1", "HTTP/1.0"])
def test_sse_records_reach_the_socket_framed_as_the_http_version_says(hub, version):
    sock = socket.create_connection(("127.0.0.1", hub.hub._server.http_port), timeout=10)
    try:
        sock.sendall(f"GET /wot/pad/events/{EVENT} {version}\r\nHost: x\r\nAccept: text/event-stream\r\n\r\n"
                     .encode())
        buf = bytearray()
        raw = _read_until(sock, buf, lambda b: b"\r\n\r\n" in b)
        head, _, _ = raw.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 200"), head  # (tornado's status line, whatever the request's)
        assert (b"Transfer-Encoding: chunked" in head) == (version == "HTTP/1.1"), head
        del buf[:len(head) + 4]
        deadline = time.monotonic() + 10
        while _subscribers(hub) < 1:
            assert time.monotonic() < deadline, "the stream was not subscribed"
            time.sleep(0.01)

        async def publish() -> list[tuple[int, str]]:
            out = []
            for i in range(5):  # the first ones written inside publish, the others queued
                data = json.dumps({"i": i})
                out.append((hub.hub._plane.publish("pad", KIND_EVENT, EVENT, time.time_ns(), data).seq, data))
            return out

        sent = hub.call(publish)
        want = b"retry: 1000\n" + b"".join(f"id: {seq}\ndata: {data}\n\n".encode() for seq, data in sent)
        last = f"id: {sent[-1][0]}\n".encode()

        def done(stream: bytes) -> bool:
            return last in stream and stream.endswith(b"\n\n")

        if version == "HTTP/1.1":
            body = _read_until(sock, buf, lambda b: done(_dechunk(b)[0]))
            stream, rest = _dechunk(body)
            assert rest == b""
        else:
            stream = _read_until(sock, buf, done)
        assert _without_the_devices_own(stream) == want
    finally:
        sock.close()
