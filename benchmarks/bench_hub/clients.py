"""Client processes: SSE, hub WebSocket, wotpy and TD GET clients, each run in its own process.

Clients run as separate processes (``python -m bench_hub.clients SPEC``), so the hub's event
loop and the clients do not share a core's time slices in one process. Client and hub stamps
are ``time.perf_counter_ns`` (CLOCK_MONOTONIC on Linux), comparable across processes.

Protocol with the hub side (``Client``): the process prints ``ready`` once subscribed, then
one JSON line with its result. Only the standard library is imported at the top: a client
imports what it uses (httpx, tornado, wotpy) when it starts.
"""

from __future__ import annotations

import asyncio
import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path

from .common import now_ns, payload

__all__ = ["Client", "client_main"]

_BENCHMARKS = Path(__file__).resolve().parent.parent


def client_main(spec: dict) -> None:
    kind = spec["kind"]
    if kind == "sse":
        res = asyncio.run(_sse_client(spec["urls"], spec["duration"]))
    elif kind == "sse-lean":
        res = asyncio.run(_sse_lean_client(spec["urls"], spec["duration"]))
    elif kind == "wotpy":
        res = asyncio.run(_wotpy_client(spec["urls"], spec["duration"], spec["event"]))
    elif kind == "ws-raw":
        res = asyncio.run(_ws_raw_client(spec["url"], spec["event"], spec["duration"]))
    elif kind == "ws-lat":
        res = asyncio.run(_ws_latency_client(spec["urls"], spec["event"], spec["duration"]))
    elif kind == "td-get":
        res = _td_get_client(spec["urls"], spec["n"])
    elif kind == "drain":
        res = asyncio.run(_drain_client(spec["urls"], spec["duration"]))
    else:
        raise SystemExit(f"unknown client {kind}")
    print(json.dumps({**res, **_CPU}), flush=True)


def _ready() -> None:
    print("ready", flush=True)


_CPU: dict[str, float] = {}
"""The client's own CPU time (s) over its receiving window (``_measure``): its share of the cores."""


async def _measure(tasks: list[asyncio.Task], duration: float) -> None:
    """Tell the hub side the client is subscribed, receive for ``duration``, then stop."""
    _ready()
    cpu0, t0 = time.process_time(), time.monotonic()
    await asyncio.sleep(duration)
    _CPU.update(cpu_s=time.process_time() - cpu0, window_s=time.monotonic() - t0)
    for t in tasks:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)


async def _sse_client(urls: list[str], duration: float) -> dict:
    import httpx
    from httpx_sse import aconnect_sse

    got: list[tuple] = []
    connected = 0
    all_connected = asyncio.Event()

    async def one(i: int, url: str, c) -> None:
        nonlocal connected
        async with aconnect_sse(c, "GET", url) as es:
            connected += 1
            if connected == len(urls):
                all_connected.set()
            async for ev in es.aiter_sse():
                t = now_ns()
                data = json.loads(ev.data)
                stamp = data.get("timeStamp") if isinstance(data, dict) else 0
                got.append((i, int(ev.id), t, now_ns(), stamp))

    limits = httpx.Limits(max_connections=len(urls) + 2, max_keepalive_connections=len(urls) + 2)
    async with httpx.AsyncClient(timeout=None, limits=limits) as c:
        tasks = [asyncio.create_task(one(i, u, c)) for i, u in enumerate(urls)]
        await asyncio.wait_for(all_connected.wait(), 30)
        await _measure(tasks, duration)
    return {"events": got}


class _Lean(asyncio.Protocol):
    """A stream client parsed in place: ``request`` written on connect, the response head checked
    (``status``) and skipped, then ``body`` given what has come (it returns what it could not parse
    yet) with the time it came. The instrument should not need the core the hub is measured on."""

    status = b""

    def __init__(self, i: int, request: bytes, got: list, opened: asyncio.Future) -> None:
        self.i, self.request, self.got, self.opened = i, request, got, opened
        self.raw = b""  # bytes not yet parsed
        self.head_done = False
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport) -> None:
        self.transport = transport
        transport.write(self.request)

    def data_received(self, data: bytes) -> None:
        t = now_ns()
        raw = self.raw + data
        if not self.head_done:
            end = raw.find(b"\r\n\r\n")
            if end < 0:
                self.raw = raw
                return
            if not raw.startswith(self.status):
                raise RuntimeError(raw[:200])
            self.head_done = True
            raw = raw[end + 4:]
            self.head()
        self.raw = self.body(raw, t)

    def head(self) -> None:
        """The response head has come."""

    def body(self, raw: bytes, t: int) -> bytes:
        raise NotImplementedError


