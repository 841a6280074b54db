"""Issue 48 item 4 (the subscribers' part), against a real hub: a client that subscribes and never
reads is cut off at ``max_pending`` and disconnected, on SSE, WebSocket JSON-RPC and the binary HTTP
stream alike. Before, the subscription was closed but the connection stayed: its task waited on the
backed-up socket for ever, with a batch and the socket's buffer pinned (~330 MB at the default for a
200 Hz skin in the issue's run). Measured: what each non-reader gets when it finally reads (its end),
the hub's memory, and a bystander's events per second."""

from __future__ import annotations

import base64
import json
import os
import socket
import time

import pytest

from wott_hub.config import HubConfig
from wott_hub.examples import example_device
from wott_hub.network import DiscoveryConfig
from wott_hub.plugins import DeviceConfig

from . import surroundings as S

EVENT = "skinDeformedDetection"
MAX_PENDING = 300


def loaded_skin(device_id: str) -> DeviceConfig:
    """A flat skin pressed most of the time at 120 Hz: ~210 records/s, ~5 KB each (what fills the
    non-readers' sockets, then their queues, in seconds)."""
    mesh = example_device("flat").mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[len(mesh.free_indices) // 2]]]
    return DeviceConfig(device_id, "scene", {"shape": "flat", "loop": True, "rate_hz": 120.0, "step": [
        {"kind": "press", "at": at, "start_s": 0.1, "duration_s": 2.0, "depth_mm": 1.0, "radius_mm": 8.0}]})


@pytest.fixture(scope="module")
def hub(hub_thread, press_scene):
    cfg = HubConfig(http_port=0, ws_port=0, history=False, discovery=DiscoveryConfig.off(),
                    max_pending=MAX_PENDING, devices=(press_scene("pad"), loaded_skin("load")))
    ht = hub_thread(cfg).start()
    yield ht
    ht.stop()


def _connect(url: str) -> tuple[socket.socket, str, str]:
    host, _, rest = url.split("//", 1)[1].partition(":")
    port, _, path = rest.partition("/")
    s = socket.create_connection((host, int(port)), timeout=10)
    return s, host, "/" + path


def never_reads_http(url: str, accept: str = "*/*") -> socket.socket:
    s, host, path = _connect(url)
    s.sendall(f"GET {path} HTTP/1.1\r\nHost: {host}\r\nAccept: {accept}\r\n\r\n".encode())
    return s


def never_reads_ws(url: str, event: str) -> socket.socket:
    """A WebSocket handshake and one subscription (wotpy's JSON-RPC), by hand: then nothing is read."""
    s, host, path = _connect(url)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall(f"GET {path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
              f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += s.recv(1)
    assert b" 101 " in head.split(b"\r\n", 1)[0], head
    payload = json.dumps({"jsonrpc": "2.0", "method": "on_event", "params": {"name": event},
                          "id": 1}).encode()
    mask = os.urandom(4)
    assert len(payload) < 126
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    s.sendall(bytes([0x81, 0x80 | len(payload)]) + mask + masked)
    return s


def ended(s: socket.socket, within: float) -> tuple[bool, int]:
    """Read everything the hub sent: did the connection end (EOF or reset) within ``within`` s?"""
    s.settimeout(1.0)
    got, deadline = 0, time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            data = s.recv(1 << 20)
        except TimeoutError:
            continue
        except OSError:  # reset: ended too
            return True, got
        if not data:
            return True, got
        got += len(data)
    return False, got


def test_subscribers_that_never_read_are_disconnected_at_max_pending(hub, eventually):
    plane = hub.hub._plane
    meter = S.GapMeter(f"{hub.url}/wot/pad/events/{EVENT}").start()
    ws_url = hub.hub.ws_url
    r0 = time.monotonic()
    time.sleep(3.0)
    t0 = time.monotonic()
    rest_rate = meter.count(r0) / (t0 - r0)
    rest = S.rss_mb()
    base = f"{hub.url}/wot/load/events"
    clients = {
        "sse": [never_reads_http(base, "text/event-stream") for _ in range(3)],
        "binary": [never_reads_http(f"{base}/skinDisplacement/binary") for _ in range(3)],
        "ws": [never_reads_ws(f"{ws_url}/load", "skinDisplacement") for _ in range(3)],
    }
    try:
        before = plane.overflow_disconnects
        eventually(lambda: plane.overflow_disconnects - before >= 9, 60, "all nine non-readers cut off")
        time.sleep(1.0)
        t1 = time.monotonic()
        grown = S.rss_mb() - rest
        outcome = {kind: [ended(s, 10) for s in socks] for kind, socks in clients.items()}
    finally:
        for socks in clients.values():
            for s in socks:
                s.close()
        meter.stop()
    under = meter.count(t0) / (t1 - t0)
    print(f"non-readers: RSS +{grown:.0f} MB, bystander {rest_rate:.1f} -> {under:.1f}/s, {outcome}")
    for kind, results in outcome.items():
        assert all(e for e, _ in results), f"{kind}: a non-reader still connected after its cut: {results}"
    assert grown < 150, f"the non-readers grew the hub by {grown:.0f} MB"
    assert under > 0.5 * rest_rate, f"the bystander's rate fell from {rest_rate:.1f} to {under:.1f}/s"