class _LeanSSE(_Lean):
    """One SSE stream over HTTP/1.1 chunked transfer. httpx + httpx-sse (``_sse_client``) spend
    ~200 us of CPU per event (~70 % of a core at 3,300 events/s on this machine); this ~10x less.
    It still reads every byte, splits messages, takes ``id`` and decodes ``data`` as JSON."""

    status = b"HTTP/1.1 200"

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.text = b""  # de-chunked SSE text not yet a whole message

    def head(self) -> None:
        self.opened.set_result(None)

    def body(self, raw: bytes, t: int) -> bytes:
        body = [self.text]
        while raw:  # chunked transfer: <hex size>\r\n<data>\r\n
            eol = raw.find(b"\r\n")
            if eol < 0:
                break
            size = int(raw[:eol], 16)
            if len(raw) < eol + 2 + size + 2:
                break
            body.append(raw[eol + 2:eol + 2 + size])
            raw = raw[eol + 4 + size:]
        *messages, self.text = b"".join(body).split(b"\n\n")
        for m in messages:
            if m.startswith(b"retry: "):  # the stream's first line, part of its first message
                m = m.partition(b"\n")[2]
            if not m.startswith(b"id: "):
                continue  # a comment (": ping")
            head, _, data = m.partition(b"\ndata: ")
            stamp = json.loads(data).get("timeStamp", 0)
            self.got.append((self.i, int(head[4:]), t, now_ns(), stamp))
        return raw


async def _lean_clients(urls: list[str], duration: float, make, request) -> dict:
    """One ``make(i, request(path, netloc), got, opened)`` connection per URL, each open (its
    ``opened`` set) before the next; then received for ``duration``."""
    from urllib.parse import urlsplit

    loop = asyncio.get_running_loop()
    got: list[tuple] = []
    transports = []
    for i, url in enumerate(urls):
        u = urlsplit(url)
        opened = loop.create_future()
        tr, _ = await loop.create_connection(
            lambda i=i, r=request(u.path, u.netloc), f=opened: make(i, r, got, f), u.hostname, u.port)
        await asyncio.wait_for(opened, 30)
        transports.append(tr)
    await _measure([], duration)
    for tr in transports:
        tr.close()
    return {"events": got}


async def _sse_lean_client(urls: list[str], duration: float) -> dict:
    return await _lean_clients(urls, duration, _LeanSSE, lambda path, host: (
        f"GET {path} HTTP/1.1\r\nHost: {host}\r\nAccept: text/event-stream\r\n\r\n").encode())


async def _drain_client(urls: list[str], duration: float) -> dict:
    """A subscriber that reads every byte of each stream and keeps none (one GET per URL, raw sockets):
    the hub's cost of a subscriber with the least of the client's own."""
    from urllib.parse import urlsplit

    received = [0]

    async def one(url: str) -> None:
        u = urlsplit(url)
        reader, writer = await asyncio.open_connection(u.hostname, u.port)
        writer.write(f"GET {u.path} HTTP/1.1\r\nHost: {u.netloc}\r\n"
                     "Accept: text/event-stream\r\n\r\n".encode())
        try:
            while chunk := await reader.read(1 << 16):
                received[0] += len(chunk)
        finally:
            writer.close()

    tasks = [asyncio.create_task(one(u)) for u in urls]
    await asyncio.sleep(0.5)  # connected
    await _measure(tasks, duration)
    return {"bytes": received[0]}


async def _wotpy_client(urls: list[str], duration: float, event: str) -> dict:
    from wotpy.protocols.ws.messages import WebsocketMessageEmittedItem
    from wotpy.wot.servient import Servient
    from wotpy.wot.wot import WoT

    got: list[tuple] = []
    wot = WoT(servient=Servient(catalogue_port=None))
    subs = []
    for i, url in enumerate(urls):
        thing = await wot.consume_from_url(url)
        subs.append(thing.events[event].subscribe(
            on_next=lambda ev, i=i: got.append((i, ev.data["timeStamp"], now_ns()))))
    await asyncio.sleep(0.5)  # each wotpy subscription opens its own connection
    _ready()
    await asyncio.sleep(duration)
    for s in subs:
        s.dispose()
    # what wotpy's client spends decoding one message (parse + jsonschema), for the stage table
    sample = json.dumps({"subscription": "x" * 36, "name": event, "data": payload(20, 1)})
    t = now_ns()
    for _ in range(200):
        WebsocketMessageEmittedItem.from_raw(sample)
    return {"events": got, "decode_ns": (now_ns() - t) / 200}


async def _ws_raw_client(url: str, event: str, duration: float) -> dict:
    """A minimal JSON-RPC subscriber (no wotpy client cost): counts events and checks their order."""
    from tornado.websocket import websocket_connect

    ws = await websocket_connect(url, max_message_size=1 << 26)
    await ws.write_message(json.dumps({"jsonrpc": "2.0", "method": "on_event", "params": {"name": event},
                                       "id": "sub"}))
    await ws.read_message()
    _ready()
    n = 0
    first = last = None
    out_of_order = 0
    end = time.monotonic() + duration
    while True:
        timeout = end - time.monotonic()
        if timeout <= 0:
            break
        try:
            msg = await asyncio.wait_for(ws.read_message(), timeout)
        except TimeoutError:
            break
        if msg is None:
            break
        doc = json.loads(msg)
        if "error" in doc:  # e.g. cut off for falling behind: count it as loss
            out_of_order += 1
            break
        ts = doc["data"]["timeStamp"]
        if last is not None and ts != last + 1:
            out_of_order += 1
        first = ts if first is None else first
        last = ts
        n += 1
    ws.close()
    return {"n": n, "first": first, "last": last, "out_of_order": out_of_order}


def _masked_text_frame(text: str) -> bytes:
    """A client's text frame (RFC 6455 section 5.2: FIN, opcode 1, masked; < 64 KiB)."""
    payload = text.encode()
    key = os.urandom(4)
    head = bytes([0x81, 0x80 | len(payload)]) if len(payload) < 126 else \
        bytes([0x81, 0x80 | 126]) + len(payload).to_bytes(2, "big")
    return head + key + bytes(b ^ key[k % 4] for k, b in enumerate(payload))


class _LeanWS(_Lean):
    """One JSON-RPC event subscription over a WebSocket, the server's (unmasked) frames parsed in
    place: tornado's client reads each message through several awaits and a task switch, ~46 % of
    a core at 32 devices on this machine. It still reads every byte and decodes every message as
    JSON. ``opened``: set by the answer to the subscribe request."""

    status = b"HTTP/1.1 101"
    subscribe = b""  # the request's masked frame (``_ws_latency_client``)

    def head(self) -> None:
        assert self.transport is not None
        self.transport.write(self.subscribe)

    def body(self, raw: bytes, t: int) -> bytes:
        pos = 0
        while len(raw) - pos >= 2:  # frames: FIN|opcode, length (7, 16 or 64 bits), payload
            opcode, n, at = raw[pos] & 0x0F, raw[pos + 1] & 0x7F, pos + 2
            if n == 126:
                if len(raw) - at < 2:
                    break
                n, at = int.from_bytes(raw[at:at + 2], "big"), at + 2
            elif n == 127:
                if len(raw) - at < 8:
                    break
                n, at = int.from_bytes(raw[at:at + 8], "big"), at + 8
            if len(raw) - at < n:
                break
            pos = at + n
            if opcode != 1:  # the hub sends only whole text frames to a subscriber
                continue
            doc = json.loads(raw[at:pos])
            if not self.opened.done():  # the subscribe request's answer
                self.opened.set_result(None)
                continue
            data = doc.get("data")
            if data is not None:  # (None: a subscription error, cut off for falling behind)
                self.got.append((self.i, data["timeStamp"], t, now_ns()))
        return raw[pos:]


async def _ws_latency_client(urls: list[str], event: str, duration: float) -> dict:
    """Raw JSON-RPC subscriptions to several Things: arrival time of each event (no wotpy client)."""
    import base64

    class Subscription(_LeanWS):
        subscribe = _masked_text_frame(json.dumps({"jsonrpc": "2.0", "method": "on_event",
                                                   "params": {"name": event}, "id": "sub"}))

    return await _lean_clients(urls, duration, Subscription, lambda path, host: (
        f"GET {path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {base64.b64encode(os.urandom(16)).decode()}\r\nSec-WebSocket-Version: 13\r\n\r\n"
    ).encode())


def _td_get_client(urls: list[str], n: int) -> dict:
    import httpx

    rnd = random.Random(1)
    lat = []
    with httpx.Client(timeout=120) as c:
        c.get(urls[0])
        _ready()
        for _ in range(n):
            url = rnd.choice(urls)
            t = now_ns()
            r = c.get(url)
            r.json()
            lat.append(now_ns() - t)
            assert r.status_code == 200
    return {"lat_ns": lat}


class Client:
    """A client process: started, waited for ``ready``, then its JSON result."""

    def __init__(self, spec: dict) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_BENCHMARKS), env.get("PYTHONPATH")) if p)
        self.proc = subprocess.Popen([sys.executable, "-m", f"{__package__}.clients", json.dumps(spec)],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)

    async def ready(self, timeout: float = 60) -> None:
        line = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), timeout)
        if line.strip() != "ready":
            raise RuntimeError(f"client failed: {line}{self.proc.stderr.read()}")

    async def result(self, timeout: float = 120) -> dict:
        out = await asyncio.wait_for(asyncio.to_thread(self.proc.stdout.readline), timeout)
        self.proc.wait(30)
        if not out:
            raise RuntimeError(f"client failed: {self.proc.stderr.read()}")
        return json.loads(out)


if __name__ == "__main__":
    client_main(json.loads(sys.argv[1]))
